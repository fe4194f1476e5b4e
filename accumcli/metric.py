"""The paper's distance between local 3D line segments (section 2.2.2).

For l = (p, u) and l' = (p', u'):

- ``d_o(l, l') = arccos(|u . u'|)``: the angle between the directions; lines
  are undirected, hence the absolute value (the paper writes u . u').
- ``f_p(l, l')``: the position of p' in the frame of l (origin p, x axis u),
  with the along-axis coordinate x' shrunk by ``1 / (1 + l / 2)``:
  ``f_p = sqrt((x' / (1 + l/2))^2 + y'^2 + z'^2)``. The paper leaves l's unit
  open. Here every length is measured in units of the position threshold
  ``s_p``; then ``f_p <= s_p`` allows a shift along u of up to
  ``s_p + length / 2`` (the paper's "up to half the segment's length", plus
  the ordinary tolerance) and a sideways shift of only ``s_p``.
- ``f_p`` is asymmetric (the ellipse follows the first segment);
  ``d_p = min(f_p(l, l'), f_p(l', l))``.

Two segments correspond when ``d_o <= s_o`` and ``d_p <= s_p``.

Gating by uncertainty (beyond the paper): a fixed 3 mm / 7 degrees is too
tight for a far or short segment (at 0.8 m a quarter pixel of disparity is
3.3 mm of depth) and looser than needed for a precise one. Where both sides
carry standard deviations of position (m) and direction (rad), the thresholds
of a pair are ``s_p' = clip(k sqrt(sigma_a^2 + sigma_b^2), s_p, max_scale s_p)``
and likewise ``s_o'`` up to ``max_scale_direction s_o`` (``k = gate_sigmas``):
the paper's thresholds are the floor (an allowance for calibration and pose
errors that no sigma models), ``k`` standard deviations of the difference the
gate, and the ceiling keeps a wildly unsure piece from absorbing its
neighbours. ``d_o`` and ``d_p`` stay the metric; only the thresholds they are
compared to (and ``f_p``'s shrink, in units of the threshold) scale. The
direction's ceiling is 1 by default, i.e. the paper's 7 degrees: pieces alone
on their stretch claimed a flat 6 degrees then but were off by 7 (median) to 19
(80th percentile) on the devset; a direction gate widened by their sigma let such
pieces confirm each other into accepted segments 10 to 19 degrees off (devset
precision median 0.84 -> 0.79), or, with the accumulator discounting
confirmations in wider gates, cost completeness (0.37 -> 0.29). With their honest
sigmas of now (``stereo``) and acceptance only of segments sure of their direction
(``line_model.to_model``), a ceiling of 1.5 or 2 still cost completeness on
``make suite`` (median 0.589 -> 0.548, 0.504).

The direction gate by covariance (beyond the paper): a stereo direction is not equally unsure in
every sense. The plane through the camera and the segment is as sure as the left image's line (its
normal n, its sigma ``line_model`` computes), while the tilt within that plane (depth along the
segment) is what short pieces get wrong: on ``make suite``, single-frame pieces on an edge but more
than 10 degrees off it are off by a median of 1 degree in the image and the rest in depth. A model
segment's direction is unsure in the same way until views from other aspects pin it: its direction
information (``line_model``'s ``dir_info``) holds that. Where the second side b carries its view
plane (``plane_b``: an observation) and a its direction information (``info_a``, else its sigma in
every sense), the pair's direction difference, in the tangent plane of a's direction, is tested by
its Mahalanobis distance under the sum of the two covariances plus (s_o / k)^2 (the paper's
threshold as the floor, as above): at most k, and the angle at most ``max_angle_scale`` s_o (the
ceiling). The cost's angle term is that distance over k, squared; the widening counts the position
gate only. Measured on ``make suite`` (precision / completeness medians, worst row of each,
the real teabox's surface precision / completeness) with the one-aspect rule of
``line_model.to_model``: 0.957 / 0.581, 0.609 / 0.273, teabox 0.609 / 0.646; against a two-part
test (out of b's plane against s_o, within it against s_o widened by both sigmas up to 2 s_o, a's
sigma the same in every sense): 0.962 / 0.581, 0.575 / 0.248, teabox 0.575 / 0.604, and ``make
motion`` 8 of 12 within 0.02 against 9 (teabox with ``--motion tracked``: 0.608 / 0.697 against
0.611 / 0.704). Without either gate (the paper's 7 degrees, widened by sigmas at most to it):
0.984 / 0.563 with the one-aspect rule. Counting the gate's width in the widening (a solid angle)
lowered the completeness median 0.607 -> 0.533 (two-part test, without the one-aspect rule).
Measured and not kept (accumulation alone on the suite's recordings, 4 runs a row, 2026-12-07,
against docs/suite.md's precision median 0.963 with 3 rows under 0.95, completeness mean 0.691,
worst 0.359): the ceiling ``max_angle_scale`` 4 instead of 2, so that pieces tilted in depth by 15
to 28 degrees confirm the segment of their edge: completeness mean 0.710, worst 0.388, but 7 rows
under 0.95 (sim_104 0.973 -> 0.918, dev_cube_small 0.908 -> 0.860); 3 instead of 2: completeness
median 0.673 -> 0.683, mean 0.703, worst 0.389, but precision median 0.957, 4 rows under 0.95
(sim_111 0.942) and the worst simulated or devset row lower (dev_cube_small 0.874); tracing sim_104's new wrong
segments (13 to 29 degrees off, claiming 1 to 4) found observations whose view plane missed the
true edge by 2 to 7 degrees (single-frame planes of pieces unsure in depth miss by over 3 claimed
sigmas ten times as often as a Gaussian's). With it, neither that ceiling only for model segments
sure to 3 degrees (completeness mean 0.694), nor such pieces' planes taken at twice their sigma
(0.699, 8 rows under 0.95), nor accepting only directions whose planes agree (least over middle
eigenvalue of ``dir_info`` at most 0.01: 0.690, 4 rows; that rule alone is ``accum accumulate
--plane-agreement``, ``line_model.direction_known``) kept the gain without the loss; position
gates widened by each line's direction sigma times the offset along it changed nothing (0.689).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .metric_kernel import pair_costs_at


@dataclass(frozen=True)
class MetricThresholds:
    s_p: float = 0.003              # metres
    s_o_deg: float = 7.0            # degrees
    gate_sigmas: float = 2.5        # k: a pair's thresholds are k standard deviations of its difference ...
    max_scale: float = 2.5          # ... but at least s_p and at most max_scale times it
    max_scale_direction: float = 1.0  # ... and for the angle, at most this many times s_o
    max_angle_scale: float = 2.0      # ... and by covariance, at most this many times s_o (direction gate by covariance)


def d_o(u: np.ndarray, u_other: np.ndarray) -> np.ndarray:
    """Angle (radians) between undirected unit directions, row by row."""
    return np.arccos(np.clip(np.abs(np.sum(u * u_other, axis=-1)), 0.0, 1.0))


def f_p(p, u, length, p_other, s_p: float) -> np.ndarray:
    """The paper's asymmetric elliptical distance of p_other from the segment (p, u, length), metres."""
    rel = p_other - p
    along = np.sum(rel * u, axis=-1)
    across_sq = np.maximum(np.sum(rel * rel, axis=-1) - along ** 2, 0.0)
    shrink = 1.0 + length / (2.0 * s_p)
    return np.sqrt((along / shrink) ** 2 + across_sq)


