"""The checks of re-observations against the recorded motion (``motion_check``): stereo depths a few
percent off the recorded motion's (a baseline or focal length a little wrong) are named, and so are
jittering poses; right ones, or a motion that cannot tell, say nothing."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from accumcli.geometry import make_transform, transform_points
from accumcli.motion_check import MotionCheck
from accumcli.segments import Segments


def _frames(scale: float, turn_deg: float = 6.0, frames: int = 10, seed: int = 0, pose_noise: tuple = (0.0, 0.0),
            count: int = 300):
    """(segments in the camera frame, their depths times ``scale``; T_camera_object) of an object of
    random segments turning about its centre 0.6 m in front of the camera; the recorded pose off the
    true one by ``pose_noise`` (deg, m) RMS per frame."""
    rng = np.random.default_rng(seed)
    centers = rng.uniform(-0.05, 0.05, (count, 3))
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for k in range(frames):
        rotation = Rotation.from_rotvec([0.0, np.radians(turn_deg) * k, np.radians(turn_deg / 3) * k]).as_matrix()
        T = make_transform(rotation, [0.02 * np.sin(k), 0.0, 0.6])
        seen = Segments("camera_left", scale * transform_points(T, centers), directions @ rotation.T,
                        np.full(count, 0.01), np.ones(count), np.ones(count, np.int64),
                        {"sigma_direction_rad": np.full(count, 0.01)})
        noise_deg, noise_m = pose_noise
        error = make_transform(Rotation.from_rotvec(rng.normal(size=3) * np.radians(noise_deg) / np.sqrt(3)).as_matrix(),
                               rng.normal(size=3) * noise_m / np.sqrt(3))
        yield seen, T @ error


def _check(scale: float, **motion) -> MotionCheck:
    check = MotionCheck()
    for segments, T in _frames(scale, **motion):
        check.add(segments, T)
    return check


def test_depths_three_percent_long_are_named():
    check = _check(1.03)
    assert check.estimate()[0] == 1.03
    assert "stereo depths are 1.03 times what the recorded motion implies" in check.scale_warning()


def test_large_scale_errors_are_named_and_beyond_the_range_as_a_bound():
    assert "stereo depths are 1.20 times" in _check(1.2).scale_warning()
    assert "stereo depths are at least 1.40 times" in _check(1.42).scale_warning()
    assert "stereo depths are at most 0.70 times" in _check(0.68).scale_warning()


def test_right_depths_and_a_motion_that_cannot_tell_say_nothing():
    right = _check(1.0)
    assert right.estimate()[0] == 1.0 and right.scale_warning() is None
    still = _check(1.03, turn_deg=0.0)   # no motion: every scale matches alike
    assert still.estimate() is None or still.estimate()[0] == 1.0
    assert still.scale_warning() is None


def test_noisy_recorded_poses_are_not_named_a_calibration_error():
    """Poses 1.5 deg / 4 mm off per frame (make motion's noise) with right depths: the frame pairs'
    best scales split about 1, whatever the sum of their counts peaks at."""
    for seed in range(6):
        check = MotionCheck()
        for segments, T in _frames(1.0, frames=30, seed=seed, pose_noise=(1.5, 0.004)):
            check.add(segments, T)
        assert check.scale_warning() is None, seed
    assert _check(1.03, pose_noise=(0.05, 0.0001)).estimate()[0] == 1.03   # small noise: still named


def test_jittering_poses_are_named_and_exact_ones_are_not():
    """Poses 1.5 deg / 4 mm off per frame (make motion's noise) scatter consecutive re-observations out
    of the narrow gate; exact ones, and poses 0.05 deg / 0.1 mm off, keep them in it. 60 segments in a
    10 cm cube: about as sparse as the extractions of real frames (denser ones meet within 2 mm by
    chance more often)."""
    for seed in range(3):
        noisy = MotionCheck()
        for segments, T in _frames(1.0, frames=30, seed=seed, pose_noise=(1.5, 0.004), count=60):
            noisy.add(segments, T)
        assert noisy.near_share() < 0.09 and "the recorded poses seem to jitter" in noisy.jitter_warning(), seed
    for noise in ((0.0, 0.0), (0.05, 0.0001)):
        assert _check(1.0, frames=30, pose_noise=noise, count=60).jitter_warning() is None


def _swinging(lag_ms: float, frames: int = 30, count: int = 300, swing: float = 1.0):
    """(segments in the camera frame, recorded T_camera_object, stamp) of an object of random segments
    swinging about its centre (yaw 25 deg * ``swing`` * sin, a 2 s period, and 30 mm * ``swing``
    sideways) 0.6 m in front of the camera at
    10 frames/s; each image shows the object ``lag_ms`` before its stamp, the recorded pose is the
    stamp's."""
    rng = np.random.default_rng(4)
    centers = rng.uniform(-0.05, 0.05, (count, 3))
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)

    def pose(t: float) -> np.ndarray:
        phase = swing * np.sin(np.pi * t)
        rotation = Rotation.from_rotvec([0.0, np.radians(25.0) * phase, np.radians(5.0) * phase])
        return make_transform(rotation.as_matrix(), [0.03 * phase, 0.0, 0.6])

    for k in range(frames):
        t = 0.1 * k
        shown = pose(t - lag_ms / 1000)
        seen = Segments("camera_left", transform_points(shown, centers), directions @ shown[:3, :3].T,
                        np.full(count, 0.01), np.ones(count), np.ones(count, np.int64),
                        {"sigma_direction_rad": np.full(count, 0.01)})
        yield seen, pose(t), int(round(t * 1e9)) + 1_700_000_000_000_000_000


def test_images_stamped_apart_from_their_poses_are_named_with_the_offset_to_give():
    """Images that show the object 50 ms before (or 30 ms after) their stamps: the check proposes the
    --time-offset-ms that looks the poses up at the moment shown; on time, or a still object, it says
    nothing."""
    def warning(lag_ms, **swing):
        check = MotionCheck()
        for segments, T, t_ns in _swinging(lag_ms, **swing):
            check.add(segments, T, t_ns)
        return check.offset_warning()

    late = warning(50.0)
    assert late is not None and late.startswith("the images seem stamped 50 ms after the moment they show")
    assert late.endswith("try --time-offset-ms -50")
    assert warning(-30.0).endswith("try --time-offset-ms 30")
    check = MotionCheck()   # a run given --time-offset-ms 12.5 already is told the whole offset
    for segments, T, t_ns in _swinging(50.0):
        check.add(segments, T, t_ns)
    assert check.offset_warning(current_ms=12.5).endswith("try --time-offset-ms -37.5")
    assert warning(0.0) is None
    assert warning(50.0, swing=0.0) is None


def test_a_proposed_offset_is_written_out_whole():
    """Never in exponent form (``:g`` wrote 1234567 as 1.23457e+06, 33 ms off)."""
    from accumcli.motion_check import _milliseconds

    assert [_milliseconds(v) for v in (1234567.0, -50.0, 12.5, 1749998765801.0)] == \
        ["1234567", "-50", "12.5", "1749998765801"]


def test_the_compiled_alignment_test_equals_numpy_s():
    from accumcli.motion_check import _aligned

    rng = np.random.default_rng(9)
    a, b = (v / np.linalg.norm(v, axis=1, keepdims=True) for v in rng.normal(size=(2, 500, 3)))
    b[:250] = a[:250] + rng.normal(0, 0.05, (250, 3))
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    i, j = rng.integers(0, 500, 20000), rng.integers(0, 500, 20000)
    j[:5000] = i[:5000]
    limit = np.cos(np.radians(5.0))
    got = _aligned(i, j, a, b, limit)
    assert np.array_equal(got, np.abs(np.sum(a[i] * b[j], axis=1)) >= limit) and 0 < got.sum() < len(i)
