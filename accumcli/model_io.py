"""Files of accum (formats.md sections 2-4): models (JSON, PLY), per-frame
segments (JSONL), poses (JSON, MCAP) and ground-truth sidecars (JSON).

Writers take a path (written atomically, ``atomic.atomic_open``) or a file
opened by an ``outputs.OutputSet``. All JSON is strict: NaN and infinities
are written as ``null`` (``dumps``). Readers recognise their input by its
content first (``file_kind``) and refuse another kind with ``FileFormatError``
("x.ply: expected a model JSON (accum.model/1), got a PLY file"); then they
check the fields they need; fields they do not know are ignored (and kept in
``extra``).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
from dataclasses import dataclass, field, replace
from typing import Iterable, Iterator

import numpy as np
import orjson

from .atomic import opened
from .errors import FileFormatError, InputError
from .geometry import quat_from_transform, transform_from_quat
from .segments import Segments

MODEL_FORMAT = "accum.model/1"
POSES_FORMAT = "accum.poses/1"
TRUTH_FORMAT = "accum.truth/1"
CORE_FIELDS = ("center", "direction", "length", "confidence", "observations")
POSES_TOPIC = "/accum/poses"
TRACKED_SUFFIX = "_tracked"

# file_kind results and how messages name them
KIND_NAMES = {"model": f"a model JSON ({MODEL_FORMAT})", "frames": f"a frames JSONL file ({MODEL_FORMAT} lines)",
              "poses": f"a poses JSON ({POSES_FORMAT})", "truth": f"a truth JSON ({TRUTH_FORMAT})",
              "ply": "a PLY file", "recording": "a recording (MCAP, rosbag2 or ROS 1 bag)", "json": "a JSON file of another kind",
              "text": "a text file", "binary": "a binary file", "empty": "an empty file"}
SNIFF_BYTES = 65536


# -- strict JSON -------------------------------------------------------------------------------
def _json_default(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


def _finite(value):
    """``value`` with every non-finite float replaced by None (numpy values made plain)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, np.ndarray):
        return _finite(value.tolist())
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def dumps(obj, indent: int | None = None) -> str:
    """Strict JSON of ``obj`` (dicts, lists, numbers, numpy scalars and arrays): NaN and
    +-inf become ``null``, never the bare ``NaN``/``Infinity`` that JSON parsers reject.
    Compact separators unless ``indent`` is given. Compact JSON comes from orjson (floats in the
    same shortest round-trip digits as Python's, exponents without padding: 1e-7, not 1e-07):
    the frames file of ``accum extract`` spent a tenth of the run in ``json.dumps``."""
    if indent is None:
        return orjson.dumps(obj, default=_json_default, option=orjson.OPT_SERIALIZE_NUMPY).decode("utf-8")
    try:
        return json.dumps(obj, indent=indent, allow_nan=False, default=_json_default)
    except ValueError:  # a non-finite float somewhere
        return json.dumps(_finite(obj), indent=indent, allow_nan=False, default=_json_default)


def write_json(target, obj, indent: int | None = None) -> None:
    """``obj`` as strict JSON (``dumps``) and a newline, to a path (atomically) or an open text file."""
    with opened(target) as f:
        f.write(dumps(obj, indent) + "\n")


def write_json_lines(target, rows: Iterable) -> None:
    """One strict JSON line per row (e.g. accumulation history), to a path (atomically) or an open text file."""
    with opened(target) as f:
        for row in rows:
            f.write(dumps(row) + "\n")


# -- recognising files -------------------------------------------------------------------------
_FORMAT_TAG = re.compile(rb'"format"\s*:\s*"([^"\\]{0,100})"')


def _head(path) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(SNIFF_BYTES)
    except FileNotFoundError:
        raise FileFormatError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise FileFormatError(f"{path}: is a folder, expected a file") from None
    except PermissionError:
        raise FileFormatError(f"{path}: permission denied; check the file's permissions") from None


def _is_text(head: bytes) -> bool:
    if b"\0" in head:
        return False
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as e:
        return e.start >= len(head) - 3 and len(head) == SNIFF_BYTES  # a character cut by the sniff
    return True


