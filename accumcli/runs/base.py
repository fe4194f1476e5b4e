"""What every library run shares: how a recording is opened, which frames are
used, how progress is reported, and how the run's outputs are written.

A run (``extract_recording``, ``accumulate_recording``, ``track_recording``,
``view``) does the whole job the command line asks for and returns a result
object; cli.py only parses options, calls it and prints. Benchmarks and tests
call the same functions.
"""

from __future__ import annotations

import logging
import math
import os
import re
from dataclasses import dataclass, field, replace
from typing import Callable

from ..errors import AccumError, InputError, is_whole_number
from ..recording import Recording, Topics
from ..recording.tf_tree import OUTSIDE_SAMPLES, OUTSIDE_SAMPLES_PATTERN, frame_name

log = logging.getLogger("accumcli")

Progress = Callable[[int, "int | None"], None]
"""``progress(done, total)``: the work done so far and the work expected (None when unknown), in frames;
with ``motion='tracked'`` in frames of its passes, each weighted by what a frame of it costs
(``runs.accumulation.TRACKED_PASS_COST``: 8 frames count 80), so that done / total is the share done."""


def no_progress(done: int, total: int | None) -> None:
    """The default progress callback: says nothing."""


MAX_OFFSET_NS = 4 * 10 ** 18   # with a stamp of today (1.75e18 ns), a time moved by this still fits an int64


@dataclass(frozen=True)
class RecordingOptions:
    """How to read a recording: topic names, the two frames the tool needs, and the time
    tolerance (nanoseconds) for pairing left and right images and for looking up transforms."""

    topics: Topics = field(default_factory=Topics)
    camera_frame: str = "camera_left"
    object_frame: str = "gripper"
    tolerance_ns: int = 1_000_000
    time_offset_ns: int = 0     # poses are looked up this long after an image's stamp (``Recording.pose_at``)
    dither: int = 0             # the seed of a noise pattern added to every image (``Recording``), 0: none

    def __post_init__(self):
        for name, lowest in (("tolerance_ns", 0), ("time_offset_ns", -MAX_OFFSET_NS)):
            value = getattr(self, name)
            if not is_whole_number(value) or not lowest <= value <= MAX_OFFSET_NS:
                raise InputError(f"{name}: expected whole nanoseconds from {lowest} to {MAX_OFFSET_NS}, found {value!r}")
            object.__setattr__(self, name, int(value))
        if not is_whole_number(self.dither) or self.dither < 0:
            raise InputError(f"dither: expected a whole number from 0 (none), found {self.dither!r}")
        object.__setattr__(self, "dither", int(self.dither))
        for name in ("camera_frame", "object_frame"):
            if not isinstance(getattr(self, name), str) or not frame_name(getattr(self, name)):
                raise InputError(f"{name}: expected a frame name, found {getattr(self, name)!r}")
            object.__setattr__(self, name, frame_name(getattr(self, name)))   # '/board' is tf2's 'board'

    def open(self, path, require_pose: bool = True) -> Recording:
        """The recording at ``path``; with ``require_pose`` a transform path from the camera
        frame to the object frame must exist (extraction needs none)."""
        return Recording(path, topics=self.topics, camera_frame=self.camera_frame,
                         object_frame=self.object_frame, tolerance_ns=self.tolerance_ns,
                         require_pose=require_pose, time_offset_ns=self.time_offset_ns, dither=self.dither)


_RANGE = re.compile(r"^\s*(\d*)\s*:\s*(\d*)\s*$")


def options_for_model(options: RecordingOptions, model_frame_id: str, object_frame_of_model: bool) -> RecordingOptions:
    """``options`` with the object's frame the one a model names (``model_frame_id``, as the
    recording's tree keys it) where ``object_frame_of_model`` (the user gave no --object-frame)."""
    model_frame = frame_name(model_frame_id)
    if object_frame_of_model and model_frame and model_frame != options.object_frame:
        log.info("the object's frame is the model's: %s (--object-frame names another)", model_frame)
        return replace(options, object_frame=model_frame)
    return options


