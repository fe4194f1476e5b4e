"""The option groups that several ``accum`` commands share, declared once: which recording to
read and how (``options``: a ``RecordingOptions``), which frames (``frames``: a ``FrameRange``),
and how to extract (``extract_params``: an ``ExtractParams``). Values are parsed by the library
(its ``InputError`` becomes a usage error of the option)."""

from __future__ import annotations

import functools
import math

import click


def library_value(parse):
    """A click callback turning the library's ``InputError`` into a usage error of this option."""
    def callback(ctx, param, value):
        from .errors import InputError

        try:
            return parse(value) if value is not None else None
        except InputError as e:
            raise click.BadParameter(str(e)) from None
    return callback


def _parse_frames(text):
    from .runs import FrameRange

    return FrameRange.parse(text)


workers_option = click.option(
    "--workers", type=click.IntRange(min=1), default=None,
    help="Recordings processed at once by a local pool [default: 1; not with --ray, whose cluster schedules "
         "them]. The output is the same whatever the number.")


def _parse_workers(text: str) -> int | None:
    if text == "auto":
        return None
    if text.isdigit() and int(text) >= 1:
        return int(text)
    raise click.BadParameter(f"expected a number of processes (1 or more) or 'auto', got {text!r}")


frame_workers_option = click.option(
    "--workers", default="auto", show_default=True, metavar="N|auto",
    callback=lambda ctx, param, value: _parse_workers(value),
    help="Processes extracting frames ahead of this one (auto: 2 on two or more CPUs for 40 frames or more, "
         "else 1). The output is the same whatever the number.")

frames_option = click.option("--frames", "frames", default="0:", callback=library_value(_parse_frames),
                             metavar="START:STOP", help="Stereo frames to use (0-based, STOP excluded; "
                             "either side may be empty).")
lines_option = click.option("--frames", "frames", default="0:", callback=library_value(_parse_frames),
                            metavar="START:STOP", help="Lines of a frames or poses file to use (0-based, STOP "
                            "excluded; either side may be empty): the file's lines, not the recording's frame "
                            "numbers (a frames file of --frames 5:15 has its frame 5 on line 0).")


MAX_MILLISECONDS = 4e12   # 127 years: with a stamp of today (1.75e18 ns) its nanoseconds still fit an int64


