"""The ``accum`` command line: parses options, calls the library runs (``accumcli.runs``), prints.

One error policy: an ``AccumError`` (a problem the user can fix) and a usage error end in one
line ``error: ...`` on stderr and exit status 1; an interrupt (Ctrl-C, SIGTERM) in
``error: interrupted`` and 130; anything else is a bug and keeps its traceback. Warnings from
the library (a skipped frame) go to stderr as ``warning: ...``.
"""

from __future__ import annotations

import functools
import logging
import os
import stat
import sys

import click
from click.core import ParameterSource

from . import __version__
from .cli_options import (
    box_option,
    extraction_options,
    frames_option,
    library_value,
    lines_option,
    number_pair,
    parse_pose,
    recording_options,
    frame_workers_option,
    workers_option,
)
from .errors import AccumError, InputError
from .outputs import caused_by_interrupt, interrupt_received, names_open_file, raise_pending_interrupt

log = logging.getLogger("accumcli")


# -- plumbing -----------------------------------------------------------------------------------
class _ClickHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        prefix = {logging.WARNING: "warning: ", logging.ERROR: "error: "}.get(record.levelno, "")
        click.echo(prefix + record.getMessage(), err=True)


class _Interrupted(Exception):
    """An interrupt inside a command, past click (which would print an empty line on stderr first)."""


class AccumGroup(click.Group):
    """Maps the library's errors and click's usage errors to one line and exit 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as e:
            raise _Interrupted() from e

    def main(self, args=None, prog_name=None, **extra):
        extra.pop("standalone_mode", None)
        try:
            code = super().main(args, prog_name, standalone_mode=False, **extra)
            raise_pending_interrupt()   # one noted while the compiler ran, after the last check
        except click.exceptions.Exit as e:
            code = e.exit_code
        except click.UsageError as e:
            hint = f" (see '{e.ctx.command_path} --help')" if e.ctx else ""
            click.echo(f"error: {e.format_message()}{hint}", err=True)
            code = 1
        except AccumError as e:
            click.echo(f"error: {e}", err=True)
            code = 1
        except (KeyboardInterrupt, _Interrupted, click.Abort):
            click.echo("error: interrupted", err=True)
            code = 130
        except Exception as e:
            # an interrupt that C code handed on as another error (a SystemError of compiled code, a
            # TypeError of numpy's); any other error is a bug and keeps its traceback
            if not (interrupt_received() or caused_by_interrupt(e)):
                raise
            click.echo("error: interrupted", err=True)
            code = 130
        sys.exit(code if isinstance(code, int) else 0)


def _set_verbosity(ctx: click.Context, param, value):
    """-v/-q are accepted before and after the command; they add up over both places."""
    meta = ctx.find_root().meta
    if param.name == "verbose":
        meta["verbose"] = meta.get("verbose", 0) + (value or 0)
    elif value:
        meta["quiet"] = True
    verbose = meta.get("verbose", 0)
    log.setLevel(logging.DEBUG if verbose > 1 else logging.INFO if verbose else logging.WARNING)
    return value


def verbosity_options(func):
    func = click.option("-q", "--quiet", is_flag=True, expose_value=False, callback=_set_verbosity,
                        help="No progress bars and no run report (what was done, what was written): only "
                             "warnings, errors and the figures a command exists to print (info, eval).")(func)
    return click.option("-v", "--verbose", count=True, expose_value=False, callback=_set_verbosity,
                        help="More detail (-vv for debugging output).")(func)


@click.group(cls=AccumGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="accum")
@verbosity_options
def main() -> None:
    """Accumulate 3D line-segment models of a grasped object from stereo recordings.

    \b
    Typical session on the bundled sample:
      accum info sample_data/sim_box.mcap
      accum extract sample_data/sim_box.mcap -o out/frames.jsonl
      accum accumulate sample_data/sim_box.mcap -o out/model.json -o out/model.ply --rrd out/run.rrd
      accum eval out/model.json sample_data/sim_box.truth.json
    """
    if not log.handlers:
        log.addHandler(_ClickHandler())
    log.propagate = False


def command(*args, **kwargs):
    """A subcommand of ``accum`` that also takes -q/-v."""
    def decorate(func):
        return main.command(*args, **kwargs)(verbosity_options(func))
    return decorate


def progress_callback(label: str):
    """A ``progress(done, total)`` for the library runs: a click progress bar on stderr, only on a
    terminal and without -q. Returns (callback, finish)."""
    ctx = click.get_current_context()
    if ctx.find_root().meta.get("quiet") or not sys.stderr.isatty():
        return (lambda done, total: raise_pending_interrupt()), (lambda: None)
    state = {}

    def update(done: int, total: int | None) -> None:
        raise_pending_interrupt()   # a signal noted while the compiler ran (outputs._raise_interrupt)
        if "bar" not in state and total:
            state["bar"] = click.progressbar(length=total, label=label, file=sys.stderr, show_pos=True,
                                             show_eta=True)
            state["bar"].__enter__()
            state["done"] = 0
        if "bar" in state:
            state["bar"].update(done - state["done"])
            state["done"] = done

    return update, (lambda: state["bar"].__exit__(None, None, None) if "bar" in state else None)


def run_with_progress(label: str, run, *args, **kwargs):
    update, finish = progress_callback(label)
    try:
        return run(*args, progress=update, **kwargs)
    finally:
        finish()


def _quiet() -> bool:
    return bool(click.get_current_context().find_root().meta.get("quiet"))


def _stdout_is_an_output() -> bool:
    """Whether an option of the running command names this process's stdout (``-o /dev/stdout``)."""
    values = []
    for value in click.get_current_context().params.values():
        values += value if isinstance(value, (list, tuple)) else [value]
    try:
        fd = sys.stdout.fileno()
        if stat.S_ISCHR(os.fstat(fd).st_mode) and not sys.stdout.isatty():   # /dev/null: nothing to keep apart
            return False
    except (OSError, ValueError):
        return False
    return any(isinstance(value, str) and value and names_open_file(value, fd) for value in values)


