"""``describe_recording``: what ``accum info`` shows, and whether the object can be reached."""

from __future__ import annotations

from ..errors import AccumError, RecordingError
from .base import RecordingOptions


def describe_recording(recording, options: RecordingOptions = RecordingOptions()):
    """The ``RecordingInfo`` of ``recording``, and an ``AccumError`` (not raised) when no transform path
    leads from the camera frame to the object frame, since nothing can then be accumulated, or when a
    topic accum reads is missing (then the summary holds the recording's topics and transforms only)."""
    try:
        rec = options.open(recording, require_pose=False)
    except RecordingError as e:   # a topic missing: what the recording holds, and the error with its proposal
        if getattr(e, "info", None) is None:
            raise
        return e.info, e
    with rec:
        summary = rec.info()
        reachable = rec.tree.path(rec.camera_frame, rec.object_frame) is not None
        hint = None if reachable else rec.pose_path_hint()
    problem = None
    if not reachable:
        frames = ", ".join(summary.tf_frames) or "none"
        problem = AccumError(f"{recording}: no transform path from {options.camera_frame!r} to "
                             f"{options.object_frame!r} (frames in the transform tree: {frames}); {hint}")
    return summary, problem
