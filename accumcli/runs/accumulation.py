"""``accumulate_recording``: the model of the object over a recording, with the frame-by-frame
figures, pictures and Rerun log the user asked for."""

from __future__ import annotations

from contextlib import closing
import collections
import logging
import pickle
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import AccumError, InputError
from ..evaluate import EdgeSamples, score_segments
from ..lines2d import StageTimes
from ..logs import LimitedWarnings
from ..geometry import invert, pose_error
from ..model_io import POSES_TOPIC, PoseTrack, read_truth, write_json_lines, write_model, write_ply
from ..motion import MotionParams, corrected, frame_to_frame, fuse, object_segments, on_model
from ..outputs import OutputSet
from ..pipeline import AccumulateParams, LineAccumulation
from ..row_check import RowCheck
from ..motion_check import MotionCheck
from ..segments import Segments
from ..surface import faces_of
from .base import (MODEL_OUTPUTS, POSES_OUTPUTS, FrameRange, Progress, RecordingOptions, check_output_kinds,
                   frame_range, in_frames, no_progress, nothing_done, path_list, write_pose_outputs)
from .checks import check_same_time, check_truth_matches, check_truth_poses
from .frame_logs import rerun_log, scene_log
from .parallel import extracted_frames, resolve_workers

log = logging.getLogger("accumcli")

POSES_COMPARED = 5    # the first frames' recorded poses compared with a given truth's (``check_truth_poses``)


@dataclass
class AccumulationResult:
    """The final model (object frame), the frames used and skipped (reason -> count), one row of
    figures per used frame (counts; with a truth, precision / completeness / background of the
    accepted segments so far), the final scores against the truth, per-stage times, the number of
    frames whose refined pose was used (tracked motion), the wall time and the files written."""

    model: Segments
    row_warning: str | None = None   # what the rows' check (``row_check``) found, None when nothing
    offset_warning: str | None = None  # what the images' time stamps' check (``motion_check``) found
    scale_warning: str | None = None   # what the depth scale's check (``motion_check``) found
    jitter_warning: str | None = None  # what the recorded poses' jitter check (``motion_check``) found
    frames: int = 0
    skipped: dict = field(default_factory=dict)
    rows: list = field(default_factory=list)
    scores: dict | None = None
    times: StageTimes = field(default_factory=StageTimes)
    refined_frames: int = 0
    seconds: float = 0.0
    outputs: list = field(default_factory=list)
    distances_m: list = field(default_factory=list)   # the object's distance from the camera per frame, by its pose

    @property
    def accepted(self) -> int:
        return int(self.model.accepted.sum())

    @property
    def pairs_per_second(self) -> float:
        return self.frames / max(self.seconds, 1e-9)


