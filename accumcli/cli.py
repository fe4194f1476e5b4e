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
@click.option("--frames", "n_frames", type=click.IntRange(min=1), default=24, show_default=True)
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
      accum simulate -o out/prism.mcap --shape prism --seed 3 --frames 30
    """
    from .simulation import SimulationOptions, simulate as run

    try:
        width, height = (int(x) for x in size.lower().split("x"))
        assert width >= 64 and height >= 48
    except (ValueError, AssertionError):
        raise click.BadParameter(f"expected WIDTHxHEIGHT of at least 64x48, found {size!r}", param_hint="--size")
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


if __name__ == "__main__":
    main()