@dataclass(frozen=True)
class FrameRange:
    """Stereo frames ``start <= index < stop`` (0-based; ``stop`` None: to the end)."""

    start: int = 0
    stop: int | None = None

    def __post_init__(self):
        if not is_whole_number(self.start) or self.start < 0 or (
                self.stop is not None and (not is_whole_number(self.stop) or self.stop <= self.start)):
            raise InputError(f"frames {self.start!r}:{self.stop!r}: expected whole numbers 0 <= START < STOP")
        object.__setattr__(self, "start", int(self.start))   # numpy integers as Python's (JSON, hashing)
        object.__setattr__(self, "stop", None if self.stop is None else int(self.stop))

    @classmethod
    def parse(cls, text: str) -> "FrameRange":
        """``START:STOP`` with either side empty (``10:``, ``:20``, ``:``). A bare number is refused:
        it is ambiguous between a count and a single frame."""
        m = _RANGE.match(str(text))
        if not m:
            if str(text).strip().isdigit():
                n = int(text)
                raise InputError(f"expected START:STOP, found {text!r} (frame {n} alone is {n}:{n + 1}, "
                                 f"the first {n} frames are 0:{n})")
            raise InputError(f"expected START:STOP with whole numbers, found {text!r}")
        start = int(m.group(1)) if m.group(1) else 0
        stop = int(m.group(2)) if m.group(2) else None
        if stop is not None and stop <= start:
            raise InputError(f"expected START < STOP, found {text!r}")
        return cls(start, stop)

    def __str__(self) -> str:
        return f"{self.start}:{'' if self.stop is None else self.stop}"

    def contains(self, index: int) -> bool:
        """Whether frame ``index`` lies in the range."""
        return index >= self.start and (self.stop is None or index < self.stop)

    def count_in(self, total: int) -> int:
        """How many of ``total`` frames the range selects."""
        return max(0, (total if self.stop is None else min(self.stop, total)) - self.start)

    def check(self, rec: Recording) -> int:
        """The number of frames to do in ``rec``; an empty selection is an error before any work."""
        total = rec.frame_count_hint
        n = self.count_in(total)
        if n == 0 and total > 0:
            raise AccumError(f"{rec.path}: frames {self} select no frame: the recording has {total} stereo "
                             f"frames (0:{total})")
        return n


def nothing_done(path, what: str, skipped: dict[str, int] | None = None, rec=None) -> AccumError:
    """The error for a run that would produce nothing: which frames were skipped, and why (``skipped``,
    and the frames the recording ``rec`` could not decode, first: they never reach a run)."""
    reasons = {**(getattr(rec, "undecodable", None) or {}), **(skipped or {})}
    current_ms = getattr(rec, "time_offset_ns", 0) * 1e-6
    listed = "; ".join(f"{n} frame(s): {why}" for why, n in _grouped_by_time(reasons, current_ms).items())
    return AccumError(f"{path}: {what}" + (f" ({listed})" if listed else ""))


def _grouped_by_time(reasons: dict[str, int], current_ms: float = 0.0) -> dict[str, int]:
    """``reasons`` (why -> frames) with the reasons that differ only in the frame's time (a pose outside
    the transforms' time range) as one, naming the range of times; where those times lie more than a
    minute from the transforms', a remark on the clocks (36 such reasons made one line of 4,350
    characters: the camera's clock counted from its boot, the transforms' from 1970) with the
    ``--time-offset-ms`` that puts the first image 1 ms after the first transform (the times are
    lookups: the stamps plus ``current_ms``, the run's own offset)."""
    grouped: dict[str, list] = {}
    for why, n in reasons.items():
        found = OUTSIDE_SAMPLES_PATTERN.search(why)
        key = why if found is None else OUTSIDE_SAMPLES_PATTERN.sub("\0", why)   # the times' place
        entry = grouped.setdefault(key, [0, [], found])
        entry[0] += n
        if found is not None:
            entry[1].append(float(found.group(1)))
    out = {}
    for key, (n, times, found) in grouped.items():
        if found is None:
            out[key] = n
            continue
        lo, hi = float(found.group(2)), float(found.group(3))
        text = key.replace("\0", OUTSIDE_SAMPLES.format(min(times), lo, hi))
        if min(times) != max(times):
            text = text.replace(f"{min(times):.3f} s", f"{min(times):.3f} to {max(times):.3f} s", 1)
        gap = max(lo - max(times), min(times) - hi)
        if gap > 60:
            shift_ms = current_ms + math.ceil((lo - min(times)) * 1000) + 1
            text += (f", {gap:.0f} s away: the images and the transforms seem to be stamped by different clocks; "
                     f"record both with one clock, or if both began together try --time-offset-ms {shift_ms:.0f}")
        out[text] = n
    return out