def accumulate_recording(recording, outputs=(), *, params: AccumulateParams = AccumulateParams(),
                         options: RecordingOptions = RecordingOptions(), frames: FrameRange = FrameRange(),
                         truth=None, history=None, plot=None, rrd=None, png=None, panel=None,
                         ply_all: bool = False, poses=(),
                         workers: int | None = 1, progress: Progress = no_progress) -> AccumulationResult:
    """Accumulate the frames in ``frames`` of ``recording`` into one model.

    outputs: model files, ``.json`` (accum.model/1), ``.ply`` (accepted segments; all with
    ``ply_all``) and/or ``.mcap`` (the model of every frame as a Foxglove SceneUpdate in the object
    frame, and its counts, ``foxglove_scene``); truth: a truth sidecar path, to score the model
    frame by frame; history: JSON lines, one row per frame; plot: a PNG of those rows over the
    frames (``plots``); rrd: a Rerun recording; png / panel: pictures of the model and of the last
    frame; poses (``motion='tracked'`` only): the repaired poses T_camera_object, as ``accum track``
    writes them (``POSES_OUTPUTS``), each with its status (``REPAIR_STATUS``) and its correction of the
    recorded pose (``correction_deg``, ``correction_mm``): a robot's /tf checked on the images. All
    outputs are checked before the work and written together at the end. workers: processes
    extracting the next frames while this one accumulates (``runs.parallel``; the same model bytes
    whatever the number; None: ``parallel.resolve_workers``; more than 1 starts them from a fork
    server, which imports the caller's main module: guard a script's entry point with
    ``if __name__ == "__main__":``). params: extraction, line model, update rule and motion
    (``AccumulateParams``); options: topics, frames and time tolerance (``RecordingOptions``);
    progress: ``Progress``. Raises ``AccumError`` (``InputError`` for bad arguments,
    ``RecordingError`` for a recording that cannot be used).
    """
    outputs, frames, poses = path_list(outputs, "outputs"), frame_range(frames), path_list(poses, "poses")
    check_output_kinds(outputs, MODEL_OUTPUTS)
    check_output_kinds(poses, POSES_OUTPUTS)
    if poses and params.motion != "tracked":
        raise InputError("the poses output holds the poses that --motion tracked repairs: add --motion tracked "
                         "(with the recorded poses, the recording's /tf is what it holds)")
    if ply_all and not any(str(path).lower().endswith(".ply") for path in outputs):
        raise InputError("--all chooses what a .ply output holds, and no .ply output is given")
    files = OutputSet([*outputs, *poses, history, plot, rrd, png, panel], inputs=[recording, truth])
    edges = None
    if truth is not None:
        truth_doc = read_truth(truth)
        check_truth_matches(truth_doc, options.object_frame, truth, "the run")
        edges = EdgeSamples.of(truth_doc)
    t0 = time.perf_counter()
    with options.open(recording) as rec, files:
        total = frames.check(rec)
        if truth is not None:
            check_same_time(truth_doc.times_ns, rec.time_span_ns, options.tolerance_ns, truth, recording)
        workers = resolve_workers(workers, total)
        acc = LineAccumulation(params, rec.object_frame, rec.camera_frame)
        result = AccumulationResult(acc.model(), times=acc.times)
        step, done, rows, motion_check, recorded = None, 0, RowCheck(), MotionCheck(), []

        # --motion tracked streams the recording once per pass (``tracked_poses``): one bar over all of
        # them, each pass's frames weighted by what a frame of it costs (``TRACKED_PASS_COST``)
        costs = TRACKED_PASS_COST if params.motion == "tracked" else (1,)
        total_steps = None if total is None else total * sum(costs)
        passes_begun = 0

        def counted_frames():
            nonlocal done, passes_begun
            cost = costs[min(passes_begun, len(costs) - 1)]
            passes_begun += 1
            for frame in rec.frames(frames.start, frames.stop):
                done += cost
                progress(done, total_steps)
                yield frame

        def frames_with_pose():
            for frame in counted_frames():
                if frame.T_camera_object is None:
                    no_pose.warning("no pose", "%s: frame %d: no pose (%s): skipped", recording, frame.index,
                                    frame.pose_problem)
                    result.skipped[frame.pose_problem] = result.skipped.get(frame.pose_problem, 0) + 1
                    continue
                yield frame

        repaired, store, repair_rows = None, None, []
        if params.motion == "tracked":
            with_pose = (lambda: (f for f in counted_frames() if f.T_camera_object is not None))
            store = ExtractionStore()
            repaired, repair_status, pose_covariance = tracked_poses(with_pose, params, rec.object_frame, rec.camera_frame, workers,
                                                    acc.times, store)
        # closing: an interrupt must end the extraction helpers here, not when the generator is collected
        with rerun_log(files, rrd, "accumulate") as viz, scene_log(files, outputs) as scenes, \
                LimitedWarnings(log) as no_pose, \
                closing(store.replay(frames_with_pose()) if store else extracted_frames(
                    frames_with_pose(), params.extract, rec.camera_frame, workers, acc.times)) as extractions:
            for frame, extraction in extractions:
                step = acc.step(frame, frame.T_camera_object, extraction,
                                T_corrected=None if repaired is None else repaired[frame.index],
                                pose_covariance=None if repaired is None else pose_covariance.get(frame.index))
                if repaired is not None:
                    repair_rows.append((frame.timestamp_ns, frame.T_camera_object, repaired[frame.index],
                                        repair_status[frame.index]))
                rows.add(step.extraction, frame.intrinsics, frame.T_camera_object)
                motion_check.add(step.extraction.segments, frame.T_camera_object, frame.timestamp_ns)   # the recorded motion
                result.distances_m.append(float(np.linalg.norm(frame.T_camera_object[:3, 3])))
                if truth is not None and len(recorded) < POSES_COMPARED:
                    recorded.append((frame.timestamp_ns, frame.T_camera_object))
                    if len(recorded) == POSES_COMPARED:   # before the run goes on with the truth of another recording
                        check_truth_poses(truth_doc, *zip(*recorded), "the run", truth, options.tolerance_ns)
                row = {"frame_index": frame.index, "timestamp_ns": frame.timestamp_ns, **step.stats.__dict__}
                if params.box is not None:
                    row["outside_box"] = step.outside_box
                if params.temporal is not None:
                    row.update(across_frames=step.across_frames, across_frames_replacing=step.replaced)
                if step.tracking is not None:
                    row.update(tracking=step.tracking.status, residual_px=step.tracking.residual_px)
                if edges is not None or viz or scenes:
                    model = acc.model()
                if scenes:
                    for scene in scenes:
                        scene.frame(model, frame.timestamp_ns, row)
                if edges is not None:
                    row.update(score_segments(model.select(model.accepted), edges).as_dict())
                    row.pop("segments")
                if viz:
                    viz.accumulation(step, model, row)
                result.rows.append(row)
        if store:
            store.close()
        result.frames = len(result.rows)
        if truth is not None and 0 < len(recorded) < POSES_COMPARED:
            check_truth_poses(truth_doc, *zip(*recorded), "the run", truth, options.tolerance_ns)
        if result.frames == 0:
            raise nothing_done(recording, f"no frame{in_frames(frames)} has both images and a pose of "
                                          f"{rec.object_frame!r} in {rec.camera_frame!r}; nothing was accumulated",
                               result.skipped, rec)
        result.model = acc.model()
        if len(result.model) == 0:   # an empty model is no result (calibration or images are wrong)
            raise AccumError(f"{recording}: the model is empty: {_nothing_accepted(result)}")
        if result.accepted == 0:     # nothing claimed: units or frames are likely wrong, or too few frames
            log.warning("%s: the model accepted no segment: %s", recording, _nothing_accepted(result))
        result.row_warning = rows.report(recording, params.extract.stereo.row_offset_px)
        # a wrong clock or scale also scatters re-observations: named once, by its cause; --motion tracked
        # repairs jitter
        result.offset_warning = motion_check.offset_warning(options.time_offset_ns * 1e-6)
        result.scale_warning = None if result.offset_warning else motion_check.scale_warning()
        if not (result.offset_warning or result.scale_warning) and params.motion != "tracked":
            result.jitter_warning = motion_check.jitter_warning()
        for text in (result.offset_warning, result.scale_warning, result.jitter_warning):
            if text:
                log.warning("%s: %s", recording, text)
        result.refined_frames = sum(not np.allclose(T, np.eye(4)) for T in acc.T_recorded_model)
        if edges is not None:   # the last row scored this very model
            result.scores = {"segments": result.accepted,
                             **{k: result.rows[-1][k] for k in ("precision", "completeness", "background")}}
            if faces_of(truth_doc.meta):   # such a truth judges precision by surface (``accum eval``)
                result.scores["judge_by_surface"] = True
        for path in outputs:
            if str(path).lower().endswith(".mcap"):
                continue   # written frame by frame above
            if str(path).lower().endswith(".ply"):
                write_ply(files.open(path), result.model, all_segments=ply_all)
            else:   # the times it was accumulated over: ``accum eval`` refuses a truth of other times
                write_model(files.open(path), result.model,
                            source_times_ns=[result.rows[0]["timestamp_ns"], result.rows[-1]["timestamp_ns"]])
        if poses:   # in the object frame of the model written (``LineAccumulation.T_object_model``)
            times_ns, recorded_poses, used, status = zip(*repair_rows)
            written = np.array(used) @ invert(acc.T_object_model())
            write_pose_outputs(files, poses, PoseTrack(
                rec.camera_frame, rec.object_frame, np.array(times_ns, np.int64), written, list(status),
                [pose_correction(T_recorded, T) for T_recorded, T in zip(recorded_poses, written)]),
                POSES_TOPIC, f"{rec.object_frame}_repaired")
        if history:
            write_json_lines(files.open(history), result.rows)
        if plot:
            from ..plots import plot_frames

            plot_frames(files.open(plot, "wb"), result.rows, f"accum accumulate {Path(recording).name}")
        if png or panel:
            from ..render import render_frame_panel, render_model, write_png

            if png:
                write_png(files.open(png, "wb"), render_model(result.model))
            if panel:
                write_png(files.open(panel, "wb"), render_frame_panel(step.frame, step.extraction, result.model,
                                                                step.T_camera_object))
    result.seconds = time.perf_counter() - t0
    result.outputs = [str(p) for p in (*outputs, *poses, history, plot, rrd, png, panel) if p]
    return result


