"""``view``: any mix of a recording, models, frames, poses and truth files, shown in Rerun or drawn
as a picture."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import AccumError, InputError
from ..geometry import invert, transform_from_quat
from ..model_io import check_kind, read_frames, read_model, read_poses, read_truth
from ..outputs import OutputSet
from ..segments import Segments
from .base import FrameRange, Progress, RecordingOptions, frame_range, no_progress, path_list
from .checks import check_same_time

log = logging.getLogger("accumcli")


@dataclass
class ViewInputs:
    """The inputs sorted by kind (recognised by content): at most one recording, models by name, a
    truth's edges (``Segments``, drawn apart from the models), pose tracks and frames files."""

    recording: str | None = None
    models: dict = field(default_factory=dict)
    truth: Segments | None = None
    truth_poses: object = None     # the truth file's (``Truth``: its ``pose_at``), where the truth is drawn
    tracks: list = field(default_factory=list)
    track_paths: list = field(default_factory=list)
    frames_files: list = field(default_factory=list)

    @classmethod
    def of(cls, paths) -> "ViewInputs":
        inputs = cls()
        for path in paths:
            kind = check_kind(path, "recording", "model", "frames", "poses", "truth")
            if kind == "recording":
                if inputs.recording is not None:
                    raise InputError(f"{path}: give at most one recording (already {inputs.recording})")
                inputs.recording = str(path)
            elif kind == "model":
                inputs.models[inputs._name(Path(path).stem.replace(".", "_"))] = read_model(path)
            elif kind == "truth":
                truth = read_truth(path)
                direction = truth.b - truth.a
                length = np.linalg.norm(direction, axis=1)
                if inputs.truth is not None:
                    raise InputError(f"{path}: give at most one truth")
                inputs.truth = Segments(truth.object_frame, (truth.a + truth.b) / 2, direction / length[:, None],
                                        length, np.ones(len(length)), np.ones(len(length), np.int64))
                inputs.truth_poses = truth
            elif kind == "poses":
                inputs.tracks.append(read_poses(path))
                inputs.track_paths.append(str(path))
            elif kind == "frames":
                inputs.frames_files.append(str(path))
            else:
                raise InputError(f"{path}: accum view cannot show a {kind} file")
        return inputs

    def _name(self, stem: str) -> str:
        """``stem``, or ``stem_2``, ``stem_3``... when a model of that name is shown already (two
        out/*/model.json would otherwise be one entity, the second hiding the first)."""
        name, k = stem, 1
        while name in self.models:
            k += 1
            name = f"{stem}_{k}"
        return name

    def truth_pose(self, t_ns: int) -> np.ndarray | None:
        """The truth file's own T_camera_object at ``t_ns`` (None: no truth, or no pose then)."""
        return None if self.truth_poses is None else self.truth_poses.pose_at(int(t_ns))

    def check_tracks(self, span_ns, tolerance_ns: int, recording: str) -> None:
        """AccumError when a poses file's times lie outside the recording's (``span_ns``): it would
        place nothing, and the recording's own poses would be shown instead without a word."""
        for track, path in zip(self.tracks, self.track_paths):
            check_same_time(track.times_ns, span_ns, tolerance_ns, path, recording)

    def pose_at(self, t_ns: int, recorded: np.ndarray | None, tolerance_ns: int) -> tuple[np.ndarray | None, str]:
        """The object's pose at ``t_ns`` and where it comes from: the first poses file with an entry
        within the tolerance decides (its pose where that entry is 'tracked', or has no status; else
        no pose, and its status and reason: a tracker's failure is shown as one, not hidden behind
        the recording's pose); without such an entry, ``recorded`` ('recorded')."""
        for track, path in zip(self.tracks, self.track_paths):
            if not len(track.times_ns):
                continue
            i = int(np.argmin(np.abs(track.times_ns - t_ns)))
            if abs(int(track.times_ns[i]) - t_ns) > tolerance_ns:
                continue
            status = track.status[i] if track.status else "tracked"
            if status == "tracked" and np.isfinite(track.poses[i]).all():
                return track.poses[i], f"{Path(path).name}: tracked"
            reason = track.extra[i].get("reason", "") if track.extra else ""
            return None, f"{Path(path).name}: {status}" + (f" ({reason})" if reason else "")
        return recorded, "recorded"


