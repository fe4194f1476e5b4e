"""Measuring models, single-frame extractions and poses against a truth sidecar.

Definitions (issue 4, used for every figure accum reports):
- a segment is *correct* if its centre lies within ``position_tol`` (4 mm) of a
  truth edge (as a finite segment) and its direction is within ``angle_tol``
  (10 degrees) of that edge;
- *precision* is the fraction of evaluated segments that are correct;
- *background* is the fraction farther than ``background_dist`` (20 mm) from
  every truth edge;
- *completeness* is the fraction of truth edge length that is covered by a
  correct segment, taken as a finite segment of its length: an edge sample is
  covered when its projection on the segment's line falls within half the
  segment's length of the centre and lies within ``position_tol`` of it. Only
  samples seen in at least ``min_seen`` frames count (the truth's ``seen``
  counts; an edge without them counts wholly, sampled every 2 mm), and edges
  marked ``"completeness": false`` do not count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError, is_whole_number
from .geometry import invert, pose_error
from .model_io import Truth
from .segments import Segments


@dataclass(frozen=True)
class Tolerances:
    """What counts as right: a segment within ``position_tol`` (m) and ``angle_tol_deg`` of a truth edge
    is correct, one farther than ``background_dist`` (m) from every edge is background; completeness
    counts the truth's samples, every ``sample_spacing`` (m) along its edges, seen in at least
    ``min_seen`` frames. ``InputError`` unless each is a positive finite number (``min_seen`` whole)."""

    position_tol: float = 0.004
    angle_tol_deg: float = 10.0
    background_dist: float = 0.020
    min_seen: int = 3
    sample_spacing: float = 0.002

    def __post_init__(self):
        for name in ("position_tol", "angle_tol_deg", "background_dist", "sample_spacing"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                    or not np.isfinite(value) or value <= 0:
                raise InputError(f"{name}: expected a positive number, found {value!r}")
        if not is_whole_number(self.min_seen) or self.min_seen < 1:
            raise InputError(f"min_seen: expected a whole number of frames of at least 1, found {self.min_seen!r}")
        object.__setattr__(self, "min_seen", int(self.min_seen))


@dataclass
class EdgeSamples:
    """Truth edges a, b (E, 3) (object frame) and their samples: points (S, 3), edge (S,), counted (S,)."""

    a: np.ndarray
    b: np.ndarray
    points: np.ndarray
    edge: np.ndarray
    counted: np.ndarray

    @classmethod
    def of(cls, truth: Truth, tol: Tolerances = Tolerances()) -> "EdgeSamples":
        from .edge_sampling import edge_samples, sample_count

        points, owner, counted = [], [], []
        for i, (a, b, seen, use) in enumerate(zip(truth.a, truth.b, truth.seen, truth.for_completeness)):
            k = len(seen) if seen is not None and len(seen) else sample_count(a, b, tol.sample_spacing)
            points.append(edge_samples(a, b, k))
            owner.append(np.full(k, i))
            ok = np.full(k, bool(use))
            if seen is not None and len(seen):
                ok &= np.asarray(seen) >= tol.min_seen
            counted.append(ok)
        return cls(truth.a, truth.b, np.concatenate(points), np.concatenate(owner), np.concatenate(counted))


def _point_edge_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (N, E) from points (N, 3) to finite edges a, b (E, 3)."""
    ab = b - a
    t = np.clip(np.einsum("nek,ek->ne", p[:, None, :] - a[None], ab) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=2)


