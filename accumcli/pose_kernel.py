"""The tracker's Gauss-Newton normal equations over both images, compiled (numba).

Why compiled: one iteration projects the samples into both images, picks each sample's nearest
edge candidate along its normal, and sums the Tukey-weighted Jacobian products; in numpy that was
some forty small array operations per iteration, about a third of the tracking time, for arithmetic
that is one pass over the samples. This is the same arithmetic as ``track._residuals`` and
``track._jacobian`` (which verification still uses), summed in one loop.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel


@kernel
def normal_equations(P, pivot, uv0, normal, candidates, expected, fx, fy, cx, cy, baseline, tukey):  # pragma: no cover
    """(H (6, 6), g (6,), found, sum w r^2, sum w) of one Gauss-Newton step at the camera-frame
    points ``P`` (S, 3) for an increment (rotation vector about ``pivot`` (3,), translation), both in
    the camera frame. Per image side (0 left, 1 right): ``uv0`` (2, S, 2) px where the samples were
    measured, ``normal`` (2, S, 2) their unit normals, ``candidates`` (2, S, C) px along the normal
    to each edge found (NaN: none). A sample's residual is the signed distance from its current
    projection to its nearest candidate (the first of equals); its weight is Tukey's biweight of
    ``tukey`` px times ``expected`` (S,). ``found`` counts the residuals over both images."""
    H = np.zeros((6, 6))
    g = np.zeros(6)
    J = np.empty(6)
    found, swr2, sw = 0, 0.0, 0.0
    for side in range(2):
        for s in range(P.shape[0]):
            X, Y, Z = P[s, 0] - baseline * side, P[s, 1], P[s, 2]
            u, v = fx * X / Z + cx, fy * Y / Z + cy
            nx, ny = normal[side, s, 0], normal[side, s, 1]
            moved = (u - uv0[side, s, 0]) * nx + (v - uv0[side, s, 1]) * ny
            r, best = 0.0, np.inf
            for c in range(candidates.shape[2]):
                gap = moved - candidates[side, s, c]
                if abs(gap) < best:
                    best, r = abs(gap), gap
            if best == np.inf:
                continue
            found += 1
            nu, nv = nx / Z, ny / Z
            d0, d1 = fx * nu, fy * nv
            d2 = -(fx * nu * X + fy * nv * Y) / Z
            a0, a1, a2 = P[s, 0] - pivot[0], P[s, 1] - pivot[1], P[s, 2] - pivot[2]
            J[0], J[1], J[2] = a1 * d2 - a2 * d1, a2 * d0 - a0 * d2, a0 * d1 - a1 * d0
            J[3], J[4], J[5] = d0, d1, d2
            w = (1 - (r / tukey) ** 2) ** 2 * expected[s] if abs(r) < tukey else 0.0
            swr2 += w * r * r
            sw += w
            for i in range(6):
                g[i] += w * J[i] * r
                for j in range(6):
                    H[i, j] += w * J[i] * J[j]
    for i in range(6):
        H[i, i] += 1e-6
    return H, g, found, swr2, sw
