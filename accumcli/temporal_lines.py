"""Line segments triangulated across frames with the known motion (multi-view, not stereo).

A left-image piece fixes the plane through the camera and its edge; the recorded motion puts the
planes of two frames in the object frame, and their intersection is the edge's line. The object turns
5 to 10 degrees a frame on the suite's recordings, so two frames apart the views lie 15 to 25 degrees
apart: a baseline several times the stereo rig's, and in another direction, which is what a short or
near-horizontal piece lacks in stereo (its direction from two planes 8 cm apart is tilted in depth by
tens of degrees, and near the epipolar direction it has no disparity at all).

Pairs: a piece of the current frame and a piece of a frame 2 or 4 back (``frames_back``) that share
an epipolar plane and whose rays meet within ``reach_m`` of the object frame's origin (sorted
intervals, not all pairs), whose planes meet at ``min_dihedral_deg`` or more, whose extents overlap
along the line, and that do not lie on one image line (``still_px``: what stands still in the camera
meets its own planes where the motion's axis crosses it). A pair of pieces always meets somewhere, so
the line must be shown by ``min_votes`` of the other buffered views (a piece along its projection,
``verify_px``, ``verify_deg``, not on the current piece's own image line): one verifying view let
gratings of parallel background lines through (the motion moved them along themselves onto their
neighbours): with three of four verifying views 94 of sim_104's 742 lines lay more than 30 mm from
the object, with four of four 3 of 322, with four of five (the default) 10 of 460. A piece keeps its best-verified partner, none when another verifies a different
line as often (ambiguous, ``ambiguous_votes``). A piece that stereo placed keeps only a line within four of its
depth sigmas (and 3 mm).

Sigmas, measured on the devset (``benchmarks``-style, against the truth): a line's direction error
times the sine of its planes' angle is ``plane_turn_px_rad`` over the pieces' lengths, with a floor
(``direction_floor_deg``); its depth, a piece's position across itself over the ray's angle to the
partner's plane. On exact pieces with 0.15 px of noise the errors over sigma have median 0.70 and
95th percentile 1.98 (a calibrated Gaussian's 0.67 and 1.96; ``tests/test_temporal_lines.py``). Near
the object (within 20 mm) 0.91 to 0.99 of the lines were right (4 mm / 10 degrees) on dev_tprofile,
dev_cube_small and sim_104, against 0.60 to 0.88 of their stereo segments.

Measured on ``make suite`` (``benchmarks/suite.py --across-frames``, 4 runs a row, 2026-12-08, at
91c317a): completeness median 0.774 -> 0.778, mean 0.745 -> 0.756, worst row 0.450 -> 0.465, higher on
16 of 19 rows (dev_tprofile 0.637 -> 0.668, sim_105 0.483 -> 0.517, sim_104 0.791 -> 0.810, sim_103
0.884 -> 0.900), sim_102, the real chessboard and teabox the same (the teabox barely turns: 0.3
degrees a frame); precision median 0.971 -> 0.969, mean 0.946 -> 0.947 (sim_105 0.884 -> 0.928,
sim_104 0.989 -> 0.965, sim_106 0.967 -> 0.987), the same four rows under 0.95; background the same.
Tracking with these models (``benchmarks/track_suite.py --across-frames``): no false frame, the
wrong model lost everywhere, dev_steps 0.983 tracked (0.158 deg / 0.258 mm), sim_201 0.333 -> 0.533,
sim_206 0.800 -> 0.767. Before the extent gates (``_well_cut``; lines half a metre long from 12 px
pieces) and the ambiguity over every candidate, completeness was about the same (median 0.781) but
dev_steps' model tracked 0.733 of dev_steps_track. Off by default (``AccumulateParams.temporal``):
issue 10's figure compares ``--motion tracked`` (which refuses these lines) with the exact-pose model,
and with them on for the recorded poses ``make motion`` had 3 or 4 of 12 scenes within 0.02 instead
of 8 (median shortfall 0.025 to 0.029 against 0.014; two runs that shared a cache by mistake: a rough
measurement). With a blind right camera it builds
the sample's model alone: precision 1.0, completeness 0.80. Cost (one core): 11 ms a frame on
dev_cube_small, 15 on the sample, about 175 on sim_101's crowded frames (2,800 pieces; its
extraction takes 125).

Why written here: OpenCV has no line triangulation across posed views with these gates (its sfm
module's is not in the wheels and takes matched lines, which is the hard part).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .geometry import invert, rotate_vectors, transform_points, unit_or_zero
from .grouping import ranges
from .lines2d import Segments2D, pieces_along
from .recording.calibration import StereoIntrinsics
from .segments import Segments
from .stereo import view_plane_normals


@dataclass(frozen=True)
class TemporalParams:
    frames_back: tuple = (4, 2)     # partner frames, this many frames before the current one
    buffer: int = 6                 # frames kept for partners and verification (the current one's witnesses)
    min_length_px: float = 6.0      # shorter pieces fix no plane worth intersecting
    min_dihedral_deg: float = 8.0   # the two planes meet at least this steeply
    min_overlap: float = 0.5        # of the shorter piece's extent, along the line they meet on
    min_ray_sine: float = 0.2       # a piece's rays cross its line at least this steeply
    max_stretch: float = 3.0        # and its extent on the line is at most this times what it spans
    near_m: float = 0.1             # in front of both cameras, at least this far
    reach_m: float = 0.4            # and within this of the object frame's origin (the gripper's)
    still_px: float = 1.5           # a pair on one image line (this near across it) is the background's
    min_votes: int = 4              # other views (of buffer - 1) that must verify a line
    verify_px: float = 0.6          # a third view's piece lies this near across the projection ...
    verify_deg: float = 3.0         # ... and this near its angle, its centre within the projection
    ambiguous_votes: int = 0        # a runner-up verified this many times fewer still makes a piece ambiguous
    same_line_deg: float = 5.0      # two partners verified as often put a piece on one line only within this
    same_line_m: float = 0.002      # ... and this (else it is ambiguous, dropped)
    line_sigma_px: float = 0.3      # a piece's position across itself, for the depth's sigma
    # a line's direction error times the sine of its planes' angle is plane_turn_px_rad * hypot(1/la, 1/lb)
    # for pieces la, lb px long: measured on the devset, median 0.39 / 0.61 / 0.98 degrees for pieces of
    # 13 to 20 / 10 to 13 / under 10 px on dev_cube_small (the noisiest), half that on dev_tprofile
    plane_turn_px_rad: float = 0.085
    plane_sigma_deg: float = 0.1    # and a plane's at least this (the poses', the line's)
    # plus this in quadrature, whatever the planes' angle (the errors fall slower than 1 / sine: on
    # dev_cube_small median 2.4 / 1.8 / 1.6 degrees at sines 0.1-0.25 / 0.25-0.4 / 0.4-0.6)
    direction_floor_deg: float = 1.5


@dataclass
class View:
    """One frame's left pieces, in the object frame: ``camera`` (3,) the camera centre; ``normals`` (N, 3)
    unit normals of the pieces' planes through it; ``ends`` (N, 2, 3) unit rays through the pieces'
    ends; ``pieces`` the 2D pieces (px, for verification); ``T_camera_object``; ``intr``."""

    camera: np.ndarray
    normals: np.ndarray
    ends: np.ndarray
    pieces: Segments2D
    T_camera_object: np.ndarray
    intr: StereoIntrinsics
    index: int
    reach: tuple = ()                  # (enter, leave), (N, 2) metres along the end rays within reach
    _tree: cKDTree | None = None

    def tree(self) -> cKDTree:
        """The pieces' centres, searched by every hypothesis this view verifies (built once)."""
        if self._tree is None:
            self._tree = cKDTree(self.pieces.centers)
        return self._tree

    @classmethod
    def of(cls, pieces: Segments2D, T_camera_object: np.ndarray, intr: StereoIntrinsics, index: int,
           p: "TemporalParams") -> "View":
        ends_px = pieces.endpoints()
        rays_camera = np.concatenate([ends_px, np.ones((len(ends_px), 2, 1))], axis=2) @ np.linalg.inv(intr.K).T
        R = T_camera_object[:3, :3]
        rays = unit_or_zero(rays_camera @ R)                       # R^T r: camera -> object frame, (N, 2, 3)
        normals = unit_or_zero(view_plane_normals(ends_px[:, 0], ends_px[:, 1], intr) @ R)
        camera = invert(T_camera_object)[:3, 3]
        enter, leave = _reach_on_rays(camera, rays.reshape(-1, 3), p)
        return cls(camera, normals, rays, pieces, T_camera_object, intr, index,
                   (enter.reshape(-1, 2), leave.reshape(-1, 2)))