def view(paths, *, rrd=None, spawn: bool = False, connect: str | None = None, png=None,
         png_frame: int | None = None, options: RecordingOptions = RecordingOptions(),
         frames: FrameRange = FrameRange(), progress: Progress = no_progress,
         object_frame_of_model: bool = False) -> list[str]:
    """Show ``paths`` in Rerun (exactly one of ``rrd``, ``spawn``, ``connect``) and/or draw ``png``.
    With a recording, world is the left camera frame and each model (and the truth) is placed at the
    object's pose in every frame: a poses file's where it has that frame (none where that frame is
    not 'tracked': the tracker's status and reason are logged on ``pose_source``), else the
    recording's. Without a recording but with poses files, the same at each of their times (no
    images). With neither, world is the object frame: the models and truth as they are, a frames
    file's segments placed by its lines' ``T_camera_object``. ``frames`` selects recording frames, of a
    frames file by its lines' ``frame_index``. ``object_frame_of_model``: the recording's object frame is
    the one the models name, when they name one (``options.object_frame`` is then only a default: on the
    chessboard, whose model is in 'board', the view showed no model and said nothing). Returns the
    files written."""
    paths, frames = path_list(paths, "paths"), frame_range(frames)
    if sum(map(bool, (rrd, spawn, connect))) > 1:
        raise InputError("choose one of --rrd, --spawn and --connect")
    if not (rrd or spawn or connect or png):
        raise InputError("nothing to do: give --rrd, --spawn, --connect or --png")
    if png_frame is not None and not frames.contains(png_frame):
        raise InputError(f"--png-frame {png_frame} lies outside --frames {frames}")
    inputs = ViewInputs.of(paths)
    named = {m.frame_id for m in inputs.models.values() if m.frame_id}
    model_frame = named.pop() if object_frame_of_model and len(named) == 1 else None
    files = OutputSet([rrd, png], inputs=paths)
    with files:
        if rrd or spawn or connect:
            _log_to_rerun(inputs, files.path(rrd) if rrd else None, spawn, connect, options, frames, progress,
                          model_frame)
        if png:
            _draw_picture(inputs, files.open(png, "wb"), png_frame, frames, options, model_frame)
    return [str(p) for p in (rrd, png) if p]


def _open(recording, options: RecordingOptions, model_frame: str | None):
    """The recording, its poses those of the object frame the models name (``model_frame``) where its
    tree has that frame (a model of another object keeps ``options.object_frame``, and so the
    recording's poses); the frame is chosen on the opening that reads the recording anyway (a look of
    its own read the whole file once more)."""
    rec = options.open(recording, require_pose=False)
    if model_frame and model_frame != rec.object_frame and model_frame in rec.tree.frames:
        log.info("the object's frame is the model's: %s (--object-frame shows it in another)", model_frame)
        rec.object_frame = model_frame
    return rec


def _log_to_rerun(inputs: ViewInputs, rrd, spawn, connect, options, frames, progress, model_frame=None) -> None:
    from ..visualize import RerunLog, model_path

    viz = RerunLog("accum view", rrd=rrd, kind="view", spawn=spawn, connect=connect,
                   images=inputs.recording is not None)
    positions = []
    if inputs.recording:
        with _open(inputs.recording, options, model_frame) as rec:
            total = frames.check(rec)
            inputs.check_tracks(rec.time_span_ns, options.tolerance_ns, inputs.recording)
            for done, frame in enumerate(rec.frames(frames.start, frames.stop), 1):
                T, source = inputs.pose_at(frame.timestamp_ns, frame.T_camera_object, options.tolerance_ns)
                viz.recording_frame(frame, inputs.models, T, source, inputs.truth,
                                    inputs.truth_pose(frame.timestamp_ns))
                if T is not None:
                    if not positions:   # the first frame with a pose tells whether the models fit the images
                        _check_fit(inputs.models, frame, T)
                    positions.append(T[:3, 3])
                progress(done, total)
    elif inputs.tracks:   # world = the camera frame: the models at the poses files' times and poses
        times = np.unique(np.concatenate([track.times_ns for track in inputs.tracks]))
        chosen = list(enumerate(times))[frames.start:frames.stop]   # --frames: positions among those times
        for done, (index, t_ns) in enumerate(chosen, 1):
            progress(done, len(chosen))
            T, source = inputs.pose_at(int(t_ns), None, options.tolerance_ns)
            viz.set_frame(index, int(t_ns))
            viz.posed(inputs.models, T, source, inputs.truth, inputs.truth_pose(int(t_ns)))
            if T is not None:
                positions.append(T[:3, 3])
    else:   # world = the object frame
        for name, model in inputs.models.items():
            viz.model(model, np.eye(4), model_path(name))
        if inputs.truth is not None:
            viz.truth(inputs.truth)
    if positions:
        viz.trajectory(np.array(positions))
    object_world = not (inputs.recording or inputs.tracks) and (inputs.models or inputs.truth is not None)
    for path in inputs.frames_files:
        unplaced = 0
        for index, (t_ns, segments, doc) in enumerate(read_frames(path)):
            number = doc.get("frame_index")
            if not frames.contains(number if isinstance(number, int) and not isinstance(number, bool) else index):
                continue
            T_world_camera = np.eye(4)
            if object_world:   # the line's pose places its segments beside the model
                pose = doc.get("T_camera_object")
                try:
                    T_world_camera = invert(transform_from_quat(pose["translation"], pose["rotation_xyzw"]))
                except (KeyError, TypeError, ValueError):
                    unplaced += 1
                    continue
            viz.frame_segments(doc.get("frame_index", index), t_ns, segments, T_world_camera)
        if unplaced:
            log.warning("%s: %d frames have no T_camera_object and are not shown (the model is drawn in the "
                        "object frame); add the recording to show them in the camera's", path, unplaced)
    viz.close()


