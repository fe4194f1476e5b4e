"""Checks that inputs given together belong together (a truth of another recording gives
figures of 0 that look like a result: refuse it instead where its object frame or its times
tell; recordings simulated alike share their times, and there eval can only warn)."""

from __future__ import annotations

import numpy as np

from ..errors import AccumError
from ..geometry import pose_error
from ..recording.tf_tree import frame_name

# recorded poses this far from a truth's (medians) are of another recording: the devset's five truths
# lie 19 to 50 deg and 46 to 251 mm apart by their medians, noisy gripper poses 1.5 deg / 4 mm
MAX_POSE_GAP_DEG = 10.0
MAX_POSE_GAP_M = 0.03


def check_truth_matches(truth, object_frame: str, truth_path, what: str = "the model") -> None:
    """The truth must describe ``object_frame``, the frame of ``what`` ("the model", "the poses",
    "the run": the only one that takes --object-frame); a truth that names no frame is taken as given."""
    if truth.object_frame and object_frame and frame_name(truth.object_frame) != frame_name(object_frame):
        fix = (f"or --object-frame {truth.object_frame}" if what == "the run" else
               f"or {what} of a run with --object-frame {truth.object_frame}")
        raise AccumError(f"{truth_path}: the truth is of object frame {truth.object_frame!r}, {what} of "
                         f"{object_frame!r}; give the truth of this recording ({fix})")


def check_truth_times(truth, times_ns: np.ndarray, tolerance_ns: int, what, truth_path) -> None:
    """At least one of ``times_ns`` must have a truth pose within ``tolerance_ns``."""
    if len(times_ns) == 0 or len(truth.times_ns) == 0:
        raise AccumError(f"{truth_path}: no poses to compare (the truth has {len(truth.times_ns)}, "
                         f"{what} has {len(times_ns)})")
    sorted_truth = np.sort(truth.times_ns)
    after = np.clip(np.searchsorted(sorted_truth, times_ns), 0, len(sorted_truth) - 1)
    before = np.maximum(after - 1, 0)
    nearest = np.minimum(np.abs(sorted_truth[after] - times_ns), np.abs(sorted_truth[before] - times_ns))
    if not (nearest <= tolerance_ns).any():
        raise AccumError(f"{truth_path}: none of the {len(times_ns)} timestamps of {what} has a truth pose "
                         f"(nearest {nearest.min() * 1e-9:.3f} s away): is it the truth of another recording?")


def check_same_time(times_ns: np.ndarray, span_ns, tolerance_ns: int, what, other) -> None:
    """``what`` (its timestamps ``times_ns``) and ``other`` (its first and last timestamp ``span_ns``;
    None: unknown, nothing checked) must overlap in time: a truth or poses file of another recording
    would otherwise give figures of 0, or place nothing, that look like a result."""
    times_ns = np.asarray(times_ns, np.int64)
    if span_ns is None or len(times_ns) == 0:
        return
    first, last = int(span_ns[0]), int(span_ns[1])
    if times_ns.max() < first - tolerance_ns or times_ns.min() > last + tolerance_ns:
        raise AccumError(f"{what}: its times ({times_ns.min() * 1e-9:.3f} to {times_ns.max() * 1e-9:.3f} s) lie "
                         f"outside those of {other} ({first * 1e-9:.3f} to {last * 1e-9:.3f} s): "
                         "is it of another recording?")


def check_truth_poses(truth, times_ns, poses, what, truth_path, tolerance_ns: int) -> None:
    """The recorded poses (T_camera_object (N, 4, 4) at ``times_ns`` (N,)) of ``what`` must lie within
    ``MAX_POSE_GAP_DEG`` / ``MAX_POSE_GAP_M`` of the truth's by their medians: timestamps alone let
    the truth of another recording made at the same times through (the devset's six all start at one
    time), and gave figures of 0 with exit 0."""
    gaps = [pose_error(T, truth_pose) for t, T in zip(times_ns, poses)
            if T is not None and np.isfinite(T).all()
            and (truth_pose := truth.pose_at(int(t), tolerance_ns)) is not None]
    if not gaps:
        return
    rotation, translation = np.median(np.array(gaps), axis=0)
    if rotation > MAX_POSE_GAP_DEG or translation > MAX_POSE_GAP_M:
        raise AccumError(f"{truth_path}: the recorded poses of {what} lie a median {rotation:.0f} deg and "
                         f"{translation * 1000:.0f} mm from the truth's: is it the truth of another recording (or "
                         "are the recorded poses of another frame or unit)?")