def d_p(p, u, length, p_other, u_other, length_other, s_p: float) -> np.ndarray:
    """Symmetric position distance ``min(f_p(l, l'), f_p(l', l))``, metres."""
    return np.minimum(f_p(p, u, length, p_other, s_p), f_p(p_other, u_other, length_other, p, s_p))


def pair_thresholds(thresholds: MetricThresholds, sigma_a, sigma_b, floor: float, max_scale: float) -> np.ndarray:
    """Per-pair threshold ``clip(k sqrt(sigma_a^2 + sigma_b^2), floor, max_scale floor)`` (unit of ``floor``)."""
    gate = thresholds.gate_sigmas * np.sqrt(np.square(sigma_a) + np.square(sigma_b))
    return np.clip(gate, floor, max_scale * floor)


def candidate_pairs(centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b,
                    thresholds: MetricThresholds, neighbours: int = 6, sigmas_a=None, sigmas_b=None,
                    widening: bool = False, plane_b=None, info_a=None):
    """The pairs (i in a, j in b) with d_o <= s_o and d_p <= s_p.

    ``sigmas_a`` / ``sigmas_b``: optional (position sigma (N,) m, direction sigma (N,) rad) of each
    side; given both, every pair is gated by its own thresholds (module docstring), else by
    (s_p, s_o). ``plane_b``: optional (view-plane normal (M, 3), unit, a zero row for none; its
    sigma (M,) rad) of b's segments, and ``info_a``: optional (N, 3, 3) direction information of a's
    segments, 1/rad^2 (its part across each direction counts), for the direction gate by covariance
    (module docstring; needs both sigmas).

    A KD-tree on a's centres gives each segment of b its ``neighbours`` nearest
    centres within the distance that ``d_p <= s_p`` allows
    (``hypot(s_p + max length / 2, s_p)``); the exact metric is then evaluated
    on those only. A correspondence beyond the 6th nearest centre is not
    looked for: local segments are a centimetre apart along an edge, so it is
    practically never the right one. Returns (i (K,), j (K,), cost (K,)) with
    ``cost = (d_p / s_p)^2 + (d_o / s_o)^2`` in [0, 2] (the pair's own thresholds where gated);
    with ``widening`` also (K,) ``(s_p' / s_p) (s_o' / s_o)`` >= 1, how much wider than the paper's
    the pair's gate was (1 where not gated).
    """
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)) + ((np.zeros(0),) if widening else ())
    if len(centers_a) == 0 or len(centers_b) == 0:
        return empty
    s_p = thresholds.s_p
    gated = sigmas_a is not None and sigmas_b is not None
    widest = s_p
    if gated:   # the widest gate any pair can have
        widest = float(pair_thresholds(thresholds, np.max(sigmas_a[0]), np.max(sigmas_b[0]), s_p, thresholds.max_scale))
    longest = max(float(lengths_a.max()), float(lengths_b.max()))
    radius = float(np.hypot(widest + longest / 2, widest))
    k = min(neighbours, len(centers_a))
    distance, index = cKDTree(centers_a, balanced_tree=False, compact_nodes=False).query(
        centers_b, k=k, distance_upper_bound=radius)
    found = np.isfinite(np.asarray(distance).reshape(len(centers_b), k))
    j = np.nonzero(found)[0].astype(np.int64)
    i = np.asarray(index).reshape(len(centers_b), k)[found].astype(np.int64)
    if len(i) == 0:
        return empty
    ok, cost, wide = _pair_costs_at(i, j, centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b, thresholds,
                                    sigmas_a, sigmas_b, plane_b, info_a)
    pairs = i[ok], j[ok], cost[ok]
    return pairs + (wide[ok],) if widening else pairs


