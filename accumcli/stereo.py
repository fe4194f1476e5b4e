"""Stereo correspondence of 2D local segments and triangulation into 3D local
segments (the paper's section 2.2.1, second half).

Matching, in rectified images (epipolar lines are image rows):

- A left segment is *critical* when it is within ``critical_angle_deg`` of the
  epipolar direction (the row): its disparity along the row is undefined
  (the paper's critical plane). Critical segments are counted and rejected here;
  ``critical`` triangulates those whose edges end where disparity is defined.
  8 degrees, measured on ``make suite`` (19 rows; the paper names no angle): against 12,
  accumulated completeness median 0.541 -> 0.568 and worst row 0.159 -> 0.229 (sim_100, sim_105,
  sim_107 and dev_clutter gain 0.03 to 0.12, sim_110 loses 0.03), precision median 0.945 both;
  10 gave completeness median 0.550 and worst 0.222, 6 lowered the precision median to 0.926. The
  cost: single-frame near-object precision median 0.804 -> 0.791 (more segments, a few of them
  wrong, which accumulation removes), and the real teabox moved the other way by about the
  scoreboard's noise (surface precision 0.396 -> 0.368, completeness 0.573 -> 0.551).
- Candidates: right segments whose extent covers the left centre's row, with
  the disparity at that row in the range given by ``min_depth_m`` and
  ``max_depth_m``, the same gradient polarity, and directions within
  ``max_orientation_diff_deg``. At a silhouette the background behind may flip the polarity
  between the views; dropping the condition lost more than it found (``make suite``, 4 runs a row,
  2026-12-06: the matched share's median 0.606 -> 0.603, completeness mean 0.666 -> 0.661,
  precision rows under 0.95 three -> five), because the flipped candidates are rivals in the ratio
  tests of edges that match with their own polarity. So they get a round of their own
  (``flipped_fallback``, ``_flipped``): the left segments that the first round left unmatched,
  against the right segments it left unused, scored by the occluder's side (the one-sided score
  below), and kept only where two or more pieces of one left line flip onto one right line (a
  silhouette runs along an edge; ``min_stretch``). Measured on ``make suite`` (4 runs a row,
  2026-12-06) against one round: the matched share median 0.606 -> 0.615, correct 3D 0.457 ->
  0.463, accumulated completeness mean 0.666 -> 0.667, precision mean 0.947 both, single-frame
  near-object precision median 0.814 both. Without the two-piece condition the matched share
  rose more (median 0.641, dev_tprofile 0.594 -> 0.633; completeness mean 0.669, sim_108 0.598 ->
  0.637), but the near-object precision fell (median 0.809) and stray flipped pairs made the real
  chessboard's model hold background on one run of four (2 of 749 segments, 130 mm off the board).
- Score = NCC of grey-level patches sampled along the two segments (rows
  through the segment, horizontal offsets across it, so corresponding samples
  share a row) minus ``orientation_weight * (angle difference / max)^2``.
  NCC is blind to brightness and contrast, and every clean step edge
  correlates with every other near 1, so the score also loses
  ``(mean difference / brightness_tolerance)^2`` and
  ``(log contrast ratio / contrast_tolerance)^2``, after the right patches are
  taken to the left camera's grey levels by the frame's own gain and offset
  (``_grey_map_of_pairs``: from the pairs whose NCC alone is at least 0.9).
  Real cameras differ: the teabox's right camera shows 0.72 times the left's
  contrast 52 grey levels brighter, the chessboard's 5 to 9 levels apart, and
  such a pair lost half its matches to the brightness and contrast terms. With
  the frame's map, against none, on ``make suite``: the chessboard's single-frame
  correct 3D 0.595 -> 0.668, the teabox's completeness 0.563 -> 0.636, the
  simulated rows (equal cameras) within 0.01 but sim_102's precision (0.933 ->
  0.912); but on the teabox more print on the box is matched, mostly misplaced
  (surface precision 0.384 -> 0.322), and dev_cube_small's precision fell
  0.891 -> 0.828.
- A right line may offer several local segments to one left segment; only its
  best counts. The best right line is kept if its cost (1 - score) is below
  ``ratio`` times the second line's cost, its score at least ``min_score``,
  and the right segment's own best left line is this one (left-right check).
  Of the left pieces on true edges of dev_tprofile and dev_cube_small that stay unmatched (a
  fifth and a quarter of their length), the ratio test holds back about a third: the true line
  and a rival of another edge both near the one-sided score's cap. Measured on ``make suite`` (4
  runs a row, 2026-12-07) and not kept: rivals counted by their whole patch's score only,
  completeness mean 0.691 both, worst 0.359 -> 0.371, but rows under a precision of 0.95 three ->
  six and the teabox's 0.543 -> 0.475; ``ratio`` 0.9, completeness mean 0.691 -> 0.693, worst
  0.369, precision rows the same, the teabox 0.528: within the rows' noise. What matching adds,
  accumulation had mostly found from other frames.
- Global support in matching: along a left line that matched one right line
  in several segments, the other segments of the line are matched to that
  right line where their candidates agree with the fitted disparity
  (``_propagate``).

Triangulation with global support: the matched left segments that lie on the
same left Hough line and matched the same right line see one 3D line, along
which disparity is an affine function of image position. A weighted
least-squares fit of disparity along that stretch (outliers beyond
``fit_outlier_px`` dropped, then refitted) gives every segment of it a depth and
a 3D direction that a single short segment could not: at 0.5 m with an 8 cm
baseline one pixel of disparity is 5 mm of depth, so a 15 px segment's own
endpoints tilt it by degrees. A segment alone on its stretch keeps its own
disparity and takes its direction from the intersection of the two planes
back-projected through its left and right Hough lines (their whole fits, not
the short pieces); its ends are where the rays through its left piece's ends
pass nearest that 3D line (``_ends_on_rays``), so a piece receding in depth is
as long as the image shows it, not cut at one depth. On ``make suite`` against
the ends at one depth: the single-frame correct 3D higher on every row (median
0.379 -> 0.393), accumulated completeness median 0.579 -> 0.585 and worst row
0.232 -> 0.257, precision median 0.955 -> 0.950 (dev_wedge_far 0.955 -> 0.925,
dev_cube_small 0.860 -> 0.891). Each segment carries the standard deviations of its
depth (``sigma_depth_m``, from the fit's residuals) and of its direction
(``sigma_direction_rad``: the fitted slope's uncertainty over the segment's
length; for a segment alone, a plane's error / sin of the angle between its two planes, at
most ``max_alone_sigma_deg``: the planes' intersection turns by about a plane's own error over
that sine, so a piece near the epipolar direction, or far away, whose two planes nearly coincide,
is not sure of its direction). ``make uncertainty`` on the suite's frames: the flat 6 degrees of
before held errors of median 5.1, 90th percentile 27.6 degrees; with 1 degree over the sine the
bins' median errors are 3.7 (sigma 4-6), 4.2 (6-10), 7.5 (10-20), 12.7 (20-90): about 0.67 sigma
or less, a Gaussian's, and ordered. ``make suite``: precision median 0.949 -> 0.944, completeness
median 0.598 and worst 0.263 unchanged (rows within the run-to-run noise of docs/suite.md).
A plane's error is ``plane_sigma_deg``, or more on a short line: ``line_fit_sigma_px`` times
sqrt(12) / n rad over the span n (px) that the line's local segments reach (their ends included),
3 degrees at 10 px; the plane of the shorter of the two lines counts. An empirical figure, sqrt(n)
times the least-squares slope error of n independent edge pixels scattered by that much: the pixels
along an edge are not independent (the blur ties neighbours, and the ends bend into junctions), and
the independent figure stays under the 1-degree floor on every line of 10 px or more, i.e. changes
nothing. It came with the pieces from 8 px (``edge_chains``), whose precision it keeps: on ``make
suite``, rows under 0.95 (the teabox included) 5 -> 4, the real teabox's surface precision 0.572 ->
0.595. (``line_model``'s view planes take the independent figure, with the same 0.15 px.)

Crowding (``crowding``, ``crowded_sigma``): two edges a few pixels apart blur into each other, and
where the two views show them at different separations (a face seen at a grazing angle: a strip 3
px wide in one image, 1 px in the other) the pieces of either are placed off in the image and in
disparity, the same way frame after frame. On the suite's frames (12 rows, 13765 pieces within 15
mm and 10 degrees of a truth edge, 2026-12-07), the pieces with a parallel piece beside them within
3.5 px in the left image (9 %) were off across their line by a median of 0.5 to 0.7 px (0.1 px with
none within 5 px) and in disparity by 0.26 px (the 90th percentile over 1.645; 0.09 px alone) while
claiming 0.13 px: 10 to 14 % of them more than 4 mm off in depth, their 90th percentile at 3.5 to
6.6 claimed sigmas (1.7 alone). They repeated their error and became accepted twins 4 to 8 mm
behind the edge (sim_102: a box's edge beside its grazing bottom face, frames 7 to 20). So a piece
with another beside it (``crowding``, in either image) within ``crowded_near_px`` claims
``crowded_lateral_px`` more across its line (``sigma_lateral_px``, which ``line_model`` takes
instead of its fixed ``lateral_sigma_px``) and ``crowded_disparity_px`` more disparity (in
quadrature), both falling linearly to nothing at ``crowded_far_px``; those bins' 90th percentile
is then at 1.5 to 1.6 sigmas. ``make suite`` (4 runs a row) against none: precision mean 0.942 ->
0.946, rows under 0.95 five -> four (sim_102 0.949 -> 0.971; sim_103, 104, 106 and 109 up by 0.007
to 0.013; sim_111 0.933 -> 0.917 and sim_110 0.976 -> 0.970 down), completeness mean 0.748 ->
0.746, median 0.767 -> 0.774; the disparity term alone: precision mean 0.945, sim_110 0.960; the
lateral term alone: 0.942 (sim_102 0.949), completeness mean 0.748: the disparity term is the gain.
It is also a cost on the real teabox: the share of its accepted length that ``accum check`` finds
staying still in view rose 0.059 -> 0.083 (0.090 with the disparity term alone, 0.071 with the
lateral alone): the floor's crowded lines (tiles, grain), now less sure in depth, escape the static
contradiction more often, its margin being in units of the pair's own gate.
Measured and not kept (``make suite``, 4 runs a row): crowded pieces weighed in their stretch's fit by
their disparity variance (0.1 px for an uncrowded one) and the fitted pieces taking the fit's mean
crowding term: precision mean 0.946 -> 0.945, completeness mean 0.746 -> 0.745, every row within its
scatter (sim_106 0.967 -> 0.959, dev_cube_small 0.932 -> 0.942). With the repaired poses of
``--motion tracked`` the crowding counts for less (each observation also takes its pose's
uncertainty): on ``make motion`` the exact poses' models gained more precision than the tracked ones
(within 0.02 of them: 8 of 12 scenes instead of 11; the tracked models' own precision rose on 9 of 12).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from .grouping import best_per_key, group_range, ranges
from .lines2d import Segments2D, dot2, sample
from .recording import StereoIntrinsics
from .segments import Segments

REFERENCE_PAIRS = 64  # of the frame's matches, scored again with new pairs (``scored_beside``)


@dataclass(frozen=True)
class StereoParams:
    min_depth_m: float = 0.2
    max_depth_m: float = 3.0
    critical_angle_deg: float = 8.0
    max_orientation_diff_deg: float = 20.0
    orientation_weight: float = 0.3
    min_score: float = 0.6
    ratio: float = 0.8
    patch_half_width_px: int = 3
    brightness_tolerance: float = 25.0   # grey levels: patch means this far apart cost 1 in score
    contrast_tolerance: float = 0.5      # log ratio of patch contrasts that costs 1 in score
    side_score: float = 0.75             # best score of a one-sided (occluding edge) match
    flipped_fallback: bool = True        # a second round over the candidates of opposite polarity (``_flipped``)
    min_stretch: int = 2                 # matched segments on a line before its fit is trusted
    propagate_px: float = 1.0            # disparity agreement with the stretch fit for a propagated match
    propagate_score: float = 0.0
    fit_outlier_px: float = 1.0
    default_disparity_sigma_px: float = 0.25
    plane_sigma_deg: float = 1.0         # a back-projected plane's angular error (at least, on a short line, ...
    line_fit_sigma_px: float = 0.15      # ... this times sqrt(12) / its span in px, rad): a segment alone ...
    max_alone_sigma_deg: float = 60.0    # ... on its stretch has that error / sin(planes' angle), at most this
    # critical segments from their runs' ends (``critical``)
    critical_by_ends: bool = True
    end_window_px: int = 5               # half width of the block-matching window at a run end
    end_min_ncc: float = 0.8
    end_ratio: float = 0.5               # peak cost below this share of the best cost 3 px or more away
    end_gap_px: float = 3.0              # a longer gap along a line starts another run
    end_min_run_px: float = 20.0
    end_across_px: float = 1.5           # a run end this far across a segment's line lies on it
    end_continuity: float = 0.8          # share of the left image's edge between two ends that must be shown
    end_verify: float = 0.7              # share of the predicted right edge that the right image must show
    end_disparity_sigma_px: float = 0.5
    end_skip_interrupted: bool = True    # an end facing another on its line within ... is not used:
    end_continuation_px: float = 40.0    # ... this far, an interruption (occluder, mark), not an end
    end_max_direction_sigma_deg: float = 3.0   # segments whose direction is less sure are dropped
    end_inner_window: bool = True        # an end whose window fails tries the window beside it, inside
    end_junctions: bool = True           # a run end without a trusted block match takes the disparity ...
    end_junction_px: float = 4.0         # ... of a triangulated segment ending this near it
    end_max_depth_ratio: float = 1.5     # ends farther apart in depth: an occluded edge, not a receding one
    end_agree_px: float = 2.0            # a sure block match inside a span this far from the interpolation refutes it
    # a piece with another edge running beside it this close (``crowding``) is placed less surely
    lateral_sigma_px: float = 0.3        # a piece's place across its line in the image, alone ...
    crowded_lateral_px: float = 1.0      # ... and, with a neighbour crowded_near_px or nearer, this too (hypot)
    crowded_disparity_px: float = 0.25   # the same for its disparity
    crowded_near_px: float = 3.5         # the crowding terms fall linearly to 0 from here ...
    crowded_far_px: float = 5.5          # ... to here
    # the right image's rows lie this much below the left's (``row_check``): the matched pieces' disparities
    # are corrected in ``triangulate``; the critical pieces' run ends (``critical``, block matching) are not
    row_offset_px: float = 0.0


@dataclass
class Matches:
    """Accepted correspondences: left, right: (K,) indices; disparity (K,) px at the left centre; score (K,)."""

    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    score: np.ndarray
    critical: int = 0      # left segments rejected as near the critical plane
    unmatched: int = 0     # non-critical left segments without an accepted match


def angle_from_rows(directions: np.ndarray) -> np.ndarray:
    return np.degrees(np.arcsin(np.clip(np.abs(directions[:, 1]), 0.0, 1.0)))


def _row_crossing(seg: Segments2D, index: np.ndarray, v: np.ndarray) -> np.ndarray:
    """u where the line of segments ``index`` crosses rows ``v``."""
    c, d = seg.centers[index], seg.directions[index]
    return c[..., 0] + (v - c[..., 1]) * d[..., 0] / d[..., 1]


def match(left_img: np.ndarray, right_img: np.ndarray, left: Segments2D, right: Segments2D,
          intr: StereoIntrinsics, params: StereoParams) -> Matches:
    """Stereo correspondences between the local segments of a rectified pair (module docstring);
    with ``flipped_fallback``, a second round for the left segments still unmatched takes the
    candidates of opposite polarity (``_flipped``)."""
    critical_l = angle_from_rows(left.directions) < params.critical_angle_deg
    usable_r = np.flatnonzero(angle_from_rows(right.directions) >= params.critical_angle_deg)
    usable_l = np.flatnonzero(~critical_l)
    empty = Matches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0),
                    int(critical_l.sum()), len(usable_l))
    if len(usable_l) == 0 or len(usable_r) == 0:
        return empty
    li, rj, disparity, cos_diff, same = _candidates(left, right, usable_l, usable_r, intr, params)
    flipped = (li[~same], rj[~same], disparity[~same], cos_diff[~same])
    li, rj, disparity, cos_diff = li[same], rj[same], disparity[same], cos_diff[same]
    if len(li) == 0:
        return empty
    score = _ncc(left_img, right_img, left, right, li, rj, params) - orientation_penalty(cos_diff, params)
    li, rj, disparity, score, accept = _decide(left, right, li, rj, disparity, score, params)
    accept |= _propagate(left, right, li, rj, disparity, score, accept, params)
    k = np.flatnonzero(accept)
    found = Matches(li[k], rj[k], disparity[k], score[k], int(critical_l.sum()), len(usable_l) - len(k))
    if params.flipped_fallback:
        found = _flipped(left_img, right_img, left, right, found, flipped, params)
    return found


def scored_beside(left_img, right_img, left: Segments2D, right: Segments2D, found: Matches, li: np.ndarray,
                  rj: np.ndarray, params: StereoParams) -> np.ndarray:
    """``_ncc`` of the pairs li, rj (P,) scored together with up to ``REFERENCE_PAIRS`` of the frame's
    matches ``found``, from which ``_ncc`` takes the right grey levels to the left's (it needs 20 pairs
    whose NCC alone is high: new pairs of a flipped polarity or of found pieces may have too few)."""
    reference = slice(0, min(len(found.left), REFERENCE_PAIRS))
    return _ncc(left_img, right_img, left, right, np.concatenate([found.left[reference], li]),
                np.concatenate([found.right[reference], rj]), params)[len(found.left[reference]):]


def _candidates(left: Segments2D, right: Segments2D, usable_l: np.ndarray, usable_r: np.ndarray,
                intr: StereoIntrinsics, params: StereoParams):
    """Candidate pairs (P,): left and right indices, disparity at the left centre's row (px), |cos| of
    the lines' angle, and whether their gradients share a polarity: right segments whose rows cover
    the left centre's row, in the depth range and within ``max_orientation_diff_deg``."""
    order = usable_r[np.argsort(right.centers[usable_r, 1])]
    v_sorted = right.centers[order, 1]
    reach = right.lengths.max() / 2 + 0.5
    v_left = left.centers[usable_l, 1]
    start = np.searchsorted(v_sorted, v_left - reach)
    count = np.searchsorted(v_sorted, v_left + reach) - start
    li = np.repeat(usable_l, count)
    rj = order[ranges(start, count)]
    v = left.centers[li, 1]
    half_height = right.lengths[rj] / 2 * np.abs(right.directions[rj, 1]) + 0.5
    disparity = left.centers[li, 0] - _row_crossing(right, rj, v)
    d_min = intr.fx * intr.baseline / params.max_depth_m
    d_max = intr.fx * intr.baseline / params.min_depth_m
    cos_diff = np.abs(dot2(left.directions[li], right.directions[rj]))
    ok = ((np.abs(v - right.centers[rj, 1]) <= half_height) & (disparity >= d_min) & (disparity <= d_max)
          & orientation_close(cos_diff, params))
    li, rj = li[ok], rj[ok]
    same = dot2(left.normals[li] * left.polarity[li, None], right.normals[rj] * right.polarity[rj, None]) > 0
    return li, rj, disparity[ok], cos_diff[ok], same


