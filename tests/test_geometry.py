"""Transform checks at the library's entry points, and the increment of Gauss-Newton."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from accumcli.accumulate import Accumulator
from accumcli.errors import AccumError, InputError
from accumcli.geometry import check_points, check_transform, make_transform, rotation_about_point
from accumcli.line_model import FrameContext, LineSegmentType
from accumcli.segments import Segments
from accumcli.track import PoseTracker, refine_pose

from .scenes import INTRINSICS, render_pair, rotated_square

T_GOOD = make_transform(Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix(), [0.01, 0.02, 0.5])


def test_input_error_is_an_accum_error_and_a_value_error():
    assert issubclass(InputError, AccumError) and issubclass(InputError, ValueError)


def test_check_transform_coerces_a_rigid_transform_to_float64():
    T = check_transform(np.eye(4, dtype=int).tolist())
    assert T.dtype == np.float64 and T.shape == (4, 4) and np.array_equal(T, np.eye(4))
    assert np.array_equal(check_transform(T_GOOD), T_GOOD)


@pytest.mark.parametrize("T, message", [
    (np.eye(4)[:3], r"^T_camera_object: expected a \(4, 4\) rigid transform, got shape \(3, 4\)$"),
    (np.eye(3), r"got shape \(3, 3\)"),
    (np.full((4, 4), np.nan), r"non-finite"),
    (T_GOOD.T, r"last row must be \[0, 0, 0, 1\], got \[0.01, 0.02, 0.5, 1\] \(a transposed matrix\?\)$"),
    (np.diag([1.0, 1.0, np.sqrt(1.3), 1.0]), r"not rigid: R\^T R differs from I by 0\.3$"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), r"det R = -1, a reflection"),
])
def test_check_transform_says_what_is_wrong(T, message):
    with pytest.raises(InputError, match=message):
        check_transform(T)


def test_check_transform_names_the_argument_and_tolerates_rounding():
    with pytest.raises(InputError, match=r"^T_guess: expected"):
        check_transform(np.zeros((2, 2)), "T_guess")
    rounded = np.round(T_GOOD, 7)                        # as files store it
    assert np.allclose(check_transform(rounded), T_GOOD, atol=1e-7)


def test_check_points():
    P = check_points([[1, 2, 3]], "centres")
    assert P.dtype == np.float64 and P.shape == (1, 3)
    with pytest.raises(InputError, match=r"^centres: expected \(N, 3\) points, got shape \(3,\)$"):
        check_points([1.0, 2.0, 3.0], "centres")
    with pytest.raises(InputError, match=r"got 1 of 2 with NaN or inf"):
        check_points([[0, 0, 0], [np.inf, 0, 0]], "centres")


def test_rotation_about_point_keeps_the_pivot_and_is_not_the_se3_exponential():
    rotvec, pivot, t = np.array([0.0, 0.0, np.pi / 2]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.1])
    T = rotation_about_point(rotvec, pivot, t)
    assert np.allclose(T[:3, :3] @ pivot + T[:3, 3], pivot + t)           # the pivot only translates
    assert np.allclose(T[:3, :3] @ [2.0, 0, 0] + T[:3, 3], [1.0, 1.0, 0.1])
    # about the origin the translation is taken as it is (the SE(3) exponential would bend it: V t)
    T0 = rotation_about_point(np.array([0.0, 0.0, 1.0]), np.zeros(3), np.array([1.0, 0.0, 0.0]))
    assert np.allclose(T0[:3, 3], [1.0, 0.0, 0.0])


def _segments(n=5) -> Segments:
    return Segments("gripper", np.zeros((n, 3)), np.tile([0.0, 1.0, 0.0], (n, 1)), np.full(n, 0.012),
                    np.ones(n), np.ones(n, np.int64))


def test_entry_points_reject_a_bad_transform():
    bad = np.eye(4)[:3]
    with pytest.raises(InputError, match=r"^T_new_old: expected a \(4, 4\)"):
        _segments().transformed(bad, "camera")
    with pytest.raises(InputError, match=r"^T_camera_object: expected a \(4, 4\)"):
        FrameContext(bad, INTRINSICS)
    kind = LineSegmentType()
    core = Accumulator(kind, kind.empty("gripper"))
    with pytest.raises(InputError, match=r"^T_model_observed: not rigid"):
        core.update(_segments(), np.diag([2.0, 2.0, 2.0, 1.0]), FrameContext(T_GOOD, INTRINSICS))
    square, _ = rotated_square((0.0, 0.0), 0.03, 10.0, 0.5)
    frame = render_pair([square])
    with pytest.raises(InputError, match=r"^T_init \(T_camera_object\): expected"):
        refine_pose(_segments(), frame, bad)
    with pytest.raises(InputError, match=r"^T_guess \(T_camera_object\): not a rigid transform: the last row"):
        PoseTracker(_segments()).update(frame, T_GOOD.T)
    broken = _segments()
    broken.centers[0, 0] = np.nan
    with pytest.raises(InputError, match=r"^model segment centres: expected finite"):
        PoseTracker(broken)
    with pytest.raises(InputError, match=r"^observed segment centres: expected finite"):
        kind.observe(broken, FrameContext(T_GOOD, INTRINSICS))


def test_transformed_moves_centres_and_directions_and_keeps_extra_columns():
    segments = _segments(2)
    segments.extra = {"view_direction": np.tile([0.0, 0.0, -1.0], (2, 1))}
    turn = make_transform(Rotation.from_rotvec([0.0, 0.0, np.pi / 2]).as_matrix(), [0.0, 0.0, 0.5])
    moved = segments.transformed(turn, "camera")
    assert moved.frame_id == "camera" and np.allclose(moved.centers, [[0.0, 0.0, 0.5]] * 2)
    assert np.allclose(moved.directions, [[-1.0, 0.0, 0.0]] * 2)
    assert moved.extra["view_direction"] is segments.extra["view_direction"]


def test_check_transform_projects_a_slightly_drifted_rotation_back_onto_a_rotation():
    from accumcli.geometry import check_transform

    T = np.eye(4)
    T[:3, :3] += 3e-5 * np.array([[0, 1, 0], [0, 0, 0], [0, 0, 0]])   # what chained estimates drift to
    out = check_transform(T)
    assert np.abs(out[:3, :3].T @ out[:3, :3] - np.eye(3)).max() < 1e-12
    assert np.abs(out - T).max() < 1e-4


def test_extrapolate_interpolates_inside_and_keeps_the_velocity_beyond():
    from accumcli.geometry import extrapolate, interpolate, pose_error

    T0 = make_transform(Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix(), [0.1, 0.0, 0.5])
    step = Rotation.from_rotvec(np.radians([0.0, 5.0, 0.0])).as_matrix()
    T1 = make_transform(step @ T0[:3, :3], [0.11, 0.002, 0.49])
    assert np.allclose(extrapolate(T0, T1, 0.0), T0) and np.allclose(extrapolate(T0, T1, 1.0), T1)
    assert np.allclose(extrapolate(T0, T1, 0.3), interpolate(T0, T1, 0.3))
    T3 = extrapolate(T0, T1, 3.0)                  # two more steps of 5 degrees, 10 mm and 2 mm
    assert pose_error(T3, T0)[0] == pytest.approx(15.0)
    assert np.allclose(T3[:3, 3], [0.13, 0.006, 0.47])
    assert np.allclose(T3[:3, :3], step @ step @ step @ T0[:3, :3])