def _plane_sigma(lengths_px: np.ndarray, p: TemporalParams) -> np.ndarray:
    """(N,) rad: how far a piece's plane turns, as it meets another: ``plane_turn_px_rad`` over its
    length, at least ``plane_sigma_deg`` (measured, ``TemporalParams``)."""
    return np.hypot(np.radians(p.plane_sigma_deg), p.plane_turn_px_rad / np.maximum(lengths_px, 1.0))


def _reach_on_rays(camera: np.ndarray, rays: np.ndarray, p: TemporalParams) -> tuple[np.ndarray, np.ndarray]:
    """(K,) and (K,) metres: where the unit ``rays`` (K, 3) from ``camera`` (object frame) enter and
    leave the ball of ``reach_m`` about the object frame's origin, from ``near_m`` on (nan: never)."""
    along = rays @ -camera
    half = np.sqrt(np.maximum(along ** 2 - (camera @ camera - p.reach_m ** 2), 0.0))
    enter, leave = np.maximum(along - half, p.near_m), along + half
    missed = (along ** 2 < camera @ camera - p.reach_m ** 2) | (leave <= enter)
    return np.where(missed, np.nan, enter), np.where(missed, np.nan, leave)


def _candidate_pairs(a: View, b: View, ia: np.ndarray, jb: np.ndarray, p: TemporalParams
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i of ``ia``, j of ``jb``) of pieces of views ``a`` and ``b`` that can show one edge
    within reach: they share an epipolar plane (through both cameras; each piece's ends span an
    interval of the planes' angle about the baseline, as rectified stereo's rows), and b's rays
    meet a's within the ball of ``reach_m`` (an interval of their angle to the baseline). Sorted and
    searched on the first, not all pairs: a frame has a thousand pieces or more."""
    if not len(ia) or not len(jb):
        return ia[:0], jb[:0]
    axis = unit_or_zero(b.camera - a.camera)
    rays = np.concatenate([a.ends[ia].reshape(-1, 3), b.ends[jb].reshape(-1, 3)])
    across = rays - (rays @ axis)[:, None] * axis
    u1 = unit_or_zero(across.mean(axis=0))      # the angle counted from the pieces' mean: no wrap near them
    u2 = np.cross(axis, u1)
    angle = np.arctan2(across @ u2, across @ u1).reshape(-1, 2)
    lo, hi = angle.min(axis=1), angle.max(axis=1)
    usable = hi - lo < np.pi / 2                # a piece around the epipole: no interval
    # the angle to the baseline of b's rays, and of the points of a's rays within reach seen from b
    enter, leave = a.reach[0][ia].reshape(-1), a.reach[1][ia].reshape(-1)
    reach = np.concatenate([a.camera + enter[:, None] * a.ends[ia].reshape(-1, 3),
                            a.camera + leave[:, None] * a.ends[ia].reshape(-1, 3)]) - b.camera
    elevation_a = (unit_or_zero(reach) @ axis).reshape(2, -1, 2).transpose(1, 0, 2).reshape(-1, 4)  # cosines
    low_a, high_a = np.fmin.reduce(elevation_a, axis=1), np.fmax.reduce(elevation_a, axis=1)   # nan: out of reach
    elevation_b = (b.ends[jb].reshape(-1, 3) @ axis).reshape(-1, 2)
    low_b, high_b = elevation_b.min(axis=1), elevation_b.max(axis=1)
    lo_a, hi_a, lo_b, hi_b = lo[:len(ia)], hi[:len(ia)], lo[len(ia):], hi[len(ia):]
    ok_a, ok_b = usable[:len(ia)] & np.isfinite(low_a), usable[len(ia):]
    order = np.flatnonzero(ok_b)[np.argsort(lo_b[ok_b])]
    widest = (hi_b - lo_b)[ok_b].max(initial=0.0)
    first = np.searchsorted(lo_b[order], lo_a - widest)
    count = np.where(ok_a, np.searchsorted(lo_b[order], hi_a, side="right") - first, 0)
    x = np.repeat(np.arange(len(ia)), count)
    y = order[ranges(first, count)]
    keep = (hi_b[y] >= lo_a[x]) & (high_b[y] >= low_a[x]) & (low_b[y] <= high_a[x])
    return ia[x[keep]], jb[y[keep]]


def pair_hypotheses(a: View, b: View, p: TemporalParams, wanted: np.ndarray | None = None,
                    distance: np.ndarray | None = None) -> dict:
    """Every pair (piece i of ``a``, piece j of ``b``) whose planes meet on a line that both pieces
    overlap along, in front of both cameras: arrays ``i``, ``j``, ``start``/``end`` (K, 3) the overlap's
    ends (object frame, metres), ``a_start``/``a_end`` piece i's extent on the line, ``sine`` (K,) of
    the planes' angle."""
    ia = np.flatnonzero((a.pieces.lengths >= p.min_length_px) & (True if wanted is None else wanted))
    jb = np.flatnonzero(b.pieces.lengths >= p.min_length_px)
    i, j = _candidate_pairs(a, b, ia, jb, p)
    na, nb = a.normals[i], b.normals[j]
    ok = np.abs(_dot(na, nb)) <= np.cos(np.radians(p.min_dihedral_deg))     # planes that meet steeply enough
    i, j, na, nb = i[ok], j[ok], na[ok], nb[ok]
    # each piece's ends along their rays to the other's plane: in front and within reach
    ra, rb = a.ends[i], b.ends[j]
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = _dot(b.camera - a.camera, nb)[:, None] / _dot(ra, nb[:, None])        # (K, 2) metres
        tb = _dot(a.camera - b.camera, na)[:, None] / _dot(rb, na[:, None])
    ok = ((ta >= a.reach[0][i]) & (ta <= a.reach[1][i]) & (tb >= b.reach[0][j]) & (tb <= b.reach[1][j])).all(axis=1)
    if distance is not None:     # where stereo put the piece: (lo, hi) metres from the camera, nan: anywhere
        middle = (ta[:, 0] + ta[:, 1]) / 2
        ok &= ~(middle < distance[0][i]) & ~(middle > distance[1][i])
    # not the same image line in both frames: a line fixed in the camera (the background) meets its
    # own planes of other frames where the motion's axis crosses it, the same point in every view
    ok[ok] = ~_on_line(b.pieces.centers[j[ok]], b.pieces.directions[j[ok]], a.pieces.centers[i[ok]],
                       a.pieces.directions[i[ok]], p.still_px, p.verify_deg)
    i, j, na, nb, ra, rb, ta, tb = (x[ok] for x in (i, j, na, nb, ra, rb, ta, tb))
    normal = np.cross(na, nb)
    sine = np.linalg.norm(normal, axis=1)
    direction = normal / sine[:, None]
    pa = a.camera + ta[:, :, None] * ra       # (K, 2, 3), on the line
    pb = b.camera + tb[:, :, None] * rb
    origin = pa[:, 0]
    along_a = _dot(pa - origin[:, None], direction[:, None])                     # (K, 2) metres
    along_b = _dot(pb - origin[:, None], direction[:, None])
    a0, a1 = np.minimum(along_a[:, 0], along_a[:, 1]), np.maximum(along_a[:, 0], along_a[:, 1])
    b0, b1 = np.minimum(along_b[:, 0], along_b[:, 1]), np.maximum(along_b[:, 0], along_b[:, 1])
    lo, hi = np.maximum(a0, b0), np.minimum(a1, b1)
    keep = ((hi - lo) >= p.min_overlap * np.minimum(a1 - a0, b1 - b0)) & \
        _well_cut(ra, ta, a1 - a0, direction, a.pieces.lengths[i] / a.intr.fx, nb, p) & \
        _well_cut(rb, tb, b1 - b0, direction, b.pieces.lengths[j] / b.intr.fx, na, p)
    along = (lambda t: (origin + t[:, None] * direction)[keep])
    return {"i": i[keep], "j": j[keep], "direction": direction[keep], "sine": sine[keep],
            "start": along(lo), "end": along(hi), "a_start": along(a0), "a_end": along(a1)}


