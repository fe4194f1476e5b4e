"""A repaired pose's uncertainty (``motion.fuse``) and what the accumulation does with it
(``line_model.pose_sigmas``, ``FrameContext.pose_covariance``)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from accumcli.line_model import FrameContext, LineSegmentType, pose_sigmas
from accumcli.motion import MotionParams, _block_covariance, _recorded_sigma, _solve, fuse
from accumcli.segments import Segments
from tests.test_accumulate import INTR, _tilted_towards_camera

Y = np.array([0.0, 1.0, 0.0])


def _links(n: int, unlinked: int, rng):
    """Frame-to-frame links of ``n`` frames with random corrections and information, none to or from
    frame ``unlinked``."""
    links = {}
    for k in range(1, n):
        if unlinked in (k - 1, k):
            continue
        B = rng.normal(size=(6, 6))
        links[k - 1, k] = (rng.normal(0, 1e-3, 6), B @ B.T * 1e8 + np.eye(6) * 1e10)
    return links


def test_fused_covariance_is_the_inverse_of_the_normal_equations_blocks():
    """Each frame's covariance is the diagonal block of the inverse of the (dense) normal equations of
    the recorded poses' prior and the links; a frame without links keeps the prior's variance."""
    rng = np.random.default_rng(7)
    n, unlinked = 9, 4
    params = MotionParams(residual_chi2=None, gate_chi2=np.inf, gate_sigmas=np.inf)
    links = _links(n, unlinked, rng)
    _, covariance = fuse(links, n, params)
    r = np.repeat([np.radians(params.sigma_relative_deg), params.sigma_relative_m], 3)
    s = np.maximum(np.repeat(_recorded_sigma(links.values()), 3), r)
    H = np.diag(np.tile(1 / s ** 2, n))
    for (j, k), (_, L) in links.items():
        L = L / params.information_scale
        for a, b, sign in ((j, j, 1), (k, k, 1), (j, k, -1), (k, j, -1)):
            H[6 * a:6 * a + 6, 6 * b:6 * b + 6] += sign * L
    dense = np.linalg.inv(H)
    for k in range(n):
        assert np.allclose(covariance[k], dense[6 * k:6 * k + 6, 6 * k:6 * k + 6], rtol=1e-9, atol=1e-18)
    assert np.allclose(covariance[unlinked], np.diag(s ** 2))
    linked = [k for k in range(n) if k != unlinked]
    # two chains of four frames: each shares its mean error, a quarter of the prior variance
    assert (np.diagonal(covariance[linked], axis1=1, axis2=2) < 0.3 * s ** 2).all()
    assert fuse({}, n, params)[1] is None          # nothing fused: no uncertainty to tell
    # the blocks solved a few frames at a time are those solved all at once
    used = {jk: (c, L / params.information_scale) for jk, (c, L) in links.items()}
    factor, _ = _solve(used, n, s, {})
    assert np.allclose(_block_covariance(factor, n, chunk=2), covariance, rtol=1e-12, atol=0)


def test_pose_sigmas_are_what_sampled_pose_errors_do_to_points_and_directions():
    """For a random covariance, the position sigma of two points (one at the origin, one 60 mm off) and
    the rotation sigma match those of 20000 poses drawn from it, within 3 %."""
    rng = np.random.default_rng(2)
    D = np.diag(np.repeat([0.02, 0.001], 3))          # about a degree, a millimetre
    B = D @ rng.normal(size=(6, 6))
    covariance = B @ B.T
    points = np.array([[0.0, 0.0, 0.0], [0.05, -0.02, 0.03]])
    position, rotation = pose_sigmas(points, covariance)
    x = rng.multivariate_normal(np.zeros(6), covariance, size=20000)
    # the object's points where a pose T exp(x), taken as T, places them: exp(x)^-1 p = R^T (p - t)
    turned = Rotation.from_rotvec(x[:, :3]).inv()
    moved = np.stack([turned.apply(p - x[:, 3:]) for p in points], axis=1)          # (20000, 2, 3)
    sampled = np.sqrt(np.mean(np.sum((moved - points) ** 2, axis=2), axis=0) / 3)
    assert np.allclose(position, sampled, rtol=0.03)
    assert position[1] > 1.2 * position[0]          # the rotation's lever
    assert np.isclose(rotation, np.sqrt(np.mean(np.sum(x[:, :3] ** 2, axis=1)) / 3), rtol=0.03)


def _along_y(x_m: float) -> Segments:
    """A 20 mm segment along y at (x_m, 0, 0), sure (0.5 mm deep, 1 degree)."""
    return Segments("gripper", np.array([[x_m, 0.0, 0.0]]), Y[None], np.array([0.02]), np.ones(1),
                    np.ones(1, np.int64), {"sigma_depth_m": np.array([0.0005]), "sigma_direction_rad": np.radians([1.0])})


def test_an_observation_placed_by_an_unsure_pose_confirms_its_segment_and_moves_it_little():
    """An observation 6 mm beside a model segment, from a frame whose pose is exact, is another segment
    (beyond the gate); from a frame whose pose is 1.5 degrees / 4 mm unsure, the gate widens to hold it.
    Merged, one 3 mm off moves the segment half way with an exact pose and under a fiftieth of that with
    the unsure one."""
    kind = LineSegmentType()
    T, _ = _tilted_towards_camera(0.0, 0.0)
    unsure = np.diag(np.repeat([np.radians(1.5) ** 2, 0.004 ** 2], 3))

    def model():
        return kind.observe(_along_y(0.0), FrameContext(T, INTR))

    for covariance, pairs in ((None, 0), (unsure, 1)):
        observed = kind.observe(_along_y(0.006), FrameContext(T, INTR, pose_covariance=covariance))
        assert len(kind.correspondences(model(), observed)[0]) == pairs
    moved = []
    for covariance in (None, unsure):
        context = FrameContext(T, INTR, pose_covariance=covariance)
        merged = kind.merge(model(), kind.observe(_along_y(0.003), context), np.array([0]), np.array([0]), context)
        moved.append(merged.centers[0, 0])
    # information (0.25 mm / about 4 mm)^2: the unsure observation weighs a few thousandths of the segment
    assert abs(moved[0] - 0.0015) < 0.0002 and 0 < moved[1] < 0.02 * moved[0]
