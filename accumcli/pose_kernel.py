"""The tracker's Gauss-Newton normal equations over both images, and the visibility, sampling,
projection and residuals around them, compiled (numba).

Why compiled: one iteration projects the samples into both images, picks each sample's nearest
edge candidate along its normal, and sums the Tukey-weighted Jacobian products; in numpy that was
some forty small array operations per iteration, about a third of the tracking time, for arithmetic
that is one pass over the samples. The others replace numpy forms of some thirty small array
operations per call each, run at every level and verification: with them ``make bench``'s tracking
went from 24.4 to 28.7-30.2 frames/s, the poses bit for bit the same (tests/test_pose_kernel.py
compares them with the numpy forms). ``gauss_newton_steps`` (a level's iterations, with the prior
of ``--motion tracked``'s repair too) and ``verification_sums`` (2026-12-07), with the edge search's
rewrite (``edge_search``), took it from 25.8 to 33.4 frames/s on a slower machine, the poses of the
tracking bench and of dev_steps_track within 1e-15 of the numpy forms' (with a prior 4e-14: the
rotation vector of its departure by the skew part's formula, not scipy's; the tests compare them:
tests/test_pose_kernel.py, tests/test_track.py).
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
            _jacobian_row(P, s, side, pivot, normal, fx, fy, baseline, J)
            w = _tukey(r, tukey) * expected[s]
            swr2 += w * r * r
            sw += w
            for i in range(6):
                g[i] += w * J[i] * r
                for j in range(6):
                    H[i, j] += w * J[i] * J[j]
    for i in range(6):
        H[i, i] += 1e-6
    return H, g, found, swr2, sw


@kernel
def in_view(centers, directions, lengths, R, t, camera, view_direction, view_spread_deg, cones, fx, fy, cx, cy,
            baseline, width, height, margin_px, min_depth_m, margin_deg):  # pragma: no cover
    """Per model segment (``centers``, unit ``directions`` (N, 3), ``lengths`` (N,), object frame) at the
    pose R (3, 3), t (3,) (T_camera_object; ``camera`` (3,) its centre in the object frame): whether
    both endpoints lie deeper than ``min_depth_m`` and ``margin_px`` inside both images and, with
    ``cones``, the direction to the camera lies within ``margin_deg`` of its cone of views
    (``view_direction`` (N, 3), ``view_spread_deg`` (N,)); and the degrees beyond the cone (N,).
    ``track._in_view`` in one pass: numpy took some thirty array operations per call, and the tracker
    calls it at every Gauss-Newton level and verification (a sixth of its time)."""
    n = len(centers)
    keep = np.zeros(n, np.bool_)
    beyond = np.zeros(n)
    for k in range(n):
        ok = True
        half = lengths[k] / 2
        for sign in (-1.0, 1.0):     # the endpoints as ``Segments.endpoints`` computes them
            p0 = centers[k, 0] + sign * (half * directions[k, 0])
            p1 = centers[k, 1] + sign * (half * directions[k, 1])
            p2 = centers[k, 2] + sign * (half * directions[k, 2])
            x = R[0, 0] * p0 + R[0, 1] * p1 + R[0, 2] * p2 + t[0]
            y = R[1, 0] * p0 + R[1, 1] * p1 + R[1, 2] * p2 + t[1]
            z = R[2, 0] * p0 + R[2, 1] * p1 + R[2, 2] * p2 + t[2]
            if not z > min_depth_m:
                ok = False
                break
            u, v = fx * x / z + cx, fy * y / z + cy
            ur = u - fx * baseline / z
            if not (margin_px <= v <= height - 1 - margin_px and margin_px <= u <= width - 1 - margin_px
                    and margin_px <= ur <= width - 1 - margin_px):
                ok = False
                break
        if cones:
            a0, a1, a2 = camera[0] - centers[k, 0], camera[1] - centers[k, 1], camera[2] - centers[k, 2]
            norm = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            a0, a1, a2 = a0 / norm, a1 / norm, a2 / norm
            cosine = a0 * view_direction[k, 0] + a1 * view_direction[k, 1] + a2 * view_direction[k, 2]
            beyond[k] = np.degrees(np.arccos(min(max(cosine, -1.0), 1.0))) - view_spread_deg[k]
            ok = ok and beyond[k] <= margin_deg
        keep[k] = ok
    return keep, beyond


@kernel
def sample_points(centers, directions, lengths, keep, per_segment):  # pragma: no cover
    """``per_segment`` points (S, 3) evenly along each kept segment (``keep`` (N,) bool; ``centers``,
    unit ``directions`` (N, 3), ``lengths`` (N,)), their directions (S, 3) and their segment (S,), an
    index among the kept ones: the samples the tracker fits and verifies with."""
    kept = np.flatnonzero(keep)
    m = len(kept) * per_segment
    points, dirs, owner = np.empty((m, 3)), np.empty((m, 3)), np.empty(m, np.int64)
    for i in range(len(kept)):
        k = kept[i]
        for j in range(per_segment):
            along = ((j + 0.5) / per_segment - 0.5) * lengths[k]
            row = i * per_segment + j
            for c in range(3):
                points[row, c] = centers[k, c] + along * directions[k, c]
                dirs[row, c] = directions[k, c]
            owner[row] = i
    return points, dirs, owner


@kernel
def projected_normals(points, dirs, fx, fy, cx, cy, baseline, step_m):  # pragma: no cover
    """Per image side (0 left, 1 right): the projections uv (2, S, 2) of the camera-frame ``points``
    (S, 3) and the unit normals (2, S, 2) of their projected directions (``dirs`` (S, 3), taken as
    the projection of the point ``step_m`` along them), rotated (-dv, du): ``track._measure``'s
    geometry, bit for bit, in one pass."""
    s = len(points)
    uv, normal = np.empty((2, s, 2)), np.empty((2, s, 2))
    for i in range(s):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        x2, y2, z2 = x + step_m * dirs[i, 0], y + step_m * dirs[i, 1], z + step_m * dirs[i, 2]
        u, v, d = fx * x / z + cx, fy * y / z + cy, fx * baseline / z
        u2, v2, d2 = fx * x2 / z2 + cx, fy * y2 / z2 + cy, fx * baseline / z2
        for side in range(2):
            a, b = (u, u2) if side == 0 else (u - d, u2 - d2)
            uv[side, i, 0], uv[side, i, 1] = a, v
            du, dv = b - a, v2 - v
            norm = max(np.sqrt(du * du + dv * dv), 1e-9)
            normal[side, i, 0], normal[side, i, 1] = -(dv / norm), du / norm
    return uv, normal


@kernel
def nearest_residuals(P, uv0, normal, candidates, fx, fy, cx, cy, baseline):  # pragma: no cover
    """Per image side (0 left, 1 right): the signed distance (2, S) from each camera-frame point's
    (``P`` (S, 3)) projection, along its ``normal`` (2, S, 2) since it was measured at ``uv0``
    (2, S, 2), to its nearest ``candidates`` (2, S, C) edge (the first of equals; NaN where it has
    none), in one pass."""
    s_count = P.shape[0]
    out = np.full((2, s_count), np.nan)
    for side in range(2):
        for s in range(s_count):
            z = P[s, 2]
            u, v = fx * P[s, 0] / z + cx, fy * P[s, 1] / z + cy
            if side == 1:
                u = u - fx * baseline / z
            moved = (u - uv0[side, s, 0]) * normal[side, s, 0] + (v - uv0[side, s, 1]) * normal[side, s, 1]
            best = np.inf
            for c in range(candidates.shape[2]):
                gap = moved - candidates[side, s, c]
                if abs(gap) < best:
                    best, out[side, s] = abs(gap), gap
    return out


@kernel
def gauss_newton_steps(points_obj, T, uv0, normal, candidates, expected, fx, fy, cx, cy, baseline, tukey,
                       iterations, converged_rad, converged_m, prior_inverse, prior_information):  # pragma: no cover
    """Up to ``iterations`` Gauss-Newton steps of ``normal_equations`` from the pose ``T`` (4, 4,
    T_camera_object) for the object-frame sample points ``points_obj`` (S, 3) measured as given
    (``uv0``, ``normal``, ``candidates``, ``expected``: ``normal_equations``'): each step rotates by
    its rotation vector about the points' mean and translates (``geometry.rotation_about_point``, the
    rotation by Rodrigues' formula), and the loop stops once a step turns less than
    ``converged_rad`` and moves less than ``converged_m``. Returns (the pose (4, 4), not yet
    orthonormalized; whether every step found 6 residuals or more: else the pose is that of the
    step before). With a prior (``prior_information`` (6,), its inverse variances per camera axis,
    rad^-2 and m^-2, all zero for none; ``prior_inverse`` (4, 4) the inverse of its centre pose), each
    step also weighs the pose's departure from it (rotation vector of ``T prior^-1`` and the pivot's
    move), scaled into pixels by the step's weighted residual variance (floor 0.1 px):
    ``track._gauss_newton``'s loop in one call; in Python each step cost a dozen small numpy
    operations, a sixth of the tracking time."""
    T = T.copy()
    s_count = points_obj.shape[0]
    P = np.empty((s_count, 3))
    for _ in range(iterations):
        pivot = np.zeros(3)
        for s in range(s_count):
            for r in range(3):
                P[s, r] = (T[r, 0] * points_obj[s, 0] + T[r, 1] * points_obj[s, 1] + T[r, 2] * points_obj[s, 2]
                           + T[r, 3])
                pivot[r] += P[s, r]
        pivot /= s_count
        H, g, found, swr2, sw = normal_equations(P, pivot, uv0, normal, candidates, expected, fx, fy, cx, cy,
                                                 baseline, tukey)
        if found < 6:
            return T, False
        if prior_information.any():
            sigma2 = max(swr2 / max(sw, 1e-9), 0.01)
            D = T @ prior_inverse                 # the pose's departure from the prior, camera frame
            departure = np.empty(6)
            departure[:3] = _rotation_vector(D)
            for i in range(3):
                departure[3 + i] = D[i, 0] * pivot[0] + D[i, 1] * pivot[1] + D[i, 2] * pivot[2] + D[i, 3] - pivot[i]
            for i in range(6):
                H[i, i] += sigma2 * prior_information[i]
                g[i] += sigma2 * prior_information[i] * departure[i]
        step = np.linalg.solve(H, -g)
        theta = np.sqrt(step[0] ** 2 + step[1] ** 2 + step[2] ** 2)
        R = np.eye(3)
        if theta > 1e-300:
            k = step[:3] / theta
            c, s_, c1 = np.cos(theta), np.sin(theta), 1.0 - np.cos(theta)
            R[0, 0], R[0, 1], R[0, 2] = c + c1 * k[0] * k[0], c1 * k[0] * k[1] - s_ * k[2], c1 * k[0] * k[2] + s_ * k[1]
            R[1, 0], R[1, 1], R[1, 2] = c1 * k[1] * k[0] + s_ * k[2], c + c1 * k[1] * k[1], c1 * k[1] * k[2] - s_ * k[0]
            R[2, 0], R[2, 1], R[2, 2] = c1 * k[2] * k[0] - s_ * k[1], c1 * k[2] * k[1] + s_ * k[0], c + c1 * k[2] * k[2]
        D = np.eye(4)
        D[:3, :3] = R
        D[:3, 3] = pivot + step[3:] - R @ pivot
        T = D @ T
        if theta < converged_rad and np.sqrt(step[3] ** 2 + step[4] ** 2 + step[5] ** 2) < converged_m:
            break
    return T, True


@kernel
def verification_sums(P, pivot, normal, residuals, owner, n_owner, tukey, fx, fy, baseline):  # pragma: no cover
    """The sums of ``track._verify``'s last Gauss-Newton step over the residuals found in both
    images (``residuals`` (2, S) px, NaN: none; ``P`` (S, 3) camera frame, ``pivot`` (3,),
    ``normal`` (2, S, 2), each sample's model segment ``owner`` (S,) < ``n_owner``): (H (6, 6) =
    sum w J J^T, sum w r^2, sum w, G (n_owner, 6) the per-segment sums of w r J), w Tukey's biweight
    of ``tukey`` px and J ``normal_equations``' row. In numpy these were a Jacobian per image, a
    stacked copy and six bincounts per verification."""
    H = np.zeros((6, 6))
    G = np.zeros((n_owner, 6))
    J = np.empty(6)
    swr2, sw = 0.0, 0.0
    for side in range(2):
        for s in range(P.shape[0]):
            r = residuals[side, s]
            if np.isnan(r):
                continue
            w = _tukey(r, tukey)
            if w == 0.0:
                continue
            _jacobian_row(P, s, side, pivot, normal, fx, fy, baseline, J)
            swr2 += w * r * r
            sw += w
            for i in range(6):
                G[owner[s], i] += w * r * J[i]
                for j in range(6):
                    H[i, j] += w * J[i] * J[j]
    return H, swr2, sw, G


@kernel
def _jacobian_row(P, s, side, pivot, normal, fx, fy, baseline, J):  # pragma: no cover
    """Into ``J`` (6,): the derivative of sample ``s``'s residual along its ``normal`` in image ``side``
    (0 left, 1 right) for an increment (rotation vector about ``pivot``, translation), camera frame."""
    X, Y, Z = P[s, 0] - baseline * side, P[s, 1], P[s, 2]
    nu, nv = normal[side, s, 0] / Z, normal[side, s, 1] / Z
    d0, d1 = fx * nu, fy * nv
    d2 = -(fx * nu * X + fy * nv * Y) / Z
    a0, a1, a2 = P[s, 0] - pivot[0], P[s, 1] - pivot[1], P[s, 2] - pivot[2]
    J[0], J[1], J[2] = a1 * d2 - a2 * d1, a2 * d0 - a0 * d2, a0 * d1 - a1 * d0
    J[3], J[4], J[5] = d0, d1, d2


@kernel
def _tukey(r, tukey):  # pragma: no cover
    """Tukey's biweight of a residual ``r`` px for the width ``tukey`` px."""
    return (1 - (r / tukey) ** 2) ** 2 if abs(r) < tukey else 0.0


