"""The metric's row-by-row pair costs (``metric.pair_costs``), compiled (numba).

Why compiled: accumulation evaluates the metric on every candidate pair twice a frame (the
correspondences, and the static test), and numpy spent it in some sixty small array operations
per call (the elliptical distance both ways, the 2x2 covariance algebra of the direction gate by
covariance), a sixth of the accumulation's time. Here each pair is one pass of the same formulas
(``metric``'s module docstring), indexing the two sides' rows itself.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel


@kernel
def _f_p(px, py, pz, ux, uy, uz, length, qx, qy, qz, s_p):  # pragma: no cover
    """``metric.f_p`` of one pair."""
    rx, ry, rz = qx - px, qy - py, qz - pz
    along = rx * ux + ry * uy + rz * uz
    across_sq = max(rx * rx + ry * ry + rz * rz - along ** 2, 0.0)
    shrink = 1.0 + length / (2.0 * s_p)
    return np.sqrt((along / shrink) ** 2 + across_sq)


@kernel
def _gate(k, sigma_a, sigma_b, floor, max_scale):  # pragma: no cover
    """``metric.pair_thresholds`` of one pair."""
    return min(max(k * np.sqrt(sigma_a ** 2 + sigma_b ** 2), floor), max_scale * floor)


@kernel
def _inverse_2x2(m00, m01, m10, m11):  # pragma: no cover
    det = m00 * m11 - m01 * m10
    return m11 / det, -m01 / det, -m10 / det, m00 / det


@kernel
def _across_2x2(basis, m):  # pragma: no cover
    """(2, 2) basis^T m basis of a (3, 3) ``m`` in the (3, 2) ``basis``, summed as numpy's einsum."""
    out = np.zeros((2, 2))
    for a in range(2):
        for b in range(2):
            for i in range(3):
                for j in range(3):
                    out[a, b] += basis[i, a] * m[i, j] * basis[j, b]
    return out


@kernel
def _direction_distance(ua, sigma_a, info, has_info, ub, sigma_b, normal, plane_sigma, floor):  # pragma: no cover
    """``metric.direction_distance`` of one pair (``ua``, ``ub``, ``normal`` (3,); ``info`` (3, 3))."""
    has_plane = normal[0] != 0 or normal[1] != 0 or normal[2] != 0
    cov_b = np.empty((3, 3))
    if has_plane:
        w0 = normal[1] * ub[2] - normal[2] * ub[1]
        w1 = normal[2] * ub[0] - normal[0] * ub[2]
        w2 = normal[0] * ub[1] - normal[1] * ub[0]
        norm = max(np.sqrt(w0 * w0 + w1 * w1 + w2 * w2), 1e-12)
        w = (w0 / norm, w1 / norm, w2 / norm)
        for i in range(3):
            for j in range(3):
                cov_b[i, j] = sigma_b ** 2 * (w[i] * w[j]) + plane_sigma ** 2 * (normal[i] * normal[j])
    else:
        for i in range(3):
            for j in range(3):
                cov_b[i, j] = sigma_b ** 2 * ((1.0 if i == j else 0.0) - ub[i] * ub[j])
    h0, h1 = (1.0, 0.0) if abs(ua[0]) < 0.9 else (0.0, 1.0)
    c0 = ua[1] * 0.0 - ua[2] * h1
    c1 = ua[2] * h0 - ua[0] * 0.0
    c2 = ua[0] * h1 - ua[1] * h0
    norm = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    e1 = (c0 / norm, c1 / norm, c2 / norm)
    e2 = (ua[1] * e1[2] - ua[2] * e1[1], ua[2] * e1[0] - ua[0] * e1[2], ua[0] * e1[1] - ua[1] * e1[0])
    basis = np.empty((3, 2))
    for i in range(3):
        basis[i, 0], basis[i, 1] = e1[i], e2[i]
    if has_info:
        along = 0.0
        for i in range(3):
            for j in range(3):
                along += ua[i] * info[i, j] * ua[j]
        m = _across_2x2(basis, info)
        for a in range(2):
            for b in range(2):
                m[a, b] = m[a, b] - along * (1.0 if a == b else 0.0) + (2 / np.pi) ** 2 * (1.0 if a == b else 0.0)
        c00, c01, c10, c11 = _inverse_2x2(m[0, 0], m[0, 1], m[1, 0], m[1, 1])
    else:
        c00, c01, c10, c11 = sigma_a ** 2, 0.0, 0.0, sigma_a ** 2
    p = _across_2x2(basis, cov_b)
    c00, c01 = c00 + p[0, 0] + floor ** 2, c01 + p[0, 1]
    c10, c11 = c10 + p[1, 0], c11 + p[1, 1] + floor ** 2
    sign = 1.0 if ua[0] * ub[0] + ua[1] * ub[1] + ua[2] * ub[2] >= 0 else -1.0
    o0 = basis[0, 0] * (ub[0] * sign) + basis[1, 0] * (ub[1] * sign) + basis[2, 0] * (ub[2] * sign)
    o1 = basis[0, 1] * (ub[0] * sign) + basis[1, 1] * (ub[1] * sign) + basis[2, 1] * (ub[2] * sign)
    i00, i01, i10, i11 = _inverse_2x2(c00, c01, c10, c11)
    return np.sqrt(o0 * i00 * o0 + o0 * i01 * o1 + o1 * i10 * o0 + o1 * i11 * o1)


