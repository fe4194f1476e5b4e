"""Stereo matches found by searching the right image where its detector found no partner.

The right image's 2D segments miss edges that the left image's show: noise breaks a short edge into
runs too short for a piece, a junction bends its ends, a piece lands a pixel or two beside the edge.
Measured on the devset (``make suite`` frames, left pieces on seen object edges, not critical): 8 to
14 % found no right piece within 1.5 px and 10 degrees of the edge's projection in the right image,
although half of them had one within 3 px; 3 to 5 % more had right pieces on the edge that did not
cover the left piece's rows.

For each usable left piece left unmatched, the right image is searched along the piece's own rows
(``stereo.points_along``, where ``stereo._ncc`` samples it), at the disparities of its matched
neighbours in the left image (the range of the ``NEIGHBOURS`` nearest within ``neighbour_px``,
widened by ``margin_px``, searched only if at most ``max_range_px`` wide: without a prior a row holds
too many edges). A disparity gets a row's vote
where the right image has an edge of the piece's polarity there (a local maximum, within a pixel, of
the gradient across the piece, of at least ``min_contrast`` of the piece's own): the best disparity
needs ``min_rows`` votes and every disparity ``min_gap_px`` or more away at most ``max_rival_rows``
(an edge parallel to it nearby makes the piece ambiguous, and it is left alone). The right edge is
then located on each row to sub-pixel (a parabola through the gradient, within ``locate_px`` of the
voted disparity), a line through those points (at most ``max_residual_px`` RMS from them) is the
right piece, and the pair must pass matching's tests: depth range, orientation difference, and score
(``stereo._ncc`` less ``stereo.orientation_penalty``) at least ``min_score``. Its
direction comes from its own short line, so its 3D direction is as unsure as a lone piece's
(``stereo.triangulate`` says so in its sigma); what it brings is the edge's place in 3D and its view
plane, to accumulation. Searching by patch score (NCC) instead found half as many, and on the
devset 1 in 7 of those wrong against 1 in 10 by votes.

Off by default (``--right-search`` switches it on). Measured with it against without, ``make
suite``: completeness median 0.624 -> 0.636, worst row 0.271 -> 0.273 (higher on 14 of 19 rows, lower
on the teabox, 0.665 -> 0.653, and sim_100; before its pairs had to pass matching's orientation
test, 0.293, and with every image read shifted by 0.004 px, the scoreboard's noise, 0.617 -> 0.626
and 0.245 -> 0.271), single-frame correct 3D higher on every row (median 0.418 -> 0.430); the costs:
the single-frame near-object precision median 0.753 -> 0.737 (its pieces' directions are a lone
piece's), precision rows under 0.95 3 -> 5 (the teabox's included; within the rows' noise of about
0.03), extraction about 2 ms a frame. What keeps it off is tracking with its models: over four runs of the tracking
scoreboard with image reads shifted by 0, +-0.004 and 0.008 px, sim_206 turns to an aspect its
model barely covers (3 to 5 % of it in view) and frames there were tracked 3.2 to 5.4 deg off in
every run (without the search: one false frame in the four runs, dev_steps at 0.008 px); a floor of
8 % in view (``TrackParams.min_shown``) removed them but lost right frames of the chessboard's
snapshots, whose many-aspect model shows 3 % of itself at a right pose. On the 21 off-scoreboard
runs over three shifts it made no difference (11 false frames either way, measured with 10 Gauss-Newton
steps a level). Again on 2026-12-06, with stereo's second round for flipped polarities (its first form, without
the two-piece condition): ``make suite``
(4 runs a row) completeness mean 0.669 -> 0.675, median 0.673 -> 0.675, worst 0.308 -> 0.350
(dev_cube_small), precision median 0.975 -> 0.970 (rows under 0.95 three both); the tracking
scoreboard with its models: sim_201 tracked two frames 10.8 and 10.9 mm off (none since the tracker
tries a sliding model's slid twins, ``track.PoseTracker._slid_twins``), and tracked less: sim_201
0.433 -> 0.067, the chessboard 0.923 -> 0.692 (more frames 'ambiguous'). Still off. On 2026-12-07 at
82efe5a (``make suite --right-search``, 4 runs a row): completeness higher on 17 of 19 rows but mean
0.745 -> 0.750, median 0.774 -> 0.775, worst 0.450 -> 0.467; single-frame near-object precision lower on
every row (median 0.814 -> 0.798); precision median 0.971 -> 0.968, the same four rows under 0.95.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .lines2d import Gradients, Segments2D, dot2, parabola_peak, sample
from .recording import StereoIntrinsics
from .stereo import (Matches, StereoParams, angle_from_rows, orientation_close, orientation_penalty,
                     points_along, scored_beside)

NEIGHBOURS = 8        # matched pieces looked at for a piece's disparity prior


@dataclass(frozen=True)
class GuidedParams:
    enabled: bool = False
    neighbour_px: float = 40.0   # matched left pieces this near (the ``NEIGHBOURS`` nearest) give the prior ...
    margin_px: float = 3.0       # ... their disparities' range widened by this ...
    max_range_px: float = 48.0   # ... and searched only if at most this wide
    min_rows: int = 7            # rows (of ``stereo.SAMPLES_ALONG``) showing the right edge at the best disparity ...
    max_rival_rows: int = 3      # ... and at most this many at any disparity ``min_gap_px`` or more away
    min_gap_px: float = 3.0
    min_contrast: float = 0.5    # a right edge point's gradient, against the left piece's contrast
    locate_px: float = 2.0       # the right edge is located this far either side of the best disparity
    max_residual_px: float = 0.5  # RMS distance of the located edge points from their line


def guided_matches(left_img: np.ndarray, right_img: np.ndarray, left: Segments2D, right: Segments2D,
                   m: Matches, right_gradients: Gradients, intr: StereoIntrinsics, stereo: StereoParams,
                   params: GuidedParams = GuidedParams()) -> tuple[Matches, Segments2D]:
    """``m`` with the matches the search adds (disparities in px at the left centre's row), and
    ``right`` (right image, px) with the right pieces they found appended, each on a line of its own
    (so each is triangulated as a lone piece, even where several lie on one left line)."""
    if not params.enabled or len(m.left) == 0:
        return m, right
    matched = np.zeros(len(left), bool)
    matched[m.left] = True
    pieces_left = np.flatnonzero((angle_from_rows(left.directions) >= stereo.critical_angle_deg) & ~matched)
    if len(pieces_left) == 0:
        return m, right
    d_min, d_max = intr.fx * intr.baseline / stereo.max_depth_m, intr.fx * intr.baseline / stereo.min_depth_m
    lo, hi = _disparity_prior(left, m, pieces_left, params)
    lo, hi = np.maximum(lo, np.ceil(d_min)), np.minimum(hi, np.floor(d_max))
    keep = hi >= lo
    pieces_left, lo, hi = pieces_left[keep], lo[keep], hi[keep]
    if len(pieces_left) == 0:
        return m, right
    rows, u_left = points_along(left, pieces_left)     # (T, R) px: where the votes and the location look
    best_d, voted = _vote(right_gradients, left, pieces_left, rows, u_left, lo, hi, params)
    pieces_left, best_d = pieces_left[voted], best_d[voted]
    found, located = _locate(right_gradients, left, pieces_left, rows[voted], u_left[voted], best_d, params)
    pieces_left = pieces_left[located]
    found = found.select(located)
    # the left centre's row crosses each found right piece at its centre (``_locate``)
    disparity = left.centers[pieces_left, 0] - found.centers[:, 0]
    cos_diff = np.abs(dot2(left.directions[pieces_left], found.directions))
    plausible = (disparity >= d_min) & (disparity <= d_max) & orientation_close(cos_diff, stereo)
    pieces_left, found, disparity, cos_diff = (pieces_left[plausible], found.select(plausible), disparity[plausible],
                                               cos_diff[plausible])
    if len(pieces_left) == 0:
        return m, right
    # scored as matching scores (``match``), beside the frame's matched pairs
    trial = right.concatenate(found)
    score = scored_beside(left_img, right_img, left, trial, m, pieces_left, len(right) + np.arange(len(pieces_left)),
                          stereo) - orientation_penalty(cos_diff, stereo)
    take = score >= stereo.min_score
    if not take.any():
        return m, right
    pieces_left, found, disparity, score = pieces_left[take], found.select(take), disparity[take], score[take]
    first_line = int(right.line_id.max()) + 1 if len(right) else 0
    found.line_id = np.arange(first_line, first_line + len(pieces_left))
    out = Matches(np.concatenate([m.left, pieces_left]),
                  np.concatenate([m.right, len(right) + np.arange(len(pieces_left))]),
                  np.concatenate([m.disparity, disparity]), np.concatenate([m.score, score]),
                  m.critical, m.unmatched - len(pieces_left))
    return out, right.concatenate(found)


def _disparity_prior(left: Segments2D, m: Matches, todo: np.ndarray, params: GuidedParams):
    """(T,) and (T,) the lowest and highest disparity (px, whole) to search per left piece ``todo``
    (inf and -inf where there is no prior): the range of the matched pieces' within ``neighbour_px``
    in the left image (the ``NEIGHBOURS`` nearest), widened by ``margin_px``."""
    k = min(NEIGHBOURS, len(m.left))
    distance, index = cKDTree(left.centers[m.left]).query(left.centers[todo], k=k,
                                                          distance_upper_bound=params.neighbour_px)
    distance, index = distance.reshape(len(todo), k), index.reshape(len(todo), k)
    neighbour = np.isfinite(distance)
    d = m.disparity[np.where(neighbour, index, 0)]
    lo = np.floor(np.where(neighbour, d, np.inf).min(axis=1) - params.margin_px)
    hi = np.ceil(np.where(neighbour, d, -np.inf).max(axis=1) + params.margin_px)
    bad = ~neighbour.any(axis=1) | (hi - lo > params.max_range_px)
    lo[bad], hi[bad] = np.inf, -np.inf
    return lo, hi


def _vote(right_gradients: Gradients, left: Segments2D, todo, rows, u_left, lo, hi, params: GuidedParams):
    """(T,) per left piece ``todo`` (its points ``rows``, ``u_left`` (T, R) px, ``stereo.points_along``)
    the whole disparity (px) in [lo, hi] that the most of its rows vote
    for, and (T,) whether it has ``min_rows`` votes and no disparity ``min_gap_px`` or more away more
    than ``max_rival_rows``. A row votes for a disparity where the right image, along that row, has a
    local maximum (within a pixel) of the gradient across the piece, of the piece's polarity and at
    least ``min_contrast`` of its contrast (``Segments2D.contrast``, grey levels per px)."""
    width = int((hi - lo).max()) + 1
    d = lo[:, None] + np.arange(width)                                                   # (T, W)
    response = _response(right_gradients, left, todo, u_left[:, :, None] - d[:, None, :], rows)   # (T, R, W)
    inside = (d <= hi[:, None])[:, None, :]
    strong = response >= params.min_contrast * left.contrast[todo, None, None]
    peak = np.zeros(response.shape, bool)
    peak[:, :, 1:-1] = (response[:, :, 1:-1] >= response[:, :, :-2]) & (response[:, :, 1:-1] >= response[:, :, 2:])
    peak &= strong & inside
    vote = peak.copy()
    vote[:, :, 1:] |= peak[:, :, :-1]
    vote[:, :, :-1] |= peak[:, :, 1:]
    support = vote.sum(axis=1)                                                           # (T, W)
    best = np.argmax(support, axis=1)
    far = np.abs(np.arange(width)[None, :] - best[:, None]) >= params.min_gap_px
    rival = np.where(far, support, 0).max(axis=1)
    top = support[np.arange(len(todo)), best]
    ok = (top >= params.min_rows) & (rival <= params.max_rival_rows)
    return lo + best, ok


def _locate(gradients: Gradients, left: Segments2D, todo, rows, u_left, d, params: GuidedParams):
    """(T) right pieces (right image, px; line ids 0, ``t`` 0) through the right edge located on each
    left piece's rows (its points ``rows``, ``u_left`` (T, R) px) within ``locate_px`` of disparity
    ``d`` (T,) px, and (T,) whether ``min_rows`` rows found it, within ``max_residual_px`` RMS of a
    straight line."""
    u0 = u_left - d[:, None]
    offsets = np.arange(-params.locate_px, params.locate_px + 0.5)                      # (O,)
    response = _response(gradients, left, todo, u0[:, :, None] + offsets, rows)         # (T, R, O)
    k = np.clip(np.argmax(response, axis=2), 1, len(offsets) - 2)
    r0, r1, r2 = (np.take_along_axis(response, (k + j)[:, :, None], axis=2)[:, :, 0] for j in (-1, 0, 1))
    peak = ((r1 >= r0) & (r1 >= r2) & (r0 - 2 * r1 + r2 < 0)
            & (r1 >= params.min_contrast * left.contrast[todo, None]))
    edge_u = u0 + offsets[k] + np.where(peak, parabola_peak(r0, r1, r2), 0.0)          # (T, R) px
    w = peak.astype(float)
    n = w.sum(axis=1)
    safe = np.maximum(n, 1.0)
    mv, mu = (w * rows).sum(1) / safe, (w * edge_u).sum(1) / safe
    svv = (w * (rows - mv[:, None]) ** 2).sum(1)
    slope = (w * (rows - mv[:, None]) * (edge_u - mu[:, None])).sum(1) / np.maximum(svv, 1e-9)   # du / dv
    residual = np.sqrt((w * (edge_u - mu[:, None] - slope[:, None] * (rows - mv[:, None])) ** 2).sum(1) / safe)
    found = (n >= params.min_rows) & (residual <= params.max_residual_px) & (svv > 1e-6)
    direction = np.column_stack([slope, np.ones(len(todo))])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    v_c = left.centers[todo, 1]
    centers = np.column_stack([mu + slope * (v_c - mv), v_c])
    contrast = np.where(found, (w * np.max(response, axis=2)).sum(1) / safe, 0.0)
    pieces = Segments2D(centers, direction, left.lengths[todo].copy(), left.polarity[todo].copy(), contrast,
                        np.zeros(len(todo), np.int64), np.zeros(len(todo)), direction.copy())
    return pieces, found


def _response(gradients: Gradients, left: Segments2D, todo, u: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(T, R, K) the right image's gradient (grey levels per px) across the left pieces ``todo`` (along
    their normal, signed by their polarity) at columns ``u`` (T, R, K) on ``rows`` (T, R), right image px."""
    v = np.broadcast_to(rows[:, :, None], u.shape)
    normal = left.normals[todo] * left.polarity[todo, None]
    return sample(gradients.gx, u, v) * normal[:, None, None, 0] + sample(gradients.gy, u, v) * normal[:, None, None, 1]