def _decide(left: Segments2D, right: Segments2D, li, rj, disparity, score, params: StereoParams):
    """The scored candidate pairs reduced to the best local segment per (left segment, right line),
    sorted by left segment and falling score, and (last) which of them are accepted: each left
    segment's best right line, if its score is at least ``min_score``, its cost (1 - score) below
    ``ratio`` times the second line's, and the right segment's own best left line is this one
    (left-right check)."""
    n_right_lines = int(right.line_id.max()) + 1
    best = best_per_key(li * n_right_lines + right.line_id[rj], -score)
    li, rj, disparity, score = li[best], rj[best], disparity[best], score[best]
    order = np.lexsort((-score, li))
    li, rj, disparity, score = li[order], rj[order], disparity[order], score[order]
    first = np.ones(len(li), bool)
    first[1:] = li[1:] != li[:-1]
    second_score = np.full(len(li), -np.inf)
    has_second = np.zeros(len(li), bool)
    has_second[:-1] = first[:-1] & (li[1:] == li[:-1])
    second_score[has_second] = score[np.flatnonzero(has_second) + 1]
    cost, second_cost = 1.0 - score, 1.0 - second_score
    accept = first & (score >= params.min_score) & (~has_second | (cost < params.ratio * second_cost))
    n_left_lines = int(left.line_id.max()) + 1
    best_for_right = best_per_key(rj * n_left_lines + left.line_id[li], -score)
    top = best_per_key(rj[best_for_right], -score[best_for_right])
    right_choice = np.full(len(right), -1)
    right_choice[rj[best_for_right][top]] = left.line_id[li[best_for_right][top]]
    accept &= right_choice[rj] == left.line_id[li]
    return li, rj, disparity, score, accept


