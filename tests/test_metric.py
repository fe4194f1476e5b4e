"""The paper's metric: the properties it states, with lengths in units of s_p."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from accumcli.geometry import outer, unit
from accumcli.metric import MetricThresholds, candidate_pairs, d_o, d_p, f_p, pair_costs, pair_thresholds

S_P = 0.003
X, Y = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
ORIGIN = np.zeros(3)


def test_orientation_distance_is_undirected():
    assert d_o(X, -X) == 0.0
    assert np.isclose(np.degrees(d_o(X, np.array([np.cos(0.2), np.sin(0.2), 0.0]))), np.degrees(0.2))


def test_shift_along_the_segment_is_forgiven_up_to_half_its_length():
    length = 0.012
    limit = S_P + length / 2   # f_p <= s_p exactly up to this shift along u
    assert f_p(ORIGIN, X, length, 0.99 * limit * X, S_P) < S_P
    assert f_p(ORIGIN, X, length, 1.01 * limit * X, S_P) > S_P


def test_sideways_shift_is_not_forgiven():
    length = 0.012
    assert np.isclose(f_p(ORIGIN, X, length, 0.004 * Y, S_P), 0.004)
    assert d_p(ORIGIN, X, length, 0.004 * Y, X, length, S_P) > S_P


def test_f_p_is_asymmetric_and_d_p_takes_the_smaller():
    long_segment, short_segment = 0.030, 0.002
    p_short = 0.012 * X  # inside the long segment's ellipse, far outside the short one's
    forward = f_p(ORIGIN, X, long_segment, p_short, S_P)
    backward = f_p(p_short, X, short_segment, ORIGIN, S_P)
    assert forward < S_P < backward
    assert d_p(ORIGIN, X, long_segment, p_short, X, short_segment, S_P) == forward


def _random_segments(rng, n):
    """Two sets of n segments in a 5 cm cube, half of b parallel to a: centres, directions, lengths."""
    ca, cb = rng.uniform(0, 0.05, (n, 3)), rng.uniform(0, 0.05, (n, 3))
    da, db = (v / np.linalg.norm(v, axis=1, keepdims=True) for v in rng.normal(size=(2, n, 3)))
    db[: n // 2] = da[: n // 2]
    return ca, cb, da, db, rng.uniform(0.005, 0.02, n), rng.uniform(0.005, 0.02, n)


def test_candidate_pairs_match_brute_force():
    rng = np.random.default_rng(0)
    n = 300
    ca, cb, da, db, la, lb = _random_segments(rng, n)
    th = MetricThresholds(S_P, 10.0)
    i, j, cost = candidate_pairs(ca, da, la, cb, db, lb, th, neighbours=n)
    ia, jb = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    ok = (d_o(da[ia], db[jb]) <= np.radians(10)) & (d_p(ca[ia], da[ia], la[ia], cb[jb], db[jb], lb[jb], S_P) <= S_P)
    assert set(zip(i.tolist(), j.tolist())) == set(zip(*np.nonzero(ok)))
    assert len(i) > 0 and np.all((cost >= 0) & (cost <= 2))


def test_frame_accuracy_counts_near_correct_and_background():
    from accumcli.evaluate import EdgeSamples, frame_accuracy
    from accumcli.geometry import make_transform
    from accumcli.model_io import Truth
    from accumcli.segments import Segments

    truth = Truth("gripper", "camera_left", np.array([[0.0, -0.05, 0.0]]), np.array([[0.0, 0.05, 0.0]]), ["edge"],
                  [None], np.array([True]), np.zeros(0, np.int64), np.zeros((0, 4, 4)), {})   # 100 mm along y
    edges = EdgeSamples.of(truth)
    T = make_transform(np.eye(3), [0.0, 0.0, 0.5])
    centres = np.array([[0.0, 0.0, 0.5], [0.002, 0.03, 0.5], [0.010, 0.0, 0.5], [0.1, 0.0, 0.5]])  # camera frame
    on_edge = Segments("camera", centres, np.tile(Y, (4, 1)), np.full(4, 0.012), np.ones(4), np.ones(4, np.int64))
    figures = frame_accuracy(on_edge, T, edges)
    assert {k: figures[k] for k in ("segments", "near_object", "correct_near", "background")} == \
        {"segments": 4, "near_object": 3, "correct_near": 2, "background": 1}
    assert abs(figures["completeness"] - 0.24) < 1e-9        # two 12 mm pieces of a 100 mm edge


def _pair(offset, sigma_position, sigma_direction=np.radians(0.5), angle_deg=0.0, thresholds=MetricThresholds()):
    """candidate_pairs of one segment (12 mm along x) and one shifted by ``offset`` and turned in the xy plane,
    both with the given sigmas: (paired?, cost, widening)."""
    u = np.array([[np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg)), 0.0]])
    sig = (np.array([sigma_position]), np.array([sigma_direction]))
    i, j, cost, wide = candidate_pairs(np.zeros((1, 3)), X[None], np.array([0.012]), np.array([offset]), u,
                                       np.array([0.012]), thresholds, sigmas_a=sig, sigmas_b=sig, widening=True)
    return len(i) == 1, (cost[0] if len(i) else None), (wide[0] if len(i) else None)


def test_gate_follows_each_pair_s_own_uncertainty():
    # 5 mm deeper (z): a far, unsure pair (2 mm each: gate 2.5 * 2.83 = 7.1 mm) corresponds, 2.36 times the
    # paper's gate; a precise near pair (0.3 mm each: 1.1 mm, floored at s_p = 3 mm) does not
    paired, cost, wide = _pair([0.0, 0.0, 0.005], 0.002)
    assert paired and abs(cost - (0.005 / (2.5 * np.sqrt(8) * 1e-3)) ** 2) < 1e-9 and abs(wide - 2.357) < 0.001
    assert not _pair([0.0, 0.0, 0.005], 0.0003)[0]
    # the precise pair keeps the paper's gate exactly: 2.9 mm in, 3.1 mm out, widening 1
    assert _pair([0.0, 0.0, 0.0029], 0.0003)[2] == 1.0 and not _pair([0.0, 0.0, 0.0031], 0.0003)[0]
    # however unsure, at most max_scale (2.5) times s_p: 7.4 mm in, 7.6 mm out
    assert _pair([0.0, 0.0, 0.0074], 0.05)[0] and not _pair([0.0, 0.0, 0.0076], 0.05)[0]
    # direction: by default the paper's 7 degrees whatever the sigma; with max_scale_direction 2.5, 2.5 sigmas
    assert not _pair(ORIGIN, 0.001, np.radians(6.0), angle_deg=10.0)[0]
    assert _pair(ORIGIN, 0.001, np.radians(6.0), angle_deg=10.0,
                 thresholds=MetricThresholds(max_scale_direction=2.5))[0]


def test_gated_candidate_pairs_match_brute_force():
    rng = np.random.default_rng(2)
    n = 300
    ca, cb, da, db, la, lb = _random_segments(rng, n)
    sa = (rng.uniform(0.0002, 0.004, n), rng.uniform(0.001, 0.1, n))
    sb = (rng.uniform(0.0002, 0.004, n), rng.uniform(0.001, 0.1, n))
    th = MetricThresholds(S_P, 10.0, max_scale_direction=2.0)
    i, j, cost = candidate_pairs(ca, da, la, cb, db, lb, th, neighbours=n, sigmas_a=sa, sigmas_b=sb)
    ia, jb = (x.ravel() for x in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    ok, _, _ = pair_costs(ca[ia], da[ia], la[ia], cb[jb], db[jb], lb[jb], th, (sa[0][ia], sa[1][ia]),
                          (sb[0][jb], sb[1][jb]))
    assert set(zip(i.tolist(), j.tolist())) == set(zip(ia[ok].tolist(), jb[ok].tolist()))
    ungated = candidate_pairs(ca, da, la, cb, db, lb, th, neighbours=n)
    assert len(i) > len(ungated[0]) > 0 and np.all((cost >= 0) & (cost <= 2))


def test_direction_gate_by_covariance_forgives_a_tilt_where_a_side_is_unsure_only():
    """An observation on the x axis seen from a camera on the z axis: its view plane is the xz plane
    (normal y), its depth tilt is unsure (8 degrees). A model segment 12 degrees off it within that
    plane corresponds (no widening for it); the same 12 degrees out of the plane, or 16 within it
    (over the ceiling of 2 s_o), do not; without the plane the 12 degrees do not either. A model
    segment unsure in one sense (its own information, 10 degrees towards z) takes a precise
    observation tilted that way, not one tilted across."""
    sigma_model = (np.array([0.0005]), np.array([np.radians(1.0)]))
    sigma_observed = (np.array([0.0005]), np.array([np.radians(8.0)]))
    plane = (np.array([[0.0, 1.0, 0.0]]), np.array([np.radians(0.5)]))

    def paired(turn_axis, angle_deg, with_plane=True, sigmas_b=sigma_observed, plane_b=plane, info_a=None):
        u = Rotation.from_rotvec(np.radians(angle_deg) * np.asarray(turn_axis, float)).apply(X)
        i, j, cost, wide = candidate_pairs(np.zeros((1, 3)), u[None], np.array([0.012]), np.zeros((1, 3)), X[None],
                                           np.array([0.012]), MetricThresholds(), sigmas_a=sigma_model,
                                           sigmas_b=sigmas_b, widening=True,
                                           plane_b=plane_b if with_plane else None, info_a=info_a)
        return len(i) == 1 and wide[0] == 1.0

    assert paired([0, 1, 0], 12.0)                 # tilted in depth, within the view plane
    assert not paired([0, 0, 1], 12.0)             # turned out of the view plane
    assert paired([0, 0, 1], 6.0)                  # out of the plane within the paper's 7 degrees
    assert not paired([0, 1, 0], 16.0)             # within the plane, but over 2 x 7 degrees
    assert not paired([0, 1, 0], 12.0, with_plane=False)
    precise = sigma_model
    no_plane = (np.zeros((1, 3)), np.zeros(1))
    unsure_towards_z = (np.radians(10.0) ** -2 * np.outer([0, 0, 1.0], [0, 0, 1.0])
                        + np.radians(0.5) ** -2 * np.outer(Y, Y))[None]      # information, 1/rad^2
    assert paired([0, 1, 0], 12.0, sigmas_b=precise, plane_b=no_plane, info_a=unsure_towards_z)
    assert not paired([0, 0, 1], 12.0, sigmas_b=precise, plane_b=no_plane, info_a=unsure_towards_z)


# The numpy form of the pair costs, the reference of the compiled kernel (``metric_kernel``).
def _numpy_pair_costs(centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b, thresholds: MetricThresholds,
               sigmas_a=None, sigmas_b=None, plane_b=None, info_a=None):
    """``pair_costs`` as numpy computed it before the compiled kernel (2026-12-06)."""
    s_p, nominal = thresholds.s_p, np.radians(thresholds.s_o_deg)
    s_o = nominal         # the angle's threshold; by covariance the widening counts the position only
    angle = d_o(dirs_a, dirs_b)
    gated = sigmas_a is not None and sigmas_b is not None
    by_covariance = gated and plane_b is not None
    if gated:
        s_p = pair_thresholds(thresholds, sigmas_a[0], sigmas_b[0], s_p, thresholds.max_scale)
        if not by_covariance:
            s_o = pair_thresholds(thresholds, sigmas_a[1], sigmas_b[1], s_o, thresholds.max_scale_direction)
    dist = d_p(centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b, s_p)
    angle_cost = (angle / s_o) ** 2
    if by_covariance:    # only where the position and the ceiling let a pair through
        angle_cost = np.full(len(angle), np.inf)
        rows = np.flatnonzero((dist <= s_p) & (angle <= thresholds.max_angle_scale * nominal))
        distance = _numpy_direction_distance(
            dirs_a[rows], sigmas_a[1][rows], None if info_a is None else info_a[rows], dirs_b[rows],
            sigmas_b[1][rows], (plane_b[0][rows], plane_b[1][rows]), nominal / thresholds.gate_sigmas)
        angle_cost[rows] = (distance / thresholds.gate_sigmas) ** 2
    ok = (angle_cost <= 1.0) & (dist <= s_p)
    cost = np.where(ok, (dist / s_p) ** 2 + angle_cost, np.inf)
    return ok, cost, np.broadcast_to(s_p / thresholds.s_p * s_o / nominal, ok.shape)


def _numpy_across(dirs, sigma) -> np.ndarray:
    """(K, 3, 3) covariances ``sigma`` (K,) rad in every sense across unit directions (K, 3)."""
    return sigma[:, None, None] ** 2 * (np.eye(3) - outer(dirs))


def _numpy_direction_distance(dirs_a, sigma_a, info_a, dirs_b, sigma_b, plane_b, floor) -> np.ndarray:
    """(K,) Mahalanobis distance of undirected unit directions b from a (K, 3), in the tangent plane of a,
    under a's covariance (the inverse of ``info_a`` (K, 3, 3) 1/rad^2 across a, less its information
    along a, as ``line_model.merge`` pins a sigma; at most about a right angle in any sense; without
    ``info_a``, ``sigma_a`` (K,) rad in every sense), b's (``sigma_b`` (K,) rad within its view plane
    ``plane_b`` = (normal (K, 3), a zero row for none; sigma (K,)) and the plane's sigma across it;
    ``sigma_b`` in every sense where it has no plane) and ``floor`` rad in every sense. 2x2 algebra
    throughout: no eigen-decomposition per pair."""
    normal, plane_sigma = plane_b
    has_plane = np.any(normal != 0, axis=1)
    within = np.cross(normal, dirs_b)
    within /= np.maximum(np.linalg.norm(within, axis=1, keepdims=True), 1e-12)
    cov_b = np.where(has_plane[:, None, None],
                     sigma_b[:, None, None] ** 2 * outer(within) + plane_sigma[:, None, None] ** 2 * outer(normal),
                     _numpy_across(dirs_b, sigma_b))
    helper = np.where(np.abs(dirs_a[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = unit(np.cross(dirs_a, helper))
    basis = np.stack([e1, np.cross(dirs_a, e1)], axis=2)                    # (K, 3, 2), across a
    eye = np.eye(2)
    if info_a is None:
        cov = sigma_a[:, None, None] ** 2 * eye
    else:
        along = np.einsum("ki,kij,kj->k", dirs_a, info_a, dirs_a)
        info = np.einsum("kia,kij,kjb->kab", basis, info_a, basis) - along[:, None, None] * eye + (2 / np.pi) ** 2 * eye
        cov = _numpy_inverse_2x2(info)
    cov = cov + np.einsum("kia,kij,kjb->kab", basis, cov_b, basis) + floor ** 2 * eye
    sign = np.where(np.sum(dirs_a * dirs_b, axis=1) >= 0, 1.0, -1.0)
    offset = np.einsum("kia,ki->ka", basis, dirs_b * sign[:, None])
    return np.sqrt(np.einsum("ka,kab,kb->k", offset, _numpy_inverse_2x2(cov), offset))


def _numpy_inverse_2x2(m: np.ndarray) -> np.ndarray:
    """(K, 2, 2) inverses of (K, 2, 2) matrices, in closed form."""
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    adjugate = np.stack([np.stack([m[:, 1, 1], -m[:, 0, 1]], 1), np.stack([-m[:, 1, 0], m[:, 0, 0]], 1)], 1)
    return adjugate / det[:, None, None]


def test_compiled_pair_costs_equal_the_numpy_form():
    """Ungated, gated, and gated by covariance with and without a's direction information, on random
    pairs (half of them parallel, some observations without a view plane): the same ok, cost and
    widening (to the last bit on this machine)."""
    rng = np.random.default_rng(21)
    n = 4000
    ca, cb, da, db, la, lb = _random_segments(rng, n)
    db[n // 2: n // 2 + n // 4] = unit(da[n // 2: n // 2 + n // 4] + rng.normal(0, 0.15, (n // 4, 3)))  # near
    th = MetricThresholds()
    sa = (rng.uniform(0.0002, 0.004, n), rng.uniform(0.001, 0.2, n))
    sb = (rng.uniform(0.0002, 0.004, n), rng.uniform(0.001, 0.2, n))
    normal = unit(np.cross(db, rng.normal(size=(n, 3))))
    normal[rng.uniform(size=n) < 0.2] = 0.0                                    # no plane
    plane = (normal, rng.uniform(0.002, 0.02, n))
    a = rng.normal(size=(n, 3, 3))
    info = np.einsum("nij,nkj->nik", a, a) * 1e3 + np.eye(3) * 10.0             # symmetric positive definite
    cases = [(None, None, None, None), (sa, sb, None, None), (sa, sb, plane, None), (sa, sb, plane, info)]
    for sigmas_a, sigmas_b, plane_b, info_a in cases:
        got = pair_costs(ca, da, la, cb, db, lb, th, sigmas_a, sigmas_b, plane_b, info_a)
        with np.errstate(invalid="ignore"):   # random information is not always positive across a: NaN both
            ref = _numpy_pair_costs(ca, da, la, cb, db, lb, th, sigmas_a, sigmas_b, plane_b, info_a)
        finite = np.isfinite(ref[1])     # bit for bit where numpy's arccos is the C library's (not where it
        # is vectorised, AVX-512: there within an ulp of it)
        assert np.array_equal(got[0], ref[0]) and np.array_equal(np.isfinite(got[1]), finite)
        assert np.allclose(got[1][finite], ref[1][finite], rtol=1e-12, atol=0) and np.array_equal(got[2], ref[2])
        assert 0 < got[0].sum() < n
