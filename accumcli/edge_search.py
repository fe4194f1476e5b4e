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
    its magnitude (the gradient agrees with the normal, either polarity).

    A point whose whole search lies inside the image reads without ``_bilinear``'s guards (the
    same arithmetic: the guards change nothing there), and the maxima are listed once, then ranked:
    the same bits in two thirds of the time of guarding every read and scanning every position per
    candidate (400 calls recorded from the tracking bench, 0.40 -> 0.27 s)."""
    h, w = gxy.shape[0], gxy.shape[1]
    s_count = uv.shape[0]
    k_count = 2 * half_width + 1
    out = np.full((s_count, n_candidates), np.nan)
    along = np.empty(k_count)
    good = np.empty(k_count, np.bool_)
    peaks = np.empty(k_count, np.int64)
    for s in range(s_count):
        nx, ny = normal[s, 0], normal[s, 1]
        x0, y0 = uv[s, 0], uv[s, 1]
        xa, xb = x0 - half_width * nx, x0 + half_width * nx
        ya, yb = y0 - half_width * ny, y0 + half_width * ny
        inside = (np.isfinite(xa) and np.isfinite(xb) and np.isfinite(ya) and np.isfinite(yb)
                  and min(xa, xb) >= 0.0 and max(xa, xb) < w - 1.0 and min(ya, yb) >= 0.0 and max(ya, yb) < h - 1.0)
        n_peaks = 0
        for k in range(k_count):
            step = k - half_width
            x, y = x0 + step * nx, y0 + step * ny
            if inside and 0.0 <= x < w - 1.0 and 0.0 <= y < h - 1.0:
                i0, j0 = int(x), int(y)
                fx, fy = x - i0, y - j0
                gx = ((1 - fx) * gxy[j0, i0, 0] + fx * gxy[j0, i0 + 1, 0]) * (1 - fy) + \
                    ((1 - fx) * gxy[j0 + 1, i0, 0] + fx * gxy[j0 + 1, i0 + 1, 0]) * fy
                gy = ((1 - fx) * gxy[j0, i0, 1] + fx * gxy[j0, i0 + 1, 1]) * (1 - fy) + \
                    ((1 - fx) * gxy[j0 + 1, i0, 1] + fx * gxy[j0 + 1, i0 + 1, 1]) * fy
            else:
                gx, gy = _bilinear(gxy, x, y)
            a = abs(gx * nx + gy * ny)
            along[k] = a
            good[k] = a >= min_gradient and a >= min_orientation_cos * np.sqrt(gx * gx + gy * gy)
        for k in range(1, k_count - 1):   # the local maxima of the gradient across, at positions that count
            m = along[k]
            if good[k] and m > 0.0 and m >= along[k - 1] and m > along[k + 1]:
                peaks[n_peaks] = k
                n_peaks += 1
        for c in range(n_candidates):      # the strongest peak not taken yet (ties: the lower offset first)
            best, best_p = 0.0, -1
            for q in range(n_peaks):
                k = peaks[q]
                if k >= 0 and along[k] > best:
                    best, best_p = along[k], q
            if best_p < 0:
                break
            best_k = peaks[best_p]
            peaks[best_p] = -1
            m0, m1, m2 = along[best_k - 1], along[best_k], along[best_k + 1]
            curvature = m0 - 2 * m1 + m2
            offset = 0.5 * (m0 - m2) / curvature if curvature < 0 else 0.0
            offset = min(max(offset, -0.5), 0.5)
            out[s, c] = best_k - half_width + offset
    return out
