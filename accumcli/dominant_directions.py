"""Directions of unsure model segments and observations taken from the model's own dominant directions.

A segment confirmed but held back for its direction (``line_model.to_model``: its views all from one
aspect, so stereo's tilt in depth along the viewing ray stays unknown) still knows one thing well: the
plane through the camera and its edge (``line_model``'s ``dir_info``). The objects a robot grasps are
mostly made, and their edges share a few directions (a box three, an L or T profile or steps three
or four, a wedge five): where that plane holds one of the directions that the accepted segments
share, and the segment's own stereo direction lies near it, that is its direction.

The rule (``DominantParams``), at writing time (``line_model.to_model``), on the written model only:

- candidates are the accepted segments seen from more than one aspect (their stored views spanning
  more than ``LineModelParams.single_aspect_span_deg``: their direction is pinned by distinct view
  planes, not by one aspect's stereo) whose direction lies in the held segment's view plane (the
  plane through its mean viewing direction and its line, ``plane_deg``) and within ``max_turn_deg``
  of its own direction;
- a dominant direction is the candidate with the largest length of candidates within
  ``cluster_deg`` of it; it is taken only if that length is at least ``share`` of all the
  candidates' (one direction, not a choice between two that the plane holds alike) and comes from
  at least ``min_segments`` accepted segments (a shared direction, not one segment's);
- the direction is their length-weighted mean, projected into the held segment's plane; it turns
  the segment's own by at most ``turn_sigmas`` of its direction sigma (a segment that claims 2
  degrees and would turn by 15 is something else: a texture line, a piece of another edge);
- not where one of those accepted segments within ``covered_m`` across already covers that stretch
  in that direction (within ``covered_deg``, overlapping along it): there a held segment adds no
  edge, only the risk of a wrong one (most of the held segments off every edge by 4 to 9 mm lay
  beside an accepted segment of that kind);
- not a segment within ``min_plane_sine`` of its viewing ray (its plane is as unsure as its line, as
  ``line_model``'s planes), nor, with ``--plane-agreement``, one held back because its planes do not
  meet on one line (they disagree: no plane to hold a direction).

Such a segment is accepted (``direction_dominant`` in the model file), its direction sigma the
length-weighted root-mean-square angle of the cluster's members to their mean (at least
``min_sigma_deg``). Objects whose edges share no direction (curved, irregular) have no clusters of
two and are left as they were; so is a recording that never turns the object (no segment seen from
two aspects: the real teabox).

The running accumulation's observations too (``observations``): an observation whose stereo direction
is less sure than ``unsure_deg`` (a piece alone on its stretch, a short one) takes the dominant direction
its view plane holds among the directions the model shared as of the last frame (``FrameContext.shared``,
set by ``LineAccumulation``; the same tests but the covered one: an observation on an accepted segment's
stretch is what confirms it), with a sigma of at least ``observation_sigma_deg``. Why: such a piece,
tilted in depth, lands beside its edge's model segment or off its direction by more than the gate, and
starts a twin that one aspect never confirms; moved to the shared direction, it confirms the segment of
its edge, and its view plane, which ``line_model.merge`` weighs far more than a direction of 4 degrees,
still sets the segment's direction with the other views. ``make suite`` (4 runs a row, 2026-12-07)
against the held segments' rule alone: completeness median 0.754 -> 0.767, mean 0.733 -> 0.748, worst
0.401 -> 0.455 (dev_cube_small; dev_wedge_far 0.616 -> 0.675, sim_110 0.576 -> 0.608); precision
median 0.966 -> 0.969, rows under 0.95 six -> five (dev_wedge_far 0.949 -> 0.969, dev_cube_small 0.903
-> 0.934, sim_110 0.953 -> 0.976; sim_105 0.916 -> 0.896, sim_100 0.974 -> 0.966); the teabox unchanged;
tracking without a false frame (sim_201, the thinnest model, tracked 13 -> 2 of 30 frames, but over four
noise patterns on its model's recording 2, 4, 15 and 16 against 13, 3, 15 and 3 without: a draw, not
the rule). Measured and not kept (accumulation alone, same runs): the taken direction's sigma at least 2
degrees: completeness 0.766 / 0.749 / 0.468 but sim_105 0.875, sim_111 0.933 -> 0.912; only observations
less sure than 5 degrees (sigma 2): 0.767 / 0.749 / 0.468, sim_105 0.894, sim_111 0.921.

Held segments' rule measured with ``make suite`` (4 runs a row, 2026-12-07) against the model without it: completeness
median 0.693 -> 0.754, mean 0.708 -> 0.733, worst row 0.372 -> 0.401 (dev_cube_small), every row the
same or up (dev_wedge_far 0.546 -> 0.616, sim_111 0.673 -> 0.754, dev_steps 0.676 -> 0.722); precision
median 0.966 both, mean 0.941 -> 0.940, the same six rows under 0.95 (sim_111 0.943 -> 0.933, sim_105
0.920 -> 0.916, sim_109 0.973 -> 0.967); the teabox unchanged; tracking (the scoreboard's second table)
without a false frame, dev_steps -> dev_steps_track 58 -> 60 of 60 tracked. On the last of those runs'
models the rule took 91 segments (2.8 % of the accepted), 90 % of them within 4 mm and 10 degrees of a
true edge (sim_111 8 of 13). Chosen on one run of the suite's models: without the covered test,
completeness median +0.011 but precision median -0.010; a share of 0.8 kept 0.038 of the 0.067
gained; the plane within 1 or 3 degrees, clusters of 5 degrees, 3 members or 3 sigmas moved the
completeness median by at most 0.008 and the precision median by none. With candidates from any
accepted segment, one aspect or not, the same on the simulated and devset rows but the real teabox,
which barely turns, took 91 segments of which 14 on the box or its board (surface precision 0.538 ->
0.414): its one-aspect directions rest on stereo alone; candidates only within 3 to 10 cm of the held
segment instead cost a quarter to two thirds of the gain elsewhere and still lowered the teabox's (0.490
to 0.533).

Measured and not kept (``make suite``, 4 runs a row, 2026-12-07): each frame's unsure segments taking
the directions its own sure ones share (stereo sigma at most ``unsure_deg``; this rule with the frame's
camera), in the extraction: single-frame correct 3D up by 0.005 to 0.02 a row (dev_tprofile 0.496 ->
0.505) and near-object precision by 0.02 to 0.04 (dev_steps 0.821 -> 0.857, dev_tprofile 0.879 ->
0.901), but the accumulated models no better: precision median of the simulated and chessboard rows
0.966 -> 0.962 (sim_104 0.980 -> 0.962), completeness within 0.01 on every row (dev_cube_small 0.455 ->
0.447, the teabox 0.658 -> 0.647). The model's shared directions, seen from more than one aspect,
already do this for the accumulation, and a frame's sure segments rest on one aspect's stereo. Of the
single-frame segments within 4 mm of an edge but more than 10 degrees off its direction (10 to 27 % of
the near-object length on the devset and sim_105), such a rule reaches few: for 16 to 52 % of them no
sure segment of the frame has the edge's direction, for 19 to 48 % that direction lies more than 2
degrees out of the segment's view plane (its 2D line is off).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .geometry import unit_or_zero
from .metric import d_o
from .segments import Segments


@dataclass(frozen=True)
class DominantParams:
    plane_deg: float = 2.0           # a shared direction this near a segment's view plane is a candidate ...
    max_turn_deg: float = 20.0       # ... if this near the segment's own direction
    cluster_deg: float = 3.0         # directions this near each other are one
    share: float = 0.6               # the dominant one holds this share of the candidates' length ...
    min_segments: int = 2            # ... from this many accepted segments
    turn_sigmas: float = 2.0         # the direction turns by at most this many of its sigmas
    covered_m: float = 0.010         # a held segment not where a shared one this near across ...
    covered_deg: float = 10.0        # ... and this near in direction covers the stretch
    min_plane_sine: float = 0.2      # a segment this near its viewing ray (sin) has no plane to hold a direction
    min_sigma_deg: float = 0.5       # a held segment's taken direction's sigma at least this
    observations: bool = True        # the running accumulation's unsure observations too ...
    unsure_deg: float = 2.0          # ... those whose stereo direction sigma exceeds this ...
    observation_sigma_deg: float = 4.0   # ... their taken direction's sigma at least this


def dominant_directions(directions: np.ndarray, view_direction: np.ndarray, sigma_direction: np.ndarray,
                        shared: Segments, p: DominantParams = DominantParams()):
    """The dominant directions of ``shared`` (the accepted segments seen from more than one aspect,
    ``line_model.shared_directions``) that segments of ``directions`` (H, 3) unit take (module docstring).

    Object frame; ``view_direction`` (H, 3) unit, from each segment to the camera (its mean);
    ``sigma_direction`` (H,) rad. Returns (taken (H,) bool, directions (H, 3) unit with the taken
    rows replaced, sign kept, the taken directions' sigma (H,) rad: the members' root-mean-square
    angle to their mean, meaningful where taken). Clusters are formed among the candidates of the
    segments that have any (K of them), dense (K, K): per frame of the running accumulation most
    observations have none, and a KD-tree over every shared direction cost more."""
    taken, out = np.zeros(len(directions), bool), np.array(directions, float)
    rms = np.zeros(len(directions))
    if len(directions) == 0 or len(shared) < p.min_segments:
        return taken, out, rms
    cross = np.cross(view_direction, out)
    sine = np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(sine, 1e-12)[:, None]                     # (H, 3) the view planes
    candidate = (np.abs(normal @ shared.directions.T) <= np.sin(np.radians(p.plane_deg))) & (
        np.abs(out @ shared.directions.T) >= np.cos(np.radians(p.max_turn_deg))) & (
        sine >= p.min_plane_sine)[:, None]                                 # (H, A)
    rows = np.flatnonzero(candidate.any(axis=1))
    if len(rows) == 0:
        return taken, out, rms
    cols = np.flatnonzero(candidate[rows].any(axis=0))
    candidate, u_a, length = candidate[np.ix_(rows, cols)], shared.directions[cols], shared.lengths[cols]
    u_h, normal = out[rows], normal[rows]
    near = np.abs(u_a @ u_a.T) >= np.cos(np.radians(p.cluster_deg))      # (K, K), symmetric
    weight = candidate * length
    support = np.where(candidate, weight @ near, -1.0)
    best = np.argmax(support, axis=1)
    members = candidate & near[best]
    ok = (support[np.arange(len(rows)), best] >= p.share * weight.sum(axis=1)) & (
        members.sum(axis=1) >= p.min_segments)
    mean = unit_or_zero((members * length * np.where(u_h @ u_a.T >= 0, 1.0, -1.0)) @ u_a)
    mean = unit_or_zero(mean - np.sum(mean * normal, axis=1, keepdims=True) * normal)     # into the plane
    ok &= d_o(mean, u_h) <= p.turn_sigmas * sigma_direction[rows]
    spread = np.arccos(np.clip(np.abs(mean @ u_a.T), 0.0, 1.0))            # (R, K)
    weight = members * length
    rms[rows] = np.sqrt(np.sum(weight * spread ** 2, axis=1) / np.maximum(np.sum(weight, axis=1), 1e-12))
    k = rows[ok]
    taken[k] = True
    out[k] = mean[ok] * np.where(np.sum(mean[ok] * u_h[ok], axis=1) >= 0, 1.0, -1.0)[:, None]   # sign kept
    return taken, out, rms


def covered(centers: np.ndarray, lengths: np.ndarray, directions: np.ndarray, shared: Segments,
            p: DominantParams) -> np.ndarray:
    """(H,) bool: a segment of ``shared`` overlaps each segment (``centers`` (H, 3) m, object frame,
    ``lengths`` (H,) m) along its line, lies within ``covered_m`` across it and within ``covered_deg``
    of the direction (H, 3) it would take."""
    rel = centers[:, None, :] - shared.centers[None, :, :]                # (H, A, 3)
    along = np.einsum("haj,aj->ha", rel, shared.directions)
    across = np.linalg.norm(rel - along[:, :, None] * shared.directions[None], axis=2)
    overlap = np.abs(along) <= (shared.lengths[None, :] + lengths[:, None]) / 2
    parallel = np.abs(directions @ shared.directions.T) >= np.cos(np.radians(p.covered_deg))
    return np.any((across <= p.covered_m) & overlap & parallel, axis=1)


def observations_directed(observed: Segments, ray: np.ndarray, shared: Segments, p: DominantParams) -> Segments:
    """``observed`` (object frame, with ``sigma_direction_rad``) with the observations less sure than
    ``unsure_deg`` given the dominant direction their view plane holds (``dominant_directions``; ``ray``
    (N, 3) unit, from each observation to the camera) and that direction's sigma, at least
    ``observation_sigma_deg``; the rest as they are."""
    sigma = observed.extra["sigma_direction_rad"]
    unsure = np.flatnonzero(sigma > np.radians(p.unsure_deg))
    taken, directions, rms = dominant_directions(observed.directions[unsure], ray[unsure], sigma[unsure], shared, p)
    if not taken.any():
        return observed
    k = unsure[taken]
    new_directions, new_sigma = observed.directions.copy(), sigma.copy()
    new_directions[k] = directions[taken]
    new_sigma[k] = np.maximum(rms[taken], np.radians(p.observation_sigma_deg))
    return replace(observed, directions=new_directions, extra={**observed.extra, "sigma_direction_rad": new_sigma})