def _report(lines, product: bool = False) -> None:
    """Print a run's report on stdout (not with -q), or with ``product`` what the command exists to
    print (info's summary: printed whatever -q); on stderr when an output is stdout (``-o
    /dev/stdout``: the report would mix with, or overwrite, the output)."""
    if product or not _quiet():
        err = _stdout_is_an_output()
        for line in lines:
            click.echo(line, err=err)


def _wrote(paths) -> None:
    _report(["wrote " + ", ".join(str(p) for p in paths)])


recording_arg = functools.partial(click.argument, "recording", type=click.Path())   # a file or a rosbag2 folder


def _dash_is_stdout(ctx, param, value):
    """An output named ``-`` is the standard output, as Unix tools have it (a file named '-' is ``./-``)."""
    if isinstance(value, tuple):
        return tuple("/dev/stdout" if v == "-" else v for v in value)
    return "/dev/stdout" if value == "-" else value


_OUTPUT_PATH = dict(type=click.Path(dir_okay=False, allow_dash=True), callback=_dash_is_stdout)   # a file, or -


def _check_formats(outputs, suffixes: tuple, option: str = "--output") -> None:
    """Each output names its format by one of ``suffixes`` (the library's check, as ``option``'s error)."""
    from .runs.base import check_output_kinds

    try:
        check_output_kinds(outputs, suffixes)
    except InputError as e:
        raise click.BadParameter(str(e), param_hint=option) from None


output_option = functools.partial(click.option, "-o", "--output", **_OUTPUT_PATH)


# -- info -----------------------------------------------------------------------------------------
@command()
@recording_arg()
@recording_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def info(recording, options, as_json):
    """Summarise a stereo recording: topics, frames, images, calibration, pose coverage.

    Exits 1 (after the summary) if the object frame cannot be reached in the
    transform tree, since nothing can then be accumulated.

    \b
    Example:
      accum info sample_data/chessboard/chessboard.mcap --object-frame board
    """
    from .report import info_json, info_lines
    from .runs import describe_recording

    summary, problem = describe_recording(recording, options)
    _report([info_json(summary)] if as_json else info_lines(summary, options.object_frame, options.camera_frame),
            product=True)
    if problem:
        raise problem