def pair_costs(centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b, thresholds: MetricThresholds,
               sigmas_a=None, sigmas_b=None, plane_b=None, info_a=None):
    """Row by row (K rows): (ok (K,) bool, cost (K,), widening (K,)) of the pairs (a[k], b[k]), as
    ``candidate_pairs`` defines them (cost inf where not ok)."""
    rows = np.arange(len(centers_a))
    return _pair_costs_at(rows, rows, centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b, thresholds,
                          sigmas_a, sigmas_b, plane_b, info_a)


def _pair_costs_at(i, j, centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b, thresholds: MetricThresholds,
                   sigmas_a=None, sigmas_b=None, plane_b=None, info_a=None):
    """``pair_costs`` of the pairs (a[i[k]], b[j[k]]) (``metric_kernel.pair_costs_at``, which reads the
    rows itself). The direction gate by covariance (module docstring): the Mahalanobis distance of b's
    direction from a's, in the tangent plane of a, under a's covariance (the inverse of ``info_a``
    across a, less its information along a, plus (2 / pi)^2 so that it stays at most about a right
    angle; without ``info_a`` a's sigma in every sense), b's (its sigma within its view plane and the
    plane's sigma across it; its sigma in every sense where it has no plane) and (s_o / k)^2."""
    gated = sigmas_a is not None and sigmas_b is not None
    by_covariance = gated and plane_b is not None
    none, no_rows = np.zeros(1), np.zeros((1, 3))
    contiguous = np.ascontiguousarray
    return pair_costs_at(
        contiguous(i, np.int64), contiguous(j, np.int64), *(contiguous(x, np.float64) for x in (
            centers_a, dirs_a, lengths_a, centers_b, dirs_b, lengths_b)),
        float(thresholds.s_p), float(thresholds.s_o_deg), float(thresholds.gate_sigmas), float(thresholds.max_scale),
        float(thresholds.max_scale_direction), float(thresholds.max_angle_scale),
        *((contiguous(x, np.float64) for x in (*sigmas_a, *sigmas_b)) if gated else (none,) * 4), gated,
        contiguous(plane_b[0], np.float64) if by_covariance else no_rows,
        contiguous(plane_b[1], np.float64) if by_covariance else none, by_covariance,
        contiguous(info_a, np.float64) if by_covariance and info_a is not None else np.zeros((1, 3, 3)),
        by_covariance and info_a is not None)