@kernel
def _rotation_vector(T):  # pragma: no cover
    """(3,) the rotation vector (rad) of ``T``'s rotation, from its skew part and trace (an angle well
    short of a half turn: a Gauss-Newton step's departure from its prior)."""
    v = np.array([T[2, 1] - T[1, 2], T[0, 2] - T[2, 0], T[1, 0] - T[0, 1]])     # 2 sin(angle) axis
    sine = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2) / 2
    angle = np.arctan2(sine, (T[0, 0] + T[1, 1] + T[2, 2] - 1) / 2)
    return v / 2 if sine < 1e-12 else v * (angle / (2 * sine))


@kernel
def nearest_rotation(R):  # pragma: no cover
    """(3, 3) the rotation nearest to ``R`` (3, 3) (SVD, the sign of the last singular vector flipped
    where U V^T would reflect): ``geometry.orthonormalized``'s, bit for bit (the same LAPACK routine),
    without numpy's per-call overhead, which was a twentieth of the tracking time."""
    U, _, Vt = np.linalg.svd(R)
    M = U @ Vt
    if np.linalg.det(M) < 0:
        U[:, 2] = -U[:, 2]
        M = U @ Vt
    return M


@kernel
def condition_number(H):  # pragma: no cover
    """The 2-norm condition number of a square matrix (``np.linalg.cond``'s, by the same SVD)."""
    return np.linalg.cond(H)