# -- simulate ---------------------------------------------------------------------------------
@command()
@output_option(required=True, help="Recording to write (NAME.mcap); the truth goes to NAME.truth.json.")
@click.option("--count", type=click.IntRange(min=1), default=36, show_default=True, help="Stereo frames.")
@click.option("--size", default="640x480", show_default=True, help="Image size WIDTHxHEIGHT.",
              callback=library_value(lambda text: number_pair(text.lower(), "x", "WIDTHxHEIGHT")))
@click.option("--scene", type=click.Choice(["random", "classic"]), default="random", show_default=True,
              help="random: everything below not given is drawn from the seed; classic: the original box/prism/house "
                   "scene.")
@click.option("--shape", type=click.Choice(sorted({"box", "prism", "house", "wedge", "trapezoid", "L", "T", "U",
                                                   "steps", "cross"})), help="[default: drawn; classic: box]")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--size-mm", type=click.FloatRange(10, 300), help="Largest dimension of the object [drawn: 30 to 120].")
@click.option("--distance", type=click.FloatRange(0.25, 3.0),
              help="Depth of the object's path, m [drawn: 0.45 to 0.85].")
@click.option("--contrast", type=click.FloatRange(0.0, 0.9), help="Object against background albedo [drawn: 0.05 to "
              "0.45].")
@click.option("--blur", type=click.FloatRange(0.0, 5.0), help="Optics blur sigma, px [drawn: 0.5 to 1.2].")
@click.option("--noise", type=click.FloatRange(0.0, 20.0), help="Image noise, grey levels [drawn: 0.5 to 2.5].")
@click.option("--illumination", type=click.FloatRange(0.0, 0.5), help="Lighting drift over the sequence [drawn: 0 "
              "to 0.2].")
@click.option("--background", type=click.Choice(["texture", "planes", "lines"]), help="[default: drawn]")
@click.option("--clutter/--no-clutter", default=None, help="Static solids at the object's depth [drawn: 30 %].")
@click.option("--raw", is_flag=True, help="Distorted, unrectified images (the calibration rectifies them).")
@click.option("--distortion", type=click.Choice(["plumb_bob", "fisheye"]), default="plumb_bob", show_default=True,
              help="With --raw: the lens model (fisheye: kannala_brandt, ROS's equidistant).")
@click.option("--tf-tree", is_flag=True, help="world -> camera_left static plus world -> gripper at 3x the image "
              "rate, offset in time.")
@click.option("--pose-noise", default="0,0", metavar="DEG,MM", show_default=True,
              callback=library_value(lambda text: number_pair(text, ",", "DEG,MM such as 1.5,4")),
              help="RMS rotation (degrees) and translation (mm) noise on the recorded gripper poses (with "
                   "--tf-tree on its /tf samples, three per frame: at the image times about 0.75 of it).")