def _sniff(path) -> tuple[str, str | None]:
    """(kind, the format tag if a JSON file has one). A recording is an MCAP file, a rosbag2
    ``.db3`` (SQLite) file, a rosbag2 folder (with its metadata.yaml), a ROS 1 ``.bag`` or a folder of
    them (a split bag): the last four as ``recording.ros2.bag_kind`` tells them."""
    from .recording.ros2 import bag_kind   # the bags' own test (heavier imports: only when a file is looked at)

    if bag_kind(str(path)):
        return "recording", None
    head = _head(path)
    if not head.strip():
        return "empty", None
    if head.startswith(b"\x89MCAP"):
        return "recording", None
    if head.startswith((b"ply\n", b"ply\r\n")):
        return "ply", None
    if not _is_text(head):
        return "binary", None
    text = head.lstrip()
    if not text.startswith((b"{", b"[")):
        return "text", None
    tag = _FORMAT_TAG.search(head)
    tag = tag.group(1).decode("utf-8", "replace") if tag else None
    kind = {MODEL_FORMAT: "model", POSES_FORMAT: "poses", TRUTH_FORMAT: "truth"}.get(tag, "json")
    if kind == "model":
        first, newline, rest = text.partition(b"\n")
        try:
            doc = json.loads(first)
        except ValueError:
            if newline:  # a pretty-printed model, several lines per document
                return "model", tag
            return ("frames" if str(path).endswith(".jsonl") else "model"), tag
        if isinstance(doc, dict) and ("timestamp_ns" in doc or rest.strip()):
            return "frames", tag
    return kind, tag


def file_kind(path) -> str:
    """The kind of file at ``path``, by content (never by name alone): one of KIND_NAMES'
    keys, from the first 64 KiB (magic bytes; for JSON the first ``"format"`` tag, which
    accum writes first). 'frames' is a file of JSON lines tagged accum.model/1 with a
    ``timestamp_ns`` (or more than one such line); 'json' any other JSON-looking text. The name's
    '.jsonl' decides between model and frames only when the first line is longer than
    the part read (64 KiB) and the tag alone cannot tell."""
    return _sniff(path)[0]


def describe_kind(path) -> str:
    """How messages name the kind of file at ``path`` ("a PLY file", "a JSON file of format 'x'", ...)."""
    return _kind_name(*_sniff(path))


def _kind_name(kind: str, tag: str | None) -> str:
    return f"a JSON file of format {tag!r}" if kind == "json" and tag else KIND_NAMES[kind]


def check_kind(path, *expected: str) -> str:
    """``file_kind(path)`` if it is one of ``expected``, else FileFormatError
    "x.ply: expected a model JSON (accum.model/1), got a PLY file"."""
    kind, tag = _sniff(path)
    if kind not in expected:
        wanted = " or ".join(KIND_NAMES[k] for k in expected)
        got = _kind_name(kind, tag)
        if kind == "json" and not tag and os.path.getsize(path) < 1 << 26:   # another kind, or no JSON at all?
            try:
                with open(path, "rb") as f:
                    json.loads(f.read().decode("utf-8", errors="replace"))
            except json.JSONDecodeError as e:
                if e.msg != "Extra data":   # JSON lines of another kind are JSON
                    got = f"text that is not valid JSON ({e})"
        raise FileFormatError(f"{path}: expected {wanted}, got {got}")
    return kind


def _load_json(path, kind: str):
    """The JSON document of a file that ``check_kind`` recognises as ``kind``."""
    check_kind(path, kind)
    try:
        with open(path, "rb") as f:
            return json.loads(f.read().decode("utf-8"))
    except UnicodeDecodeError as e:
        raise FileFormatError(f"{path}: byte {e.start} is not UTF-8 text; expected {KIND_NAMES[kind]}") from None
    except json.JSONDecodeError as e:
        raise FileFormatError(f"{path}: not valid JSON ({e}); expected {KIND_NAMES[kind]}") from None


# -- models ------------------------------------------------------------------------------------
def _round(values: np.ndarray, digits: int) -> list:
    return np.round(values, digits).tolist()


def _confidence_digits(confidence: np.ndarray) -> list:
    """Confidences to 5 digits, none rounded up onto the acceptance line 0.5 (0.499996 would be read
    back as an accepted segment)."""
    rounded = np.round(confidence, 5)
    return np.where((confidence < 0.5) & (rounded >= 0.5), 0.49999, rounded).tolist()