@kernel
def pair_costs_at(i, j, centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b, s_p0, s_o_deg, k, max_scale,
                  max_scale_direction, max_angle_scale, sigma_pos_a, sigma_dir_a, sigma_pos_b, sigma_dir_b, gated,
                  normal_b, plane_sigma_b, by_covariance, info_a, has_info):  # pragma: no cover
    """(ok (K,) bool, cost (K,), widening (K,)) of the pairs (a[i[k]], b[j[k]]): ``metric.pair_costs``.
    ``gated``: both sides' sigmas given (``sigma_*`` (N,) / (M,)); ``by_covariance``: b's view planes
    (``normal_b`` (M, 3), ``plane_sigma_b`` (M,)) and, with ``has_info``, a's direction information
    ``info_a`` (N, 3, 3) 1/rad^2."""
    n = len(i)
    ok = np.zeros(n, np.bool_)
    cost = np.full(n, np.inf)
    widening = np.ones(n)
    nominal = np.radians(s_o_deg)
    for q in range(n):
        a, b = i[q], j[q]
        cosine = abs(dirs_a[a, 0] * dirs_b[b, 0] + dirs_a[a, 1] * dirs_b[b, 1] + dirs_a[a, 2] * dirs_b[b, 2])
        angle = np.arccos(min(max(cosine, 0.0), 1.0))
        s_p, s_o = s_p0, nominal
        if gated:
            s_p = _gate(k, sigma_pos_a[a], sigma_pos_b[b], s_p0, max_scale)
            if not by_covariance:
                s_o = _gate(k, sigma_dir_a[a], sigma_dir_b[b], nominal, max_scale_direction)
        dist = min(_f_p(centers_a[a, 0], centers_a[a, 1], centers_a[a, 2], dirs_a[a, 0], dirs_a[a, 1], dirs_a[a, 2],
                        lengths_a[a], centers_b[b, 0], centers_b[b, 1], centers_b[b, 2], s_p),
                   _f_p(centers_b[b, 0], centers_b[b, 1], centers_b[b, 2], dirs_b[b, 0], dirs_b[b, 1], dirs_b[b, 2],
                        lengths_b[b], centers_a[a, 0], centers_a[a, 1], centers_a[a, 2], s_p))
        widening[q] = s_p / s_p0 * s_o / nominal
        if by_covariance and gated:
            if not (dist <= s_p and angle <= max_angle_scale * nominal):
                continue
            distance = _direction_distance(dirs_a[a], sigma_dir_a[a], info_a[a if has_info else 0], has_info,
                                           dirs_b[b], sigma_dir_b[b], normal_b[b], plane_sigma_b[b], nominal / k)
            angle_cost = (distance / k) ** 2
        else:
            angle_cost = (angle / s_o) ** 2
        if angle_cost <= 1.0 and dist <= s_p:
            ok[q] = True
            cost[q] = (dist / s_p) ** 2 + angle_cost
    return ok, cost, widening