@click.option("--encoding", type=click.Choice(["png", "jpeg", "mono8"]), default="png", show_default=True)
def simulate(output, count, size, scene, shape, seed, size_mm, distance, contrast, blur, noise, illumination,
             background, clutter, raw, distortion, tf_tree, pose_noise, encoding):
    """Render a synthetic stereo recording with ground truth.

    \b
    Examples:
      accum simulate -o out/rec.mcap --seed 3 --count 12
      accum simulate -o out/t.mcap --shape T --clutter --noise 2 --count 4
    """
    from .simulation import SimulationOptions
    from .simulation import simulate as run

    width, height = int(size[0]), int(size[1])
    if width < 64 or height < 48 or width > 8192 or height > 8192:
        raise click.BadParameter(f"expected 64x48 to 8192x8192, found {width}x{height}", param_hint="--size")
    _check_formats([output], (".mcap",))
    if distortion != "plumb_bob" and not raw:
        raise click.BadParameter("applies to raw images only; add --raw", param_hint="--distortion")
    options = SimulationOptions(frames=count, width=width, height=height, shape=shape, seed=seed, raw=raw,
                                distortion=distortion, tf_tree=tf_tree, pose_noise_deg=pose_noise[0],
                                pose_noise_m=pose_noise[1] / 1000,
                                encoding=encoding, scene=scene, size_mm=size_mm, distance_m=distance,
                                contrast=contrast, blur_sigma=blur, noise_sigma=noise, illumination=illumination,
                                background=background, clutter=clutter)
    update, finish = progress_callback("rendering")
    try:
        result = run(output, options, progress=lambda done: update(done, count))
    finally:
        finish()
    _report([f"wrote {result.recording} ({result.frames} frames) and {result.truth} "
             f"({result.edges} edges, {result.seen_fraction:.0%} of edge length seen in >= 3 frames)"])


# -- extract -------------------------------------------------------------------------------------
@command()
@recording_arg()
@output_option(required=True, help="Frames file to write (JSON lines, one stereo frame per line).")
@click.option("--rrd", **_OUTPUT_PATH,
              help="Also save a Rerun recording of each frame's images, 2D and 3D segments.")
@click.option("--with-2d", is_flag=True, help="Also write each frame's left 2D segments (for the funnel of eval).")
@frame_workers_option
@frames_option
@extraction_options
@recording_options
def extract(recording, output, rrd, with_2d, workers, frames, extract_params, options):
    """Extract local 3D line segments from every stereo pair.

    Each line of the output is a model-format object in the left camera frame
    with the frame's timestamp, its counts, and its recorded pose if any.
    No object pose is needed.

    \b
    Example:
      accum extract sample_data/sim_box.mcap -o out/frames.jsonl --frames 0:10
    """
    from .report import extraction_lines
    from .runs import extract_recording

    result = run_with_progress("extracting", extract_recording, recording, output, params=extract_params,
                               options=options, frames=frames, rrd=rrd, with_2d=with_2d,
                               workers=workers)
    _report(extraction_lines(result))
    _wrote(result.outputs)


# -- accumulate ----------------------------------------------------------------------------------
@command()
@recording_arg()
@output_option("outputs", multiple=True, required=True,
               help="Model to write: .json (the model), .ply (line set) and/or .mcap (Foxglove SceneUpdate over "
                    "time); repeatable.")
@click.option("--all", "ply_all", is_flag=True, help="The PLY holds every segment, not only the accepted ones.")
@click.option("--rrd", **_OUTPUT_PATH,
              help="Also save a Rerun recording: images, segments, the model by confidence, counts over time.")
@click.option("--truth", type=click.Path(dir_okay=False, exists=True),
              help="A truth sidecar: also measure precision, completeness and background frame by frame.")
@click.option("--history", **_OUTPUT_PATH,
              help="Write the per-frame counts of the running accumulation (and with --truth the figures of the "
                   "model as written, its twins merged and held segments given the dominant directions) as JSON "
                   "lines.")
@click.option("--plot", **_OUTPUT_PATH, help="Draw the per-frame counts (and figures) as a PNG.")
@click.option("--png", **_OUTPUT_PATH,
              help="Write a picture of the model (confidence as grey level, dark = high).")
@click.option("--panel", **_OUTPUT_PATH,
              help="Write the last frame's input image, extraction and the model side by side.")
@click.option("--motion", type=click.Choice(["gripper", "tracked"]), default="gripper", show_default=True,
              help="gripper: the recorded poses (the paper); tracked: the recorded poses repaired first, in "
                   "passes over the recording (frame-to-frame refinement on the images, fused with the "
                   "recorded poses, then refined on the model they give; the extraction runs once; "
                   "the whole 1.4 to 3 times the time, the progress bar counts every pass).")