class ExtractionStore:
    """Each frame's extraction (without its gradients) kept in a temporary file by the first pass over a
    recording and read back, in order, by the later ones: the extraction runs once however many passes
    (``--motion tracked`` makes five: ``TRACKED_PASS_COST``), and memory stays flat (the file grows by about 160 kB a frame;
    it is deleted when closed or collected)."""

    def __init__(self):
        self.file = tempfile.TemporaryFile()

    def record(self, extractions):
        """(frame, extraction) pairs passed through, each extraction written (gradients dropped)."""
        for frame, extraction in extractions:
            extraction.gradients = None   # megabytes a frame; refinement computes the same ones again
            pickle.dump(extraction, self.file, protocol=pickle.HIGHEST_PROTOCOL)
            yield frame, extraction

    def replay(self, frames):
        """(frame, its recorded extraction) for the same frames, in the same order, as recorded."""
        self.file.seek(0)
        for frame in frames:
            extraction = pickle.load(self.file)
            if extraction.index != frame.index:
                raise RuntimeError(f"replayed extraction of frame {extraction.index} for frame {frame.index}")
            yield frame, extraction

    def close(self) -> None:
        self.file.close()


def _nothing_accepted(result: AccumulationResult) -> str:
    """Why a model accepted no segment, as far as the run can tell, and what to check."""
    if result.frames < 2:
        return "one frame confirms no segment (a segment is accepted when a second frame sees it again); give more frames"
    observed = sum(row.get("observed", 0) for row in result.rows) / result.frames
    outside = sum(row.get("outside_box", 0) for row in result.rows)
    if observed == 0 and outside:
        return (f"all {outside} 3D segments of {result.frames} frames lay outside --box: give it in metres in the "
                f"object's frame (the poses' T_camera_object), the object {np.median(result.distances_m):.3g} m from "
                "the camera by them")
    if observed == 0:
        return (f"no 3D segment was extracted in {result.frames} frames: check the images (8 bits, or 16 with "
                "their bit depth) and the calibration")
    where = f", the object {np.median(result.distances_m):.3g} m from the camera by the poses"
    return (f"{result.frames} frames gave {observed:.0f} 3D segments each but no model segment was seen again "
            f"where the poses put it{where}: check that the poses are T_camera_object in metres and that "
            f"they belong to these images (--object-frame, --camera-frame)")


