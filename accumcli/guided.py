"""Stereo matches found by searching the right image where its detector found no partner.

The right image's 2D segments miss edges that the left image's show: noise breaks a short edge into
runs too short for a piece, a junction bends its ends, a piece lands a pixel or two beside the edge.
Measured on the devset (``make suite`` frames, left pieces on seen object edges, not critical): 8 to
14 % found no right piece within 1.5 px and 10 degrees of the edge's projection in the right image,
although half of them had one within 3 px; 3 to 5 % more had right pieces on the edge that did not
cover the left piece's rows.

For each usable left piece left unmatched, the right image is searched along the piece's own rows
(``ROWS`` of them), at the disparities of its matched neighbours in the left image (the range of the
``NEIGHBOURS`` nearest within ``neighbour_px``, widened by ``margin_px``, searched only if at most
``max_range_px`` wide: without a prior a row holds too many edges). A disparity gets a row's vote
where the right image has an edge of the piece's polarity there (a local maximum, within a pixel, of
the gradient across the piece, of at least ``min_contrast`` of the piece's own): the best disparity
needs ``min_rows`` votes and every disparity ``min_gap_px`` or more away at most ``max_rival_rows``
(an edge parallel to it nearby makes the piece ambiguous, and it is left alone). The right edge is
then located on each row to sub-pixel (a parabola through the gradient), a line through those points
is the right piece, and the pair must reach matching's ``min_score`` (``stereo._ncc``). Its
direction comes from its own short line, so its 3D direction is as unsure as a lone piece's
(``stereo.triangulate`` says so in its sigma); what it brings is the edge's place in 3D and its view
plane, to accumulation. Searching by patch score (NCC) instead found half as many, and on the
devset 1 in 7 of those wrong against 1 in 10 by votes.

Off by default (``--right-search`` switches it on). Measured with it against without, ``make
suite``: completeness median 0.624 -> 0.636, worst row 0.271 -> 0.293 (higher on 15 of 19 rows; the
same gain, 0.617 -> 0.626 and 0.245 -> 0.271, with every image read shifted by 0.004 px: the
scoreboard's noise), single-frame correct 3D higher on every row (median 0.418 -> 0.431); the costs:
the single-frame near-object precision median 0.753 -> 0.737 (its pieces' directions are a lone
piece's), precision rows under 0.95 2 -> 4 (within the rows' noise of about 0.03), extraction about
2 ms a frame. What keeps it off is tracking with its models: over four runs of the tracking
scoreboard with image reads shifted by 0, +-0.004 and 0.008 px, sim_206 turns to an aspect its
model barely covers (3 to 5 % of it in view) and frames there were tracked 3.2 to 5.4 deg off in
every run (without the search: one false frame in the four runs, dev_steps at 0.008 px); a floor of
8 % in view (``TrackParams.min_shown``) removed them but lost right frames of the chessboard's
snapshots, whose many-aspect model shows 3 % of itself at a right pose. On the 21 off-scoreboard
runs over three shifts it made no difference (11 false frames either way, measured with 10 Gauss-Newton
steps a level).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .lines2d import Gradients, Segments2D, sample
from .recording import StereoIntrinsics
from .stereo import Matches, StereoParams, _ncc, angle_from_rows

ROWS = 8              # sample rows along a piece, as ``stereo._ncc`` samples it
NEIGHBOURS = 8        # matched pieces looked at for a piece's disparity prior
REFERENCE_PAIRS = 64  # of the frame's matches, scored again with the found pieces


@dataclass(frozen=True)
class GuidedParams:
    enabled: bool = False
    neighbour_px: float = 40.0   # matched left pieces this near (the ``NEIGHBOURS`` nearest) give the prior ...
    margin_px: float = 3.0       # ... their disparities' range widened by this ...
    max_range_px: float = 48.0   # ... and searched only if at most this wide
    min_rows: int = 7            # of ``ROWS``: rows that must show the right edge at the best disparity ...
    max_rival_rows: int = 3      # ... and at most this many at any disparity ``min_gap_px`` or more away
    min_gap_px: float = 3.0
    min_contrast: float = 0.5    # a right edge point's gradient, against the left piece's contrast
    locate_px: float = 2.0       # the right edge is located this far either side of the best disparity
    max_residual_px: float = 0.5  # RMS distance of the located edge points from their line


def guided_matches(left_img: np.ndarray, right_img: np.ndarray, left: Segments2D, right: Segments2D,
                   m: Matches, right_gradients: Gradients, intr: StereoIntrinsics, stereo: StereoParams,
                   params: GuidedParams = GuidedParams()) -> tuple[Matches, Segments2D]:
    """``m`` with the matches the search adds, and ``right`` with the right pieces they found appended
    (each on a line of its own)."""
    if not params.enabled or len(m.left) == 0:
        return m, right
    matched = np.zeros(len(left), bool)
    matched[m.left] = True
    todo = np.flatnonzero((angle_from_rows(left.directions) >= stereo.critical_angle_deg) & ~matched)
    if len(todo) == 0:
        return m, right
    lo, hi = _disparity_prior(left, m, todo, params)
    lo = np.maximum(lo, np.floor(intr.fx * intr.baseline / stereo.max_depth_m))
    hi = np.minimum(hi, np.ceil(intr.fx * intr.baseline / stereo.min_depth_m))
    keep = hi >= lo
    todo, lo, hi = todo[keep], lo[keep], hi[keep]
    if len(todo) == 0:
        return m, right
    best_d, ok = _vote(right_gradients, left, todo, lo, hi, params)
    todo = todo[ok]
    pieces, found = _locate(right_gradients, left, todo, best_d[ok], params)
    todo = todo[found]
    if len(todo) == 0:
        return m, right
    first = int(right.line_id.max()) + 1 if len(right) else 0
    pieces.line_id = np.arange(first, first + len(todo))
    extended = _concatenate(right, pieces)
    new = len(right) + np.arange(len(todo))
    # scored with some of the frame's matches, so that ``_ncc`` maps the right grey levels to the left's
    # as it did in matching (``stereo._grey_map_of_pairs``: from 20 pairs or more)
    known = slice(0, min(len(m.left), REFERENCE_PAIRS))
    score = _ncc(left_img, right_img, left, extended, np.concatenate([m.left[known], todo]),
                 np.concatenate([m.right[known], new]), stereo)[-len(todo):]
    take = score >= stereo.min_score
    if not take.any():
        return m, right
    todo, new, score = todo[take], new[take], score[take]
    kept = np.concatenate([np.arange(len(right)), new])
    # the left centre's row crosses each found right piece at its centre (``_locate``)
    disparity = left.centers[todo, 0] - extended.centers[new, 0]
    out = Matches(np.concatenate([m.left, todo]), np.concatenate([m.right, len(right) + np.arange(len(todo))]),
                  np.concatenate([m.disparity, disparity]), np.concatenate([m.score, score]),
                  m.critical, m.unmatched - len(todo))
    return out, extended.select(kept)


def _disparity_prior(left: Segments2D, m: Matches, todo: np.ndarray, params: GuidedParams):
    """(T,) lowest and highest disparity to search per piece ``todo`` (inf where no prior): the range of
    the matched pieces' within ``neighbour_px`` (the ``NEIGHBOURS`` nearest), widened by ``margin_px``."""
    k = min(NEIGHBOURS, len(m.left))
    distance, index = cKDTree(left.centers[m.left]).query(left.centers[todo], k=k,
                                                          distance_upper_bound=params.neighbour_px)
    distance, index = distance.reshape(len(todo), k), index.reshape(len(todo), k)
    near = np.isfinite(distance)
    d = m.disparity[np.where(near, index, 0)]
    lo = np.floor(np.where(near, d, np.inf).min(axis=1) - params.margin_px)
    hi = np.ceil(np.where(near, d, -np.inf).max(axis=1) + params.margin_px)
    bad = ~near.any(axis=1) | (hi - lo > params.max_range_px)
    lo[bad], hi[bad] = np.inf, -np.inf
    return lo, hi