class _FiniteMilliseconds(click.ParamType):
    """A finite number of milliseconds from ``minimum`` to ``MAX_MILLISECONDS`` (a camera counting from
    its boot against transforms counting from 1970 is 1.75e12 ms), so that a stamp moved by it still
    fits an int64 of nanoseconds: click's FloatRange lets NaN through (every comparison with it is
    false), which ended in a traceback."""

    name = "float"

    def __init__(self, minimum: float = -MAX_MILLISECONDS):
        self.minimum = minimum

    def convert(self, value, param, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not (math.isfinite(number) and self.minimum <= number <= MAX_MILLISECONDS):
            self.fail(f"{value!r}: expected a finite number of milliseconds from {self.minimum:g} to "
                      f"{MAX_MILLISECONDS:g}", param, ctx)
        return number


def recording_options(func):
    """Options of every command that reads a recording, given to the run as ``options``."""
    options = [
        click.option("--object-frame", default="gripper", show_default=True,
                     help="Frame of the object (the gripper) in the transform tree."),
        click.option("--camera-frame", default="camera_left", show_default=True,
                     help="Rectified left camera optical frame."),
        click.option("--tolerance-ms", type=_FiniteMilliseconds(0.0), default=1.0, show_default=True,
                     help="Left/right pairing and transform time tolerance."),
        click.option("--left-topic", default="/stereo/left/image", show_default=True),
        click.option("--right-topic", default="/stereo/right/image", show_default=True),
        click.option("--left-calibration-topic", default="/stereo/left/calibration", show_default=True),
        click.option("--right-calibration-topic", default="/stereo/right/calibration", show_default=True),
        click.option("--tf-topic", default="/tf", show_default=True),
        click.option("--time-offset-ms", type=_FiniteMilliseconds(), default=0.0, show_default=True,
                     help="Look the poses up this long after each image's stamp: where the camera's clock runs "
                          "ahead of the robot's, minus that (accumulate warns when the motion says the stamps are off)."),
        click.option("--tf-static-topic", default=None,
                     help="Static transforms' topic.  [default: the --tf-topic's name + '_static': /tf_static, "
                          "or /robot/tf_static for --tf-topic /robot/tf]"),
    ]
    for option in reversed(options):
        func = option(func)

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from .recording import Topics
        from .runs import RecordingOptions

        tf = kwargs.pop("tf_topic")
        topics = Topics(left_image=kwargs.pop("left_topic"), right_image=kwargs.pop("right_topic"),
                        left_calibration=kwargs.pop("left_calibration_topic"),
                        right_calibration=kwargs.pop("right_calibration_topic"), tf=tf,
                        tf_static=kwargs.pop("tf_static_topic") or f"{tf}_static")
        kwargs["options"] = RecordingOptions(topics, kwargs.pop("camera_frame"), kwargs.pop("object_frame"),
                                             int(round(kwargs.pop("tolerance_ms") * 1e6)),
                                             int(round(kwargs.pop("time_offset_ms") * 1e6)))
        return func(*args, **kwargs)

    return wrapper


def extraction_options(func):
    """Options of single-frame extraction (extract, accumulate and track), given as ``extract_params``."""
    options = [
        click.option("--detector", type=click.Choice(["chains", "hough", "lsd", "fld", "ed"]), default="chains",
                     show_default=True,
                     help="2D line detector: edge chains split at corners (the default, best on the suite), the "
                          "paper's orientation-sensitive Hough transform, or OpenCV's LSD, FastLineDetector, "
                          "EdgeDrawing."),
        click.option("--segment-length", type=click.FloatRange(4.0, 100.0), default=15.0, show_default=True,
                     help="Length of a local segment, pixels."),
        click.option("--gradient-threshold", type=click.FloatRange(0.1, 100.0), default=3.0, show_default=True,
                     help="Edge gradient threshold, grey levels per pixel."),
        click.option("--gradient-blur", type=click.FloatRange(0.0, 5.0), default=0.5, show_default=True,
                     metavar="PX",
                     help="Gaussian blur of the images before their gradients, pixels: more smooths noise, less "
                          "finds fainter and more crowded edges (accumcli/lines2d.py)."),
        click.option("--critical-angle", type=click.FloatRange(0.0, 45.0), default=8.0, show_default=True,
                     help="Segments closer than this to the epipolar direction (degrees) are not matched "
                          "along the rows."),
        click.option("--critical-ends/--no-critical-ends", default=True, show_default=True,
                     help="Triangulate such critical segments from their edge's ends, where disparity is "
                          "defined (--no-critical-ends: reject them, as the paper does)."),
        click.option("--right-search/--no-right-search", default=False, show_default=True,
                     help="Search the right image along the rows of left segments left unmatched, at their "
                          "matched neighbours' disparities, for an edge its segment detector missed: a "
                          "fuller model, at some cost to single-frame precision and to tracking with it."),
        click.option("--row-offset", type=click.FloatRange(-5.0, 5.0), default=0.0, show_default=True,
                     metavar="PX",
                     help="The right image's rows lie this many pixels below the left's (a calibration a "
                          "little off): disparities along the rows are corrected. extract and accumulate warn "
                          "when the edges' junctions show such an offset, and name the value to try."),
        click.option("--depth-range", default="0.2:3.0", show_default=True, metavar="MIN:MAX",
                     callback=library_value(lambda text: number_pair(text, ":", "MIN:MAX metres", positive=True)),
                     help="Depths searched by stereo matching, metres."),
    ]
    for option in reversed(options):
        func = option(func)

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from .extract import ExtractParams
        from .guided import GuidedParams
        from .lines2d import LineParams
        from .stereo import StereoParams

        near, far = kwargs.pop("depth_range")
        kwargs["extract_params"] = ExtractParams(
            LineParams(detector=kwargs.pop("detector"), segment_length_px=kwargs.pop("segment_length"),
                       gradient_threshold=kwargs.pop("gradient_threshold"), blur_sigma=kwargs.pop("gradient_blur")),
            StereoParams(min_depth_m=near, max_depth_m=far, critical_angle_deg=kwargs.pop("critical_angle"),
                         critical_by_ends=kwargs.pop("critical_ends"), row_offset_px=kwargs.pop("row_offset")),
            GuidedParams(enabled=kwargs.pop("right_search")))
        return func(*args, **kwargs)

    return wrapper


def number_pair(text: str, sep: str, form: str, positive: bool = False) -> tuple[float, float]:
    from .errors import InputError

    try:
        a, b = (float(x) for x in text.split(sep))
    except ValueError:
        raise InputError(f"expected {form}, found {text!r}") from None
    if positive and not 0 < a < b:
        raise InputError(f"expected {form} with 0 < first < second, found {text!r}")
    if min(a, b) < 0:
        raise InputError(f"expected {form} with values >= 0, found {text!r}")
    return a, b


def parse_box(text: str) -> tuple:
    """``X0:X1,Y0:Y1,Z0:Z1`` (metres) as ((x0, x1), (y0, y1), (z0, z1)), checked by the library
    (``pipeline.check_box``)."""
    from .errors import InputError
    from .pipeline import check_box

    form = "X0:X1,Y0:Y1,Z0:Z1 (metres, object frame)"
    try:
        box = tuple(tuple(float(x) for x in part.split(":")) for part in text.split(","))
    except ValueError:
        raise InputError(f"expected {form}, found {text!r}") from None
    return check_box(box, form, shown=text)


box_option = click.option(
    "--box", metavar="X0:X1,Y0:Y1,Z0:Z1", callback=library_value(parse_box),
    help="Keep only 3D segments centred in this box (metres, object frame): for a fixture, a board or fingers "
         "that move with the object. Example: -0.01:0.17,-0.01:0.08,-0.09:0.01.")


def parse_pose(value):
    """``recording`` (None: the recording's pose) or x,y,z,qx,qy,qz,qw as a (4, 4) T_camera_object."""
    import numpy as np

    from .errors import InputError
    from .geometry import transform_from_quat

    if value == "recording":
        return None
    try:
        numbers = [float(x) for x in value.split(",")]
    except ValueError:
        numbers = []
    if len(numbers) != 7 or not np.isfinite(numbers).all():
        raise InputError(f"expected 'recording' or x,y,z,qx,qy,qz,qw, found {value!r}")
    norm = float(np.linalg.norm(numbers[3:]))
    if abs(norm - 1.0) > 1e-3:   # a typo, or another order of the numbers: not silently normalised
        raise InputError(f"expected a unit quaternion qx,qy,qz,qw (x,y,z first), found one of norm {norm:.4g} in "
                         f"{value!r}")
    return transform_from_quat(numbers[:3], np.array(numbers[3:]) / norm)