# how ``tracked_poses`` placed a frame (the status of ``accum accumulate --poses``): its fused pose was
# refined on the model of the fused poses and the refinement verified there (and fused again); else
# frame-to-frame refinements with its neighbours placed it (``fuse`` kept at least one); else neither: its
# recorded pose
REPAIR_STATUS = ("tracked", "linked", "recorded")

# ``tracked_poses``' four passes over the recording, then the accumulation itself: what a frame of each
# costs, relative to the lightest (measured with workers=1: on the teabox 6.0, 3.1, 1.2, 2.6 and 1.3 s,
# on sim_box 1.25, 0.81, 0.33, 0.50 and 0.40 s), for an ETA that holds from the first pass on: counted
# alike, the first pass (extraction) promised 2.5 minutes for a 14 s run
TRACKED_PASS_COST = (4, 2, 1, 2, 1)
TRACKED_PASSES = len(TRACKED_PASS_COST)


def pose_correction(T_recorded: np.ndarray, T_repaired: np.ndarray) -> dict:
    """How far a repaired pose moved the recorded one: ``correction_deg`` (the rotation's angle) and
    ``correction_mm`` (the translation of the object frame's origin, camera frame)."""
    angle_deg, translation_m = pose_error(T_repaired, T_recorded)
    return {"correction_deg": round(angle_deg, 4), "correction_mm": round(translation_m * 1000, 4)}


