"""The tracker's edge search along projected normals, compiled (numba).

Why compiled: per point and image the search reads the gradient at up to 81 positions along the
normal, keeps the local maxima of the gradient across the segment and ranks them; in numpy that
was an (S, K) bilinear remap and a dozen (S, K) arrays per search, a third of the tracking time.
Here each point is one loop over its K positions. The gradient is read by exact bilinear
interpolation (OpenCV's remap rounds the position to 1/32 px), with the border replicated.
"""

from __future__ import annotations

import numpy as np
from .jit import kernel


@kernel
def _bilinear(gxy, x, y):  # pragma: no cover
    """(gx, gy) of the (H, W, 2) image at (x, y) px, border replicated."""
    h, w = gxy.shape[0], gxy.shape[1]
    if not (np.isfinite(x) and np.isfinite(y)):
        return 0.0, 0.0
    x, y = min(max(x, -1.0), float(w)), min(max(y, -1.0), float(h))   # beyond: the border (no int overflow)
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    i0, j0 = int(x0), int(y0)
    i1, j1 = min(max(i0 + 1, 0), w - 1), min(max(j0 + 1, 0), h - 1)
    i0, j0 = min(max(i0, 0), w - 1), min(max(j0, 0), h - 1)
    out0 = ((1 - fx) * gxy[j0, i0, 0] + fx * gxy[j0, i1, 0]) * (1 - fy) + \
        ((1 - fx) * gxy[j1, i0, 0] + fx * gxy[j1, i1, 0]) * fy
    out1 = ((1 - fx) * gxy[j0, i0, 1] + fx * gxy[j0, i1, 1]) * (1 - fy) + \
        ((1 - fx) * gxy[j1, i0, 1] + fx * gxy[j1, i1, 1]) * fy
    return out0, out1


@kernel
def edge_candidates(gxy, uv, normal, half_width, min_gradient, min_orientation_cos, n_candidates):  # pragma: no cover
    """(S, C) offsets, px along each point's unit ``normal`` (S, 2) from ``uv`` (S, 2) px, of the
    ``n_candidates`` strongest local maxima of the gradient across the normal within
    ``half_width`` px (integer steps, each to sub-pixel precision by a parabola through its
    neighbours, within half a step), strongest first; NaN where fewer are found. A position counts
    when its gradient across is at least ``min_gradient`` and at least ``min_orientation_cos`` of
    its magnitude (the gradient agrees with the normal, either polarity)."""
    s_count = uv.shape[0]
    k_count = 2 * half_width + 1
    out = np.full((s_count, n_candidates), np.nan)
    along = np.empty(k_count)
    good = np.empty(k_count, np.bool_)
    taken = np.empty(n_candidates, np.int64)
    for s in range(s_count):
        nx, ny = normal[s, 0], normal[s, 1]
        for k in range(k_count):
            step = k - half_width
            gx, gy = _bilinear(gxy, uv[s, 0] + step * nx, uv[s, 1] + step * ny)
            a = abs(gx * nx + gy * ny)
            along[k] = a
            good[k] = a >= min_gradient and a >= min_orientation_cos * np.sqrt(gx * gx + gy * gy)
        for c in range(n_candidates):      # the strongest peak not taken yet (ties: the lower offset first)
            best, best_k = 0.0, -1
            for k in range(1, k_count - 1):
                if good[k] and along[k] >= along[k - 1] and along[k] > along[k + 1] and along[k] > best:
                    free = True
                    for q in range(c):
                        free = free and taken[q] != k
                    if free:
                        best, best_k = along[k], k
            if best_k < 0:
                break
            taken[c] = best_k
            m0, m1, m2 = along[best_k - 1], along[best_k], along[best_k + 1]
            curvature = m0 - 2 * m1 + m2
            offset = 0.5 * (m0 - m2) / curvature if curvature < 0 else 0.0
            offset = min(max(offset, -0.5), 0.5)
            out[s, c] = best_k - half_width + offset
    return out
