"""Near-horizontal edges triangulated from their ends (issue 9, deliverable 4).

Along an image row the disparity of a near-horizontal edge is undefined: the paper rejects
such *critical* segments (within ``critical_angle_deg`` of the epipolar direction). Where the
edge ends at a corner, the disparity *is* defined there: the grey-level window around the end
holds structure across the row. So (``StereoParams.end_*``):

1. Ends: the critical left segments of a line (``Segments2D.line_id``), sorted along it, form
   *runs* (split at gaps over ``end_gap_px``); each run has two ends.
2. An end's disparity: block matching along its row in the right image, the normalized
   cross-correlation of a (2 w + 1)^2 window (w = ``end_window_px``) at every integer disparity
   in the depth range, sub-pixel by a parabola through the peak. Trusted only when the peak
   reaches ``end_min_ncc`` and its cost (1 - NCC) is below ``end_ratio`` times that of the best
   shift 3 px or more away: a window with only horizontal structure (an edge that fades out
   rather than ends) correlates about as well at every shift and is refused. Where it is refused,
   the window beside the end on its own edge's side is tried (``end_inner_window``): at a
   silhouette corner the centred window holds a side face or background that the two cameras
   see differently (on the teabox this raised the completeness from 0.240 to 0.415). Where both
   are refused and a triangulated (non-critical) segment ends within ``end_junction_px``, the end
   takes that segment's disparity at its row (a junction). Block matching is OpenCV's domain too
   (StereoBM), but here only at a few hundred points, with a peak test of our own: written
   here, vectorised over all ends at once, on whole pixels (exact integer sums).
3. Ends that are not where the edge ends are not used: one that another run on the same image
   line faces within ``end_continuation_px`` (the edge goes on behind an occluder or across a
   mark): there the window shows the occluder, and a background edge would take the depth of
   the object in front of it. (A test for edges crossing the end on both sides, T-junctions, took
   the corners where three box edges meet for them too: the teabox's completeness fell from
   0.240 to 0.204, and it caught nothing on the suite that this test does not.)
4. A critical segment takes the nearest usable end on either side on its line (parallel within
   3 degrees, within ``end_across_px``), at least ``end_min_run_px`` apart, their depths at most
   ``end_max_depth_ratio`` apart (more: an occluded edge rather than a receding one). Disparity
   is affine in the image position along a 3D line's projection: the segment's comes from the
   line through the two ends'. Checks: the left image shows the edge all the way between the
   ends (``end_continuity``, either polarity: a silhouette's changes with the background), the
   right image where predicted (``end_verify``), and where the block match is sure at a quarter,
   half and three quarters of the span (texture beside the edge) it agrees within
   ``end_agree_px``.

Uncertainty: each end's disparity carries ``end_disparity_sigma_px``; a segment's depth sigma
is its interpolation's, its direction sigma the tilt that the two ends' errors give over the
span. Segments whose direction sigma exceeds ``end_max_direction_sigma_deg`` are dropped: a
critical piece's direction rests on two depths, and on the suite (``make suite``) 5 degrees let
through enough wrong ones to lower the median accumulated precision by 0.016; with 3 the
synthetic rows are unchanged and the real teabox (where the box lies flat and 70 % of the seen
edge length was critical at the 12-degree critical angle of then) gains. Measured again once the
model accepted only segments sure of their direction (``line_model.to_model``): 5 degrees gave
precision / completeness medians 0.959 / 0.589 against 0.963 / 0.589; 10 degrees raised the
single-frame correct 3D median from 0.393 to 0.413 and the teabox's completeness from 0.638 to
0.667, but sim_100's precision fell from 0.985 to 0.882 (medians 0.957 / 0.589).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .ncc_kernel import ends_on_lines, row_ncc
from .lines2d import Gradients, Segments2D, parabola_peak, sample
from .recording import StereoIntrinsics
from .segments import Segments
from .stereo import StereoParams, angle_from_rows, backproject, lateral_sigma


def _runs(left: Segments2D, index: np.ndarray, gap_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The runs of segments ``index`` along their lines: per run (R,) its first segment (sorted
    along the line), and where it starts and ends along the line (``Segments2D.t``, px)."""
    order = index[np.lexsort((left.t[index], left.line_id[index]))]
    start = left.t[order] - left.lengths[order] / 2
    end = left.t[order] + left.lengths[order] / 2
    new = np.ones(len(order), bool)
    new[1:] = (left.line_id[order[1:]] != left.line_id[order[:-1]]) | (start[1:] > end[:-1] + gap_px)
    first = np.flatnonzero(new)           # a run's segments follow each other in ``order``
    return order[first], np.minimum.reduceat(start, first), np.maximum.reduceat(end, first)