def segments_to_dict(segments: Segments, **header) -> dict:
    """The model-format dictionary of segments (``header`` keys go first, e.g. timestamp_ns)."""
    columns = {"center": _round(segments.centers, 7), "direction": _round(segments.directions, 7),
               "length": _round(segments.lengths, 7), "confidence": _confidence_digits(segments.confidence),
               "observations": segments.observations.astype(int).tolist()}
    columns.update({k: (_round(v, 7) if np.issubdtype(v.dtype, np.floating) else v.tolist())
                    for k, v in segments.extra.items()})
    rows = [dict(zip(columns, values)) for values in zip(*columns.values())]
    return {"format": MODEL_FORMAT, **header, "frame_id": segments.frame_id, "segments": rows}


def segments_from_dict(doc: dict, where: str) -> Segments:
    """Segments of a model-format dictionary; raises ``FileFormatError``."""
    if not isinstance(doc, dict) or doc.get("format") != MODEL_FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise FileFormatError(f"{where}: expected format {MODEL_FORMAT!r}, found {found!r}")
    rows = doc.get("segments")
    if not isinstance(rows, list):
        raise FileFormatError(f"{where}: expected a list under 'segments'")
    frame_id = str(doc.get("frame_id", ""))
    if not rows:
        return Segments.empty(frame_id)
    try:
        centers = np.array([r["center"] for r in rows], float).reshape(-1, 3)
        directions = np.array([r["direction"] for r in rows], float).reshape(-1, 3)
        lengths = np.array([r["length"] for r in rows], float)
        confidence = np.array([r.get("confidence", 1.0) for r in rows], float)
        observations = np.array([r.get("observations", 1) for r in rows], np.int64)
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise FileFormatError(f"{where}: malformed segment ({type(e).__name__}: {e})") from None
    if len(centers) != len(rows):
        raise FileFormatError(f"{where}: segments need finite 3-vectors 'center' and 'direction'")
    extra = {}
    for key in rows[0]:
        if key not in CORE_FIELDS and all(key in r for r in rows):
            with contextlib.suppress(ValueError, TypeError):
                extra[key] = np.array([r[key] for r in rows], float)
    return checked_segments(Segments(frame_id, centers, directions, lengths, confidence, observations, extra),
                            where, FileFormatError)


def checked_segments(segments: Segments, where: str, error=None) -> Segments:
    """``segments`` with unit directions, as a model file's are read; ``error`` (default ``InputError``)
    unless every row has a finite 3-vector centre and non-zero direction, a positive finite length, and
    the columns agree in length. A model given as ``Segments`` (a library caller's) is checked so too."""
    error = error or InputError
    n = len(segments.centers)
    columns = (segments.directions, segments.lengths, segments.confidence, segments.observations)
    if any(len(c) != n for c in columns) or np.shape(segments.centers) != (n, 3) or np.shape(segments.directions) != (n, 3):
        raise error(f"{where}: the segments' columns disagree in length or are not (N, 3) vectors")
    if not (np.isfinite(segments.centers).all() and np.isfinite(segments.directions).all()):
        raise error(f"{where}: segments need finite 3-vectors 'center' and 'direction'")
    norms = np.linalg.norm(segments.directions, axis=1)
    if np.any(norms < 1e-9):
        raise error(f"{where}: a segment has a zero direction")
    if not (np.isfinite(segments.lengths).all() and (segments.lengths > 0).all()):
        raise error(f"{where}: a segment's 'length' must be a positive number of metres")
    return replace(segments, directions=segments.directions / norms[:, None])


def write_model(target, segments: Segments, **header) -> None:
    """The model JSON (formats.md section 2; strict, one line) to a path (atomically) or an open text file."""
    write_json(target, segments_to_dict(segments, **header))


def load_model_doc(path) -> dict:
    """The parsed model JSON, header fields included (``segments_from_dict`` reads its segments)."""
    return _load_json(path, "model")


def read_model(path) -> Segments:
    """The segments of a model JSON; FileFormatError for any other kind of file or a malformed model."""
    return segments_from_dict(load_model_doc(path), str(path))