@click.option("--poses", "poses", multiple=True, metavar="FILE", **_OUTPUT_PATH,
              help="With --motion tracked, also write the repaired poses, as track does: .json (every frame "
                   "with a pose, its status: tracked = verified on the model, linked = measured on its "
                   "neighbours' images only, recorded = its /tf; and its correction of the /tf), .tum and/or "
                   ".mcap (the tracked ones); repeatable.")
@click.option("--sp", "position_threshold", type=click.FloatRange(0.1, 50.0), default=3.0, show_default=True,
              metavar="MM",
              help="s_p of the paper's metric (association and merging), millimetres.")
@click.option("--so", "angle_threshold", type=click.FloatRange(0.5, 45.0), default=7.0, show_default=True,
              metavar="DEG",
              help="s_o of the paper's metric, degrees.")
@click.option("--view-planes/--average-directions", default=True, show_default=True,
              help="A segment's direction from the planes through the camera and the segment in all the "
                   "frames that saw it (the object's turn as a wide baseline), or the average of its "
                   "stereo directions (the paper's; the planes trust the poses to about half a degree).")
@click.option("--plane-agreement", type=click.FloatRange(0.0001, 1.0), metavar="RATIO",
              help="Accept a segment only where the planes of the views that set its direction meet on one line: "
                   "their residual at most RATIO of what pins the direction (0.006 made every simulated and devset "
                   "row of make suite 0.95 precise or more, at 0.02 less completeness). Needs --view-planes.")
@click.option("--merge-twins/--keep-twins", default=True, show_default=True,
              help="Write the model with the twins of an edge merged: segments built from different aspects beside "
                   "each other whose view planes together pin the edge (stereo tilted each; neither is sure of its "
                   "direction alone; needs --view-planes); --keep-twins writes them as accumulated.")
@click.option("--dominant-directions/--own-directions", default=True, show_default=True,
              help="A segment confirmed but unsure of its direction, and each frame's 3D segment unsure of its own, "
                   "take the direction that the model's accepted segments share, where their view plane holds that "
                   "one and their own direction lies near it (the edges of made objects share a few directions; "
                   "the running accumulation's counts, as --history writes them, do not count the held ones it "
                   "accepts); --own-directions keeps their own.")
@click.option("--image-confirm/--no-image-confirm", default=False, show_default=True,
              help="A segment that a frame's 3D segments do not confirm, but whose edge both images show where the "
                   "recorded motion moved it, seen from a new aspect, gains a weaker confirmation: fuller models "
                   "where the poses are exact to a few tenths of a pixel (simulated, or a precise robot); off by "
                   "default: with poses a degree off it finds nothing, and tracking with its fuller models was "
                   "less safe (README). Not with --motion tracked.")
@click.option("--across-frames/--stereo-only", default=False, show_default=True,
              help="Also triangulate lines across frames with the recorded motion: a left-image edge meets its own "
                   "plane of a frame 2 or 4 back, checked in four more frames (a wide baseline for the short and "
                   "near-horizontal edges one stereo pair places badly or not at all): fuller models (make suite: "
                   "completeness higher on 16 of 19 rows, precision the same; README); off by default: --motion "
                   "tracked cannot use them, and its models fall further behind the recorded poses'. It trusts the relative poses to a tenth of a degree: not with --motion "
                   "tracked.")
