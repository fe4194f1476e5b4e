"""2D local segments from linked edge chains (``--detector chains``): fine-scale, junction-aware
line support for short and crowded edges.

The Hough detector (``lines2d``) orients each edge pixel by the structure tensor smoothed over
``tensor_sigma`` px, which a neighbouring edge 2 px away biases by several degrees, and then needs
a line's votes to pile up in a +-3 deg window: short and crowded edges are lost. Here:

1. Edge pixels are Canny's, at sub-pixel position (``lines2d.edge_points``). Each is oriented by
   its own Sobel gradient (on the image blurred by ``blur_sigma``), never by a smoothed tensor.
2. Chains: two 8-neighbouring edge pixels are linked when their gradients agree in direction
   (same polarity, within ``CHAIN_ANGLE_DEG``). Connected components of the links are the chains;
   a corner or a junction (where the orientation jumps) and a polarity flip end a chain.
3. Straight chains: as Douglas-Peucker does, a chain whose farthest point lies more than
   ``CHAIN_MAX_RESIDUAL_PX`` from the chord between its ends is cut there (at its corner, whose
   own pixels are dropped), repeatedly (``CHAIN_SPLITS`` rounds, only the chains cut are looked
   at again; ``straight_chains``).
4. Local pieces (``lines2d.local_segments``): on each straight chain, runs of support spanning
   ``piece_min_support_px`` (``corner_piece_min_support_px`` between two corners) are tiled by
   ``ceil(R / L)`` equal pieces (L = ``segment_length_px``; a run shorter than L is one piece of its
   own length), each on the chain's own line fit (orientation from the whole chain, position at the
   piece's pixels), ends extended to meeting lines' corners (``junction_radius_px``), refined on the
   gradient.
5. Lines: straight chains whose ends lie within ``2 * junction_radius_px`` of each other,
   within ``COLLINEAR_DEG`` in direction and ``COLLINEAR_PX`` across are one line (transitively),
   as a Hough line is: ``line_id``, ``t`` and ``line_direction`` are that line's, so stereo
   matching propagates along it across corners, crossings and polarity flips.

Choices where the task is vague: chains are linked by gradient agreement between neighbours,
not traced pixel by pixel (the links are found vectorised; their components and cuts in a small
compiled kernel, ``chain_kernel``);
straight chains under 10 px are not cut at a bend (``chain_min_support_px``), and runs of support
under 8 px give no piece (a piece reaches ``end_extension_px`` beyond its run). Measured on ``make
suite`` (medians, worst row in brackets), against 10 px for both: completeness 0.576 (0.257) -> 0.609
(0.269), edge length right in two single frames 0.661 -> 0.735, precision 0.980 -> 0.971 (rows under
0.95, the teabox included: 3 -> 4, sim_106 at 0.947), single-frame near-object precision 0.790 ->
0.766; the real teabox's surface precision / completeness 0.609 / 0.646 -> 0.595 / 0.663; with the
plane sigma of short lines (``stereo.triangulate``), without which precision rows under 0.95 were 5
and the teabox 0.572 / 0.660. Tracking with these models (``benchmarks/track_suite.py``): no false
frame, tracked median 0.950 -> 0.933 (dev_steps 60 -> 57 of 60, two of them 'ambiguous'; the teabox
38 -> 37 of 40); the accumulation's pairs per second median 27.7 -> 28.0, worst 12.1 -> 7.9
(sim_108, whose cloudy background gives three times the pieces). Pieces from 6 px: completeness
0.629 (0.266) but precision 0.962 with seven rows under 0.95; chains cut at 6 px too: 0.625 and the
teabox 0.558 / 0.516 (the chains' cut, not the pieces', loses on the real recording).

A run grown to a corner at both ends (``_complete_junctions``: both meet other lines there) gives a
piece from 7 px (``corner_piece_min_support_px``): Canny loses a pixel or two at each corner, so a
whole edge of 9 to 10 px between two corners spans 7, where a free run of 7 px is as likely texture
or noise. On ``make suite`` against 8 px for both: completeness median 0.609 -> 0.624 (worst 0.269 ->
0.271), higher on 15 rows and lower on one (sim_102 0.813 -> 0.806); 2D detected median 0.773 ->
0.793; precision median 0.971 both, rows under 0.95 besides the teabox 3 -> 2 (sim_106 0.947 ->
0.956; sim_111 0.975 -> 0.952 and dev_wedge_far 0.966 -> 0.953 lower); the teabox 0.595 / 0.663 ->
0.609 / 0.665; single-frame near-object precision median 0.766 -> 0.753; the accumulation's pairs
per second median 28.0 -> 24.6 (more pieces). From 6 px between corners: completeness 0.625, four
rows under 0.95 (sim_109 0.948, dev_wedge_far 0.938); from 5 px: 0.628, seven rows, precision median
0.964. With the chains also cut from 5 px the teabox fell to 0.519 (its long critical edge, which
``critical`` triangulates through its ends, lost both frames that gave it).

A line's direction (a chain's, and its collinear line's) weighs the edge pixels within
``chain_end_taper_px`` (2.5) of its chain's ends less, down to a tenth at the end pixel
(``end_tapered_weights``); its position weighs every pixel by its magnitude. Why: on the devset,
edge pixels within 2 px of a truth edge's end lie 0.23 px from it (1.4826 x the median absolute
offset), those 2 to 4 px in 0.12 to 0.13, the others 0.09 to 0.11 (the blur of the corner bends
them); on a line of 15 to 25 px these ends, with the most leverage on its angle, turn it by about
half a degree, and near the rows that tilts the stereo segment by 10 degrees and more. Of dev_steps'
3D segments near a truth edge (every third frame), those more than 10 degrees off it fell from 88 to
72 of 560 (on lines under 15 px from 58 to 41 %). On ``make suite`` (4 runs a row): single-frame
near-object precision higher on 14 rows and lower on none (mean 0.711 -> 0.721; the devset's +0.01
to +0.025), correct 3D median 0.422 -> 0.427; the accumulated precision mean 0.939 both (median
0.964 -> 0.956), completeness mean 0.617 -> 0.621 (median 0.623 -> 0.621, worst 0.268 -> 0.269),
every row within twice its scatter between runs but dev_wedge_far (completeness +0.035), sim_100
(precision -0.023, completeness +0.022) and sim_102 (completeness -0.023). A taper of 4 px measured
the same.
"""