def _flipped(left_img, right_img, left: Segments2D, right: Segments2D, found: Matches, flipped: tuple,
             params: StereoParams) -> Matches:
    """``found`` with the matches of a second round: the left segments it left unmatched against
    the right segments it left unused, over the candidates of opposite polarity (``flipped``: li, rj,
    disparity, |cos|). At a silhouette the background behind the edge may differ between the views
    and flip its gradient; only the occluder's side then looks alike, which the one-sided score
    (``_ncc``, at most ``side_score``) compares. A round of its own, after the first, because as
    rivals in the first round's ratio tests the flipped candidates lost more true matches than they
    added (module docstring). Scored beside the first round's matches (``scored_beside``); kept
    only where ``min_stretch`` or more pieces of one left line flip onto one right line."""
    li, rj, disparity, cos_diff = flipped
    free_l = np.ones(len(left), bool)
    free_l[found.left] = False
    free_r = np.ones(len(right), bool)
    free_r[found.right] = False
    keep = free_l[li] & free_r[rj]
    li, rj, disparity, cos_diff = li[keep], rj[keep], disparity[keep], cos_diff[keep]
    if len(li) == 0:
        return found
    score = scored_beside(left_img, right_img, left, right, found, li, rj, params) - orientation_penalty(cos_diff, params)
    li, rj, disparity, score, accept = _decide(left, right, li, rj, disparity, score, params)
    key = _line_pairs(left, right, li, rj)      # two pieces or more of a line pair: a silhouette, not a stray pair
    keys, counts = np.unique(key[accept], return_counts=True)
    accept &= np.isin(key, keys[counts >= params.min_stretch])
    k = np.flatnonzero(accept)
    return Matches(np.concatenate([found.left, li[k]]), np.concatenate([found.right, rj[k]]),
                   np.concatenate([found.disparity, disparity[k]]), np.concatenate([found.score, score[k]]),
                   found.critical, found.unmatched - len(k))