def confidence_rgb(confidence: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 RGB by confidence (N,): red at 0, yellow at 0.5 (the decision line), green at 1."""
    c = np.clip(np.nan_to_num(np.asarray(confidence, float)), 0.0, 1.0)
    return np.rint(np.column_stack([np.minimum(1, 2 * (1 - c)), np.minimum(1, 2 * c), np.zeros_like(c)])
                   * 255).astype(np.uint8)


def write_ply(target, segments: Segments, all_segments: bool = False) -> None:
    """The model as an ASCII PLY line set, to a path (atomically) or an open text file.

    Accepted segments only (confidence >= 0.5), every one with ``all_segments``.
    ``element vertex`` (2 per segment: its endpoints): float x, y, z (metres, in
    ``frame_id``), uchar red, green, blue (``confidence_rgb``); ``element edge``:
    int vertex1, vertex2, float confidence, uchar red, green, blue. ASCII, because
    trimesh reads binary edges as one (n, k) array and refuses k > 2, while it
    takes ASCII edges by their names; Open3D (``read_line_set``, which takes the
    edge colours) and plyfile read either.
    """
    kept = segments if all_segments else segments.select(segments.accepted)
    n = len(kept)
    header = (f"ply\nformat ascii 1.0\ncomment accum model, frame {kept.frame_id}, "
              f"{'all segments' if all_segments else 'accepted segments (confidence >= 0.5)'}\n"
              f"element vertex {2 * n}\nproperty float x\nproperty float y\nproperty float z\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\n"
              f"element edge {n}\nproperty int vertex1\nproperty int vertex2\nproperty float confidence\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    rgb = confidence_rgb(kept.confidence)
    vertices = np.column_stack([kept.endpoints().reshape(-1, 3), np.repeat(rgb, 2, axis=0)])
    edges = np.column_stack([2 * np.arange(n), 2 * np.arange(n) + 1, np.nan_to_num(kept.confidence), rgb])
    with opened(target) as f:
        f.write(header)
        np.savetxt(f, vertices, fmt="%.7g %.7g %.7g %d %d %d")
        np.savetxt(f, edges, fmt="%d %d %.5g %d %d %d")


# -- frames ------------------------------------------------------------------------------------
class FramesWriter:
    """Streams one strict JSON line per stereo frame to a path (atomic: appears on close
    without error) or to an open text file (e.g. from ``OutputSet.open``)."""

    def __init__(self, target):
        self._stack = contextlib.ExitStack()
        self._file = self._stack.enter_context(opened(target))

    def write(self, segments: Segments, timestamp_ns: int, **extra) -> None:
        self._file.write(dumps(segments_to_dict(segments, timestamp_ns=int(timestamp_ns), **extra)) + "\n")

    def __enter__(self) -> "FramesWriter":
        return self

    def __exit__(self, *exc) -> None:
        self._stack.__exit__(*exc)


def read_frames(path) -> Iterator[tuple[int, Segments, dict]]:
    """(timestamp_ns, segments, the line's other keys) for each line of a frames JSONL file
    (an empty file has no frames)."""
    if file_kind(path) == "empty":
        return
    check_kind(path, "frames")
    with open(path, "rb") as f:
        for number, raw in enumerate(f, 1):
            where = f"{path}, line {number}"
            try:
                line = raw.decode("utf-8")
            except UnicodeDecodeError as e:
                raise FileFormatError(f"{where}: not UTF-8 text (byte {e.start})") from None
            if not line.strip():
                continue
            try:
                doc = json.loads(line)
            except json.JSONDecodeError as e:
                raise FileFormatError(f"{where}: not JSON ({e})") from None
            segments = segments_from_dict(doc, where)
            if not isinstance(doc.get("timestamp_ns"), int):
                raise FileFormatError(f"{where}: expected an integer 'timestamp_ns'")
            yield doc["timestamp_ns"], segments, {k: v for k, v in doc.items() if k != "segments"}


# -- poses -------------------------------------------------------------------------------------
@dataclass
class PoseTrack:
    """Poses ``T_parent_child`` over time: times_ns (N,) int64, poses (N, 4, 4) (NaN where
    there is none); status ("tracked", "lost", ...) and a dict of extra fields per pose."""

    parent_frame_id: str
    child_frame_id: str
    times_ns: np.ndarray
    poses: np.ndarray
    status: list = field(default_factory=list)
    extra: list = field(default_factory=list)

    def tracked(self) -> np.ndarray:
        """(N,) bool: status "tracked" (every pose when there is no status) and a finite pose."""
        ok = np.isfinite(self.poses).all(axis=(1, 2))
        return ok & np.array([s == "tracked" for s in self.status], bool) if self.status else ok


def _pose_rows(doc: dict, where: str) -> tuple[np.ndarray, np.ndarray, list]:
    rows = doc.get("poses")
    if not isinstance(rows, list):
        raise FileFormatError(f"{where}: expected a list under 'poses'")
    try:
        times = np.array([int(r["timestamp_ns"]) for r in rows], np.int64)
        poses = np.stack([transform_from_quat(r["translation"], r["rotation_xyzw"]) for r in rows]) if rows \
            else np.zeros((0, 4, 4))
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise FileFormatError(f"{where}: malformed pose ({type(e).__name__}: {e})") from None
    return times, poses, rows


def pose_fields(T: np.ndarray) -> dict:
    """``translation`` (m) and ``rotation_xyzw`` of a (4, 4) transform, to 9 digits: a pose as poses
    files and frames files (their ``T_camera_object``) write it; ``pose_of_fields`` reads it."""
    translation, quat = quat_from_transform(T)
    return {"translation": _round(translation, 9), "rotation_xyzw": _round(quat, 9)}


def pose_of_fields(doc: dict) -> np.ndarray:
    """The (4, 4) transform of ``pose_fields``' dictionary; KeyError, TypeError or ValueError if malformed."""
    return transform_from_quat(doc["translation"], doc["rotation_xyzw"])


def _pose_dict(t_ns: int, T: np.ndarray) -> dict:
    return {"timestamp_ns": int(t_ns), **pose_fields(T)}


def write_poses(target, track: PoseTrack, **header) -> None:
    """The poses JSON (formats.md section 3; strict), to a path (atomically) or an open text file.
    A non-finite pose is written with ``translation`` and ``rotation_xyzw`` null."""
    rows = []
    for i, (t_ns, T) in enumerate(zip(track.times_ns, track.poses)):
        row = _pose_dict(t_ns, T) if np.isfinite(T).all() else {"timestamp_ns": int(t_ns), "translation": None,
                                                                  "rotation_xyzw": None}
        row["status"] = track.status[i] if track.status else "tracked"
        row.update(track.extra[i] if track.extra else {})
        rows.append(row)
    doc = {"format": POSES_FORMAT, "parent_frame_id": track.parent_frame_id,
           "child_frame_id": track.child_frame_id, **header, "poses": rows}
    write_json(target, doc, indent=1)


def write_poses_mcap(target, track: PoseTrack, topic: str = POSES_TOPIC, child_frame_id: str | None = None) -> int:
    """The tracked poses (``PoseTrack.tracked``) as ``foxglove.FrameTransform`` messages
    ``parent_frame_id -> child_frame_id`` on ``topic``, to a path (atomically) or an open
    binary file; returns the number written. ``child_frame_id`` defaults to the track's
    child + "_tracked" (e.g. gripper_tracked), so that beside the recording in Foxglove it
    neither replaces the recording's /tf nor gives its object frame a second parent."""
    from .recording.writer import RecordingWriter

    child = child_frame_id if child_frame_id is not None else track.child_frame_id + TRACKED_SUFFIX
    keep = track.tracked()
    with RecordingWriter(target) as writer:
        for t_ns, T in zip(track.times_ns[keep], track.poses[keep]):
            writer.transform(track.parent_frame_id, child, T, int(t_ns), topic=topic)
    return int(keep.sum())


def read_poses(path) -> PoseTrack:
    """A poses JSON; null poses become NaN (4, 4) matrices."""
    doc = _load_json(path, "poses")
    if not isinstance(doc, dict) or doc.get("format") != POSES_FORMAT:
        raise FileFormatError(f"{path}: expected format {POSES_FORMAT!r}")
    rows = doc.get("poses")
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise FileFormatError(f"{path}: expected a list of objects under 'poses'")
    times, poses, status = [], [], []
    try:
        for r in rows:
            times.append(int(r.get("timestamp_ns", 0)))
            status.append(r.get("status", "tracked"))
            if r.get("translation") is None or r.get("rotation_xyzw") is None:
                poses.append(np.full((4, 4), np.nan))
            else:
                poses.append(pose_of_fields(r))
    except (TypeError, ValueError) as e:
        raise FileFormatError(f"{path}: malformed pose ({type(e).__name__}: {e})") from None
    return PoseTrack(doc.get("parent_frame_id", ""), doc.get("child_frame_id", ""), np.array(times, np.int64),
                     np.array(poses).reshape(-1, 4, 4), status, rows)


# -- ground truth -----------------------------------------------------------------------------
@dataclass
class Truth:
    """A truth sidecar: edges a, b (E, 3) in the object frame, their kinds, per-edge
    ``seen`` counts (list of (k,) int arrays or None), whether each counts for
    completeness, the true poses ``T_camera_object`` by timestamp, each pose's own
    ``seen`` bits where it has them (timestamp_ns -> base64 of numpy.packbits over all samples), and
    each edge's ``part`` where the truth names one (an extra key of accum's and the devset's truths)."""

    object_frame: str
    camera_frame: str
    a: np.ndarray
    b: np.ndarray
    kinds: list
    seen: list
    for_completeness: np.ndarray
    times_ns: np.ndarray
    poses: np.ndarray
    meta: dict
    pose_seen: dict = field(default_factory=dict)
    parts: list = field(default_factory=list)   # per edge its "part" ('object', 'gripper', ...; '' if none)

    def pose_at(self, t_ns: int, tolerance_ns: int = 1_000_000) -> np.ndarray | None:
        if len(self.times_ns) == 0:
            return None
        i = int(np.argmin(np.abs(self.times_ns - t_ns)))
        return self.poses[i] if abs(int(self.times_ns[i]) - t_ns) <= tolerance_ns else None


def read_truth(path) -> Truth:
    doc = _load_json(path, "truth")
    if not isinstance(doc, dict) or doc.get("format") != TRUTH_FORMAT:
        raise FileFormatError(f"{path}: expected format {TRUTH_FORMAT!r}")
    edges = doc.get("edges")
    if not isinstance(edges, list) or not edges or not all(isinstance(e, dict) for e in edges):
        raise FileFormatError(f"{path}: expected a non-empty list of objects under 'edges'")
    try:
        a = np.array([e["a"] for e in edges], float).reshape(-1, 3)
        b = np.array([e["b"] for e in edges], float).reshape(-1, 3)
    except (KeyError, TypeError, ValueError) as e:
        raise FileFormatError(f"{path}: malformed edge ({type(e).__name__}: {e})") from None
    if len(a) != len(edges) or len(b) != len(edges):
        raise FileFormatError(f"{path}: every edge needs 'a' and 'b' of 3 numbers (metres)")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise FileFormatError(f"{path}: edge {int(np.flatnonzero(~np.isfinite(a - b).all(axis=1))[0])} has NaN or "
                              "infinite coordinates")
    degenerate = np.flatnonzero(np.linalg.norm(b - a, axis=1) < 1e-6)
    if len(degenerate):   # no direction: every distance to it is NaN, and it would silently hide background
        raise FileFormatError(f"{path}: edge {int(degenerate[0])} has no length (a == b); remove it or give its "
                              "other end")
    seen = [np.asarray(e["seen"], np.int64) if "seen" in e else None for e in edges]
    times, poses, rows = _pose_rows(doc, str(path)) if "poses" in doc else (np.zeros(0, np.int64),
                                                                             np.zeros((0, 4, 4)), [])
    pose_seen = {int(r["timestamp_ns"]): r["seen"] for r in rows if isinstance(r.get("seen"), str)}
    return Truth(doc.get("object_frame", ""), doc.get("camera_frame", ""), a, b,
                 [e.get("kind", "") for e in edges], seen,
                 np.array([bool(e.get("completeness", True)) for e in edges]), times, poses,
                 {k: v for k, v in doc.items() if k not in ("edges", "poses")}, pose_seen,
                 [str(e.get("part", "")) for e in edges])
