"""``describe_recording``: what ``accum info`` shows, and whether the object can be reached."""

from __future__ import annotations

from ..errors import AccumError
from .base import RecordingOptions


def describe_recording(recording, options: RecordingOptions = RecordingOptions()):
    """The ``RecordingInfo`` of ``recording``, and an ``AccumError`` (not raised) when no transform path
    leads from the camera frame to the object frame, since nothing can then be accumulated."""
    with options.open(recording, require_pose=False) as rec:
        summary = rec.info()
        reachable = rec.tree.path(rec.camera_frame, rec.object_frame) is not None
        hint = None if reachable else rec.pose_path_hint()
    problem = None
    if not reachable:
        frames = ", ".join(summary.tf_frames) or "none"
        problem = AccumError(f"{recording}: no transform path from {options.camera_frame!r} to "
                             f"{options.object_frame!r} (frames in the transform tree: {frames}); {hint}")
    return summary, problem