def orientation_close(cos_diff: np.ndarray, params: StereoParams) -> np.ndarray:
    """(P,) bool: pairs whose image lines (``cos_diff``, (P,) |cos|) are within ``max_orientation_diff_deg``."""
    return cos_diff >= np.cos(np.radians(params.max_orientation_diff_deg))


def orientation_penalty(cos_diff: np.ndarray, params: StereoParams) -> np.ndarray:
    """(P,) what a pair's score loses for the angle between its two image lines (``cos_diff``, (P,)
    |cos|): ``orientation_weight`` at ``max_orientation_diff_deg``, quadratic below it."""
    return params.orientation_weight * (np.degrees(np.arccos(np.clip(cos_diff, -1, 1)))
                                        / params.max_orientation_diff_deg) ** 2


def _line_pairs(left: Segments2D, right: Segments2D, li: np.ndarray, rj: np.ndarray) -> np.ndarray:
    """(P,) one integer per (left line, right line) of the pairs li, rj: the stretch a pair lies on."""
    return left.line_id[li] * (int(right.line_id.max()) + 1) + right.line_id[rj]


def _propagate(left: Segments2D, right: Segments2D, li, rj, disparity, score, accept, params: StereoParams):
    """(P,) bool: candidate pairs that the global support of an accepted stretch adds.

    Where at least ``min_stretch`` segments of a left line matched one right line,
    the disparity along the left line is fitted (it is affine in the image
    position along a 3D line); a still unmatched segment of that left line
    whose candidate on the same right line lies within ``propagate_px`` of the
    fitted disparity, with a score of at least ``propagate_score``, is matched
    too. This recovers the parts of an edge that one view's background made
    ambiguous, e.g. along an occluding contour.
    """
    key = _line_pairs(left, right, li, rj)
    stretches, stretch = np.unique(key[accept], return_inverse=True)
    if len(stretches) == 0:
        return np.zeros(len(li), bool)
    stretch = stretch.ravel()
    s_acc = left.t[li[accept]]
    a, b, _, count, _, _ = _fit_lines(stretch, len(stretches), s_acc, disparity[accept], np.ones(len(s_acc)))
    position = np.searchsorted(stretches, key)
    in_stretch = (position < len(stretches)) & (stretches[np.minimum(position, len(stretches) - 1)] == key)
    position = np.minimum(position, len(stretches) - 1)
    predicted = a[position] + b[position] * left.t[li]
    matched_left = np.zeros(len(left), bool)
    matched_left[li[accept]] = True
    extra = (in_stretch & (count[position] >= params.min_stretch) & ~matched_left[li] & ~accept
             & (np.abs(disparity - predicted) <= params.propagate_px) & (score >= params.propagate_score))
    best = best_per_key(li[extra], -score[extra])  # one per left segment
    out = np.zeros(len(li), bool)
    out[np.flatnonzero(extra)[best]] = True
    return out