def classify(segments: Segments, edges: EdgeSamples, tol: Tolerances = Tolerances()):
    """Per segment (object frame): distance to the nearest edge (N,), correct (N,) bool, and the
    (N, E) bool matrix of edges each segment is correct for."""
    if len(segments) == 0:
        return np.zeros(0), np.zeros(0, bool), np.zeros((0, len(edges.a)), bool)
    distance = np.concatenate([_point_edge_distance(chunk, edges.a, edges.b)
                               for chunk in np.array_split(segments.centers, max(1, len(segments) // 2000))])
    edge_dir = (edges.b - edges.a) / np.linalg.norm(edges.b - edges.a, axis=1, keepdims=True)
    cos = np.abs(segments.directions @ edge_dir.T)
    correct_for = (distance <= tol.position_tol) & (cos >= np.cos(np.radians(tol.angle_tol_deg)))
    return distance.min(axis=1), correct_for.any(axis=1), correct_for


def covered_samples(segments: Segments, correct_for: np.ndarray, edges: EdgeSamples,
                    tol: Tolerances = Tolerances()) -> np.ndarray:
    """(S,) bool: edge samples covered by a segment that is correct for the sample's edge."""
    covered = np.zeros(len(edges.points), bool)
    good = np.flatnonzero(correct_for.any(axis=1))
    if len(good) == 0:
        return covered
    tree = cKDTree(edges.points)
    radius = segments.lengths[good].max() / 2 + tol.position_tol
    pairs = cKDTree(segments.centers[good]).sparse_distance_matrix(tree, radius, output_type="ndarray")
    k, s = good[pairs["i"]], pairs["j"]
    rel = edges.points[s] - segments.centers[k]
    along = np.sum(rel * segments.directions[k], axis=1)
    across = np.linalg.norm(rel - along[:, None] * segments.directions[k], axis=1)
    hit = (np.abs(along) <= segments.lengths[k] / 2) & (across <= tol.position_tol) & correct_for[k, edges.edge[s]]
    covered[s[hit]] = True
    return covered


@dataclass
class SegmentScores:
    segments: int
    precision: float
    completeness: float
    background: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _completeness(covered: np.ndarray, edges: EdgeSamples) -> float:
    """The share of the counted samples that ``covered`` (S,) bool marks."""
    return float(covered[edges.counted].mean()) if edges.counted.any() else float("nan")


def _scores(segments: Segments, distance, correct, covered, edges: EdgeSamples, tol: Tolerances) -> SegmentScores:
    """``score_segments`` from the segments' ``classify`` result and the samples they cover (``covered_samples``)."""
    n = max(len(segments), 1)
    return SegmentScores(len(segments), float(correct.sum() / n) if len(segments) else float("nan"),
                         _completeness(covered, edges),
                         float((distance > tol.background_dist).sum() / n) if len(segments) else float("nan"))


def score_segments(segments: Segments, edges: EdgeSamples, tol: Tolerances = Tolerances()) -> SegmentScores:
    """Precision, completeness and background of ``segments`` (object frame)."""
    distance, correct, correct_for = classify(segments, edges, tol)
    return _scores(segments, distance, correct, covered_samples(segments, correct_for, edges, tol), edges, tol)


def evaluate_model(model: Segments, truth: Truth, tol: Tolerances = Tolerances()) -> dict:
    """Scores of a model's accepted segments (confidence >= 0.5) against the truth, and the
    completeness of all its segments whatever their confidence (``completeness_any_confidence``:
    what accumulation found but has not accepted) and, where the model marks them
    (``direction_held``), of the accepted ones and those confirmed but held back for their direction
    (``completeness_with_held``: how much of that gap is the direction's; the rest is not, or no
    longer, confirmed).
    Where the truth's edges name two or more parts (the object, the gripper that holds it),
    ``completeness_<part>`` of each: the gripper's many short edges were most of the counted length on
    the scoreboard, and a model can lose it alone."""
    edges = EdgeSamples.of(truth, tol)
    distance, correct, correct_for = classify(model, edges, tol)   # once for all segments, accepted or not
    a = model.accepted
    covered = covered_samples(model.select(a), correct_for[a], edges, tol)   # once: the scores and the parts
    scores = _scores(model.select(a), distance[a], correct[a], covered, edges, tol).as_dict()
    anywhere = _completeness(covered_samples(model, correct_for, edges, tol), edges)
    figures = {"segments": len(model), "accepted": scores.pop("segments"), **scores,
               "completeness_any_confidence": anywhere}
    if "direction_held" in model.extra:   # what a set of segments covers is the union of what each covers
        held = ~a & (model.extra["direction_held"] > 0.5)
        figures["completeness_with_held"] = _completeness(
            covered | covered_samples(model.select(held), correct_for[held], edges, tol), edges)
    parts = np.asarray(truth.parts if len(truth.parts) == len(truth.a) else [""] * len(truth.a), dtype=object)
    named = sorted({p for p in parts if p})
    if len(named) >= 2:
        for part in named:
            counted = edges.counted & (parts[edges.edge] == part)
            figures[f"completeness_{part}"] = float(covered[counted].mean()) if counted.any() else float("nan")
    return figures


def frame_accuracy(segments_camera: Segments, T_camera_object: np.ndarray, edges: EdgeSamples,
                   tol: Tolerances = Tolerances()) -> dict:
    """Single-frame counts of ``segments_camera`` placed in the object frame by ``T_camera_object``:
    all segments, those near the object (within the background distance), the correct ones among
    those, and the others (background); and the completeness of all segments."""
    segments = segments_camera.transformed(invert(T_camera_object), "object")
    distance, correct, correct_for = classify(segments, edges, tol)
    near = distance <= tol.background_dist
    covered = covered_samples(segments, correct_for, edges, tol)
    return {"segments": len(segments), "near_object": int(near.sum()), "correct_near": int((correct & near).sum()),
            "completeness": float(covered[edges.counted].mean()) if edges.counted.any() else float("nan"),
            "background": int((~near).sum())}


def pose_errors(times_ns: np.ndarray, poses: np.ndarray, status: list, truth: Truth) -> dict:
    """Median and max rotation (deg) and translation (mm) errors of tracked poses, and the tracked
    fraction, over the frames the truth has a pose for (``frames``; the others are counted in
    ``frames_without_truth`` when there are any: a frame without truth can be judged neither way)."""
    rot, trans, tracked, judged = [], [], 0, 0
    for t_ns, T, st in zip(times_ns, poses, status):
        T_true = truth.pose_at(int(t_ns))
        if T_true is None:
            continue
        judged += 1
        if st != "tracked" or not np.isfinite(T).all():
            continue
        tracked += 1
        r, t = pose_error(T, T_true)
        rot.append(r)
        trans.append(t * 1000)
    stats = {"frames": judged, "tracked_fraction": tracked / max(judged, 1)}
    if judged < len(times_ns):
        stats["frames_without_truth"] = len(times_ns) - judged
    for name, values in (("rotation_deg", rot), ("translation_mm", trans)):
        stats[f"median_{name}"] = float(np.median(values)) if values else float("nan")
        stats[f"max_{name}"] = float(np.max(values)) if values else float("nan")
    return stats


def evaluate_frames(frames, truth: Truth, tol: Tolerances = Tolerances(), rows: list | None = None) -> dict:
    """Single-frame figures over ``frames`` (iterable of (timestamp_ns, Segments in the camera frame)),
    placed with the truth's poses: the fraction of segments within the background distance of the
    object that are correct, the mean single-frame completeness, and the background fraction, over the
    frames the truth has a pose for (the others are counted in ``frames_without_truth``, if any).
    ``rows``: if a list, each frame's own figures are appended to it (for a plot over frames)."""
    edges = EdgeSamples.of(truth, tol)
    per_frame, near, correct, background, total, skipped = [], 0, 0, 0, 0, 0
    for t_ns, segments in frames:
        T = truth.pose_at(int(t_ns))
        if T is None:
            skipped += 1
            continue
        r = frame_accuracy(segments, T, edges, tol)
        per_frame.append(r["completeness"])
        if rows is not None:
            rows.append({"frame_index": len(rows), "timestamp_ns": int(t_ns), "segments": r["segments"],
                         "accuracy_near_object": r["correct_near"] / r["near_object"] if r["near_object"]
                         else float("nan"), "completeness": r["completeness"],
                         "background": r["background"] / r["segments"] if r["segments"] else float("nan")})
        near += r["near_object"]
        correct += r["correct_near"]
        background += r["background"]
        total += r["segments"]
    figures = {"frames": len(per_frame), "segments_per_frame": total / max(len(per_frame), 1),
               "accuracy_near_object": correct / near if near else float("nan"),
               "single_frame_completeness": float(np.mean(per_frame)) if per_frame else float("nan"),
               "background": background / total if total else float("nan")}
    if skipped:
        figures["frames_without_truth"] = skipped
    return figures