def _vote(right_gradients: Gradients, left: Segments2D, todo, lo, hi, params: GuidedParams):
    """(T,) the integer disparity in [lo, hi] where most of each piece's rows show a right edge of the
    piece's polarity and at least ``min_contrast`` of its contrast (a local maximum of the gradient
    across the piece, within a pixel), its support in rows, and (T,) whether it has ``min_rows``
    and no disparity ``min_gap_px`` or more away has more than ``max_rival_rows``."""
    width = int((hi - lo).max()) + 1
    rows, u_left = _rows(left, todo)
    d = lo[:, None] + np.arange(width)                                                   # (T, W)
    response = _response(right_gradients, left, todo, u_left[:, :, None] - d[:, None, :], rows)   # (T, R, W)
    inside = (d <= hi[:, None])[:, None, :]
    strong = response >= params.min_contrast * left.contrast[todo, None, None]
    peak = np.zeros(response.shape, bool)
    peak[:, :, 1:-1] = (response[:, :, 1:-1] >= response[:, :, :-2]) & (response[:, :, 1:-1] >= response[:, :, 2:])
    peak &= strong & inside
    near = peak.copy()
    near[:, :, 1:] |= peak[:, :, :-1]
    near[:, :, :-1] |= peak[:, :, 1:]
    support = near.sum(axis=1)                                                           # (T, W)
    best = np.argmax(support, axis=1)
    far = np.abs(np.arange(width)[None, :] - best[:, None]) >= params.min_gap_px
    rival = np.where(far, support, 0).max(axis=1)
    top = support[np.arange(len(todo)), best]
    ok = (top >= params.min_rows) & (rival <= params.max_rival_rows)
    return lo + best, ok


