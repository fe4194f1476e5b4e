"""The tracker's compiled visibility, sampling, projection and residual kernels give what numpy
computed before them (``track`` used these numpy forms until 2026-12-06)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from accumcli.geometry import invert, make_transform, rotate_vectors, transform_points
from accumcli.pose_kernel import in_view, nearest_residuals, projected_normals, sample_points
from accumcli.recording import StereoIntrinsics
from accumcli.segments import Segments
from accumcli.visibility import IMAGE_MARGIN_PX, MIN_DEPTH_M, segments_in_both_images

INTR = StereoIntrinsics(600.0, 600.0, 319.5, 239.5, 0.08, 640, 480)


def _model(n=400, seed=11):
    """Segments in a 0.5 m cube around the object origin, some behind or beside the cameras' view."""
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    views = rng.normal(size=(n, 3)) + [0, 0, -2]
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    return Segments("object", rng.uniform(-0.25, 0.25, (n, 3)), directions, rng.uniform(0.005, 0.06, n), np.ones(n),
                    np.ones(n, np.int64), {"view_direction": views, "view_spread_deg": rng.uniform(0, 30, n)})


def _pose():
    return make_transform(Rotation.from_rotvec([0.2, -0.3, 0.1]).as_matrix(), [0.02, -0.01, 0.6])


def test_in_view_is_segments_in_both_images_and_the_cone_test():
    model, T = _model(), _pose()
    keep, beyond = in_view(model.centers, model.directions, model.lengths, T[:3, :3].copy(), T[:3, 3].copy(),
                           invert(T)[:3, 3], model.extra["view_direction"], model.extra["view_spread_deg"], True,
                           INTR.fx, INTR.fy, INTR.cx, INTR.cy, INTR.baseline, INTR.width, INTR.height,
                           IMAGE_MARGIN_PX, MIN_DEPTH_M, 25.0)
    to_camera = invert(T)[:3, 3] - model.centers
    to_camera /= np.linalg.norm(to_camera, axis=1, keepdims=True)
    ref_beyond = np.degrees(np.arccos(np.clip(np.sum(to_camera * model.extra["view_direction"], axis=1), -1, 1))) \
        - model.extra["view_spread_deg"]
    inside = segments_in_both_images(model, T, INTR)
    assert np.allclose(beyond, ref_beyond, rtol=0, atol=1e-9)
    assert np.array_equal(keep, inside & (ref_beyond <= 25.0))
    assert 0.1 < inside.mean() < 0.9 and 0 < keep.sum() < inside.sum()     # both tests decide somewhere
    plain, _ = in_view(model.centers, model.directions, model.lengths, T[:3, :3].copy(), T[:3, 3].copy(),
                       invert(T)[:3, 3], np.zeros((0, 3)), np.zeros(0), False, INTR.fx, INTR.fy, INTR.cx, INTR.cy,
                       INTR.baseline, INTR.width, INTR.height, IMAGE_MARGIN_PX, MIN_DEPTH_M, 0.0)
    assert np.array_equal(plain, inside)


def test_sample_points_are_evenly_along_the_kept_segments_bit_for_bit():
    model = _model(50)
    keep = np.arange(50) % 3 != 0
    points, dirs, owner = sample_points(model.centers, model.directions, model.lengths, keep, 5)
    kept = model.select(keep)
    s = (np.arange(5) + 0.5) / 5 - 0.5
    ref = kept.centers[:, None, :] + (s[None, :, None] * kept.lengths[:, None, None]) * kept.directions[:, None, :]
    assert np.array_equal(points, ref.reshape(-1, 3))
    assert np.array_equal(dirs, np.repeat(kept.directions, 5, axis=0))
    assert np.array_equal(owner, np.repeat(np.arange(keep.sum()), 5))


def _numpy_geometry(points_cam, dirs_cam):
    """The projections and unit normals per side as ``track._measure`` computed them with numpy."""
    projected = INTR.project(points_cam)[:2], INTR.project(points_cam + 0.002 * dirs_cam)[:2]
    out = []
    for side in (0, 1):
        uv = projected[0][side]
        d = projected[1][side] - uv
        d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        out.append((uv, np.column_stack([-d[:, 1], d[:, 0]])))
    return out


def test_projected_normals_and_nearest_residuals_equal_the_numpy_forms_bit_for_bit():
    model, T = _model(), _pose()
    points, dirs, _ = sample_points(model.centers, model.directions, model.lengths, np.ones(len(model), bool), 3)
    P, D = transform_points(T, points), rotate_vectors(T, dirs)
    P = P[P[:, 2] > 0.1]
    D = D[: len(P)]
    uv, normal = projected_normals(P, D, INTR.fx, INTR.fy, INTR.cx, INTR.cy, INTR.baseline, 0.002)
    for side, (ref_uv, ref_normal) in enumerate(_numpy_geometry(P, D)):
        assert np.array_equal(uv[side], ref_uv) and np.array_equal(normal[side], ref_normal)
    rng = np.random.default_rng(12)
    candidates = rng.normal(0, 3, (2, len(P), 3))
    candidates[rng.uniform(size=candidates.shape) < 0.4] = np.nan        # some samples with none
    moved = transform_points(make_transform(Rotation.from_rotvec([0.002, 0.0, -0.001]).as_matrix(), [0.001, 0, 0]), P)
    got = nearest_residuals(moved, uv, normal, candidates, INTR.fx, INTR.fy, INTR.cx, INTR.cy, INTR.baseline)
    projected = INTR.project(moved)
    for side in (0, 1):
        along = np.sum((projected[side] - uv[side]) * normal[side], axis=1)
        gaps = along[:, None] - candidates[side]
        distance = np.where(np.isnan(gaps), np.inf, np.abs(gaps))
        ref = np.take_along_axis(gaps, np.argmin(distance, axis=1)[:, None], axis=1)[:, 0]
        assert np.array_equal(got[side], ref, equal_nan=True)
    assert np.isnan(got).any() and not np.isnan(got).all()