def _grey_map_of_pairs(ncc, mean_a, mean_b, energy_a, energy_b, li: np.ndarray, min_ncc: float = 0.9,
                       min_pairs: int = 20):
    """(gain, offset) that take this frame's right grey levels to the left's, from the moments
    (``_correlation``, each (P,)) of the patches of candidate pairs of left segments ``li`` (P,):
    over each left segment's best candidate by NCC alone, where that is at least ``min_ncc``, the
    median contrast ratio and then the median remaining difference of means; (1, 0) with fewer
    than ``min_pairs`` such segments."""
    best = best_per_key(li, -ncc)
    best = best[(ncc[best] >= min_ncc) & (energy_b[best] > 1e-6)]
    if len(best) < min_pairs:
        return 1.0, 0.0
    gain = float(np.median(np.sqrt(energy_a[best] / energy_b[best])))
    return gain, float(np.median(mean_a[best] - gain * mean_b[best]))


def _correlation(a: np.ndarray, b: np.ndarray):
    """Row by row of (P, n) samples: NCC (P,) (0 where flat), the means (P,) and the energies (P,)
    about them."""
    mean_a, mean_b = a.mean(axis=1), b.mean(axis=1)
    a = a - mean_a[:, None]
    b = b - mean_b[:, None]
    energy_a, energy_b = (a * a).sum(axis=1), (b * b).sum(axis=1)
    denominator = np.sqrt(energy_a * energy_b)
    ncc = np.where(denominator > 1e-6, (a * b).sum(axis=1) / np.maximum(denominator, 1e-12), 0.0)
    return ncc, mean_a, mean_b, energy_a, energy_b