from __future__ import annotations


from typing import NamedTuple

import numpy as np

from .chain_kernel import neighbour_links, straight_chain_labels
from .group_kernel import end_tapered, line_extents, link_components
from .pair_kernel import collinear_links
from .lines2d import (EdgePoints, Gradients, LineParams, Segments2D, StageTimes, _canonical, _weighted_line_fit,
                      detection_start, directed_line_fit, dot2, edge_points, local_segments, refine_on_gradient)

CHAIN_ANGLE_DEG = 20.0        # neighbouring edge pixels link when their gradients differ less than this
CHAIN_MAX_RESIDUAL_PX = 0.6   # a chain with a point farther than this from its chord is cut there
COLLINEAR_DEG = 2.0           # straight chains this close in direction ...
COLLINEAR_PX = 1.0            # ... and offset across, with ends near each other, are one line
CHAIN_SPLITS = 8              # rounds of cutting (a loop needs two to open and cut once)
END_TAPER_FLOOR = 0.1         # the least weight of a chain's end pixel in its direction (``end_tapered_weights``)


def chain_links(points: EdgePoints, shape: tuple[int, int]) -> np.ndarray:
    """(E, 2) index pairs of 8-neighbouring edge points whose gradients agree (same polarity,
    directions within ``CHAIN_ANGLE_DEG``), each pair once. Compiled (``chain_kernel.neighbour_links``):
    the numpy version filled a padded index image and gathered four neighbour arrays, 1.5 ms per
    640x480 image of the 0.1 the loop takes."""
    return neighbour_links(np.ascontiguousarray(points.pixel, np.int64), np.ascontiguousarray(points.g, np.float64),
                           np.ascontiguousarray(points.mag, np.float64), int(shape[0]), int(shape[1]),
                           float(np.cos(np.radians(CHAIN_ANGLE_DEG))))


def straight_chains(points: EdgePoints, shape: tuple[int, int], max_residual_px: float = CHAIN_MAX_RESIDUAL_PX,
                    rounds: int = CHAIN_SPLITS, min_length_px: float = 0.0) -> np.ndarray:
    """(M,) label 0..K-1 of the straight chain of every edge point (-1: none).

    Chains are the connected components of ``chain_links``. Each round, as Douglas-Peucker does:
    the chord joins a chain's first and last point along its (magnitude-weighted) TLS line; where
    the farthest point lies more than ``max_residual_px`` from the chord, the chain is cut across
    its line at that point: its links across the cut are dropped, and that point with its
    8-neighbours in the chain (at a corner, its own pixels bend both arms); a part left in pieces
    becomes several chains. Only the chains cut are looked at again; chains still bent after
    ``rounds`` rounds, or shorter than ``min_length_px`` (too short to give a piece), stay as
    they are. Straight chains are numbered in the round they end in, by their lowest point index.
    Compiled: ``chain_kernel.straight_chain_labels``."""
    links = chain_links(points, shape)
    return straight_chain_labels(np.ascontiguousarray(points.xy, np.float64), np.ascontiguousarray(points.mag, np.float64),
                                 np.ascontiguousarray(points.pixel, np.int64), np.ascontiguousarray(links, np.int64),
                                 float(max_residual_px), int(rounds), float(min_length_px))


class ChainFits(NamedTuple):
    """Every straight chain's magnitude-weighted line, fitted once per image for ``collinear_lines``
    and ``end_tapered_weights``: centre and unit direction (K, 2), each edge point's position t
    (M,) along its chain's line (undefined off the chains) and each chain's extent along it,
    t_lo and t_hi (K,)."""

    center: np.ndarray
    direction: np.ndarray
    t: np.ndarray
    t_lo: np.ndarray
    t_hi: np.ndarray