def _well_cut(rays: np.ndarray, distance: np.ndarray, extent: np.ndarray, direction: np.ndarray,
              angle: np.ndarray, other_normal: np.ndarray, p: TemporalParams) -> np.ndarray:
    """(K,) bool: a piece's extent on its line is well posed: its end ``rays`` (K, 2, 3) cross the line
    (``direction`` (K, 3)) at ``min_ray_sine`` or more, the middle ray meets the other view's plane
    (``other_normal``) at half the sine of ``min_dihedral_deg`` or more (it lies in its own plane, so
    never steeper than the planes meet), and the ``extent`` (K,) metres is at most
    ``max_stretch`` times what the piece spans at that ``distance`` (K, 2) (``angle`` (K,): its length
    over fx). Where a ray runs nearly along the line or the plane, its end lands anywhere (a 12 px
    piece made lines half a metre long on the sample); as ``stereo._ends_on_rays``."""
    crossing = np.linalg.norm(np.cross(rays, direction[:, None]), axis=2).min(axis=1)
    middle = unit_or_zero(rays.sum(axis=1))
    spans = angle * (distance[:, 0] + distance[:, 1]) / 2
    return (crossing >= p.min_ray_sine) & (extent <= p.max_stretch * spans) & \
        (np.abs(_dot(middle, other_normal)) >= np.sin(np.radians(p.min_dihedral_deg)) / 2)


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Dot products over the last axis (of length 3), broadcast: written out, as numpy's sum and
    einsum run several times slower on short last axes."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def _on_line(centers: np.ndarray, directions: np.ndarray, line_centers: np.ndarray, line_directions: np.ndarray,
             across_px: float, max_deg: float) -> np.ndarray:
    """(K,) bool: 2D pieces (``centers``, unit ``directions``, (K, 2) px) lying on the lines through
    ``line_centers`` along ``line_directions`` (K, 2): within ``across_px`` across, ``max_deg`` of their angle."""
    rel = centers - line_centers
    across = np.abs(rel[:, 0] * line_directions[:, 1] - rel[:, 1] * line_directions[:, 0])
    return (across <= across_px) & (np.abs(np.sum(directions * line_directions, axis=1)) >= np.cos(np.radians(max_deg)))