@box_option
@frame_workers_option
@frames_option
@extraction_options
@recording_options
def accumulate(recording, outputs, ply_all, rrd, truth, history, plot, png, panel, motion, poses, position_threshold,
               angle_threshold, view_planes, plane_agreement, merge_twins, dominant_directions, image_confirm,
               across_frames, box, workers, frames, extract_params, options):
    """Accumulate a model of the object over the recording, with the gripper's known motion.

    \b
    Example:
      accum accumulate sample_data/sim_box.mcap -o out/model.json -o out/model.ply --rrd out/run.rrd
      accum accumulate sample_data/chessboard/chessboard.mcap --object-frame board -o out/board.json
    """
    from .accumulate import image_confirming
    from .dominant_directions import DominantParams
    from .line_model import LineModelParams
    from .metric import MetricThresholds
    from .pipeline import AccumulateParams
    from .report import accumulation_lines
    from .runs import accumulate_recording
    from .runs.base import MODEL_OUTPUTS, POSES_OUTPUTS
    from .temporal_lines import TemporalParams

    _check_formats(outputs, MODEL_OUTPUTS)
    _check_formats(poses, POSES_OUTPUTS, "--poses")
    if plane_agreement is not None and not view_planes:
        raise click.UsageError("--plane-agreement tests the planes of --view-planes; --average-directions has none")
    line_model = LineModelParams(thresholds=MetricThresholds(position_threshold / 1000.0, angle_threshold),
                                 view_planes=view_planes, plane_agreement=plane_agreement,
                                 merge_twins=merge_twins,
                                 dominant=DominantParams() if dominant_directions else None)
    params = AccumulateParams(extract=extract_params, line_model=line_model, rule=image_confirming(image_confirm),
                              motion=motion, box=box,
                              temporal=TemporalParams() if across_frames else None)
    result = run_with_progress("accumulating", accumulate_recording, recording, outputs, params=params,
                               options=options, frames=frames, truth=truth, history=history, plot=plot, rrd=rrd,
                               png=png, panel=panel, ply_all=ply_all, poses=poses, workers=workers)
    _report(accumulation_lines(result, motion))
    _wrote(result.outputs)


# -- track -----------------------------------------------------------------------------------------
@command()
@click.argument("model_file", metavar="MODEL.json", type=click.Path(dir_okay=False, exists=True))
@recording_arg()
@output_option("outputs", multiple=True, required=True,
               help="Poses to write: .json (accum.poses/1), .tum (for evo) and/or .mcap (FrameTransforms for "
                    "Foxglove); repeatable.")
@click.option("--init", "init_pose", default="recording", show_default=True, callback=library_value(parse_pose),
              metavar="recording|x,y,z,qx,qy,qz,qw",
              help="Pose of the first frame: the recording's, or given (metres, quaternion).")
@click.option("--rrd", **_OUTPUT_PATH,
              help="Also save a Rerun recording: the model over the images at the estimated pose, the trajectory.")
@click.option("--reacquire/--no-reacquire", default=True, show_default=True,
              help="After a loss, search by RANSAC over the frame's extracted 3D segments.")
@click.option("--poses-topic", default="/accum/poses", show_default=True, help="Topic of the poses in .mcap.")
@click.option("--poses-child-frame", metavar="FRAME", help="Child frame of the poses in .mcap "
              "[default: OBJECT_tracked, beside the recording's own OBJECT].")
@frames_option
@extraction_options
@recording_options
def track(model_file, recording, outputs, init_pose, rrd, reacquire, poses_topic, poses_child_frame, frames,
          extract_params, options):
    """Estimate the object's pose in every frame from its model and the images.

    The recording's pose seeds the first frame only (or --init gives it;
    frames before the first recorded pose are lost, tracking starts there);
    after that, poses come from the images alone. The object's frame is
    the one the model names unless --object-frame is given.

    \b
    Example:
      accum track out/model.json sample_data/sim_box.mcap -o out/poses.json -o out/poses.tum -o out/poses.mcap
    """
    from .report import tracking_lines
    from .runs import track_recording
    from .runs.base import POSES_OUTPUTS

    _check_formats(outputs, POSES_OUTPUTS)
    result = run_with_progress("tracking", track_recording, model_file, recording, outputs, init_pose=init_pose,
                               extract_params=extract_params, options=options, frames=frames,
                               reacquire=reacquire, rrd=rrd, poses_topic=poses_topic,
                               poses_child_frame=poses_child_frame, object_frame_of_model=not _object_frame_given())
    _report(tracking_lines(result))
    _wrote(result.outputs)


def _object_frame_given() -> bool:
    """Whether the user gave --object-frame (else track and view take the frame the model names)."""
    return click.get_current_context().get_parameter_source("object_frame") != ParameterSource.DEFAULT


