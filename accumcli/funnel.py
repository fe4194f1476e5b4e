"""The single-frame funnel: where the edge length that a frame shows is lost on its way to
correct 3D segments. Stage by stage, as fractions of the edge samples seen in the frame:

1. ``detected_2d``: a left 2D segment lies on the sample's projection (within ``DETECT_PX``
   across, inside its extent plus ``DETECT_PX``, direction within ``DETECT_DEG``);
2. ``not_critical``: one such segment is not critical (farther than the critical angle from the
   epipolar direction, so ordinary stereo matching tries it);
3. ``matched``: one such segment became a 3D segment (a critical one through its line's ends,
   ``critical``; so this stage may exceed the previous one);
4. ``correct_3d``: the frame's 3D segments cover the sample correctly (as in ``evaluate``).

Over the whole recording, ``correct_twice``: the share of the samples that completeness counts
which the single-frame segments of at least two frames cover correctly. An accumulator accepts what
a second frame confirms, so this is about the completeness it can reach from these frames (a
little more where merged pieces grow along an edge): the gap between it and the model's
completeness is lost in accumulation, the gap below 1 in extraction.

Where that gap below 1 is lost (when every frame judged carries its 2D segments): each counted
sample that fewer than two frames got right is charged to the last stage that at least two of its
frames passed, as shares of the counted samples: ``lost_unseen`` (fewer than two of the frames judged
showed it: a ``--frames`` subset, frames without a truth pose), ``lost_2d`` (shown, but fewer than
two frames detected it), ``lost_critical`` (detected, but critical, and not triangulated from its
line's ends), ``lost_unmatched`` (usable, but stereo matched it in fewer than two frames), ``lost_3d``
(matched in two or more, but its 3D segments were wrong: on the devset mostly a direction tilted in
depth, which one stereo pair of short pieces cannot fix). The five and ``correct_twice`` sum to 1.
Why: a figure that misses its target should name the stage that limits it, and the per-frame funnel
does not say whether the same edges fail in every frame.

Which samples a frame shows: the truth's per-pose ``seen`` bits (base64 of numpy.packbits over
the samples of all edges, in edge order) where it has them; otherwise (an approximation, said in
the result) every sample that lies in front of the camera and inside both images and that the
truth counts for completeness. Needs the frames file to carry the 2D segments and intrinsics
(``accum extract --with-2d``); without them only stage 4 is given.
"""

from __future__ import annotations

import base64

import numpy as np
from scipy.spatial import cKDTree

from .evaluate import EdgeSamples, Tolerances, classify, covered_samples
from .geometry import invert, rotate_vectors, transform_points
from .segments import Segments

DETECT_PX = 1.5      # across-distance of a 2D segment from a sample's projection, pixels
DETECT_DEG = 10.0    # direction difference of a 2D segment from the projected edge, degrees
STAGES = ("detected_2d", "not_critical", "matched", "correct_3d")
LOSSES = ("lost_unseen", "lost_2d", "lost_critical", "lost_unmatched", "lost_3d")   # module docstring


def per_pose_seen(truth, samples: int) -> dict[int, np.ndarray]:
    """timestamp_ns -> (samples,) bool: the samples seen in that frame, from the truth's per-pose
    bits (empty when it has none or they do not cover ``samples``)."""
    total = sum(len(s) for s in truth.seen if s is not None)   # the bits cover the edges' own samples
    if total != samples:
        return {}
    bits = {t_ns: np.unpackbits(np.frombuffer(base64.b64decode(text), np.uint8))[:total].astype(bool)
            for t_ns, text in truth.pose_seen.items()}
    return {t_ns: b for t_ns, b in bits.items() if len(b) == total}


def _project(points_cam: np.ndarray, intr: dict) -> tuple[np.ndarray, np.ndarray]:
    """Left and right pixel coordinates (u, v), (N, 2), of camera-frame points (N, 3)."""
    z = points_cam[:, 2]
    u = intr["fx"] * points_cam[:, 0] / z + intr["cx"]
    v = intr["fy"] * points_cam[:, 1] / z + intr["cy"]
    d = intr["fx"] * intr["baseline"] / z
    return np.stack([u, v], 1), np.stack([u - d, v], 1)


def approximate_seen(edges: EdgeSamples, T_camera_object: np.ndarray, intr: dict) -> np.ndarray:
    """(S,) bool: samples counted for completeness, in front of the camera and inside both images."""
    points = transform_points(T_camera_object, edges.points)
    left, right = _project(points, intr)
    inside = [(p[:, 0] >= 0) & (p[:, 0] <= intr["width"] - 1) & (p[:, 1] >= 0) & (p[:, 1] <= intr["height"] - 1)
              for p in (left, right)]
    return edges.counted & (points[:, 2] > 0.05) & inside[0] & inside[1]