def chain_fits(points: EdgePoints, chains: np.ndarray) -> ChainFits:
    """The ``ChainFits`` of the straight chains (``chains``: (M,) label 0..K-1 or -1; K >= 1)."""
    on = chains >= 0
    lab = chains[on].astype(np.int64)
    _, center, direction = _weighted_line_fit(lab, int(lab.max()) + 1, points.xy[on], points.mag[on])
    x, y = (np.ascontiguousarray(points.xy[:, k], np.float64) for k in (0, 1))
    return ChainFits(center, direction, *line_extents(np.ascontiguousarray(chains, np.int64), x, y, center, direction))


def collinear_lines(points: EdgePoints, chains: np.ndarray, reach_px: float, max_deg: float = COLLINEAR_DEG,
                    max_offset_px: float = COLLINEAR_PX, fits: ChainFits | None = None) -> np.ndarray:
    """(K,) line 0..L-1 of every straight chain (``chains``: (M,) chain label 0..K-1 of every edge
    point, or -1). Chains whose ends lie within ``reach_px`` of each other, whose directions
    agree within ``max_deg`` and whose ends lie within ``max_offset_px`` of the other chain's
    line are one line (transitively), as a Hough line is: a corner, a crossing or a polarity flip
    interrupts a chain but not the line that stereo matching propagates along. ``fits``: the
    chains' ``chain_fits`` if already computed."""
    if not (chains >= 0).any():
        return np.zeros(0, np.int64)
    center, direction, _, t_lo, t_hi = fits if fits is not None else chain_fits(points, chains)
    ends = np.concatenate([center + t_lo[:, None] * direction, center + t_hi[:, None] * direction])
    normal = np.column_stack([-direction[:, 1], direction[:, 0]])
    links = collinear_links(ends, center, direction, normal, float(reach_px), float(max_deg),
                            float(np.cos(np.radians(max_deg))), float(max_offset_px))
    return link_components(len(center), np.ascontiguousarray(links, np.int64))


def end_tapered_weights(points: EdgePoints, chains: np.ndarray, taper_px: float, fits: ChainFits | None = None
                        ) -> np.ndarray:
    """(M,) the edge points' magnitudes, those within ``taper_px`` of their straight chain's nearer end
    (``chains``: (M,) label or -1) scaled by (d + 0.5) / ``taper_px`` at d px from it (at least
    ``END_TAPER_FLOOR``): the weights that orient a chain's line (module docstring). Compiled
    (``group_kernel.end_tapered``): a dozen whole-array calls took a tenth of the chains' time.
    ``fits``: the chains' ``chain_fits`` if already computed."""
    if taper_px <= 0 or not (chains >= 0).any():
        return points.mag.copy()
    fits = fits if fits is not None else chain_fits(points, chains)
    return end_tapered(np.ascontiguousarray(chains, np.int64), fits.t, fits.t_lo, fits.t_hi,
                       np.ascontiguousarray(points.mag, np.float64), float(taper_px), END_TAPER_FLOOR)


def _on_lines(segments: Segments2D, points: EdgePoints, chains: np.ndarray, line_of_chain: np.ndarray,
              direction_weight: np.ndarray) -> Segments2D:
    """``segments`` (whose line_id is their chain) with line_id, t and line_direction those of the
    chain's collinear line (fitted to all its chains' points, oriented by ``direction_weight``)."""
    if len(segments) == 0:
        return segments
    on = chains >= 0
    line = line_of_chain[chains[on]]
    _, center, direction = directed_line_fit(line, int(line.max()) + 1, points.xy[on], points.mag[on],
                                             direction_weight[on])
    line_id = line_of_chain[segments.line_id]
    direction = _canonical(direction[line_id])
    t = dot2(segments.centers - center[line_id], direction)
    return Segments2D(segments.centers, segments.directions, segments.lengths, segments.polarity,
                      segments.contrast, line_id, t, direction)


def detect_chains(image: np.ndarray, params: LineParams, grad: Gradients | None = None,
                  times: StageTimes | None = None) -> Segments2D:
    """Local segments of an (H, W) uint8 image from straight edge chains (module docstring)."""
    grad, times, t0 = detection_start(image, params, grad, times)
    points = edge_points(grad, with_phi=False)
    chains = straight_chains(points, image.shape, min_length_px=params.chain_min_support_px)
    fits = chain_fits(points, chains) if (chains >= 0).any() else None
    line_of_chain = collinear_lines(points, chains, 2 * params.junction_radius_px, fits=fits)
    direction_weight = end_tapered_weights(points, chains, params.chain_end_taper_px, fits=fits)
    t0 = times.add("lines", t0)  # the line-finding stage (whatever the detector), for comparable breakdowns
    segments = local_segments(points, chains, params, adapt_length=True, line_fit=True,
                              min_support_px=params.piece_min_support_px,
                              corner_min_support_px=params.corner_piece_min_support_px,
                              direction_weight=direction_weight)
    # the chain's fit orients a piece better than its 13 cuts near a corner: refinement may turn it 1 deg
    segments = _on_lines(refine_on_gradient(segments, grad.magnitude, max_turn_deg=1.0), points, chains,
                         line_of_chain, direction_weight)
    times.add("local segments", t0)
    return segments
