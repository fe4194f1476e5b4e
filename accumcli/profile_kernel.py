"""The compiled cuts across local segments of ``lines2d.refine_on_gradient`` (numba, installed as
a wheel).

Why compiled: the numpy version built (N, P, H) coordinate arrays in five passes and took the
peak of every cut in five more (argmax, three gathers, the parabola), a fifth of the 2D detection
time. The arithmetic is the numpy version's, in the same order and the same precision (the
magnitude samples and their parabola in float32, positions in float64): the same bits.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel


@kernel
def cut_grid(centers, directions, normals, t, h):  # pragma: no cover
    """Cut positions of N segments (``centers``, ``directions``, ``normals`` (N, 2) px): the cut
    centres ``base`` (N, P, 2) at ``t`` (N, P) px along each segment, and the sample positions x, y
    (N, P, H) at offsets ``h`` (H,) px along the normal."""
    n, p = t.shape
    base = np.empty((n, p, 2))
    x = np.empty((n, p, len(h)))
    y = np.empty((n, p, len(h)))
    for i in range(n):
        for j in range(p):
            bx = centers[i, 0] + t[i, j] * directions[i, 0]
            by = centers[i, 1] + t[i, j] * directions[i, 1]
            base[i, j, 0], base[i, j, 1] = bx, by
            for k in range(len(h)):
                x[i, j, k] = bx + h[k] * normals[i, 0]
                y[i, j, k] = by + h[k] * normals[i, 1]
    return base, x, y


@kernel
def cut_peaks(m, base, normals, h, reach):  # pragma: no cover
    """The edge in every cut: (N, P, 2) px the parabola's vertex through the strongest magnitude
    sample of ``m`` (N, P, H) float32 (the first of equals, not at the cut's ends) and its two
    neighbours, within ``reach`` px of the cut centre ``base``; and (N, P) float64 the weight of
    each, that strongest sample (at least 1e-6)."""
    n, p, count = m.shape
    peaks = np.empty((n, p, 2))
    weights = np.empty((n, p))
    two, half, floor = np.float32(2.0), np.float32(0.5), np.float32(1e-6)
    for i in range(n):
        for j in range(p):
            best = 0
            for k in range(1, count):
                if m[i, j, k] > m[i, j, best]:
                    best = k
            best = min(max(best, 1), count - 2)
            m0, m1, m2 = m[i, j, best - 1], m[i, j, best], m[i, j, best + 1]
            curvature = m0 - two * m1 + m2
            vertex = half * (m0 - m2) / curvature if curvature < 0 else np.float32(0.0)
            offset = min(max(h[best] + np.float64(vertex), -reach), reach)
            peaks[i, j, 0] = base[i, j, 0] + offset * normals[i, 0]
            peaks[i, j, 1] = base[i, j, 1] + offset * normals[i, 1]
            weights[i, j] = np.float64(max(m1, floor))
    return peaks, weights
