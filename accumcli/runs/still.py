"""``check_model``: which share of a model moves with the object in a recording's images (``still_check``)."""

from __future__ import annotations

from ..errors import AccumError
from ..lines2d import Gradients
from ..model_io import read_model
from ..still_check import StillCheckParams, sampled_frames, still_check
from .base import FrameRange, Progress, RecordingOptions, frame_range, no_progress, options_for_model


def check_model(model_path, recording, options: RecordingOptions = RecordingOptions(),
                frames: FrameRange = FrameRange(), params: StillCheckParams = StillCheckParams(),
                object_frame_of_model: bool = False, progress: Progress = no_progress) -> dict:
    """The model's accepted segments checked on ``params.frames`` frames of ``recording`` spread evenly
    over ``frames`` (every pair of them; ``still_check``): the shares of their length that move
    with the object, stay still (background the accumulation kept) or are undecided, with the counts.
    ``object_frame_of_model``: the object's frame is the one the model names (as ``track_recording``).
    Raises ``AccumError`` for a model with no accepted segment, or fewer than two frames with a pose."""
    frames = frame_range(frames)
    model = read_model(model_path)
    accepted = model.select(model.accepted)
    if not len(accepted):
        raise AccumError(f"{model_path}: the model has no accepted segment (confidence >= 0.5) to check")
    options = options_for_model(options, model.frame_id, object_frame_of_model)
    with options.open(recording) as rec:
        total = frames.check(rec)
        wanted = set((frames.start + sampled_frames(total, params.frames)).tolist())
        views, intrinsics = [], None
        for done, frame in enumerate(rec.frames(frames.start, frames.stop), 1):
            progress(done, total)
            if frame.index not in wanted or frame.T_camera_object is None:
                continue
            border = frame.border_distance[0] if frame.border_distance is not None else None
            views.append((Gradients.of(frame.left, border_distance=border), frame.T_camera_object))
            intrinsics = frame.intrinsics
    if len(views) < 2:
        raise AccumError(f"{recording}: {len(views)} of the frames checked has a pose of {options.object_frame!r}; "
                         "the check compares two or more (give --frames a range with poses)")
    result = still_check(accepted, views, intrinsics, params)
    return {"model": str(model_path), "recording": str(recording), **result.shares()}