SAMPLES_ALONG = 8   # points along a segment where its patch is sampled (``_ncc``)


def points_along(segments: Segments2D, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P, SAMPLES_ALONG) rows and (P, SAMPLES_ALONG) columns (px, the segments' image) of points
    spread over the middle 80 % of segments ``index`` (P,)."""
    s = np.linspace(-0.4, 0.4, SAMPLES_ALONG)[None, :] * segments.lengths[index][:, None]
    return (segments.centers[index, 1][:, None] + s * segments.directions[index, 1][:, None],
            segments.centers[index, 0][:, None] + s * segments.directions[index, 0][:, None])


def _ncc(left_img, right_img, left: Segments2D, right: Segments2D, li, rj, params: StereoParams) -> np.ndarray:
    """Photometric score (P,) of patches along matched segments: the better of the
    whole patch's score and a one-sided score. At an occluding edge only the
    occluder's side looks the same in both views; the one-sided score compares
    the mean brightness of one side (the step itself excluded) and is capped at
    ``side_score``, below what a good whole-patch match reaches."""
    rows, u_left = points_along(left, li)                                             # (P, S)
    u_right = _row_crossing(right, rj[:, None], rows)
    w = params.patch_half_width_px
    h = np.arange(-w, w + 1, dtype=float)
    rows3 = np.repeat(rows[:, :, None], len(h), axis=2)
    a = sample(left_img, u_left[:, :, None] + h, rows3)     # (P, S, H)
    b = sample(right_img, u_right[:, :, None] + h, rows3)
    ncc, mean_a, mean_b, energy_a, energy_b = _correlation(a.reshape(len(li), -1), b.reshape(len(li), -1))
    # the right patches in the left camera's grey levels: NCC is blind to the map, the moments follow it
    gain, offset = _grey_map_of_pairs(ncc, mean_a, mean_b, energy_a, energy_b, li)
    whole = _patch_score(ncc, mean_a, gain * mean_b + offset, energy_a, gain ** 2 * energy_b, a[0].size, params)
    sides = [params.side_score - ((a[:, :, c].mean(axis=(1, 2)) - gain * b[:, :, c].mean(axis=(1, 2)) - offset)
                                  / params.brightness_tolerance) ** 2 for c in (slice(0, w), slice(w + 1, None))]
    return np.max([whole, *sides], axis=0)


def _patch_score(ncc, mean_a, mean_b, energy_a, energy_b, n: int, params: StereoParams) -> np.ndarray:
    """NCC minus brightness and contrast differences, from the moments (``_correlation``, each (P,))
    of (P, n) samples."""
    # NCC alone cannot tell one step edge from another: compare brightness and contrast too
    contrast = np.log((np.sqrt(energy_a / n) + 1.0) / (np.sqrt(energy_b / n) + 1.0))
    return ncc - ((mean_a - mean_b) / params.brightness_tolerance) ** 2 - (contrast / params.contrast_tolerance) ** 2


def backproject(u: np.ndarray, v: np.ndarray, d: np.ndarray, intr: StereoIntrinsics) -> np.ndarray:
    """(N, 3) points in the left camera frame, metres, from pixel (u, v) and disparity d."""
    z = intr.fx * intr.baseline / d
    return np.column_stack([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z])


def triangulate(left: Segments2D, right: Segments2D, m: Matches, intr: StereoIntrinsics,
                params: StereoParams, frame_id: str,
                crowd: tuple[np.ndarray, np.ndarray]) -> tuple[Segments, np.ndarray]:
    """3D local segments (left camera frame) of the matches, and the (K,) indices of ``m`` they come from.
    ``crowd``: ``crowding`` of the left and of the right segments."""
    if len(m.left) == 0:
        return Segments.empty(frame_id), np.zeros(0, np.int64)
    if params.row_offset_px:   # a row offset dy moves an edge's crossing of a row by dy times its cotangent
        line = left.line_direction[m.left]
        m = replace(m, disparity=m.disparity - params.row_offset_px * line[:, 0] / line[:, 1])
    stretch = stretch_ids(left, right, m.left, m.right)
    n = int(stretch.max()) + 1
    centers, dirs = left.centers[m.left], left.directions[m.left]
    axis = np.zeros((n, 2))
    np.add.at(axis, stretch, dirs)
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    s = np.sum(centers * axis[stretch], axis=1)
    weight = np.clip(m.score, 0.05, None)
    keep = np.ones(len(s), bool)
    for _ in range(2):  # fit, drop outliers, refit
        a, b, sigma, count, spread, mean_s = _fit_lines(stretch, n, s, m.disparity, weight * keep)
        residual = m.disparity - (a[stretch] + b[stretch] * s)
        fitted = (count[stretch] >= 3) & (spread[stretch] >= left.lengths[m.left])
        keep = ~fitted | (np.abs(residual) <= params.fit_outlier_px)
    fitted = fitted & keep
    idx = np.flatnonzero(keep)
    half = (left.lengths[m.left] / 2)[:, None] * dirs
    along = np.sum(dirs * axis[stretch], axis=1) * left.lengths[m.left] / 2
    d_center = np.where(fitted, a[stretch] + b[stretch] * s, m.disparity)
    d_minus = np.where(fitted, d_center - b[stretch] * along, m.disparity)
    d_plus = np.where(fitted, d_center + b[stretch] * along, m.disparity)
    p_center = backproject(centers[:, 0], centers[:, 1], d_center, intr)
    p_minus = backproject(centers[:, 0] - half[:, 0], centers[:, 1] - half[:, 1], d_minus, intr)
    p_plus = backproject(centers[:, 0] + half[:, 0], centers[:, 1] + half[:, 1], d_plus, intr)
    direction = p_plus - p_minus
    alone = ~fitted
    planes_sine = np.ones(len(s))
    if alone.any():  # direction from the intersection of the two back-projected planes
        planes, planes_sine = _plane_intersection(left, right, m, intr)
        direction[alone] = planes[alone] * np.linalg.norm(direction[alone], axis=1, keepdims=True)
    length = np.linalg.norm(p_plus - p_minus, axis=1)
    direction = direction / np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    if alone.any():   # the left piece's ends lie on their rays: a tilted piece is longer than at one depth
        p_center[alone], length[alone] = _ends_on_rays(p_center[alone], direction[alone], centers[alone] - half[alone],
                                                       centers[alone] + half[alone], length[alone], intr)
    # depth uncertainty: fit residual (or a default) through the disparity's sensitivity
    sigma_d = np.where(fitted, np.maximum(sigma[stretch], 0.05) * np.sqrt(
        1.0 / np.maximum(count[stretch], 1) + (s - mean_s[stretch]) ** 2
        / np.maximum(spread[stretch] ** 2 / 3, 1e-9)), params.default_disparity_sigma_px)
    beside = np.minimum(crowd[0][m.left], crowd[1][m.right])     # px, the nearer of the pair's neighbours
    sigma_d = np.hypot(sigma_d, crowded_sigma(beside, params.crowded_disparity_px, params))
    sigma_lateral = lateral_sigma(beside, params)
    depth_per_disparity = p_center[:, 2] ** 2 / (intr.fx * intr.baseline)
    sigma_depth = depth_per_disparity * sigma_d
    # direction: the fitted slope's uncertainty tilts the segment along the viewing ray
    sigma_slope = np.maximum(sigma[stretch], 0.05) / np.sqrt(np.maximum(count[stretch] * spread[stretch] ** 2 / 12,
                                                                        1e-9))
    # a plane is as sure as the shorter of its two lines (module docstring: an empirical figure)
    span = np.minimum(line_span(left, m.left), line_span(right, m.right))
    plane_sigma = plane_sigma_deg(span, params)
    sigma_direction = np.where(fitted, np.arctan2(depth_per_disparity * sigma_slope * 2 * np.abs(along),
                                                  np.maximum(length, 1e-9)),
                               np.radians(np.minimum(plane_sigma / np.maximum(planes_sine, 1e-9),
                                                     params.max_alone_sigma_deg)))
    segments = Segments(frame_id, p_center, direction, length, np.clip(m.score, 0, 1),
                        np.ones(len(p_center), np.int64),
                        {"sigma_depth_m": sigma_depth, "sigma_direction_rad": sigma_direction,
                         "sigma_lateral_px": sigma_lateral, "disparity_px": d_center, "u": centers[:, 0],
                         "v": centers[:, 1]})
    return segments.select(idx), idx


def plane_sigma_deg(span_px, params: StereoParams) -> np.ndarray:
    """Degrees: how sure the plane of a 2D line ``span_px`` long is (its fit's angle error, at least
    ``plane_sigma_deg``; module docstring: an empirical figure)."""
    return np.maximum(params.plane_sigma_deg,
                      np.degrees(params.line_fit_sigma_px * np.sqrt(12) / np.maximum(span_px, 1.0)))


def crowding(seg: Segments2D, reach_px: float = 8.0, max_angle_deg: float = 10.0,
             same_line_px: float = 0.7) -> np.ndarray:
    """(N,) px: how far across each segment the nearest other segment of its image runs beside it
    (within ``max_angle_deg`` of its direction, overlapping it along it, and more than ``same_line_px``
    across: not a piece of its own line); inf where none does within ``reach_px``."""
    out = np.full(len(seg), np.inf)
    if len(seg) < 2:
        return out
    # two pieces beside each other have centres at most max length along and reach_px across apart
    pairs = cKDTree(seg.centers).query_pairs(float(np.hypot(seg.lengths.max(), reach_px)), output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    parallel = np.abs(dot2(seg.directions[i], seg.directions[j])) >= np.cos(np.radians(max_angle_deg))
    i, j = i[parallel], j[parallel]
    rel = seg.centers[j] - seg.centers[i]
    for a, b in ((i, j), (j, i)):        # each piece of a pair measured across its own line
        direction = seg.directions[a]
        across = np.abs(rel[:, 0] * direction[:, 1] - rel[:, 1] * direction[:, 0])
        beside = ((np.abs(dot2(rel, direction)) <= (seg.lengths[a] + seg.lengths[b]) / 2)
                  & (across > same_line_px) & (across <= reach_px))
        np.minimum.at(out, a[beside], across[beside])
    return out


def crowded_sigma(crowd_px: np.ndarray, peak: float, params: StereoParams) -> np.ndarray:
    """(N,) the crowding term of a sigma: ``peak`` where the neighbour (``crowd_px``, (N,) px) is
    ``crowded_near_px`` or nearer, falling linearly to 0 at ``crowded_far_px``."""
    ramp = (params.crowded_far_px - crowd_px) / (params.crowded_far_px - params.crowded_near_px)
    return peak * np.clip(ramp, 0.0, 1.0)


def lateral_sigma(crowd_px: np.ndarray, params: StereoParams) -> np.ndarray:
    """(N,) px: how surely each piece lies across its line in the image, given its ``crowding`` (N,) px."""
    return np.hypot(params.lateral_sigma_px, crowded_sigma(crowd_px, params.crowded_lateral_px, params))


def stretch_ids(left: Segments2D, right: Segments2D, li: np.ndarray, ri: np.ndarray) -> np.ndarray:
    """(P,) int in [0, stretches): the stretch of each matched pair (left segment ``li``, right segment
    ``ri``), i.e. the pair of left and right lines it lies on (``triangulate`` fits disparity along it)."""
    _, stretch = np.unique(left.line_id[li] * (int(right.line_id.max()) + 1) + right.line_id[ri], return_inverse=True)
    return stretch.ravel()


def line_span(side: Segments2D, index: np.ndarray) -> np.ndarray:
    """(P,) px: how far the local segments of the line that each segment ``index`` lies on reach along it."""
    low, high = side.line_extents()
    return (high - low)[side.line_id[index]]


def view_plane_normals(a: np.ndarray, b: np.ndarray, intr: StereoIntrinsics) -> np.ndarray:
    """(N, 3) normals (camera frame, not unit) of the planes through the camera centre and the image
    points ``a`` and ``b`` (N, 2) px: the plane that an image line through them back-projects to."""
    K_inv = np.linalg.inv(intr.K)
    return np.cross(np.column_stack([a, np.ones(len(a))]) @ K_inv.T, np.column_stack([b, np.ones(len(b))]) @ K_inv.T)


def nearest_to_rays(center: np.ndarray, direction: np.ndarray, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where 3D lines (``center``, unit ``direction``, (K, 3), camera frame) pass nearest the rays
    from the camera centre along unit ``rays`` (K, 3): (K,) the parameter t along each line (its point
    ``center + t direction``, metres) and (K,) the squared sine of the angle between line and ray
    (near 0 the nearest point is ill-posed)."""
    uq, pu, pq = np.sum(direction * rays, axis=1), np.sum(center * direction, axis=1), np.sum(center * rays, axis=1)
    sine2 = 1 - uq ** 2
    return (pq * uq - pu) / np.maximum(sine2, 1e-12), sine2


def _ends_on_rays(center, direction, uv_minus, uv_plus, length, intr: StereoIntrinsics, min_sine: float = 0.2,
                  max_stretch: float = 3.0):
    """(centre (K, 3), length (K,)) of 3D lines through ``center`` along ``direction`` (left camera
    frame) cut where they pass nearest the rays of the left image points ``uv_minus`` and
    ``uv_plus`` (K, 2) px; the given centre and ``length`` where a line runs within asin(``min_sine``)
    of a ray or the cut would stretch it more than ``max_stretch`` times (there the cut is ill-posed).
    On ``make suite``, a limit of 0.5 or a stretch of 1.5 kept less: completeness median 0.580."""
    def parameter(uv):
        q = np.column_stack([(uv[:, 0] - intr.cx) / intr.fx, (uv[:, 1] - intr.cy) / intr.fy, np.ones(len(uv))])
        return nearest_to_rays(center, direction, q / np.linalg.norm(q, axis=1, keepdims=True))
    t_minus, s_minus = parameter(uv_minus)
    t_plus, s_plus = parameter(uv_plus)
    new_length = np.abs(t_plus - t_minus)
    ok = (np.minimum(s_minus, s_plus) >= min_sine ** 2) & (new_length <= max_stretch * length) & (new_length > 0)
    new_center = center + ((t_plus + t_minus) / 2)[:, None] * direction
    return np.where(ok[:, None], new_center, center), np.where(ok, new_length, length)


def _fit_lines(group, n, s, d, w):
    """Weighted least squares d = a + b s per group: a, b, residual sigma, count, spread and mean of s."""
    sw = np.bincount(group, w, n)
    safe = np.where(sw > 0, sw, 1.0)
    ms = np.bincount(group, w * s, n) / safe
    md = np.bincount(group, w * d, n) / safe
    ds, dd = s - ms[group], d - md[group]
    sss = np.bincount(group, w * ds * ds, n)
    ssd = np.bincount(group, w * ds * dd, n)
    b = np.where(sss > 1e-9, ssd / np.where(sss > 1e-9, sss, 1.0), 0.0)
    a = md - b * ms
    count = np.bincount(group, (w > 0).astype(float), n)
    residual = d - (a[group] + b[group] * s)
    sigma = np.sqrt(np.bincount(group, w * residual ** 2, n) / safe * count / np.maximum(count - 2, 1))
    lo, hi = group_range(group[w > 0], n, s[w > 0])
    return a, b, sigma, count, np.where(hi > lo, hi - lo, 0.0), ms


def _plane_intersection(left: Segments2D, right: Segments2D, m: Matches,
                        intr: StereoIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) unit 3D directions from the planes through each camera centre and its 2D line, and
    (K,) the sine of the angle between the two planes."""
    def plane_normal(seg: Segments2D, index: np.ndarray) -> np.ndarray:
        return view_plane_normals(seg.centers[index], seg.centers[index] + seg.line_direction[index], intr)

    a, b = plane_normal(left, m.left), plane_normal(right, m.right)
    direction = np.cross(a, b)
    norm = np.linalg.norm(direction, axis=1)
    sine = norm / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
    return direction / np.maximum(norm, 1e-12)[:, None], sine
