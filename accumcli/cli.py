"""The ``accum`` command line: parses options, calls the library, reports.

One error policy: an ``AccumError`` (a problem the user can fix) ends in one
line ``error: ...`` on stderr and exit status 1; anything else is a bug and
keeps its traceback. Warnings from the library (a skipped frame) go to stderr
as ``warning: ...``.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import sys

import click
import numpy as np

from . import __version__
from .errors import AccumError

log = logging.getLogger("accumcli")


# -- plumbing -----------------------------------------------------------------------------------
class _ClickHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        prefix = {logging.WARNING: "warning: ", logging.ERROR: "error: "}.get(record.levelno, "")
        click.echo(prefix + record.getMessage(), err=True)


class AccumGroup(click.Group):
    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except AccumError as e:
            click.echo(f"error: {e}", err=True)
            ctx.exit(1)
        except KeyboardInterrupt:
            click.echo("error: interrupted", err=True)
            ctx.exit(130)


@click.group(cls=AccumGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="accum")
@click.option("-v", "--verbose", count=True, help="More detail (-vv for debugging output).")
@click.option("-q", "--quiet", is_flag=True, help="No progress bars, only warnings and errors.")
@click.pass_context
def main(ctx: click.Context, verbose: int, quiet: bool) -> None:
    """Accumulate 3D line-segment models of a grasped object from stereo recordings.

    \b
    Typical session on the bundled sample:
      accum info sample_data/sim_box.mcap
      accum extract sample_data/sim_box.mcap -o out/frames.jsonl
      accum accumulate sample_data/sim_box.mcap -o out/model.json -o out/model.ply --rrd out/run.rrd
      accum eval out/model.json sample_data/sim_box.truth.json
    """
    ctx.obj = {"verbose": verbose, "quiet": quiet}
    if not log.handlers:
        log.addHandler(_ClickHandler())
    log.propagate = False
    log.setLevel(logging.DEBUG if verbose > 1 else logging.INFO if verbose else logging.WARNING)


def _progress_enabled(ctx: click.Context) -> bool:
    return not ctx.obj.get("quiet") and sys.stderr.isatty()


@contextlib.contextmanager
def progress_bar(ctx: click.Context, length: int | None, label: str):
    """A click progress bar on stderr (only on a terminal and without --quiet); yields update(n)."""
    if not _progress_enabled(ctx) or not length:
        yield lambda n=1: None
        return
    with click.progressbar(length=length, label=label, file=sys.stderr, show_pos=True, show_eta=True) as bar:
        yield bar.update


class FrameRange(click.ParamType):
    """``START:STOP`` (either may be empty) or a single index."""

    name = "START:STOP"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        text = str(value).strip()
        try:
            if ":" in text:
                start, stop = text.split(":", 1)
                result = (int(start) if start else 0, int(stop) if stop else None)
            else:
                result = (int(text), int(text) + 1)
        except ValueError:
            self.fail(f"expected START:STOP with whole numbers, found {value!r}", param, ctx)
        if result[0] < 0 or (result[1] is not None and result[1] <= result[0]):
            self.fail(f"expected 0 <= START < STOP, found {value!r}", param, ctx)
        return result


def recording_options(func):
    """Options shared by every command that reads a recording (declared once, here)."""
    options = [
        click.option("--object-frame", default="gripper", show_default=True,
                     help="Frame of the object (the gripper) in the transform tree."),
        click.option("--camera-frame", default="camera_left", show_default=True,
                     help="Rectified left camera optical frame."),
        click.option("--tolerance-ms", type=click.FloatRange(min=0.0), default=1.0, show_default=True,
                     help="Left/right pairing and transform time tolerance."),
        click.option("--left-topic", default="/stereo/left/image", show_default=True),
        click.option("--right-topic", default="/stereo/right/image", show_default=True),
        click.option("--left-calibration-topic", default="/stereo/left/calibration", show_default=True),
        click.option("--right-calibration-topic", default="/stereo/right/calibration", show_default=True),
        click.option("--tf-topic", default="/tf", show_default=True),
    ]
    for option in reversed(options):
        func = option(func)

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from .recording import Topics

        kwargs["recording_kwargs"] = dict(
            topics=Topics(left_image=kwargs.pop("left_topic"), right_image=kwargs.pop("right_topic"),
                          left_calibration=kwargs.pop("left_calibration_topic"),
                          right_calibration=kwargs.pop("right_calibration_topic"), tf=kwargs.pop("tf_topic")),
            camera_frame=kwargs.pop("camera_frame"), object_frame=kwargs.pop("object_frame"),
            tolerance_ns=int(round(kwargs.pop("tolerance_ms") * 1e6)))
        return func(*args, **kwargs)

    return wrapper


frames_option = click.option("--frames", "frame_range", type=FrameRange(), default="0:",
                             help="Stereo frames to use, START:STOP (0-based, STOP excluded).")


def extraction_options(func):
    """Options of single-frame extraction (declared once; extract, accumulate and track share them)."""
    options = [
        click.option("--detector", type=click.Choice(["hough", "lsd"]), default="hough", show_default=True,
                     help="2D line detector: the paper's orientation-sensitive Hough transform, or OpenCV's LSD."),
        click.option("--segment-length", type=click.FloatRange(4.0, 100.0), default=15.0, show_default=True,
                     help="Length of a local segment, pixels."),
        click.option("--gradient-threshold", type=click.FloatRange(0.1, 100.0), default=3.0, show_default=True,
                     help="Edge gradient threshold, grey levels per pixel."),
        click.option("--critical-angle", type=click.FloatRange(0.0, 45.0), default=12.0, show_default=True,
                     help="Segments closer than this to the epipolar direction (degrees) are rejected."),
        click.option("--depth-range", default="0.2:3.0", show_default=True, metavar="MIN:MAX",
                     help="Depths searched by stereo matching, metres."),
    ]
    for option in reversed(options):
        func = option(func)

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from .extract import ExtractParams
        from .lines2d import LineParams
        from .stereo import StereoParams

        depth = kwargs.pop("depth_range")
        try:
            near, far = (float(x) for x in depth.split(":"))
            assert 0 < near < far
        except (ValueError, AssertionError):
            raise click.BadParameter(f"expected MIN:MAX metres with 0 < MIN < MAX, found {depth!r}",
                                     param_hint="--depth-range") from None
        critical = kwargs.pop("critical_angle")
        kwargs["extract_params"] = ExtractParams(
            LineParams(detector=kwargs.pop("detector"), segment_length_px=kwargs.pop("segment_length"),
                       gradient_threshold=kwargs.pop("gradient_threshold")),
            StereoParams(min_depth_m=near, max_depth_m=far, critical_angle_deg=critical))
        return func(*args, **kwargs)

    return wrapper


def _output_path(ctx, param, value):
    """Outputs must go to an existing folder (checked before any work is done)."""
    from pathlib import Path

    for path in (value if isinstance(value, tuple) else (value,)):
        if path and not Path(path).resolve().parent.is_dir():
            raise click.BadParameter(f"the folder of {path} does not exist")
    return value


def _outputs_of(*suffixes: str):
    """A callback for repeatable outputs whose kind is told by the suffix (e.g. .json, .ply)."""

    def check(ctx, param, value):
        for path in _output_path(ctx, param, value):
            if not path.lower().endswith(suffixes):
                raise click.BadParameter(f"expected a {' or '.join(suffixes)} file, found {path!r}")
        return value

    return check


# -- info -----------------------------------------------------------------------------------------
@main.command()
@click.argument("recording", type=click.Path(dir_okay=False))
@recording_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def info(recording, recording_kwargs, as_json):
    """Summarise a stereo recording: topics, frames, images, calibration, pose coverage.

    Exits 1 (after the summary) if the object frame cannot be reached in the
    transform tree, since nothing can then be accumulated.

    \b
    Example:
      accum info sample_data/chessboard/chessboard.mcap --object-frame board
    """
    from .recording import Recording

    with Recording(recording, require_pose=False, **recording_kwargs) as rec:
        summary = rec.info()
        no_path = rec.tree.path(rec.camera_frame, rec.object_frame) is None
    intr = summary.intrinsics
    if as_json:
        doc = {k: v for k, v in summary.__dict__.items() if k != "intrinsics"}
        doc["intrinsics"] = intr.as_dict() if intr else None
        click.echo(json.dumps(doc, indent=1))
    else:
        seconds = ((summary.last_ns or 0) - (summary.first_ns or 0)) * 1e-9
        click.echo(f"recording    {summary.path}")
        click.echo(f"frames       {summary.stereo_frames} stereo frames over {seconds:.3f} s, "
                   f"{summary.unpaired_images} unpaired images")
        if intr:
            kind = "rectified" if summary.rectified_input else f"raw ({summary.distortion_model}), rectified by accum"
            click.echo(f"images       {intr.width}x{intr.height} {summary.image_encoding}, {kind}")
            click.echo(f"calibration  fx {intr.fx:.2f} px, fy {intr.fy:.2f} px, cx {intr.cx:.2f}, cy {intr.cy:.2f}, "
                       f"baseline {intr.baseline * 1000:.2f} mm ({summary.calibrations} message(s))")
        click.echo(f"poses        {recording_kwargs['object_frame']} in {recording_kwargs['camera_frame']}: "
                   f"{summary.frames_with_pose}/{summary.stereo_frames} frames")
        for reason, count in summary.pose_problems:
            click.echo(f"             {count} frame(s): {reason}")
        click.echo(f"tf frames    {', '.join(summary.tf_frames) or 'none'}")
        click.echo("topics")
        for topic, schema, count in summary.topics:
            click.echo(f"  {topic:<32} {schema:<28} {count if count is not None else '?':>6}")
    if no_path:
        frames = ", ".join(summary.tf_frames) or "none"
        raise AccumError(f"{recording}: no transform path from {recording_kwargs['camera_frame']!r} to "
                         f"{recording_kwargs['object_frame']!r} (frames in the transform tree: {frames}); "
                         "choose one with --object-frame")


# -- simulate ---------------------------------------------------------------------------------
def _parse_pose_noise(ctx, param, value):
    if value is None:
        return (0.0, 0.0)
    try:
        deg, mm = (float(x) for x in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected DEG,MM such as 1.5,4, found {value!r}") from None
    if deg < 0 or mm < 0:
        raise click.BadParameter("noise levels must be >= 0")
    return deg, mm


@main.command()
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Recording to write (NAME.mcap); the truth goes to NAME.truth.json.")
@click.option("--frames", "n_frames", type=click.IntRange(min=1), default=36, show_default=True)
@click.option("--size", default="640x480", show_default=True, help="Image size WIDTHxHEIGHT.")
@click.option("--shape", type=click.Choice(["box", "prism", "house"]), default="box", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--raw", is_flag=True, help="Distorted, unrectified images (the calibration rectifies them).")
@click.option("--tf-tree", is_flag=True, help="world -> camera_left static plus world -> gripper at 3x the image "
              "rate, offset in time.")
@click.option("--pose-noise", callback=_parse_pose_noise, metavar="DEG,MM",
              help="RMS rotation (degrees) and translation (mm) noise on the recorded gripper poses.")
@click.option("--encoding", type=click.Choice(["png", "jpeg", "mono8"]), default="png", show_default=True)
@click.pass_context
def simulate(ctx, output, n_frames, size, shape, seed, raw, tf_tree, pose_noise, encoding):
    """Render a synthetic stereo recording with ground truth.

    \b
    Example:
      accum simulate -o out/prism.mcap --shape prism --seed 3 --frames 12
    """
    from .simulation import SimulationOptions, simulate as run

    try:
        width, height = (int(x) for x in size.lower().split("x"))
        assert width >= 64 and height >= 48
    except (ValueError, AssertionError):
        raise click.BadParameter(f"expected WIDTHxHEIGHT of at least 64x48, found {size!r}",
                                 param_hint="--size") from None
    if not output.endswith(".mcap"):
        raise click.BadParameter(f"expected a name ending in .mcap, found {output!r}", param_hint="--output")
    options = SimulationOptions(frames=n_frames, width=width, height=height, shape=shape, seed=seed, raw=raw,
                                tf_tree=tf_tree, pose_noise_deg=pose_noise[0], pose_noise_m=pose_noise[1] / 1000,
                                encoding=encoding)
    with progress_bar(ctx, n_frames, "rendering") as update:
        done = [0]

        def advance(i):
            update(i - done[0])
            done[0] = i

        result = run(output, options, progress=advance)
    click.echo(f"wrote {result.recording} ({result.frames} frames) and {result.truth} "
               f"({result.edges} edges, {result.seen_fraction:.0%} of edge length seen in >= 3 frames)")


# -- extract -------------------------------------------------------------------------------------
@main.command()
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), callback=_output_path,
              help="Frames file to write (JSON lines, one stereo frame per line).")
@click.option("--rrd", type=click.Path(dir_okay=False), callback=_output_path,
              help="Also save a Rerun recording of each frame's images, 2D and 3D segments.")
@frames_option
@extraction_options
@recording_options
@click.pass_context
def extract(ctx, recording, output, rrd, frame_range, extract_params, recording_kwargs):
    """Extract local 3D line segments from every stereo pair.

    Each line of the output is a model-format object in the left camera frame
    with the frame's timestamp, its counts, and its recorded pose if any.

    \b
    Example:
      accum extract sample_data/sim_box.mcap -o out/frames.jsonl --frames 0:10
    """
    import numpy as np

    from .extract import extract_frame
    from .geometry import quat_from_transform
    from .lines2d import StageTimes
    from .model_io import FramesWriter
    from .recording import Recording

    times = StageTimes()
    totals = {"frames": 0, "segments": 0, "left_2d": 0, "critical": 0, "unmatched": 0}
    with Recording(recording, **recording_kwargs) as rec, FramesWriter(output) as out, \
            _rerun(rrd, "extract") as viz, progress_bar(ctx, _frames_to_do(rec, frame_range), "extracting") as bar:
        for frame in rec.frames(*frame_range):
            result = extract_frame(frame, extract_params, rec.camera_frame, times)
            header = {"frame_index": frame.index, "counts": result.counts}
            if frame.T_camera_object is not None:
                translation, quat = quat_from_transform(frame.T_camera_object)
                header["T_camera_object"] = {"translation": np.round(translation, 9).tolist(),
                                             "rotation_xyzw": np.round(quat, 9).tolist()}
            out.write(result.segments, frame.timestamp_ns, **header)
            if viz:
                viz.extraction(frame, result)
            totals["frames"] += 1
            for key in ("segments", "left_2d", "critical", "unmatched"):
                totals[key] += result.counts[key]
            bar(1)
    n = max(totals["frames"], 1)
    click.echo(f"{totals['frames']} frames: {totals['segments'] / n:.0f} 3D segments per frame from "
               f"{totals['left_2d'] / n:.0f} left 2D segments ({totals['critical'] / n:.0f} critical, "
               f"{totals['unmatched'] / n:.0f} unmatched)")
    click.echo("time per frame: " + ", ".join(f"{k} {1000 * v / n:.1f} ms" for k, v in times.seconds.items()))
    click.echo(f"wrote {output}" + (f" and {rrd}" if rrd else ""))


def _frames_to_do(rec, frame_range) -> int:
    start, stop = frame_range
    total = rec.frame_count_hint
    return max(0, (min(stop, total) if stop is not None else total) - start)


@contextlib.contextmanager
def _rerun(rrd, kind: str):
    """A Rerun log saving to ``rrd``, or None when no .rrd was asked for."""
    if not rrd:
        yield None
        return
    from .visualize import RerunLog

    log_ = RerunLog(f"accum {kind}", rrd=rrd, kind=kind)
    try:
        yield log_
    finally:
        log_.close()


# -- accumulate ----------------------------------------------------------------------------------
@main.command()
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "outputs", multiple=True, required=True, type=click.Path(dir_okay=False),
              callback=_outputs_of(".json", ".ply"),
              help="Model to write: .json (the model) and/or .ply (line set); repeatable.")
@click.option("--rrd", type=click.Path(dir_okay=False), callback=_output_path,
              help="Also save a Rerun recording: images, segments, the model by confidence, counts over time.")
@click.option("--truth", type=click.Path(dir_okay=False, exists=True),
              help="A truth sidecar: also measure precision, completeness and background frame by frame.")
@click.option("--history", type=click.Path(dir_okay=False), callback=_output_path,
              help="Write the per-frame counts (and figures with --truth) as JSON lines.")
@click.option("--png", type=click.Path(dir_okay=False), callback=_output_path,
              help="Write a picture of the model (confidence as grey level, dark = high).")
@click.option("--panel", type=click.Path(dir_okay=False), callback=_output_path,
              help="Write the last frame's input image, extraction and the model side by side.")
@click.option("--motion", type=click.Choice(["gripper", "tracked"]), default="gripper", show_default=True,
              help="gripper: the recorded poses (the paper); tracked: each refined on the images against the "
                   "current model first.")
@click.option("--position-threshold", type=click.FloatRange(0.1, 50.0), default=3.0, show_default=True,
              help="s_p of the metric, millimetres.")
@click.option("--angle-threshold", type=click.FloatRange(0.5, 45.0), default=7.0, show_default=True,
              help="s_o of the metric, degrees.")
@frames_option
@extraction_options
@recording_options
@click.pass_context
def accumulate(ctx, recording, outputs, rrd, truth, history, png, panel, motion, position_threshold,
               angle_threshold, frame_range, extract_params, recording_kwargs):
    """Accumulate a model of the object over the recording, with the gripper's known motion.

    \b
    Example:
      accum accumulate sample_data/sim_box.mcap -o out/model.json -o out/model.ply --rrd out/run.rrd
      accum accumulate sample_data/chessboard/chessboard.mcap --object-frame board -o out/board.json
    """
    import json

    from .atomic import atomic_open
    from .evaluate import EdgeSamples, score_segments
    from .line_model import LineModelParams
    from .metric import MetricThresholds
    from .model_io import read_truth, write_model, write_ply
    from .pipeline import AccumulateParams, LineAccumulation
    from .recording import Recording

    line_model = LineModelParams(thresholds=MetricThresholds(position_threshold / 1000.0, angle_threshold),
                                 critical_angle_deg=extract_params.stereo.critical_angle_deg)
    params = AccumulateParams(extract=extract_params, line_model=line_model, motion=motion)
    edges = EdgeSamples.of(read_truth(truth)) if truth else None
    rows, skipped = [], 0
    with Recording(recording, **recording_kwargs) as rec, _rerun(rrd, "accumulate") as viz, \
            progress_bar(ctx, _frames_to_do(rec, frame_range), "accumulating") as bar:
        acc = LineAccumulation(params, rec.object_frame, rec.camera_frame)
        for frame in rec.frames(*frame_range):
            bar(1)
            if frame.T_camera_object is None:
                log.warning("%s: frame %d: no pose (%s): skipped", recording, frame.index, frame.pose_problem)
                skipped += 1
                continue
            step = acc.step(frame, frame.T_camera_object)
            row = {"frame_index": frame.index, "timestamp_ns": frame.timestamp_ns, **step.stats.__dict__}
            if step.tracking is not None:
                row.update(tracking=step.tracking.status, residual_px=step.tracking.residual_px)
            if edges is not None or viz:
                model = acc.model()
            if edges is not None:
                row.update(score_segments(model.select(model.accepted), edges).as_dict())
                row.pop("segments")
            if viz:
                viz.accumulation(step, model, row)
            rows.append(row)
        model = acc.model()
    for path in outputs:
        (write_ply if path.lower().endswith(".ply") else write_model)(path, model)
    if png or panel:
        from .render import render_frame_panel, render_model, write_png

        if png:
            write_png(png, render_model(model))
        if panel and rows:
            write_png(panel, render_frame_panel(step.frame, step.extraction, model, step.T_camera_object))
    if history:
        with atomic_open(history) as f:
            f.writelines(json.dumps(r) + "\n" for r in rows)
    n = len(rows)
    click.echo(f"{n} frames accumulated" + (f", {skipped} skipped without a pose" if skipped else "")
               + f": model of {len(model)} segments, {int(model.accepted.sum())} accepted (confidence >= 0.5)")
    if n:
        click.echo("time per frame: " + ", ".join(f"{k} {1000 * v / n:.1f} ms" for k, v in acc.times.seconds.items()))
    if motion == "tracked":
        click.echo(f"tracked motion: {len(acc.offsets)} of {n} frames used a refined pose")
    if edges is not None and rows:
        final = score_segments(model.select(model.accepted), edges).as_dict()
        last = {**rows[-1], **final}
        click.echo(f"against {truth}: precision {last['precision']:.3f}, completeness {last['completeness']:.3f}, "
                   f"background {last['background']:.3f}")
    click.echo("wrote " + ", ".join([*outputs, *(p for p in (rrd, history, png, panel) if p)]))


# -- track -----------------------------------------------------------------------------------------
def _pose_option(ctx, param, value):
    if value == "recording":
        return None
    try:
        numbers = [float(x) for x in value.split(",")]
        assert len(numbers) == 7 and np.linalg.norm(numbers[3:]) > 1e-9
    except (ValueError, AssertionError):
        raise click.BadParameter(f"expected 'recording' or x,y,z,qx,qy,qz,qw, found {value!r}") from None
    from .geometry import transform_from_quat

    return transform_from_quat(numbers[:3], np.array(numbers[3:]) / np.linalg.norm(numbers[3:]))


@main.command()
@click.argument("model_file", metavar="MODEL.json", type=click.Path(dir_okay=False, exists=True))
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "outputs", multiple=True, required=True, type=click.Path(dir_okay=False),
              callback=_outputs_of(".json", ".mcap"),
              help="Poses to write: .json (accum.poses/1) and/or .mcap (FrameTransforms for Foxglove); repeatable.")
@click.option("--init", "init_pose", default="recording", show_default=True, callback=_pose_option,
              metavar="recording|x,y,z,qx,qy,qz,qw",
              help="Pose of the first frame: the recording's, or given (metres, quaternion).")
@click.option("--rrd", type=click.Path(dir_okay=False), callback=_output_path,
              help="Also save a Rerun recording: the model over the images at the estimated pose, the trajectory.")
@click.option("--reacquire/--no-reacquire", default=True, show_default=True,
              help="After a loss, search by RANSAC over the frame's extracted 3D segments.")
@frames_option
@extraction_options
@recording_options
@click.pass_context
def track(ctx, model_file, recording, outputs, init_pose, rrd, reacquire, frame_range, extract_params,
          recording_kwargs):
    """Estimate the object's pose in every frame from its model and the images.

    The recording's pose seeds the first frame only (or --init gives it);
    after that, poses come from the images alone.

    \b
    Example:
      accum track out/model.json sample_data/sim_box.mcap -o out/poses.json -o out/poses.mcap
    """
    import time

    from .extract import extract_frame
    from .model_io import PoseTrack, read_model, write_poses
    from .recording import Recording, RecordingWriter
    from .track import PoseTracker

    model = read_model(model_file)
    if not model.accepted.any():
        raise AccumError(f"{model_file}: the model has no accepted segment (confidence >= 0.5) to track")
    tracker = PoseTracker(model)
    times, poses, status, extra, trajectory = [], [], [], [], []
    t0 = time.perf_counter()
    with Recording(recording, require_pose=init_pose is None, **recording_kwargs) as rec, \
            _rerun(rrd, "track") as viz, progress_bar(ctx, _frames_to_do(rec, frame_range), "tracking") as bar:
        first = True
        for frame in rec.frames(*frame_range):
            guess = None
            if first:
                guess = init_pose if init_pose is not None else frame.T_camera_object
                if guess is None:
                    raise AccumError(f"{recording}: the first frame has no recorded pose ({frame.pose_problem}); "
                                     "give one with --init")
                first = False
            observe = (lambda f=frame: extract_frame(f, extract_params, rec.camera_frame).segments) \
                if reacquire else None
            estimate = tracker.update(frame, guess, observe)
            times.append(frame.timestamp_ns)
            poses.append(estimate.T_camera_object)
            status.append(estimate.status)
            extra.append({"residual_px": round(estimate.residual_px, 4) if np.isfinite(estimate.residual_px)
                          else None, "inliers": estimate.inliers, "method": estimate.method})
            if estimate.status == "tracked":
                trajectory.append(estimate.T_camera_object[:3, 3])
            if viz:
                viz.tracking(frame, model, estimate, trajectory)
            bar(1)
        camera_frame, object_frame = rec.camera_frame, rec.object_frame
    seconds = time.perf_counter() - t0
    track_ = PoseTrack(camera_frame, object_frame, np.array(times, np.int64), np.array(poses).reshape(-1, 4, 4),
                       status, extra)
    for path in outputs:
        if path.lower().endswith(".json"):
            write_poses(path, track_)
        else:
            with RecordingWriter(path) as writer:
                for t_ns, T, st in zip(track_.times_ns, track_.poses, status):
                    if st == "tracked":
                        writer.transform(camera_frame, object_frame, T, int(t_ns))
    n = len(times)
    tracked = sum(s == "tracked" for s in status)
    residuals = [e["residual_px"] for e, s in zip(extra, status) if s == "tracked"]
    click.echo(f"{n} frames: {tracked} tracked ({tracked / max(n, 1):.0%}), median residual "
               f"{np.median(residuals) if residuals else float('nan'):.2f} px, {n / max(seconds, 1e-9):.1f} frames/s")
    click.echo("wrote " + ", ".join([*outputs, *([rrd] if rrd else [])]))


# -- view ------------------------------------------------------------------------------------------
@main.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False, exists=True))
@click.option("--rrd", type=click.Path(dir_okay=False), callback=_output_path, help="Save a Rerun recording.")
@click.option("--spawn", is_flag=True, help="Open the Rerun viewer (where one can run).")
@click.option("--connect", metavar="URL", help="Send to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy.")
@click.option("--png", type=click.Path(dir_okay=False), callback=_output_path,
              help="Write a picture: the model (with a recording: one frame, its extraction and the model).")
@click.option("--png-frame", type=click.IntRange(min=0), help="Frame of the recording for --png (default: middle).")
@frames_option
@recording_options
@click.pass_context
def view(ctx, inputs, rrd, spawn, connect, png, png_frame, frame_range, recording_kwargs):
    """Show recordings, models, frames files and poses files in Rerun, or as a picture.

    INPUTS is any mix of a recording (.mcap), models (.json), frames files
    (.jsonl, from extract), poses files (.json, from track) and truth sidecars.
    With a recording, world is the left camera frame and each model is placed
    at the object's pose in every frame (the poses file's if given, else the
    recording's).

    \b
    Examples:
      accum view sample_data/sim_box.mcap out/model.json out/poses.json --rrd out/view.rrd
      accum view out/model.json --png out/model.png
    """
    from pathlib import Path

    from .model_io import file_kind, read_frames, read_model, read_poses, read_truth
    from .recording import Recording
    from .segments import Segments

    if sum(map(bool, (rrd, spawn, connect))) > 1:
        raise click.UsageError("choose one of --rrd, --spawn and --connect")
    if not (rrd or spawn or connect or png):
        raise click.UsageError("nothing to do: give --rrd, --spawn, --connect or --png")
    kinds = {path: file_kind(path) for path in inputs}
    recordings = [p for p, k in kinds.items() if k == "recording"]
    models = {Path(p).stem.replace(".", "_"): read_model(p) for p, k in kinds.items() if k == "model"}
    for p, k in kinds.items():
        if k == "truth":
            truth = read_truth(p)
            direction = truth.b - truth.a
            length = np.linalg.norm(direction, axis=1)
            models["truth"] = Segments(truth.object_frame, (truth.a + truth.b) / 2, direction / length[:, None],
                                       length, np.ones(len(length)), np.ones(len(length), np.int64))
    tracks = [read_poses(p) for p, k in kinds.items() if k == "poses"]
    frames_files = [p for p, k in kinds.items() if k == "frames"]
    if len(recordings) > 1:
        raise click.UsageError("give at most one recording")

    def pose_at(t_ns, recorded):
        for track in tracks:
            i = int(np.argmin(np.abs(track.times_ns - t_ns))) if len(track.times_ns) else -1
            if i >= 0 and abs(int(track.times_ns[i]) - t_ns) <= recording_kwargs["tolerance_ns"] \
                    and np.isfinite(track.poses[i]).all():
                return track.poses[i]
        return recorded

    if rrd or spawn or connect:
        from .visualize import RerunLog

        viz = RerunLog("accum view", rrd=rrd, kind="view", spawn=spawn, connect=connect)
        positions = []
        if recordings:
            with Recording(recordings[0], require_pose=False, **recording_kwargs) as rec, \
                    progress_bar(ctx, _frames_to_do(rec, frame_range), "logging") as bar:
                for frame in rec.frames(*frame_range):
                    T = pose_at(frame.timestamp_ns, frame.T_camera_object)
                    viz.recording_frame(frame, models, T)
                    if T is not None:
                        positions.append(T[:3, 3])
                    bar(1)
        else:
            for name, model in models.items():
                viz.model(model, np.eye(4), f"world/{name}")
        for track in tracks:
            ok = np.isfinite(track.poses).all(axis=(1, 2))
            positions.extend(track.poses[ok, :3, 3])
        if positions and (recordings or tracks):
            viz.trajectory(np.array(positions))
        for path in frames_files:
            for index, (t_ns, segments, doc) in enumerate(read_frames(path)):
                viz.frame_segments(doc.get("frame_index", index), t_ns, segments)
        viz.close()
        if rrd:
            click.echo(f"wrote {rrd}")
    if png:
        _write_picture(png, png_frame, recordings, models, pose_at, recording_kwargs)
        click.echo(f"wrote {png}")


def _write_picture(png, png_frame, recordings, models, pose_at, recording_kwargs) -> None:
    """The model alone, or (with a recording) one frame, its extraction and the model, as in the paper."""
    from .extract import extract_frame
    from .recording import Recording
    from .render import render_frame_panel, render_model, write_png

    named = [m for name, m in models.items() if name != "truth"] or list(models.values())
    if not named:
        raise click.UsageError("--png needs a model")
    if not recordings:
        write_png(png, render_model(named[0]))
        return
    with Recording(recordings[0], require_pose=False, **recording_kwargs) as rec:
        wanted = png_frame if png_frame is not None else rec.frame_count_hint // 2
        for frame in rec.frames(wanted, wanted + 1):
            T = pose_at(frame.timestamp_ns, frame.T_camera_object)
            if T is None:
                raise AccumError(f"{recordings[0]}: frame {wanted} has no pose to place the model")
            write_png(png, render_frame_panel(frame, extract_frame(frame), named[0], T))
            return
    raise AccumError(f"{recordings[0]}: no frame {wanted}")


# -- eval ------------------------------------------------------------------------------------------
@main.command("eval")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False, exists=True))
@click.option("--poses", type=click.Path(dir_okay=False, exists=True), help="Evaluate a poses file (accum track).")
@click.option("--frames", "frames_file", type=click.Path(dir_okay=False, exists=True),
              help="Evaluate a frames file (accum extract), frame by frame.")
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
@click.option("--position-tol", type=click.FloatRange(0.1, 100.0), default=4.0, show_default=True,
              help="A correct segment's centre lies this near a truth edge, millimetres.")
@click.option("--angle-tol", type=click.FloatRange(0.1, 90.0), default=10.0, show_default=True,
              help="A correct segment's direction is this near the edge's, degrees.")
@click.option("--background-dist", type=click.FloatRange(1.0, 1000.0), default=20.0, show_default=True,
              help="Segments farther than this from every truth edge are background, millimetres.")
@click.option("--min-seen", type=click.IntRange(1, 1000), default=3, show_default=True,
              help="Completeness counts edge samples seen in at least this many frames.")
def eval_(inputs, poses, frames_file, as_json, position_tol, angle_tol, background_dist, min_seen):
    """Measure a model, frames or poses against a truth sidecar.

    \b
    Forms:
      accum eval MODEL.json TRUTH.json        precision, completeness, background of the accepted segments
      accum eval --frames FRAMES.jsonl TRUTH.json   single-frame accuracy and completeness
      accum eval --poses POSES.json TRUTH.json      pose errors and tracked fraction
    \b
    Example:
      accum eval out/model.json sample_data/sim_box.truth.json
    """
    from .evaluate import Tolerances, evaluate_frames, evaluate_model, pose_errors
    from .model_io import read_frames, read_model, read_poses, read_truth

    given = int(bool(poses)) + int(bool(frames_file))
    if given > 1 or len(inputs) != 2 - given:
        raise click.UsageError("expected MODEL.json TRUTH.json, or --poses/--frames FILE with TRUTH.json")
    truth = read_truth(inputs[-1])
    tol = Tolerances(position_tol / 1000.0, angle_tol, background_dist / 1000.0, min_seen)
    if poses:
        track = read_poses(poses)
        figures = pose_errors(track.times_ns, track.poses, track.status, truth)
    elif frames_file:
        figures = evaluate_frames(((t, s) for t, s, _ in read_frames(frames_file)), truth, tol)
    else:
        figures = evaluate_model(read_model(inputs[0]), truth, tol)
    if as_json:
        click.echo(json.dumps(figures, indent=1))
        return
    for key, value in figures.items():
        click.echo(f"{key:<28} {value:.4f}" if isinstance(value, float) else f"{key:<28} {value}")


if __name__ == "__main__":
    main()