# -- view ------------------------------------------------------------------------------------------
@command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("--rrd", **_OUTPUT_PATH, help="Save a Rerun recording.")
@click.option("--spawn", is_flag=True, help="Open the Rerun viewer (where one can run).")
@click.option("--connect", metavar="URL", help="Send to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy.")
@click.option("--png", **_OUTPUT_PATH,
              help="Write a picture: every model side by side, over a truth's edges in magenta (with a "
                   "recording: one frame, its extraction and each model in that camera).")
@click.option("--png-frame", type=click.IntRange(min=0), help="Frame of the recording for --png (default: the middle of --frames).")
@frames_option
@recording_options
def view(inputs, rrd, spawn, connect, png, png_frame, frames, options):
    """Show recordings, models, frames files and poses files in Rerun, or as a picture.

    INPUTS is any mix of a recording (.mcap), models (.json), frames files
    (.jsonl, from extract), poses files (.json, from track) and truth sidecars,
    recognised by content. With a recording, world is the left camera frame and
    each model is placed at the object's pose in every frame (the poses file's
    if given, else the recording's; the object's frame is the one the models
    name unless --object-frame is given). --frames selects recording frames,
    also of a frames file (its lines' frame_index).

    \b
    Examples:
      accum view sample_data/sim_box.mcap out/model.json out/poses.json --rrd out/view.rrd
      accum view out/model.json --png out/model.png
    """
    from .runs import view as run

    written = run_with_progress("logging", run, inputs, rrd=rrd, spawn=spawn, connect=connect, png=png,
                                png_frame=png_frame, options=options, frames=frames,
                                object_frame_of_model=not _object_frame_given())
    if written:
        _wrote(written)


# -- batch -----------------------------------------------------------------------------------------
@command()
@click.argument("recordings", nargs=-1, required=True, type=click.Path())
@output_option("outdir", required=True, type=click.Path(file_okay=False), callback=None, help="Folder of the results.")
@click.option("--track", is_flag=True, help="Also track each model through its recording (poses.json).")
@click.option("--truth-from-sidecar", is_flag=True, help="Evaluate each model against NAME.truth.json beside it.")
@box_option
@workers_option
@click.option("--ray", "ray_address", metavar="ADDRESS", help="Run the tasks on a Ray cluster (ray.init(address)); "
              "'local' starts Ray's local cluster. Needs pip install 'accumcli[ray]'.")
@frames_option
@extraction_options
@recording_options
def batch(recordings, outdir, track, truth_from_sidecar, box, workers, ray_address, frames, extract_params, options):
    """Accumulate (and optionally track and evaluate) many recordings: OUTDIR/NAME/ each, summary.csv.

    A recording that fails is reported in its row; the others go on, and the exit code is 1 if
    any failed (for scripts). Re-running skips the recordings whose outputs are complete for the
    same inputs and options.

    \b
    Examples:
      accum batch sample_data/sim_box.mcap -o out/batch --truth-from-sidecar --frames 0:4
      accum batch recordings/*.mcap -o out/batch --track --workers 2
      accum batch recordings/*.mcap -o out/batch --track --ray local
    """
    from .batch import BatchOptions, run_batch, table_lines
    from .pipeline import AccumulateParams

    batch_options = BatchOptions(AccumulateParams(extract=extract_params, box=box), options, frames, track,
                                 truth_from_sidecar)
    result = run_with_progress("recordings", run_batch, recordings, outdir, batch_options, workers=workers,
                               ray_address=ray_address)
    count = f"{len(result.rows)} recording" + ("" if len(result.rows) == 1 else "s")
    _report([*table_lines(result.rows), f"{count} in {result.seconds:.1f} s, {result.failed} "
             f"failed; wrote {result.summary}"])
    if result.failed == len(result.rows):
        raise AccumError(f"every recording failed (see the status column of {result.summary})")
    if result.failed:
        raise AccumError(f"{result.failed} of {len(result.rows)} recordings failed (see the status column of "
                         f"{result.summary}); the others' outputs are written")