def _check_fit(models: dict, frame, T_camera_object: np.ndarray, gradients=None) -> None:
    """Warn for each model (name -> Segments) that the frame's images do not show where the pose puts it:
    refined from that pose, the tracker does not call it 'tracked' (a model of another object was drawn
    at the recording's poses without a word; ``accum track`` refuses the pair). ``gradients``: the
    frame's, if its extraction computed them already."""
    from ..track import refine_pose

    for name, model in models.items():
        if not model.accepted.any():
            continue
        estimate = refine_pose(model, frame, T_camera_object, gradients=gradients)
        if estimate.status != "tracked":
            log.warning("%s does not fit frame %d's images at the pose shown (the tracker, refined from it: %s, %s): "
                        "a model of another object, or of another object frame? (A model of other aspects of this "
                        "object can also miss a frame.)", name, frame.index, estimate.status,
                        estimate.reason or f"coverage {estimate.coverage:.2f}")


def middle_frame(frames, count: int) -> int:
    """The middle one of the frames ``frames`` (a ``FrameRange``) selects from a recording of ``count``."""
    return frames.start + frames.count_in(count) // 2


def _draw_picture(inputs: ViewInputs, png, png_frame, frames, options, model_frame=None) -> None:
    """The model alone, or (with a recording) one frame, its extraction and the model, as in the paper:
    ``png_frame``, or the middle one of ``frames`` (a ``FrameRange``)."""
    from ..extract import extract_frame
    from ..render import render_frame_panel, render_model, render_models, write_png

    if not inputs.models and inputs.truth is None:
        raise InputError("a picture (--png) needs a model among the inputs")
    # every model, over the truth's edges (the truth alone is drawn as a model)
    named = inputs.models or {"truth": inputs.truth}
    object_frames = {m.frame_id for m in named.values() if m.frame_id}
    if len(object_frames) > 1:
        log.warning("the models are in different object frames (%s): drawn as one object",
                    ", ".join(sorted(object_frames)))
    truth_ends = inputs.truth.endpoints() if inputs.models and inputs.truth is not None else None
    if not inputs.recording:
        write_png(png, render_model(*named.values(), truth_ends=truth_ends) if len(named) == 1
                  else render_models(named, truth_ends=truth_ends))
        return
    with _open(inputs.recording, options, model_frame) as rec:
        inputs.check_tracks(rec.time_span_ns, options.tolerance_ns, inputs.recording)
        wanted = png_frame if png_frame is not None else middle_frame(frames, rec.frame_count_hint)
        for frame in rec.frames(wanted, wanted + 1):
            T, source = inputs.pose_at(frame.timestamp_ns, frame.T_camera_object, options.tolerance_ns)
            if T is None:
                why = "" if source == "recorded" else f" ({source})"
                raise AccumError(f"{inputs.recording}: frame {wanted} has no pose to place the model{why}")
            (name, first), *others = named.items()
            extraction = extract_frame(frame)
            _check_fit(inputs.models, frame, T, extraction.gradients)   # the extraction's gradients, not again
            write_png(png, render_frame_panel(frame, extraction, first, T, truth_ends, dict(others), name))
            return
        raise AccumError(f"{inputs.recording}: no frame {wanted} (the recording has {rec.frame_count_hint})")