@pytest.mark.parametrize("with_prior", [False, True])
def test_gauss_newton_steps_are_the_python_loop_of_normal_equations_and_rotations_about_the_pivot(with_prior):
    """The compiled loop against the loop it replaced: the same poses (to rounding) after each
    iteration count, with and without a prior about another pose, and the stop when a step finds
    fewer than 6 residuals."""
    from accumcli.geometry import rotation_about_point
    from accumcli.pose_kernel import gauss_newton_steps, normal_equations

    rng = np.random.default_rng(5)
    points = rng.uniform(-0.04, 0.04, (200, 3))
    T_true, T = _pose(), make_transform(Rotation.from_rotvec([0.21, -0.29, 0.1]).as_matrix(), [0.021, -0.01, 0.602])
    P_true = transform_points(T_true, points)
    uv0, normal = projected_normals(transform_points(T, points), rotate_vectors(T, rng.normal(size=(200, 3))),
                                    INTR.fx, INTR.fy, INTR.cx, INTR.cy, INTR.baseline, 0.002)
    truth_uv = np.stack(INTR.project(P_true)[:2])
    candidates = np.sum((truth_uv - uv0) * normal, axis=2)[:, :, None] + rng.normal(0, 0.1, (2, 200, 2))
    expected = rng.uniform(0.5, 1.0, 200)
    args = (INTR.fx, INTR.fy, INTR.cx, INTR.cy, INTR.baseline, 6.0)
    prior = make_transform(Rotation.from_rotvec([0.22, -0.3, 0.09]).as_matrix(), [0.02, -0.011, 0.6])
    information = (1 / np.repeat([np.radians(0.5), 0.002], 3) ** 2) if with_prior else np.zeros(6)
    for iterations in (1, 3, 12):
        loop = T.copy()
        for _ in range(iterations):
            P = transform_points(loop, points)
            pivot = P.sum(axis=0) / len(P)
            H, g, _, swr2, sw = normal_equations(P, pivot, uv0, normal, candidates, expected, *args)
            sigma2 = max(swr2 / max(sw, 1e-9), 0.01)
            D = loop @ invert(prior)
            departure = np.concatenate([Rotation.from_matrix(D[:3, :3]).as_rotvec(), D[:3, :3] @ pivot + D[:3, 3] - pivot])
            H, g = H + sigma2 * np.diag(information), g + sigma2 * information * departure
            step = np.linalg.solve(H, -g)
            loop = rotation_about_point(step[:3], pivot, step[3:]) @ loop
            if np.linalg.norm(step[:3]) < 1e-9 and np.linalg.norm(step[3:]) < 1e-9:
                break
        compiled, ok = gauss_newton_steps(points, T, uv0, normal, candidates, expected, *args, iterations, 1e-9, 1e-9,
                                          invert(prior), information)
        assert ok
        np.testing.assert_allclose(compiled, loop, rtol=0, atol=1e-12)
    assert np.degrees(np.linalg.norm(Rotation.from_matrix(compiled[:3, :3] @ T_true[:3, :3].T).as_rotvec())) < 0.2
    if with_prior:   # the prior counts: the poses with and without it differ (and each equals its loop above)
        free, _ = gauss_newton_steps(points, T, uv0, normal, candidates, expected, *args, 12, 1e-9, 1e-9,
                                     invert(prior), np.zeros(6))
        assert np.abs(free - compiled).max() > 1e-6
    none_found = np.full_like(candidates, np.nan)
    _, ok = gauss_newton_steps(points, T, uv0, normal, none_found, expected, *args, 12, 1e-9, 1e-9, invert(prior),
                               information)
    assert not ok


def test_nearest_rotation_and_condition_number_equal_numpys_svd_forms_bit_for_bit():
    """The compiled SVD forms give numpy's results exactly: the nearest rotation to a drifted or a
    reflected matrix (its last singular vector flipped), and the condition number of Gauss-Newton
    matrices from well to badly conditioned."""
    from accumcli.pose_kernel import condition_number, nearest_rotation

    rng = np.random.default_rng(3)
    for k in range(50):
        R = Rotation.from_rotvec(rng.normal(size=3)).as_matrix() + rng.normal(scale=1e-6, size=(3, 3))
        if k % 5 == 0:
            R[:, 2] = -R[:, 2]                     # a reflection: the nearest rotation flips it back
        U, _, Vt = np.linalg.svd(R)
        if np.linalg.det(U @ Vt) < 0:
            U[:, -1] = -U[:, -1]
        assert np.array_equal(nearest_rotation(np.ascontiguousarray(R)), U @ Vt)
        assert np.linalg.det(nearest_rotation(np.ascontiguousarray(R))) > 0
        A = rng.normal(size=(6, 6)) * 10.0 ** rng.uniform(-6, 6, size=6)
        assert condition_number(A @ A.T) == np.linalg.cond(A @ A.T)