def _block_match(left_img: np.ndarray, right_img: np.ndarray, ends: np.ndarray, d_lo: int, d_hi: int,
                 w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per end (M, 2) (u, v) px in the left image: the disparity (M,) px of the best NCC of its
    window along its row in the right image, that NCC (M,), and the best NCC at least 3 px away.

    Windows sit on whole pixels (the end rounded): the sums are then exact integers, so the
    result does not depend on the summation order (the same bytes out in every process). The NCC
    itself: ``ncc_kernel.row_ncc``."""
    column = np.rint(ends[:, 0]).astype(np.int64)
    row = np.rint(ends[:, 1]).astype(np.int64)
    ncc = row_ncc(left_img, right_img, row, column, int(d_lo), int(d_hi), int(w))                 # (M, D)
    k = np.argmax(ncc, axis=1)
    rows_m = np.arange(len(ends))
    best = ncc[rows_m, k]
    inner = np.clip(k, 1, ncc.shape[1] - 2)
    shift = np.clip(parabola_peak(ncc[rows_m, inner - 1], ncc[rows_m, inner], ncc[rows_m, inner + 1]), -0.5, 0.5)
    shift = np.where(inner == k, shift, 0.0)
    far = np.abs(np.arange(ncc.shape[1])[None, :] - k[:, None]) >= 3
    second = np.max(np.where(far, ncc, -1.0), axis=1)
    # window k is centred on right column (left column - d_hi + k): disparity d_hi - k, which the
    # end, half a pixel away at most, shares
    return d_hi - (k + shift), best, second


def _peak_trusted(best: np.ndarray, second: np.ndarray, params: StereoParams) -> np.ndarray:
    """(M,) bool: block matches whose peak is high and stands out from every shift 3 px or more away."""
    return (best >= params.end_min_ncc) & ((1 - best) < params.end_ratio * (1 - second))


def _shown(grad: Gradients, points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(K,) share of the points (K, S, 2) px where the gradient across the line (``normal`` (K, 2),
    either sign: a silhouette's polarity changes with the background behind it) reaches the Canny
    threshold: how much of a predicted edge the image shows."""
    gx, gy = (sample(g, points[..., 0], points[..., 1]) for g in (grad.gx, grad.gy))
    across = gx * normal[:, None, 0] + gy * normal[:, None, 1]
    return np.mean(np.abs(across) >= grad.gradient_threshold, axis=1)


def _junction_disparity(ends: np.ndarray, matched: Segments, matched_2d: Segments2D, intr: StereoIntrinsics,
                        radius_px: float) -> np.ndarray:
    """(M,) disparity px at each end (M, 2) px where a triangulated (non-critical) segment meets
    it, NaN elsewhere. ``matched``: those 3D segments (left camera frame), ``matched_2d`` their
    left 2D segments; one meets an end when one of its 2D endpoints lies within ``radius_px`` of
    it. The disparity is the 3D segment's line's at the end's row: a line across the rows fixes
    the depth there well (its own fit used all its pieces), unlike the block match of a window that
    the background behind a corner shares."""
    out = np.full(len(ends), np.nan)
    if len(matched) == 0:
        return out
    distance, nearest = cKDTree(matched_2d.endpoints().reshape(-1, 2)).query(ends, distance_upper_bound=radius_px)
    met = np.flatnonzero(np.isfinite(distance))
    if len(met) == 0:
        return out
    k = nearest[met] // 2
    c, d = matched.centers[k], matched.directions[k]
    slope = (ends[met, 1] - intr.cy) / intr.fy            # the end's row as y / z
    denominator = d[:, 1] - slope * d[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (slope * c[:, 2] - c[:, 1]) / denominator
        z = c[:, 2] + lam * d[:, 2]
        disparity = intr.fx * intr.baseline / z
    # the point must lie near the 3D segment (within its half length and the radius beyond)
    near = np.abs(lam) <= matched.lengths[k] / 2 * (1 + 2 * radius_px / np.maximum(matched_2d.lengths[k], 1.0))
    out[met] = np.where(near & (z > 0) & (np.abs(denominator) > 1e-6), disparity, np.nan)
    return out


def _interrupted(ends: np.ndarray, outward: np.ndarray, params: StereoParams) -> np.ndarray:
    """(M,) bool: the end's edge goes on beyond a gap: another run end on the same image line
    (parallel within 3 degrees, within ``end_across_px`` of the line) faces it from at most
    ``end_continuation_px`` ahead. Such an end is an interruption (an occluder in front, a mark
    across), not where the edge ends, and the window there shows what interrupts it."""
    pairs = cKDTree(ends).query_pairs(params.end_continuation_px, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros(len(ends), bool)
    i, j = pairs[:, 0], pairs[:, 1]
    rel = ends[j] - ends[i]
    ahead = np.sum(rel * outward[i], axis=1)
    across = np.abs(rel[:, 0] * outward[i, 1] - rel[:, 1] * outward[i, 0])
    facing = np.sum(outward[i] * outward[j], axis=1) <= -np.cos(np.radians(3.0))
    hit = facing & (ahead > 0) & (across <= params.end_across_px)
    out = np.zeros(len(ends), bool)
    out[i[hit]] = out[j[hit]] = True
    return out


def triangulate_critical(left_img: np.ndarray, right_img: np.ndarray, left: Segments2D,
                         grads: tuple[Gradients, Gradients], intr: StereoIntrinsics, params: StereoParams,
                         frame_id: str, matched: Segments | None = None,
                         matched_2d: Segments2D | None = None, *,
                         left_crowding: np.ndarray) -> tuple[Segments, np.ndarray]:
    """3D segments (left camera frame) of the critical left segments between two run ends whose
    disparity is known (module docstring), and the (K,) left segment indices they come from.
    ``matched``, ``matched_2d``: the frame's triangulated segments and their left 2D segments,
    whose ends give junction disparities; ``left_crowding``: ``stereo.crowding`` of ``left``."""
    critical = np.flatnonzero(angle_from_rows(left.directions) < params.critical_angle_deg)
    none = Segments.empty(frame_id), np.zeros(0, np.int64)
    if len(critical) == 0 or not params.critical_by_ends:
        return none
    ref, lo, hi = _runs(left, critical, params.end_gap_px)       # the first segment places a run's line
    base = left.centers[ref] - left.t[ref, None] * left.line_direction[ref]   # each run's line at t = 0
    ends = np.concatenate([base + lo[:, None] * left.line_direction[ref],
                           base + hi[:, None] * left.line_direction[ref]])     # (2R, 2) px
    end_ref = np.concatenate([ref, ref])
    outward = np.concatenate([-left.line_direction[ref], left.line_direction[ref]])
    if params.end_skip_interrupted:   # before the block matching, which need not look at these ends then
        real = ~_interrupted(ends, outward, params)
        ends, end_ref, outward = ends[real], end_ref[real], outward[real]
    if len(ends) < 2:
        return none
    # the searched disparities: the depth range's, within the image width
    d_lo = max(1, int(np.floor(intr.fx * intr.baseline / params.max_depth_m)))
    d_hi = int(min(np.ceil(intr.fx * intr.baseline / params.min_depth_m), left_img.shape[1] - 1))
    if d_hi - d_lo < 8:    # too few shifts for the peak test (3 px and more away)
        return none
    disparity, best, second = _block_match(left_img, right_img, ends, d_lo, d_hi, params.end_window_px)
    by_block = _peak_trusted(best, second, params)
    if params.end_inner_window and (~by_block).any():
        # at a silhouette corner half the window is background, seen differently by the two
        # cameras: the window beside the end, on its own edge's side, may match where that fails
        retry = np.flatnonzero(~by_block)
        beside = ends[retry] - outward[retry] * params.end_window_px
        d_in, best_in, second_in = _block_match(left_img, right_img, beside, d_lo, d_hi, params.end_window_px)
        sure = _peak_trusted(best_in, second_in, params)
        disparity[retry[sure]], by_block[retry[sure]] = d_in[sure], True
    if matched is not None and params.end_junctions:
        junction = _junction_disparity(ends, matched, matched_2d, intr, params.end_junction_px)
        at_junction = np.isfinite(junction) & ~by_block
        disparity = np.where(at_junction, junction, disparity)
        by_block |= at_junction
    trusted = np.flatnonzero(by_block & (disparity > d_lo) & (disparity < d_hi))
    if len(trusted) < 2:
        return none
    ends, disparity, end_ref = ends[trusted], disparity[trusted], end_ref[trusted]
    # each critical segment's nearest trusted end on either side on its line (parallel; either polarity)
    e0, e1, t0, t1 = ends_on_lines(*(np.ascontiguousarray(a, np.float64) for a in (
        ends, left.centers[critical], left.line_direction[critical], left.line_direction[end_ref],
        left.lengths[critical] / 2)), float(params.end_across_px), float(params.end_gap_px),
        float(np.cos(np.radians(3.0))))
    span = t1 - t0                                                 # t0, t1: the ends along the segment's line
    # depth ratio of the two ends (disparity ratio): an edge behind an occluding contour ends there,
    # and the window at that end matches the occluder, much nearer than the edge's other end
    ratio = np.maximum(disparity[e0], disparity[e1]) / np.minimum(disparity[e0], disparity[e1])
    rows = np.flatnonzero(np.isfinite(span) & (span >= params.end_min_run_px) & (ratio <= params.end_max_depth_ratio))
    if len(rows) == 0:
        return none
    # where the block match is sure inside the span too (texture beside the edge), it must agree
    spans, span_of = np.unique(np.stack([e0[rows], e1[rows]], 1), axis=0, return_inverse=True)
    fractions = np.array([0.25, 0.5, 0.75])
    inside = ends[spans[:, 0], None, :] + fractions[None, :, None] * (ends[spans[:, 1]] - ends[spans[:, 0]])[:, None, :]
    predicted = disparity[spans[:, 0], None] + fractions[None, :] * (disparity[spans[:, 1]] - disparity[spans[:, 0]])[:, None]
    d_inside, best_inside, second_inside = _block_match(left_img, right_img, inside.reshape(-1, 2), d_lo, d_hi,
                                                        params.end_window_px)
    against = _peak_trusted(best_inside, second_inside, params) & (np.abs(d_inside - predicted.ravel()) > params.end_agree_px)
    rows = rows[~against.reshape(-1, 3).any(axis=1)[span_of.ravel()]]
    if len(rows) == 0:
        return none
    # the left image shows the edge all the way between the two ends, the right one where predicted
    s = np.linspace(0.0, 1.0, 24)[None, :, None]
    path = ends[e0[rows]][:, None, :] + s * (ends[e1[rows]] - ends[e0[rows]])[:, None, :]     # (K, S, 2)
    line_direction = left.line_direction[critical[rows]]
    normal = np.column_stack([-line_direction[:, 1], line_direction[:, 0]])
    d_path = disparity[e0[rows]][:, None] + s[..., 0] * (disparity[e1[rows]] - disparity[e0[rows]])[:, None]
    right_path = np.stack([path[..., 0] - d_path, path[..., 1]], axis=-1)
    rows = rows[(_shown(grads[0], path, normal) >= params.end_continuity)
                & (_shown(grads[1], right_path, normal) >= params.end_verify)]
    if len(rows) == 0:
        return none
    seg, e0, e1, t0, span = critical[rows], e0[rows], e1[rows], t0[rows], span[rows]
    d0, d1 = disparity[e0], disparity[e1]
    direction = left.line_direction[seg]
    center = left.centers[seg]
    half_t = left.lengths[seg] / 2
    a_c = -t0 / span                                      # where the centre (along 0) lies between the ends

    def disparity_at(offset):
        return d0 + (offset - t0) / span * (d1 - d0)

    half = half_t[:, None] * direction
    p_c = backproject(center[:, 0], center[:, 1], disparity_at(0.0), intr)
    p_m = backproject(center[:, 0] - half[:, 0], center[:, 1] - half[:, 1], disparity_at(-half_t), intr)
    p_p = backproject(center[:, 0] + half[:, 0], center[:, 1] + half[:, 1], disparity_at(half_t), intr)
    length = np.linalg.norm(p_p - p_m, axis=1)
    direction_3d = (p_p - p_m) / np.maximum(length, 1e-12)[:, None]
    sigma_end = params.end_disparity_sigma_px
    depth_per_disparity = p_c[:, 2] ** 2 / (intr.fx * intr.baseline)
    sigma_d = sigma_end * np.sqrt((1 - a_c) ** 2 + a_c ** 2)
    slope_sigma = sigma_end * np.sqrt(2.0) / span           # px of disparity per px along the line
    sigma_direction = np.arctan2(depth_per_disparity * slope_sigma * 2 * half_t, np.maximum(length, 1e-9))
    # confidence (the stereo score): the least a trusted end scores, as a piece has no patch score of its own
    score = np.full(len(seg), params.end_min_ncc)
    segments = Segments(frame_id, p_c, direction_3d, length, score, np.ones(len(seg), np.int64),
                        {"sigma_depth_m": depth_per_disparity * sigma_d, "sigma_direction_rad": sigma_direction,
                         "sigma_lateral_px": lateral_sigma(left_crowding[seg], params),
                         "disparity_px": disparity_at(0.0), "u": center[:, 0], "v": center[:, 1]})
    sure = sigma_direction <= np.radians(params.end_max_direction_sigma_deg)
    return segments.select(sure), seg[sure]