def tracked_poses(frames_with_pose, params: AccumulateParams, object_frame: str, camera_frame: str, workers: int,
                  times, store: ExtractionStore, motion: MotionParams = MotionParams()
                  ) -> tuple[dict[int, np.ndarray], dict[int, str], dict[int, np.ndarray]]:
    """frame index -> the repaired T_camera_object (4, 4) of every frame ``frames_with_pose()`` yields,
    frame index -> how the images placed it (``REPAIR_STATUS``) and frame index -> its (6, 6)
    covariance (``motion.fuse``; empty where nothing was fused)
    (called once per pass: the recording is streamed again; its extractions are recorded in ``store``
    by pass 1 and replayed after), by the passes of ``motion``: pass 1 accumulates with the recorded
    poses, pass 2 measures the frame-to-frame corrections against pass 1's accepted segments, ``fuse``
    combines them with the recorded poses, pass 3 accumulates with the fused poses and refines each
    on that model (``on_model``), and ``fuse`` solves again with these refinements. The models of
    these passes average the stereo directions (``view_planes`` off): the planes trust the poses to
    half a degree, and these poses are not yet repaired (``make motion`` with view-plane models in
    every pass: worst shortfall 0.090 against 0.048; in pass 3 alone, median pose error 0.57 deg
    against 0.53). They accept segments seen from one aspect by the 5-degree rule alone
    (``single_aspect_sigma_deg`` off): they serve to place frames, where a segment of one aspect
    still pins the pose, and the poses are not yet good enough for the one-aspect rule. With the
    rule in these passes too: ``make motion`` 7 of 12 within 0.02 against 8, the real teabox's
    completeness 0.624 against 0.697 (``benchmarks/suite.py --only teabox --motion tracked``; both
    with the first, two-part form of ``metric``'s direction gate). Nor do they leave a frame's miss
    unsaid where it extracted nothing along a shown edge (``unextracted_no_miss``, which the final
    accumulation has): with it in these passes the repaired poses of seed 301 were 0.97 degrees off
    instead of 0.65, and the shortfalls of seeds 301, 306 and 312 (one run each) 0.059, 0.030 and
    0.019 against 0.033, 0.013 and 0.013 without."""
    averaging = replace(params.line_model, view_planes=False, single_aspect_sigma_deg=None, unextracted_no_miss=False)

    def accepted(extractions, pose_of) -> Segments:
        """The accepted segments of an accumulation, with the known motion, of (frame, extraction) pairs,
        each frame placed by ``pose_of(frame)``."""
        accumulation = LineAccumulation(AccumulateParams(params.extract, averaging, params.rule, box=params.box),
                                        object_frame, camera_frame)
        for frame, extraction in extractions:
            accumulation.step(frame, pose_of(frame), extraction)
        model = accumulation.model()
        return model.select(model.accepted)

    with closing(extracted_frames(frames_with_pose(), params.extract, camera_frame, workers, times)) as extractions:
        skeleton = accepted(store.record(extractions), lambda frame: frame.T_camera_object)
    recorded, links, previous = [], {}, collections.deque(maxlen=motion.span)
    for frame, extraction in store.replay(frames_with_pose()):
        k = len(recorded)
        for j, segments in previous:
            t0 = time.perf_counter()
            c = frame_to_frame(segments, frame, frame.T_camera_object, params.track, extraction.gradients, motion)
            times.add("tracking", t0)
            if c is not None:
                links[j, k] = c
        previous.append((k, object_segments(extraction.segments, frame.T_camera_object, skeleton, motion)))
        recorded.append((frame.index, frame.T_camera_object))
    def placed(x: np.ndarray) -> dict[int, np.ndarray]:
        return {index: corrected(T, xk) for (index, T), xk in zip(recorded, x)}

    x, covariance = fuse(links, len(recorded), motion)
    poses = placed(x)
    # a frame that ``fuse`` left unlinked (no link, or all of them dropped) keeps its recorded pose exactly
    status = {index: "linked" if np.any(xk) else "recorded" for (index, _), xk in zip(recorded, x)}
    if motion.model_pass:
        model = accepted(store.replay(frames_with_pose()), lambda frame: poses[frame.index])
        measured = {}
        for k, (frame, extraction) in enumerate(store.replay(frames_with_pose())):
            t0 = time.perf_counter()
            found = on_model(model, frame, poses[frame.index], params.track, extraction.gradients, motion)
            times.add("tracking", t0)
            if found is not None:
                measured[k] = (x[k] + found[0], found[1])   # T_recorded exp(x_k) exp(c) ~ T_recorded exp(x_k + c)
                status[frame.index] = "tracked"
        x, covariance = fuse(links, len(recorded), motion, measured)
        poses = placed(x)
    covariances = {} if covariance is None else {index: motion.covariance_scale * C
                                                 for (index, _), C in zip(recorded, covariance)}
    return poses, status, covariances