def _locate(gradients: Gradients, left: Segments2D, todo, d, params: GuidedParams):
    """Right pieces (Segments2D, line ids unset) through the right edge found on each piece's rows
    near disparity ``d``, and (T,) whether enough rows found it on a straight line."""
    rows, u_left = _rows(left, todo)
    u0 = u_left - d[:, None]
    offsets = np.arange(-params.locate_px, params.locate_px + 0.5)                      # (O,)
    response = _response(gradients, left, todo, u0[:, :, None] + offsets, rows)         # (T, R, O)
    k = np.clip(np.argmax(response, axis=2), 1, len(offsets) - 2)
    take = np.take_along_axis
    r0, r1, r2 = (take(response, (k + j)[:, :, None], axis=2)[:, :, 0] for j in (-1, 0, 1))
    curvature = r0 - 2 * r1 + r2
    peak = (r1 >= r0) & (r1 >= r2) & (curvature < 0) & (r1 >= params.min_contrast * left.contrast[todo, None])
    delta = np.where(peak, 0.5 * (r0 - r2) / np.where(curvature < 0, curvature, -1.0), 0.0)
    edge_u = u0 + offsets[k] + delta                                                     # (T, R)
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
    return pieces.select(found), found


def _rows(left: Segments2D, todo) -> tuple[np.ndarray, np.ndarray]:
    """(T, ROWS) rows and columns of points along the left pieces ``todo``, as ``stereo._ncc`` places them."""
    s = np.linspace(-0.4, 0.4, ROWS)[None, :] * left.lengths[todo][:, None]
    return (left.centers[todo, 1][:, None] + s * left.directions[todo, 1][:, None],
            left.centers[todo, 0][:, None] + s * left.directions[todo, 0][:, None])


def _response(gradients: Gradients, left: Segments2D, todo, u: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The right gradient across the left pieces ``todo`` (along their normal, signed by their polarity)
    at columns ``u`` (T, R, K) on ``rows`` (T, R)."""
    v = np.broadcast_to(rows[:, :, None], u.shape)
    normal = np.column_stack([-left.directions[todo, 1], left.directions[todo, 0]]) * left.polarity[todo, None]
    return sample(gradients.gx, u, v) * normal[:, None, None, 0] + sample(gradients.gy, u, v) * normal[:, None, None, 1]


def _concatenate(a: Segments2D, b: Segments2D) -> Segments2D:
    return Segments2D(*(np.concatenate([getattr(a, f), getattr(b, f)]) for f in a.__dataclass_fields__))