def detected_by(segments_2d: np.ndarray, edges: EdgeSamples, T_camera_object: np.ndarray, intr: dict,
                samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (sample index, 2D segment index) where a left 2D segment (rows u0, v0, u1, v1, px) lies
    on the projection of an edge sample (indices ``samples``)."""
    if len(segments_2d) == 0 or len(samples) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    points = transform_points(T_camera_object, edges.points[samples])
    tangent = rotate_vectors(T_camera_object, (edges.b - edges.a)[edges.edge[samples]])
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    uv, _ = _project(points, intr)
    uv_ahead, _ = _project(points + 1e-3 * tangent, intr)
    edge_dir = uv_ahead - uv
    edge_dir /= np.maximum(np.linalg.norm(edge_dir, axis=1, keepdims=True), 1e-12)
    a, b = segments_2d[:, :2], segments_2d[:, 2:]
    centers, lengths = (a + b) / 2, np.linalg.norm(b - a, axis=1)
    directions = (b - a) / np.maximum(lengths, 1e-12)[:, None]
    radius = lengths.max() / 2 + DETECT_PX
    pairs = cKDTree(uv).sparse_distance_matrix(cKDTree(centers), radius, output_type="ndarray")
    s, k = pairs["i"], pairs["j"]
    rel = uv[s] - centers[k]
    along = np.sum(rel * directions[k], axis=1)
    across = np.abs(rel[:, 0] * directions[k, 1] - rel[:, 1] * directions[k, 0])
    parallel = np.abs(np.sum(edge_dir[s] * directions[k], axis=1)) >= np.cos(np.radians(DETECT_DEG))
    hit = (across <= DETECT_PX) & (np.abs(along) <= lengths[k] / 2 + DETECT_PX) & parallel
    return samples[s[hit]], k[hit]


def frame_funnel(segments_camera: Segments, doc: dict, T_camera_object: np.ndarray, edges: EdgeSamples,
                 seen: np.ndarray | None, tol: Tolerances = Tolerances(),
                 times_correct: np.ndarray | None = None, times_reached: np.ndarray | None = None) -> dict:
    """Counts of seen samples reaching each stage in one frame (``doc``: the frames-file line).
    ``times_correct``: (S,) int, incremented in place at the samples this frame covers correctly;
    ``times_reached``: (4, S) int, likewise at the samples it showed, detected, found not critical,
    matched (left alone without 2D segments and intrinsics)."""
    intr = doc.get("intrinsics")
    if seen is None:
        seen = approximate_seen(edges, T_camera_object, intr) if intr else edges.counted.copy()
    seen = seen & edges.counted
    samples = np.flatnonzero(seen)
    counts = {"seen": int(len(samples))}
    two_d = doc.get("segments_2d")
    if two_d and intr:
        left = np.asarray(two_d["left"], float).reshape(-1, 4)
        sample_of, segment_of = detected_by(left, edges, T_camera_object, intr, samples)
        direction = left[:, 2:] - left[:, :2]
        angle = np.degrees(np.arctan2(np.abs(direction[:, 1]), np.abs(direction[:, 0])))
        usable = angle >= float(two_d["critical_angle_deg"])
        matched = np.zeros(len(left), bool)
        matched[np.asarray(two_d["matched"], int)] = True
        if times_reached is not None:
            times_reached[0, samples] += 1
        for row, (stage, keep) in enumerate((("detected_2d", np.ones(len(segment_of), bool)),
                                             ("not_critical", usable[segment_of]), ("matched", matched[segment_of])),
                                            start=1):
            reached = np.unique(sample_of[keep])
            counts[stage] = int(len(reached))
            if times_reached is not None:
                times_reached[row, reached] += 1
    segments = segments_camera.transformed(invert(T_camera_object), "object")
    _, _, correct_for = classify(segments, edges, tol)
    correct = covered_samples(segments, correct_for, edges, tol) & seen
    if times_correct is not None:
        times_correct += correct
    counts["correct_3d"] = int(correct.sum())
    return counts


def _losses(times_correct: np.ndarray, times_reached: np.ndarray) -> dict:
    """``funnel_lost_*`` (module docstring) of the counted samples: ``times_correct`` (S,) and
    ``times_reached`` (4, S), the frames that got each right and that showed, detected, found not
    critical and matched it."""
    twice = times_reached >= 2
    lost = times_correct < 2
    # the last stage passed twice: matched, else not critical, else detected, else shown, else none
    stage = np.select([twice[3], twice[2], twice[1], twice[0]], [4, 3, 2, 1], 0)
    return {f"funnel_{name}": float(np.mean(lost & (stage == k))) for k, name in enumerate(LOSSES)}


def funnel(frames, truth, tol: Tolerances = Tolerances()) -> dict:
    """The funnel over ``frames`` (iterable of (timestamp_ns, Segments in the camera frame, line doc)):
    each stage's share of the seen samples, summed over the frames with a truth pose, and
    ``funnel_correct_twice`` (module docstring)."""
    edges = EdgeSamples.of(truth, tol)
    bits = per_pose_seen(truth, len(edges.points))
    totals: dict[str, int] = {}
    times_correct = np.zeros(len(edges.points), np.int64)
    times_reached = np.zeros((4, len(edges.points)), np.int64)
    projected = 0   # frames without the truth's bits, whose seen samples are projected (no occlusion)
    judged = with_2d = 0
    for t_ns, segments, doc in frames:
        T = truth.pose_at(int(t_ns))
        if T is None:
            continue
        # the bits of the truth pose that pose_at chose (within its tolerance, not only at the same stamp)
        seen = bits.get(int(truth.times_ns[np.argmin(np.abs(truth.times_ns - int(t_ns)))]))
        projected += seen is None
        counts = frame_funnel(segments, doc, T, edges, seen, tol, times_correct, times_reached)
        judged, with_2d = judged + 1, with_2d + ("detected_2d" in counts)
        for key, value in counts.items():
            totals[key] = totals.get(key, 0) + value
    n = max(totals.get("seen", 0), 1)
    result = {f"funnel_{stage}": totals[stage] / n for stage in STAGES if stage in totals}
    if edges.counted.any():
        result["funnel_correct_twice"] = float((times_correct[edges.counted] >= 2).mean())
        if judged and with_2d == judged:    # a frame without them would charge its samples to 2D
            result.update(_losses(times_correct[edges.counted], times_reached[:, edges.counted]))
    result["funnel_seen_from"] = ("projection (no occlusion)" if not bits else "truth per-frame bits" if not projected
                                  else f"truth per-frame bits ({projected} frames by projection, no occlusion)")
    return result