def verified_in(view: View, start: np.ndarray, end: np.ndarray, p: TemporalParams,
                still: Segments2D | None = None) -> np.ndarray:
    """(K,) bool: a piece of ``view`` lies along the projection of each object-frame segment
    ``start``-``end`` (K, 3): within ``verify_px`` across, ``verify_deg`` of its angle, its centre
    within the projection. ``still`` (K pieces of the current image): a witness piece on the same
    image line as the current piece does not count (what stands still in the camera is there in
    every view, wherever the motion puts the line)."""
    out = np.zeros(len(start), bool)
    if not len(start) or not len(view.pieces):
        return out
    T = view.T_camera_object
    uv0, _, z0 = view.intr.project(transform_points(T, start))
    uv1, _, z1 = view.intr.project(transform_points(T, end))
    length = np.linalg.norm(uv1 - uv0, axis=1)
    usable = np.flatnonzero((z0 > p.near_m) & (z1 > p.near_m) & np.isfinite(length) & (length >= 2.0))
    if not len(usable):
        return out
    middle = (uv0 + uv1)[usable] / 2
    direction = (uv1 - uv0)[usable] / length[usable, None]
    pieces = view.pieces
    k, m, along, across, cosine = pieces_along(middle, direction, length[usable] / 2 + p.verify_px, pieces,
                                               view.tree())
    on = (across <= p.verify_px) & (cosine >= np.cos(np.radians(p.verify_deg))) & \
        (np.abs(along) <= length[usable][k] / 2)
    if still is not None:
        q = usable[k]
        on &= ~_on_line(pieces.centers[m], pieces.directions[m], still.centers[q], still.directions[q],
                        p.still_px, p.verify_deg)
    out[usable[np.unique(k[on])]] = True
    return out


