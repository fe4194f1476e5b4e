"""``track_recording``: the object's pose in every stereo frame, from its model and the images."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import AccumError, InputError
from ..extract import ExtractParams, extract_frame
from ..geometry import check_transform
from ..lines2d import frame_gradients
from ..model_io import PoseTrack, checked_segments, read_model
from ..outputs import OutputSet
from ..recording.tf_tree import frame_name
from ..segments import Segments
from ..track import PoseEstimate, PoseTracker, TrackParams
from .base import (POSES_OUTPUTS, FrameRange, Progress, RecordingOptions, check_output_kinds, frame_range, in_frames,
                   no_progress, nothing_done, options_for_model, path_list, write_pose_outputs)
from .frame_logs import rerun_log

log = logging.getLogger("accumcli")


@dataclass
class TrackingResult:
    """The poses (``track``: T_camera_object per frame with status 'tracked', 'ambiguous' or 'lost' and
    the figures of ``PoseEstimate.figures`` as extra fields), the wall time and the files written."""

    track: PoseTrack
    seconds: float = 0.0
    outputs: list = field(default_factory=list)
    params: TrackParams | None = None      # the limits used (calibrated on the first frame: ``track.calibrated``)
    limits_source: str = "the first frame"  # where the limits come from (``PoseTracker.limits_source``)

    @property
    def frames(self) -> int:
        return len(self.track.times_ns)

    @property
    def tracked(self) -> int:
        return sum(s == "tracked" for s in self.track.status)

    @property
    def median_residual_px(self) -> float:
        values = [e["residual_px"] for e, s in zip(self.track.extra, self.track.status)
                  if s == "tracked" and e.get("residual_px") is not None]
        return float(np.median(values)) if values else float("nan")

    @property
    def frames_per_second(self) -> float:
        return self.frames / max(self.seconds, 1e-9)


def track_recording(model, recording, outputs=(), *, init_pose: np.ndarray | None = None,
                    params: TrackParams = TrackParams(), extract_params: ExtractParams = ExtractParams(),
                    options: RecordingOptions = RecordingOptions(), frames: FrameRange = FrameRange(),
                    reacquire: bool = True, rrd=None, poses_topic: str = "/accum/poses",
                    poses_child_frame: str | None = None, object_frame_of_model: bool = False,
                    progress: Progress = no_progress) -> TrackingResult:
    """Track ``model`` (a model path or ``Segments`` in the object frame) through ``recording``.

    The first frame starts from ``init_pose`` (T_camera_object, (4, 4)) or else the recording's pose;
    every later frame from the images alone. outputs: ``.json`` (accum.poses/1), ``.tum`` (the
    tracked poses for evo) and/or ``.mcap`` (the tracked poses as FrameTransforms on
    ``poses_topic``, child frame ``poses_child_frame``, default ``<object>_tracked``, so they sit
    beside the recording's own /tf in Foxglove). ``object_frame_of_model``: the object's frame is the
    one the model names (``options.object_frame`` is not the user's choice but a default). ``frames``:
    the stereo frames tracked (``FrameRange``); ``params``: ``TrackParams``; ``extract_params``: the
    extraction whose 3D segments re-acquisition matches the model to (``reacquire``: after a frame is
    lost, search the whole frame that way; False: only from the last pose); ``rrd``: also a Rerun
    recording of the images, the model at each pose and the statuses; ``progress``: ``Progress``.
    A ``Segments`` model is checked as a model file is (unit directions, positive lengths). Raises
    ``AccumError`` (``InputError``, ``RecordingError``).
    """
    outputs, frames = path_list(outputs, "outputs"), frame_range(frames)
    check_output_kinds(outputs, POSES_OUTPUTS)
    for name, value in (("poses_topic", poses_topic), ("poses_child_frame", poses_child_frame)):
        if value is not None and not (isinstance(value, str) and value.strip()):
            raise InputError(f"{name} (--{name.replace('_', '-')}): expected a name, found {value!r}")
    if not isinstance(model, (Segments, str, os.PathLike)):
        raise InputError(f"model: expected a model file's path or Segments, found {type(model).__name__}")
    model_file = None if isinstance(model, Segments) else model
    if model_file is not None:
        model_path, model = model, read_model(model)
    else:
        model_path, model = "the model", checked_segments(model, "the model")
    if not model.accepted.any():
        raise AccumError(f"{model_path}: the model has no accepted segment (confidence >= 0.5) to track")
    model_frame = frame_name(model.frame_id)   # as the recording's tree keys it
    options = options_for_model(options, model.frame_id, object_frame_of_model)
    if init_pose is not None:
        init_pose = check_transform(init_pose, "init_pose")
    files = OutputSet([*outputs, rrd], inputs=[recording, model_file])
    tracker = PoseTracker(model, params)
    times, poses, status, extra, trajectory = [], [], [], [], []
    t0 = time.perf_counter()
    with options.open(recording, require_pose=init_pose is None) as rec, files:
        total = frames.check(rec)
        _check_child_frame(poses_child_frame, rec, [p for p in outputs if str(p).lower().endswith(".mcap")])
        if model_frame and model_frame != rec.object_frame:   # --object-frame given: the user's
            log.warning("%s: the model is in frame %r, tracked as the recording's %r (--object-frame): the same "
                        "object under another name, or a wrong model (then nothing is tracked)", model_path,
                        model.frame_id, rec.object_frame)
        waited, start_index = [], None   # the frames before the first with a starting pose, and that one's
        with rerun_log(files, rrd, "track") as viz:
            same_blur = extract_params.lines.blur_sigma == params.blur_sigma
            for frame in rec.frames(frames.start, frames.stop):
                guess = None
                if start_index is None:
                    guess = init_pose if init_pose is not None and not times else frame.T_camera_object
                if start_index is None and guess is None:   # the transforms begin after the images: wait for them
                    waited.append((frame.index, frame.pose_problem))
                    estimate = PoseEstimate(np.full((4, 4), np.nan), float("inf"), 0, 0, "lost",
                                            reason=f"no recorded pose to start from ({frame.pose_problem})")
                else:
                    # tracking and re-acquisition share the frame's gradients where their blur is the same;
                    # else each computes its own, re-acquisition only when it runs
                    shared = frame_gradients(frame, extract_params.lines) if same_blur else None
                    observe = (lambda f=frame: extract_frame(f, extract_params, rec.camera_frame,
                                                             gradients=shared).segments) if reacquire else None
                    estimate = tracker.update(frame, guess, observe, gradients=shared,
                                              rough_guess=not times and init_pose is not None)
                if guess is not None and start_index is None:
                    start_index = frame.index
                    if tracker.calibration_refused:
                        log.warning("%s: frame %d: %s; check that the model is of this object, and the starting "
                                    "pose (%s)", recording, frame.index, tracker.calibration_refused,
                                    "--init" if init_pose is not None else "the recorded one, or give --init")
                times.append(frame.timestamp_ns)
                poses.append(estimate.T_camera_object)
                status.append(estimate.status)
                extra.append(estimate.figures())
                log.debug("frame %d: %s by %s, coverage %.2f, residual %.2f px%s", frame.index, estimate.status,
                          estimate.method, estimate.coverage, estimate.residual_px,
                          f" ({estimate.reason})" if estimate.reason else "")
                if estimate.status == "tracked":
                    trajectory.append(estimate.T_camera_object[:3, 3])
                if viz:
                    viz.tracking(frame, model, estimate, trajectory)
                progress(len(times), total)
        if not times:
            raise nothing_done(recording, f"no stereo frame could be read{in_frames(frames)}", rec=rec)
        if start_index is None:
            raise AccumError(f"{recording}: no frame{in_frames(frames)} has a recorded pose to start from "
                             f"({waited[0][1]}); give one with --init")
        if waited:
            log.warning("%s: frames %d to %d have no recorded pose (%s): tracking starts at frame %d, the "
                        "first with one (--init gives the first frame a pose)", recording, waited[0][0],
                        waited[-1][0], waited[0][1], start_index)
        track = PoseTrack(rec.camera_frame, rec.object_frame, np.array(times, np.int64),
                          np.array(poses).reshape(-1, 4, 4), status, extra)
        write_pose_outputs(files, outputs, track, poses_topic, poses_child_frame or f"{rec.object_frame}_tracked")
        empty = [str(p) for p in outputs if str(p).lower().endswith((".tum", ".mcap"))]
        if empty and not track.tracked().any():
            log.warning("no frame tracked: %s hold%s no pose (poses.json says why each frame is lost)",
                        ", ".join(empty), "s" if len(empty) == 1 else "")
    return TrackingResult(track, time.perf_counter() - t0, [str(p) for p in (*outputs, rrd) if p], tracker.params,
                          tracker.limits_source)


def _check_child_frame(child: str | None, rec, mcap_outputs) -> None:
    """The poses MCAP's FrameTransforms go from the camera frame to ``child``: the camera frame itself
    would be its own parent (InputError), and the object frame of the recording gets a second parent
    beside its recorded one (a warning: Foxglove shows one of them)."""
    if child is None or not mcap_outputs:
        return
    named = frame_name(child)   # as the tree keys it
    if named == rec.camera_frame:
        raise InputError(f"--poses-child-frame {child}: that is the poses' parent frame (the camera's), and a "
                         f"frame cannot be its own parent; give another name (default {rec.object_frame}_tracked)")
    if named in rec.tree.frames:
        log.warning("--poses-child-frame %s: the recording's transform tree has that frame already; the tracked "
                    "poses give it a second parent, and Foxglove shows one of the two (default %s_tracked)",
                    child, rec.object_frame)
