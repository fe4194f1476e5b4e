"""Files of accum (formats.md sections 2-4): models (JSON, PLY), per-frame
segments (JSONL), poses (JSON) and ground-truth sidecars (JSON).

Every output is written atomically. Readers check the ``format`` tag and the
fields they need, and raise ``FileFormatError`` naming the file and the
problem; fields they do not know are ignored (and kept in ``extra``).
"""

from __future__ import annotations

import contextlib
import json
import math
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from .atomic import atomic_open
from .errors import FileFormatError
from .geometry import quat_from_transform, transform_from_quat
from .segments import Segments

MODEL_FORMAT = "accum.model/1"
POSES_FORMAT = "accum.poses/1"
TRUTH_FORMAT = "accum.truth/1"
CORE_FIELDS = ("center", "direction", "length", "confidence", "observations")


def _round(values: np.ndarray, digits: int) -> list:
    return np.round(values, digits).tolist()


def segments_to_dict(segments: Segments, **header) -> dict:
    """The model-format dictionary of segments (``header`` keys go first, e.g. timestamp_ns)."""
    columns = {"center": _round(segments.centers, 7), "direction": _round(segments.directions, 7),
               "length": _round(segments.lengths, 7), "confidence": _round(segments.confidence, 5),
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
        lengths = np.array([r.get("length", 0.0) for r in rows], float)
        confidence = np.array([r.get("confidence", 1.0) for r in rows], float)
        observations = np.array([r.get("observations", 1) for r in rows], np.int64)
    except (KeyError, TypeError, ValueError) as e:
        raise FileFormatError(f"{where}: malformed segment ({type(e).__name__}: {e})") from None
    if len(centers) != len(rows) or not (np.isfinite(centers).all() and np.isfinite(directions).all()):
        raise FileFormatError(f"{where}: segments need finite 3-vectors 'center' and 'direction'")
    norms = np.linalg.norm(directions, axis=1)
    if np.any(norms < 1e-9):
        raise FileFormatError(f"{where}: a segment has a zero direction")
    extra = {}
    for key in rows[0]:
        if key not in CORE_FIELDS and all(key in r for r in rows):
            with contextlib.suppress(ValueError, TypeError):
                extra[key] = np.array([r[key] for r in rows], float)
    return Segments(frame_id, centers, directions / norms[:, None], lengths, confidence, observations, extra)


def _load_json(path, what: str):
    try:
        with open(path) as f:
            return json.load(f)
    except FileNotFoundError:
        raise FileFormatError(f"{path}: no such {what} file") from None
    except IsADirectoryError:
        raise FileFormatError(f"{path}: is a folder, expected a {what} file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise FileFormatError(f"{path}: not a JSON {what} file ({e})") from None


def write_model(path, segments: Segments, **header) -> None:
    """Write the model JSON (formats.md section 2) atomically."""
    with atomic_open(path) as f:
        json.dump(segments_to_dict(segments, **header), f, separators=(",", ":"))
        f.write("\n")


def read_model(path) -> Segments:
    return segments_from_dict(_load_json(path, "model"), str(path))


def write_ply(path, segments: Segments, all_segments: bool = False) -> None:
    """Binary PLY line set: 2N vertices (float x, y, z endpoints), N edges with a float confidence;
    the accepted segments only unless ``all_segments``."""
    if not all_segments:
        segments = segments.select(segments.accepted)
    n = len(segments)
    header = (f"ply\nformat binary_little_endian 1.0\ncomment accum model, frame {segments.frame_id}\n"
              f"element vertex {2 * n}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element edge {n}\nproperty int vertex1\nproperty int vertex2\nproperty float confidence\n"
              "end_header\n").encode()
    vertices = segments.endpoints().reshape(-1, 3).astype("<f4")
    edges = np.zeros(n, dtype=[("v1", "<i4"), ("v2", "<i4"), ("c", "<f4")])
    edges["v1"] = 2 * np.arange(n)
    edges["v2"] = 2 * np.arange(n) + 1
    edges["c"] = segments.confidence
    with atomic_open(path, "wb") as f:
        f.write(header)
        f.write(vertices.tobytes())
        f.write(edges.tobytes())


class FramesWriter:
    """Streams one JSON line per stereo frame to ``path`` (atomic: appears on close)."""

    def __init__(self, path):
        self._stack = contextlib.ExitStack()
        self._file = self._stack.enter_context(atomic_open(path))

    def write(self, segments: Segments, timestamp_ns: int, **extra) -> None:
        doc = segments_to_dict(segments, timestamp_ns=int(timestamp_ns), **extra)
        self._file.write(json.dumps(doc, separators=(",", ":")) + "\n")

    def __enter__(self) -> "FramesWriter":
        return self

    def __exit__(self, *exc) -> None:
        self._stack.__exit__(*exc)


def read_frames(path) -> Iterator[tuple[int, Segments, dict]]:
    """(timestamp_ns, segments, the line's other keys) for each line of a frames JSONL file."""
    try:
        f = open(path)
    except (FileNotFoundError, IsADirectoryError):
        raise FileFormatError(f"{path}: no such frames file") from None
    with f:
        for number, line in enumerate(f, 1):
            if not line.strip():
                continue
            where = f"{path}, line {number}"
            try:
                doc = json.loads(line)
            except json.JSONDecodeError as e:
                raise FileFormatError(f"{where}: not JSON ({e})") from None
            segments = segments_from_dict(doc, where)
            if "timestamp_ns" not in doc:
                raise FileFormatError(f"{where}: expected 'timestamp_ns'")
            yield int(doc["timestamp_ns"]), segments, {k: v for k, v in doc.items() if k not in ("segments",)}


# -- poses -------------------------------------------------------------------------------------
@dataclass
class PoseTrack:
    """Poses ``T_parent_child`` over time: times_ns (N,) int64, poses (N, 4, 4); status and extra per pose."""

    parent_frame_id: str
    child_frame_id: str
    times_ns: np.ndarray
    poses: np.ndarray
    status: list = field(default_factory=list)
    extra: list = field(default_factory=list)


def _pose_rows(doc: dict, where: str) -> tuple[np.ndarray, np.ndarray, list]:
    rows = doc.get("poses")
    if not isinstance(rows, list):
        raise FileFormatError(f"{where}: expected a list under 'poses'")
    try:
        times = np.array([int(r["timestamp_ns"]) for r in rows], np.int64)
        poses = np.stack([transform_from_quat(r["translation"], r["rotation_xyzw"]) for r in rows]) if rows \
            else np.zeros((0, 4, 4))
    except (KeyError, TypeError, ValueError) as e:
        raise FileFormatError(f"{where}: malformed pose ({type(e).__name__}: {e})") from None
    return times, poses, rows


def _pose_dict(t_ns: int, T: np.ndarray) -> dict:
    translation, quat = quat_from_transform(T)
    return {"timestamp_ns": int(t_ns), "translation": _round(translation, 9), "rotation_xyzw": _round(quat, 9)}


def write_poses(path, track: PoseTrack, **header) -> None:
    rows = []
    for i, (t_ns, T) in enumerate(zip(track.times_ns, track.poses)):
        row = _pose_dict(t_ns, T) if np.isfinite(T).all() else {"timestamp_ns": int(t_ns), "translation": None,
                                                                  "rotation_xyzw": None}
        row["status"] = track.status[i] if track.status else "tracked"
        row.update(track.extra[i] if track.extra else {})
        rows.append(row)
    doc = {"format": POSES_FORMAT, "parent_frame_id": track.parent_frame_id,
           "child_frame_id": track.child_frame_id, **header, "poses": rows}
    with atomic_open(path) as f:
        json.dump(doc, f, indent=1, allow_nan=False, default=_json_default)
        f.write("\n")


def _json_default(value):
    if isinstance(value, (np.floating, np.integer)):
        return value.item() if math.isfinite(value) else None
    raise TypeError(type(value).__name__)


def read_poses(path) -> PoseTrack:
    doc = _load_json(path, "poses")
    if not isinstance(doc, dict) or doc.get("format") != POSES_FORMAT:
        raise FileFormatError(f"{path}: expected format {POSES_FORMAT!r}")
    rows = doc.get("poses")
    if not isinstance(rows, list):
        raise FileFormatError(f"{path}: expected a list under 'poses'")
    times, poses, status = [], [], []
    for r in rows:
        times.append(int(r.get("timestamp_ns", 0)))
        status.append(r.get("status", "tracked"))
        if r.get("translation") is None or r.get("rotation_xyzw") is None:
            poses.append(np.full((4, 4), np.nan))
        else:
            poses.append(transform_from_quat(r["translation"], r["rotation_xyzw"]))
    return PoseTrack(doc.get("parent_frame_id", ""), doc.get("child_frame_id", ""), np.array(times, np.int64),
                     np.array(poses).reshape(-1, 4, 4), status, rows)


# -- ground truth -----------------------------------------------------------------------------
@dataclass
class Truth:
    """A truth sidecar: edges a, b (E, 3) in the object frame, their kinds, per-edge
    ``seen`` counts (list of (k,) int arrays or None), whether each counts for
    completeness, and the true poses ``T_camera_object`` by timestamp."""

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
    if not isinstance(edges, list) or not edges:
        raise FileFormatError(f"{path}: expected a non-empty list under 'edges'")
    try:
        a = np.array([e["a"] for e in edges], float).reshape(-1, 3)
        b = np.array([e["b"] for e in edges], float).reshape(-1, 3)
    except (KeyError, TypeError, ValueError) as e:
        raise FileFormatError(f"{path}: malformed edge ({type(e).__name__}: {e})") from None
    seen = [np.asarray(e["seen"], np.int64) if "seen" in e else None for e in edges]
    times, poses, _ = _pose_rows(doc, str(path)) if "poses" in doc else (np.zeros(0, np.int64),
                                                                          np.zeros((0, 4, 4)), [])
    return Truth(doc.get("object_frame", ""), doc.get("camera_frame", ""), a, b,
                 [e.get("kind", "") for e in edges], seen,
                 np.array([bool(e.get("completeness", True)) for e in edges]), times, poses,
                 {k: v for k, v in doc.items() if k not in ("edges", "poses")})


def file_kind(path) -> str:
    """'recording', 'frames', 'model', 'poses' or 'truth', from the file's magic bytes or format tag."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except (FileNotFoundError, IsADirectoryError):
        raise FileFormatError(f"{path}: no such file") from None
    if head.startswith(b"\x89MCAP"):
        return "recording"
    text = head.decode("utf-8", "replace")
    for tag, kind in ((MODEL_FORMAT, "model"), (POSES_FORMAT, "poses"), (TRUTH_FORMAT, "truth")):
        if tag in text:
            if kind == "model" and str(path).endswith(".jsonl"):
                return "frames"
            return kind
    raise FileFormatError(f"{path}: not a recording, model, frames, poses or truth file of accum")


def write_json_lines(path, rows) -> None:
    """One strict JSON object per line (NaN and infinities as null)."""
    with atomic_open(path) as f:
        for row in rows:
            f.write(dumps_strict(row) + "\n")


def write_poses_mcap(path, track: PoseTrack, topic: str = "/accum/poses", child_frame: str | None = None) -> None:
    """The tracked poses of ``track`` as FrameTransforms on ``topic`` (child ``child_frame``)."""
    from .recording import RecordingWriter

    child = child_frame or f"{track.child_frame_id}_tracked"
    with RecordingWriter(path) as writer:
        for t_ns, T, status in zip(track.times_ns, track.poses, track.status):
            if status == "tracked":
                writer.transform(track.parent_frame_id, child, T, int(t_ns), topic=topic)


def _finite_or_none(value):
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def dumps_strict(doc, **kwargs) -> str:
    """JSON text of ``doc`` with NaN and infinities as null (strict parsers reject bare NaN)."""
    return json.dumps(_finite_or_none(doc), allow_nan=False, **kwargs)