class TemporalLines:
    """The last ``buffer`` frames' views, and the hypotheses of each new frame against them."""

    def __init__(self, params: TemporalParams = TemporalParams(), camera_frame: str = "camera_left"):
        self.params = params
        self.camera_frame = camera_frame
        self.views: deque[View] = deque(maxlen=params.buffer)

    def step(self, pieces: Segments2D, T_camera_object: np.ndarray, intr: StereoIntrinsics, index: int,
             wanted: np.ndarray | None = None, distance: tuple | None = None) -> Segments:
        """The current frame's 3D segments from pieces of it and of a buffered frame, verified in
        ``min_votes`` of the others (in the camera frame, with ``sigma_*`` extras as stereo gives them; module
        docstring); then the frame joins the buffer."""
        view = View.of(pieces, T_camera_object, intr, index, self.params)
        found = self._hypotheses(view, wanted, distance)
        self.views.append(view)
        return found

    def _hypotheses(self, view: View, wanted: np.ndarray | None, distance: tuple | None) -> Segments:
        p = self.params
        by_index = {v.index: v for v in self.views}
        nearest = max(np.linalg.norm(view.camera) - p.reach_m, p.near_m)    # metres, camera to the object's ball
        rows = []
        for back in p.frames_back:
            partner = by_index.get(view.index - back)
            # planes through two cameras this close meet a line within reach at under min_dihedral_deg
            if partner is None or np.linalg.norm(partner.camera - view.camera) < \
                    np.sin(np.radians(p.min_dihedral_deg)) * nearest:
                continue
            h = pair_hypotheses(view, partner, p, wanted, distance)
            if not len(h["i"]):
                continue
            witnesses = [v for v in self.views if v.index != partner.index]
            votes = np.zeros(len(h["i"]), np.int64)
            for left, w in enumerate(reversed(witnesses)):    # nearest first; only what can still pass
                open_ = np.flatnonzero(votes + len(witnesses) - left >= p.min_votes)
                votes[open_] += verified_in(w, h["start"][open_], h["end"][open_], p,
                                            view.pieces.select(h["i"][open_]))
            keep = votes >= p.min_votes
            rows.append({k: v[keep] for k, v in h.items()} | {"votes": votes[keep],
                                                             "b_length": partner.pieces.lengths[h["j"][keep]],
                                                             "b_normal": partner.normals[h["j"][keep]]})
        h = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]} if rows else {"i": np.zeros(0, int)}
        if not len(h["i"]):
            return Segments.empty(self.camera_frame)
        # one line per current piece: the most votes, then the steepest planes; none when any other
        # candidate of the piece verified as often (``ambiguous_votes``) puts it on a different line
        order = np.lexsort((-h["sine"], -h["votes"], h["i"]))
        i_sorted = h["i"][order]
        first = np.r_[True, i_sorted[1:] != i_sorted[:-1]]
        group = np.cumsum(first) - 1
        best = order[first]
        of_best = best[group]
        middle = (h["a_start"] + h["a_end"]) / 2
        close = h["votes"][order] >= h["votes"][of_best] - p.ambiguous_votes
        differ = (np.abs(_dot(h["direction"][order], h["direction"][of_best])) < np.cos(np.radians(p.same_line_deg))) | \
            (np.linalg.norm(middle[order] - middle[of_best], axis=1) > p.same_line_m)
        ambiguous = np.bincount(group[close & differ], minlength=len(best)) > 0
        return self._segments(view, {k: v[best[~ambiguous]] for k, v in h.items()})

    def _segments(self, view: View, h: dict) -> Segments:
        """3D segments (camera frame of ``view``) of the current pieces' extents on their lines, with
        the sigmas of the triangulation: direction from the two planes' angles over their dihedral
        sine, depth from the partner plane's position across itself over the ray's angle to it.
        Confidence 1: a line four other views show is as sure as a stereo match of score 1."""
        p = self.params
        T = view.T_camera_object
        start, end = transform_points(T, h["a_start"]), transform_points(T, h["a_end"])
        centers = (start + end) / 2
        vec = end - start
        lengths = np.linalg.norm(vec, axis=1)
        directions = vec / np.maximum(lengths, 1e-12)[:, None]
        sigma_a = _plane_sigma(view.pieces.lengths[h["i"]], p)
        sigma_b = _plane_sigma(h["b_length"], p)
        sigma_direction = np.hypot(np.hypot(sigma_a, sigma_b) / h["sine"], np.radians(p.direction_floor_deg))
        depth = centers[:, 2]
        sigma_lateral_m = depth * p.line_sigma_px / view.intr.fx
        sine_ray = np.abs(_dot(unit_or_zero(centers), rotate_vectors(T, h["b_normal"])))
        # the partner's plane, off by its line's position across itself, moves the point along this
        # ray (its turn about its own centre ray moves it little near the piece)
        sigma_depth = sigma_lateral_m / np.maximum(sine_ray, np.sin(np.radians(p.min_dihedral_deg)) / 4)   # ``_well_cut``
        uv, _, _ = view.intr.project(centers)
        return Segments(self.camera_frame, centers, directions, lengths, np.ones(len(centers)),
                        np.ones(len(centers), np.int64),
                        {"sigma_depth_m": sigma_depth, "sigma_direction_rad": sigma_direction,
                         "sigma_lateral_px": np.full(len(centers), p.line_sigma_px),
                         "disparity_px": view.intr.fx * view.intr.baseline / np.maximum(depth, 1e-9),
                         "u": uv[:, 0], "v": uv[:, 1], "piece": h["i"], "votes": h["votes"]})