# -- eval ------------------------------------------------------------------------------------------
@command("eval")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False, exists=True))
@click.option("--poses", type=click.Path(dir_okay=False, exists=True), help="A poses file (the same as giving "
              "it as the first input).")
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
@click.option("--position-tol", type=click.FloatRange(0.1, 100.0), default=4.0, show_default=True,
              help="A correct segment's centre lies this near a truth edge, millimetres.")
@click.option("--angle-tol", type=click.FloatRange(0.1, 90.0), default=10.0, show_default=True,
              help="A correct segment's direction is this near the edge's, degrees.")
@click.option("--background-dist", type=click.FloatRange(1.0, 1000.0), default=20.0, show_default=True,
              help="Segments farther than this from every truth edge are background, millimetres.")
@click.option("--min-seen", type=click.IntRange(1, 1000), default=3, show_default=True,
              help="Completeness counts edge samples seen in at least this many frames.")
@click.option("--plot", **_OUTPUT_PATH,
              help="With a frames file: its figures frame by frame as a PNG.")
@click.option("--support-face", type=click.IntRange(min=0), metavar="N",
              help="With a truth that has faces: segments on face N's plane near the object (the board it stands "
                   "on) count as on the body.")
@lines_option
def eval_(inputs, poses, as_json, position_tol, angle_tol, background_dist, min_seen, plot, support_face, frames):
    """Measure a model, frames file or poses file against a truth sidecar.

    The kind of INPUT is recognised by its content.

    \b
    Forms:
      accum eval MODEL.json TRUTH.json       precision, completeness, background of the accepted segments
      accum eval FRAMES.jsonl TRUTH.json     single-frame accuracy and completeness (--frames selects lines)
      accum eval POSES.json TRUTH.json       pose errors and tracked fraction
    \b
    Example:
      accum eval out/model.json sample_data/sim_box.truth.json
    """
    from .evaluate import Tolerances
    from .model_io import dumps
    from .report import figures_lines
    from .runs import evaluate_file

    inputs = ((poses,) if poses else ()) + tuple(inputs)
    if len(inputs) != 2:
        raise click.UsageError("expected INPUT TRUTH.json (INPUT: a model, frames or poses file)")
    tol = Tolerances(position_tol / 1000.0, angle_tol, background_dist / 1000.0, min_seen)
    figures = evaluate_file(inputs[0], inputs[1], tol, frames, support_face, plot)
    _report([dumps(figures, indent=1)] if as_json else figures_lines(figures), product=True)
    if plot:
        _wrote([plot])


# -- check -----------------------------------------------------------------------------------------
@command()
@click.argument("model_file", metavar="MODEL.json", type=click.Path(dir_okay=False, exists=True))
@recording_arg()
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
@click.option("--sample-frames", type=click.IntRange(2, 100), default=12, show_default=True,
              help="Frames compared with each other, spread evenly over --frames.")
@frames_option
@recording_options
def check(model_file, recording, as_json, sample_frames, frames, options):
    """Check a model on a recording's images, without a truth: the share of its accepted
    segments that moves with the object, and the share that stays still in the camera's
    view (background the accumulation kept).

    Each frame pair compares, per segment, the edge in the image where the object's motion
    takes the segment with the edge where it stays still. The object's frame is the one the
    model names unless --object-frame is given.

    \b
    Example:
      accum check out/model.json sample_data/sim_box.mcap
    """
    from .model_io import dumps
    from .report import figures_lines
    from .runs.still import check_model
    from .still_check import StillCheckParams

    figures = run_with_progress("checking", check_model, model_file, recording, options=options, frames=frames,
                                params=StillCheckParams(frames=sample_frames),
                                object_frame_of_model=not _object_frame_given())
    _report([dumps(figures, indent=1)] if as_json else figures_lines(figures), product=True)


if __name__ == "__main__":
    main()