def in_frames(frames: "FrameRange") -> str:
    """' in frames START:STOP' for a chosen range, '' for all frames (error messages)."""
    return "" if frames == FrameRange() else f" in frames {frames}"


MODEL_OUTPUTS = (".json", ".ply", ".mcap")    # what accumulate writes, by the output's name
POSES_OUTPUTS = (".json", ".tum", ".mcap")    # what track writes


def check_output_kinds(outputs, suffixes: tuple[str, ...]) -> None:
    """``InputError`` unless each output names its format by one of ``suffixes`` (lower-case
    extensions); a stream (stdout, ``-``, a descriptor) cannot: a model.txt, or a typo's model.jsn, was
    written as JSON by the library without a word."""
    from ..outputs import descriptor_of

    expected = (f"expected a {', '.join(suffixes[:-1])} or {suffixes[-1]} file" if len(suffixes) > 1
                else f"expected a name ending in {suffixes[0]}")
    for path in outputs:
        if not str(path).lower().endswith(suffixes):
            stream = descriptor_of(path) is not None
            found = ("the standard output (- or /dev/stdout)" if str(path) in ("-", "/dev/stdout") else
                     f"the stream {path}" if stream else repr(str(path)))
            why = ", which has no name to tell the format by: write a file" if stream else ""
            raise InputError(f"{expected}, found {found}{why}")


def write_pose_outputs(files, outputs, track, topic: str, child_frame_id: str) -> None:
    """``track`` (a ``model_io.PoseTrack``) to each of ``outputs`` (paths of ``POSES_OUTPUTS``, opened
    by ``files``, an ``OutputSet``): .tum (its 'tracked' poses), .mcap (those as FrameTransforms on
    ``topic``, to ``child_frame_id``) or .json (every pose with its status)."""
    from ..model_io import write_poses, write_poses_mcap
    from ..tum import write_poses_tum

    for path in outputs:
        if str(path).lower().endswith(".tum"):
            write_poses_tum(files.open(path), track)
        elif str(path).lower().endswith(".mcap"):
            write_poses_mcap(files.open(path, "wb"), track, topic=topic, child_frame_id=child_frame_id)
        else:
            write_poses(files.open(path), track)


def path_list(paths, what: str) -> list:
    """The paths of one path (a ``str`` or ``os.PathLike``: one path, not its characters) or of an
    iterable of them (None: none); ``InputError`` for anything else."""
    if paths is None:
        return []
    if isinstance(paths, (str, os.PathLike)):
        return [paths]
    try:
        items = list(paths)
    except TypeError:
        items = None
    if items is None or not all(isinstance(p, (str, os.PathLike)) for p in items):
        raise InputError(f"{what}: expected a path or a list of paths, found {type(paths).__name__}")
    return items


def frame_range(frames) -> FrameRange:
    """``frames`` as a ``FrameRange`` (one, or its ``START:STOP`` text); ``InputError`` for anything else."""
    if isinstance(frames, FrameRange):
        return frames
    if isinstance(frames, str):
        return FrameRange.parse(frames)
    raise InputError(f"frames: expected a FrameRange or 'START:STOP', found {type(frames).__name__}")
