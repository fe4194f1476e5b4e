"""2D local segments against rendered edges of exactly known position and orientation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from accumcli.lines2d import DETECTORS, LineParams, detect_hough, detect_lsd

DETECTOR_NAMES = sorted(DETECTORS)

from .scenes import INTRINSICS, render_pair, rotated_square


def _line_of(corners, i, j):
    """Image line (point, unit direction) through the projections of two 3D corners."""
    uv, _, _ = INTRINSICS.project(corners[[i, j]])
    d = uv[1] - uv[0]
    return uv[0], d / np.linalg.norm(d)


def _segments_on(segments, point, direction, max_distance=1.0):
    normal = np.array([-direction[1], direction[0]])
    distance = np.abs((segments.centers - point) @ normal)
    along = (segments.centers - point) @ direction
    return distance <= max_distance, distance, along


@pytest.mark.parametrize("detector", [DETECTORS[name] for name in DETECTOR_NAMES])
@pytest.mark.parametrize("angle", [7.0, 37.0, 61.0])
def test_straight_edge_found_precisely(detector, angle):
    square, corners = rotated_square((0.0, 0.0), 0.06, angle, 0.5)
    frame = render_pair([square], seed=int(angle))
    segments = detector(frame.left, LineParams())
    errors_deg, offsets = [], []
    for i in range(4):
        point, direction = _line_of(corners, i, (i + 1) % 4)
        on, distance, along = _segments_on(segments, point, direction)
        length = np.linalg.norm(INTRINSICS.project(corners[[i, (i + 1) % 4]])[0][1] - point)
        inner = on & (along > 10) & (along < length - 10)  # away from the corners
        assert inner.sum() >= 3, f"edge {i}: only {inner.sum()} segments"
        cos = np.abs(segments.directions[inner] @ direction)
        errors_deg.append(np.degrees(np.arccos(np.clip(cos, 0, 1))))
        offsets.append(distance[inner])
    errors_deg, offsets = np.concatenate(errors_deg), np.concatenate(offsets)
    print(f"{detector.__name__} {angle} deg: orientation error median {np.median(errors_deg):.3f}, "
          f"95% {np.percentile(errors_deg, 95):.3f}, max {errors_deg.max():.3f} deg; "
          f"position error max {offsets.max():.3f} px")
    # every local segment is a separate 15 px measurement with image noise: its 95th percentile must
    # stay under half a degree (the median is several times smaller)
    assert np.percentile(errors_deg, 95) < 0.5
    assert np.median(errors_deg) < 0.25
    assert offsets.max() < 0.3


def test_short_edge_is_found_by_lsd_and_hough():
    square, corners = rotated_square((0.0, 0.0), 0.012, 20.0, 0.5)   # edges of about 29 px
    frame = render_pair([square], seed=3)
    for detector in (detect_hough, detect_lsd):
        segments = detector(frame.left, LineParams())
        found = 0
        for i in range(4):
            point, direction = _line_of(corners, i, (i + 1) % 4)
            found += _segments_on(segments, point, direction)[0].any()
        assert found == 4, detector.__name__


def test_gradients_are_sobel_of_the_blurred_image_and_canny_on_the_same_integers():
    import cv2

    from accumcli.lines2d import Gradients

    square, _ = rotated_square((0.0, 0.0), 0.03, 25.0, 0.5)
    image = render_pair([square], seed=5).left
    g = Gradients.of(image, LineParams())
    blurred = cv2.GaussianBlur(image, (0, 0), LineParams().blur_sigma)
    dx, dy = cv2.Sobel(blurred, cv2.CV_16S, 1, 0, ksize=3), cv2.Sobel(blurred, cv2.CV_16S, 0, 1, ksize=3)
    assert g.gx.dtype == np.float32 and np.array_equal(g.gx * 8, dx) and np.array_equal(g.gy * 8, dy)
    # extraction's parts are computed on first use only (tracking needs gx, gy alone), then kept
    assert "edges" not in g.__dict__ and "magnitude" not in g.__dict__
    assert np.array_equal(g.edges, cv2.Canny(dx, dy, 12.0, 24.0, L2gradient=True)) and g.edges is g.edges
    assert np.array_equal(g.magnitude, np.hypot(g.gx, g.gy))
    assert g.edges.sum() > 0 and np.all(g.orientation_at(*np.nonzero(g.edges)) < np.pi)


def test_parabola_peak_finds_the_vertex():
    from accumcli.lines2d import parabola_peak

    x = np.array([-1.0, 0.0, 1.0])
    for vertex in (-0.5, -0.2, 0.0, 0.3, 0.5):
        m = 10.0 - 3.0 * (x - vertex) ** 2
        assert abs(parabola_peak(*m) - vertex) < 1e-12
    # no maximum (flat or curving upwards): 0; arrays of any shape
    assert parabola_peak(np.ones((2, 3)), np.ones((2, 3)), np.ones((2, 3))).tolist() == [[0.0] * 3] * 2
    assert parabola_peak(np.array(2.0), np.array(1.0), np.array(2.0)) == 0.0
    # unclipped when the centre is not the largest sample: the vertex lies beyond the samples
    assert abs(parabola_peak(*(10.0 - (x - 1.5) ** 2)) - 1.5) < 1e-12


# --- rendered 2D edges of exact position (supersampled polygons): short, crowded and meeting edges ---

SUPER = 8   # supersampling factor: a coarse pixel is the mean of SUPER x SUPER fine ones


def _render(polygons, shape=(240, 320), background=60.0, blur=0.8, noise=1.5, seed=0):
    """(H, W) uint8 image of filled polygons ((K, 2) corners in coarse px, (u, v), pixel centres at
    integers) with grey values, area-sampled, blurred by ``blur`` px, plus Gaussian noise."""
    import cv2

    h, w = shape
    fine = np.full((h * SUPER, w * SUPER), background, np.float32)
    shift = 4
    for corners, grey in polygons:
        pts = np.round(((np.asarray(corners, float) + 0.5) * SUPER - 0.5) * (1 << shift)).astype(np.int32)
        cv2.fillPoly(fine, [pts], float(grey), lineType=cv2.LINE_8, shift=shift)
    image = cv2.resize(fine, (w, h), interpolation=cv2.INTER_AREA)
    if blur > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur)
    image = image + np.random.default_rng(seed).normal(0.0, noise, image.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _edge_recall(segments, a, b, max_px=1.0, max_deg=5.0):
    """Share of the truth edge a-b (px) covered by segments within ``max_px`` across and
    ``max_deg`` of its direction, the errors of those segments (deg, px), and their count."""
    length = np.linalg.norm(b - a)
    d = (b - a) / length
    n = np.array([-d[1], d[0]])
    if len(segments) == 0:
        return 0.0, np.zeros(0), np.zeros(0), 0
    ends = segments.endpoints()
    across = np.abs((ends - a) @ n).max(axis=1)
    angle = np.degrees(np.arccos(np.clip(np.abs(segments.directions @ d), 0, 1)))
    on = (across <= max_px) & (angle <= max_deg)
    s = np.sort((ends[on] - a) @ d, axis=1)
    grid = np.arange(0.5, length, 0.5)
    covered = np.zeros(len(grid), bool)
    for lo, hi in s:
        covered |= (grid >= lo - 0.5) & (grid <= hi + 0.5)
    offset = np.abs((segments.centers[on] - a) @ n)
    return float(covered.mean()) if len(grid) else 0.0, angle[on], offset, int(on.sum())


def _polygon_edges(corners):
    corners = np.asarray(corners, float)
    return [(corners[i], corners[(i + 1) % len(corners)]) for i in range(len(corners))]


def _rotated_rect(center, size, angle_deg):
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    half = np.array(size) / 2
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    return local @ np.array([[c, s], [-s, c]]) + center


SHORT_RECTS = [((40 + 60 * (i % 5), 40 + 70 * (i // 5)), (side, side * 0.8), 11.0 + 23.0 * i)
               for i, side in enumerate([10, 12, 14, 16, 18, 20, 24, 28, 30, 34])]


def _short_edge_recall(params):
    image = _render([(_rotated_rect(*r), 170.0) for r in SHORT_RECTS], seed=1)
    segments = DETECTORS["chains"](image, params)
    by_length, angles, offsets = {"8-15": [], "15-34": []}, [], []
    for rect in SHORT_RECTS:
        for a, b in _polygon_edges(_rotated_rect(*rect)):
            recall, angle, offset, _ = _edge_recall(segments, a, b)
            by_length["8-15" if np.linalg.norm(b - a) < 15 else "15-34"].append(recall)
            angles.append(angle)
            offsets.append(offset)
    angles, offsets = np.concatenate(angles), np.concatenate(offsets)
    recall = {k: float(np.mean(v)) for k, v in by_length.items()}
    print(f"recall {recall}, orientation error median {np.median(angles):.2f} max {angles.max():.2f} deg, "
          f"position error median {np.median(offsets):.3f} max {offsets.max():.3f} px")
    return recall, angles, offsets


def test_short_edges_are_found_by_chains():
    """Rectangles with edges of 8 to 34 px (contrast 110 grey levels, blur 0.8 px, noise 1.5).
    With chains and pieces of 6 px support allowed, the chain detector covers >= 85 % of the length
    of the edges under 15 px (Hough: 62 % here) and >= 95 % of the longer ones, orientation and
    position errors of median < 0.5 deg and < 0.1 px. By default (straight chains of 10 px, pieces
    of 8 px on them: what measured best on the suite) the edges of 15 px and more are still covered
    to >= 95 %, and the short ones as their length allows (``_recall_by_edge_length``)."""
    recall, angles, offsets = _short_edge_recall(LineParams(chain_min_support_px=6.0, piece_min_support_px=6.0))
    assert recall["8-15"] >= 0.85 and recall["15-34"] >= 0.95
    assert np.median(angles) < 0.5 and np.median(offsets) < 0.1
    recall, angles, offsets = _short_edge_recall(LineParams())
    assert recall["15-34"] >= 0.95
    assert np.median(angles) < 0.5 and np.median(offsets) < 0.1


BLUR_BEFORE = 1.0   # px before the gradients, the default until 2026-12-06 (lines2d's module docstring)


def _recall_by_edge_length(params, low, high):
    """Mean recall of ``SHORT_RECTS``' edges from ``low`` to ``high`` px, the gradients ``BLUR_BEFORE`` px
    blurred, with which the support rules below were set: the corners bend and lose more pixels (with
    the default 0.5 px the edges of 10 to 12.5 px are found whole whatever these rules)."""
    image = _render([(_rotated_rect(*r), 170.0) for r in SHORT_RECTS], seed=1)
    segments = DETECTORS["chains"](image, dataclasses.replace(params, blur_sigma=BLUR_BEFORE))
    edges = [(a, b) for rect in SHORT_RECTS for a, b in _polygon_edges(_rotated_rect(*rect))
             if low <= np.linalg.norm(b - a) < high]
    return float(np.mean([_edge_recall(segments, a, b)[0] for a, b in edges]))


FAINT_RECTS = [((50 + 75 * (i % 4), 45 + 75 * (i // 4)), (40, 30), 7.0 + 21.0 * i) for i in range(12)]


def _faint_edge_recall(params, step, seed):
    """Mean recall of the edges of 40 x 30 px rectangles ``step`` grey levels above their background
    (optics blur 1.0 px, noise 1.0)."""
    image = _render([(_rotated_rect(*r), 60.0 + step) for r in FAINT_RECTS], background=60.0, blur=1.0, noise=1.0,
                    seed=seed)
    segments = DETECTORS["chains"](image, params)
    return float(np.mean([_edge_recall(segments, a, b)[0] for r in FAINT_RECTS for a, b in _polygon_edges(_rotated_rect(*r))]))


@pytest.mark.parametrize("seed", [1, 2])
def test_faint_steps_are_found_with_the_light_blur(seed):
    """Steps of 8 and 10 grey levels under 1 px of optics blur: with the default 0.5 px of blur before
    the gradients their gradient peaks clear Canny's threshold and most of their length is found
    (about 0.6 and 0.8 here); blurred by 1.0 px (the default until 2026-12-06) they peak under it
    (about 0 and 0.3). Strong steps (18) are found either way."""
    light, heavy = LineParams(), LineParams(blur_sigma=1.0)
    assert _faint_edge_recall(light, 8, seed) >= 0.4 >= _faint_edge_recall(heavy, 8, seed) + 0.3
    assert _faint_edge_recall(light, 10, seed) >= 0.7 and _faint_edge_recall(heavy, 10, seed) <= 0.5
    assert min(_faint_edge_recall(light, 18, seed), _faint_edge_recall(heavy, 18, seed)) >= 0.85


def test_pieces_shorter_than_their_chain_minimum_are_kept():
    """An edge of 11 to 15 px is a straight chain of at least 10 px whose pieces span 8 px or more:
    found by default (>= 85 % of its length), where pieces of 10 px (between corners too) lose the
    edges of 11 to 12.5 px (half or less)."""
    assert _recall_by_edge_length(LineParams(), 10.5, 15.0) >= 0.85
    assert _recall_by_edge_length(LineParams(piece_min_support_px=10.0, corner_piece_min_support_px=10.0),
                                  10.5, 12.5) <= 0.5


def test_an_edge_between_two_corners_needs_less_support():
    """The rectangles' edges of 8 to 10 px end at corners on both sides, where Canny loses a pixel
    or two: their runs span 7 px, which gives a piece between two corners
    (``corner_piece_min_support_px``), covering half of those edges here, where runs must span the
    8 px of a free end (``piece_min_support_px``) and none is found. The edges of 10 px are found
    whole by default, half with 8 px between corners too."""
    assert _recall_by_edge_length(LineParams(), 0.0, 9.8) >= 0.4
    assert _recall_by_edge_length(LineParams(corner_piece_min_support_px=8.0), 0.0, 9.8) == 0.0
    assert _recall_by_edge_length(LineParams(), 9.8, 10.5) >= 0.9
    assert _recall_by_edge_length(LineParams(corner_piece_min_support_px=8.0), 9.8, 10.5) <= 0.6


def _line_angle_errors(params, seed):
    """Per rectangle edge of 12 to 34 px (``SHORT_RECTS``, noise 1.5, blur 0.8; the gradients
    ``BLUR_BEFORE`` px blurred, with which the taper was set: it bends the corners' pixels most): the
    mean angle error (deg) of the line directions of the chain pieces on it (with the default 0.5 px
    the taper gains less, 0.34 -> 0.28 deg on seed 1)."""
    image = _render([(_rotated_rect(*r), 170.0) for r in SHORT_RECTS], seed=seed)
    segments = DETECTORS["chains"](image, dataclasses.replace(params, blur_sigma=BLUR_BEFORE))
    errors = []
    for a, b in (e for rect in SHORT_RECTS for e in _polygon_edges(_rotated_rect(*rect))):
        length = np.linalg.norm(b - a)
        d, n = (b - a) / length, np.array([-(b - a)[1], (b - a)[0]]) / length
        along = (segments.centers - a) @ d
        on = (np.abs((segments.centers - a) @ n) < 1.0) & (np.abs(segments.directions @ d) > np.cos(np.radians(5))) \
            & (along > 0) & (along < length)
        if length >= 12 and on.any():
            errors.append(np.degrees(np.arccos(np.clip(np.abs(segments.line_direction[on] @ d), 0, 1))).mean())
    return np.array(errors)


def test_chain_ends_weigh_less_in_a_short_lines_direction():
    """A short edge's pixels near its corners, bent by the blur, turn its line: with their weight
    tapered (``chain_end_taper_px``, the default) the lines of the rectangles' edges of 12 to 34 px
    are at most 0.8 times as far off in angle as with every pixel weighed by its magnitude (about
    0.65 times on these seeds), and under 0.3 deg on the mean."""
    for seed in (1, 2, 3):
        plain = _line_angle_errors(LineParams(chain_end_taper_px=0.0), seed)
        tapered = _line_angle_errors(LineParams(), seed)
        print(f"seed {seed}: {len(plain)} edges, mean line angle error {plain.mean():.3f} -> {tapered.mean():.3f} deg")
        assert len(tapered) == len(plain) >= 30
        assert tapered.mean() <= 0.8 * plain.mean() and tapered.mean() < 0.3


@pytest.mark.parametrize("name", ["chains", "hough"])
def test_parallel_edges_three_px_apart_are_both_found(name):
    """A bright stripe 3 px wide at 28 degrees: both of its edges (opposite polarity) are found,
    each on its own line, with orientation error under 0.5 deg. Position: the gradient maximum of
    a 3 px bar under the total blur here (about 1.3 px) lies 0.4 px outside each true edge, away
    from the other one (the second edge's gradient lowers the magnitude on the near side), so the
    pieces are asserted within 0.6 px of the edge and on its outer side."""
    d = np.array([np.cos(np.radians(28)), np.sin(np.radians(28))])
    n = np.array([-d[1], d[0]])
    a0, b0 = np.array([80.0, 60.0]), np.array([80.0, 60.0]) + 140 * d
    stripe = np.array([a0, b0, b0 + 3 * n, a0 + 3 * n])
    image = _render([(stripe, 190.0)], seed=2)
    segments = DETECTORS[name](image, LineParams())
    polarity = []
    for a, b, outward in ((a0, b0, -1.0), (a0 + 3 * n, b0 + 3 * n, 1.0)):
        recall, angle, offset, count = _edge_recall(segments, a, b)
        on = np.abs((segments.centers - a) @ n) < 1.0
        signed = ((segments.centers[on] - a) @ n) * outward
        print(f"{name}: recall {recall:.2f}, orientation error max {angle.max():.2f} deg, "
              f"position error {signed.min():.3f} to {signed.max():.3f} px outwards")
        assert recall >= 0.9
        assert np.percentile(angle, 90) < 0.5 and np.all((signed > 0) & (signed < 0.6))
        polarity.append(set(segments.polarity[on].tolist()))
    assert polarity[0].isdisjoint(polarity[1]) and len(polarity[0]) == len(polarity[1]) == 1


def test_pieces_reach_the_corner_and_do_not_bend_there():
    """An L-shaped polygon (a reflex corner) and a T junction of three grey levels: the pieces on
    each edge that ends at the corner or junction reach to within 3 px of it and at most 2 px
    past it, and the piece nearest to it is as straight as the edge (orientation error < 1 deg);
    the edge through the T junction is covered across it. (Hough's piece nearest the T junction
    is 1.6 deg off: its votes mix the two edges.)"""
    name = "chains"
    ell = np.array([[60, 50], [200, 50], [200, 90], [110, 90], [110, 190], [60, 190]], float)
    tee_right_top = np.array([[240, 40], [310, 40], [310, 120], [240, 120]], float)
    tee_right_bottom = np.array([[240, 120], [310, 120], [310, 200], [240, 200]], float)
    image = _render([(ell, 180.0), (tee_right_top, 120.0), (tee_right_bottom, 200.0)], seed=3)
    segments = DETECTORS[name](image, LineParams())
    ends = segments.endpoints()
    cases = [(np.array([200.0, 90.0]), np.array([110.0, 90.0])), (np.array([110.0, 190.0]), np.array([110.0, 90.0])),
             (np.array([300.0, 120.0]), np.array([240.0, 120.0]))]
    for a, b in cases:
        length = np.linalg.norm(b - a)
        d = (b - a) / length
        recall, angle, offset, count = _edge_recall(segments, a, b)
        on = (np.abs((ends - a) @ np.array([-d[1], d[0]])).max(axis=1) <= 1.0) & \
            (np.abs(segments.directions @ d) > np.cos(np.radians(5)))
        reach = ((ends[on] - a) @ d).max()
        nearest = np.argmax(((segments.centers[on] - a) @ d))
        print(f"{name}: recall {recall:.2f}, reach to {length - reach:.2f} px of the corner, "
              f"nearest piece off by {angle[nearest]:.2f} deg")
        assert recall >= 0.9
        assert length - 3.0 <= reach <= length + 2.0
        assert angle[nearest] < 1.0
    # the edge through the junction (the grey levels beside it change there, its polarity does not)
    assert _edge_recall(segments, np.array([240.0, 45.0]), np.array([240.0, 195.0]))[0] >= 0.9


def test_chains_across_a_crossing_are_one_line_with_consistent_positions():
    """A 2x2 checkerboard at 17 degrees: each of its two edges through the X crossing changes
    polarity there, so it gives two chains, but one line: the pieces on both halves share a
    line_id, their line_direction lies within 0.3 deg of the truth, and t is the position along
    it (t differences equal the centres' distances along line_direction)."""
    angle = 17.0
    c, s_ = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    u, v = np.array([c, s_]), np.array([-s_, c])
    centre, half = np.array([160.0, 120.0]), 50.0
    quads = []
    for i, j, grey in ((0, 0, 190.0), (1, 1, 190.0), (0, 1, 70.0), (1, 0, 70.0)):
        lo = centre + (i - 1) * half * u + (j - 1) * half * v
        quads.append((np.array([lo, lo + half * u, lo + half * u + half * v, lo + half * v]), grey))
    image = _render(quads, background=130.0, seed=4)
    segments = DETECTORS["chains"](image, LineParams())
    for d in (u, v):
        n = np.array([-d[1], d[0]])
        rel = segments.centers - centre
        on = (np.abs(rel @ n) < 1.0) & (np.abs(segments.directions @ d) > np.cos(np.radians(3)))
        along = rel[on] @ d
        assert (along < -10).sum() >= 2 and (along > 10).sum() >= 2   # pieces on both halves
        polarity_flips = set(segments.polarity[on][along < -10]) != set(segments.polarity[on][along > 10])
        assert polarity_flips
        assert len(set(segments.line_id[on].tolist())) == 1
        line_dir = segments.line_direction[on]
        assert np.degrees(np.arccos(np.clip(np.abs(line_dir @ d).min(), 0, 1))) < 0.3
        spacing = (segments.centers[on] - segments.centers[on][0]) @ line_dir[0]
        assert np.allclose(segments.t[on] - segments.t[on][0], spacing, atol=1e-6)
        assert np.abs(spacing - np.sign(line_dir[0] @ d) * (along - along[0])).max() < 0.05 * np.ptp(along)


def test_group_range_is_the_min_and_max_per_group():
    from accumcli.grouping import group_range

    groups = np.array([2, 0, 2, 2, 0])
    lo, hi = group_range(groups, 4, np.array([5.0, -1.0, 3.0, 9.0, 4.0]))
    assert lo.tolist() == [-1.0, np.inf, 3.0, np.inf] and hi.tolist() == [4.0, -np.inf, 9.0, -np.inf]


def test_pair_kernels_grow_runs_to_their_corner_and_join_collinear_chains_only():
    from accumcli.pair_kernel import collinear_links, junction_growth

    sin20 = np.sin(np.radians(20))

    def grow_of(degrees, line=(0, 1), reach=14.0, radius=7.0, nan_end=None):
        """Growth of a run along x ending at x = 7 and one at ``degrees`` to it ending 6 px before
        their lines' crossing at (10, 10)."""
        a = np.radians(degrees)
        directions = np.array([[1.0, 0.0], [np.cos(a), np.sin(a)]])
        centers = np.array([[0.0, 10.0], [10.0, 10.0]]) - np.array([[0.0, 0.0], 11.0 * directions[1]])
        t_lo, t_hi = np.array([-5.0, -5.0]), np.array([7.0, 5.0])
        ends = np.concatenate([centers + t_lo[:, None] * directions, centers + t_hi[:, None] * directions])
        if nan_end is not None:
            ends[nan_end] = np.nan
        return junction_growth(ends, np.concatenate([-directions, directions]), centers, directions,
                               np.array(line), np.ones(2, bool), reach, radius, sin20, 20.0)

    assert np.allclose(grow_of(90.0), [0.0, 0.0, 3.0, 6.0])
    assert np.allclose(grow_of(30.0), [0.0, 0.0, 3.0, 6.0])         # another direction bin
    # 19 degrees (a neighbouring bin: the sine test rejects it), one line, a corner beyond the radius
    # or the ends out of reach, a non-finite end: no growth
    for rejected in (grow_of(19.0), grow_of(90.0, line=(0, 0)), grow_of(90.0, radius=3.0),
                     grow_of(90.0, reach=2.0), grow_of(90.0, nan_end=3)):
        assert not rejected.any()

    def links_of(a_deg, b_deg, offset=0.0):
        """Links between a chain 20 px long along ``a_deg`` ending at the origin and one along
        ``b_deg`` starting 6 px further, ``offset`` px beside the first one's line."""
        d = np.radians([a_deg, b_deg])
        direction = np.column_stack([np.cos(d), np.sin(d)])
        center = np.array([-10.0 * direction[0], 6.0 * direction[0] + [0.0, offset] + 10.0 * direction[1]])
        normal = np.column_stack([-direction[:, 1], direction[:, 0]])
        ends = np.concatenate([center - 10 * direction, center + 10 * direction])
        return np.sort(collinear_links(ends, center, direction, normal, 14.0, 2.0, np.cos(np.radians(2.0)), 1.0))

    # one pair of ends within reach (0's high end, 1's low end): one link, also across the half turn
    assert links_of(0.0, 0.0).tolist() == [[0, 1]]
    assert links_of(1.0, 2.5).tolist() == [[0, 1]]              # 1.5 degrees apart, neighbouring bins
    assert links_of(179.5, 180.5).tolist() == [[0, 1]]          # 179.5 and 0.5 modulo 180: bins at both ends
    assert len(links_of(0.5, 3.0)) == 0                         # 2.5 degrees: the cosine test rejects it
    assert len(links_of(0.0, 0.0, offset=2.0)) == 0             # 2 px beside the line


def test_pair_kernels_agree_with_a_kd_tree_and_numpy_on_random_ends():
    """The kernels against the KD-tree and numpy version they replaced (same bits, same links)."""
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse import csr_matrix
    from scipy.spatial import cKDTree
    from accumcli.pair_kernel import collinear_links, junction_growth

    rng = np.random.default_rng(3)
    for trial in range(40):
        n = int(rng.integers(2, 1500))
        centers = rng.uniform(0, rng.choice([60, 640]), (n, 2))
        angle = rng.integers(0, 360, n) * np.pi / 180 if trial % 2 else rng.uniform(0, 2 * np.pi, n)
        directions = np.column_stack([np.cos(angle), np.sin(angle)])
        t_lo, t_hi = -rng.uniform(0, 20, n), rng.uniform(0, 20, n)
        line = rng.integers(0, max(1, n // 2), n)
        ends = np.concatenate([centers + t_lo[:, None] * directions, centers + t_hi[:, None] * directions])
        outward = np.concatenate([-directions, directions])
        pairs = cKDTree(ends).query_pairs(14.0, output_type="ndarray")
        p, q = pairs[:, 0], pairs[:, 1]
        rp, rq = p % n, q % n
        d1, d2 = directions[rp], directions[rq]
        cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        ok = (line[rp] != line[rq]) & (np.abs(cross) > np.sin(np.radians(20)))
        p, q, rp, rq, d1, d2, cross = p[ok], q[ok], rp[ok], rq[ok], d1[ok], d2[ok], cross[ok]
        diff = centers[rq] - centers[rp]
        meet = centers[rp] + ((diff[:, 0] * d2[:, 1] - diff[:, 1] * d2[:, 0]) / cross)[:, None] * d1
        grow_p, grow_q = (np.sum((meet - ends[e]) * outward[e], axis=1) for e in (p, q))
        ok = (grow_p >= -1.0) & (grow_p <= 7.0) & (grow_q >= -1.0) & (grow_q <= 7.0)
        expected = np.zeros(2 * n)
        np.maximum.at(expected, np.concatenate([p[ok], q[ok]]), np.concatenate([grow_p[ok], grow_q[ok]]))
        every = np.ones(n, bool)
        grown = junction_growth(ends, outward, centers, directions, line, every, 14.0, 7.0, np.sin(np.radians(20)), 20.0)
        assert np.array_equal(grown, expected), trial
        # asked for some runs only: theirs the same, the others' at most theirs
        needed = rng.random(n) < 0.3
        some = junction_growth(ends, outward, centers, directions, line, needed, 14.0, 7.0, np.sin(np.radians(20)), 20.0)
        both = np.concatenate([needed, needed])
        assert np.array_equal(some[both], expected[both]) and (some[~both] <= expected[~both]).all(), trial

        # near-collinear chains: the same components
        angle = np.where(rng.random(n) < 0.5, 0.0, np.pi / 2) + rng.normal(0, 0.02, n)
        direction = np.column_stack([np.cos(angle), np.sin(angle)])
        center = np.round(rng.uniform(0, 640, (n, 2)) / 3) * 3
        normal = np.column_stack([-direction[:, 1], direction[:, 0]])
        ends = np.concatenate([center - 5 * direction, center + 5 * direction])
        pairs = cKDTree(ends).query_pairs(14.0, output_type="ndarray")
        i, j = pairs[:, 0] % n, pairs[:, 1] % n
        ok = (i != j) & (np.abs(np.sum(direction[i] * direction[j], axis=1)) >= np.cos(np.radians(2.0)))
        ok &= np.abs(np.sum((ends[pairs[:, 1]] - center[i]) * normal[i], axis=1)) <= 1.0
        ok &= np.abs(np.sum((ends[pairs[:, 0]] - center[j]) * normal[j], axis=1)) <= 1.0
        links = collinear_links(ends, center, direction, normal, 14.0, 2.0, np.cos(np.radians(2.0)), 1.0)
        assert sorted(map(tuple, np.sort(links, axis=1).tolist())) == sorted(
            map(tuple, np.sort(np.column_stack([i[ok], j[ok]]), axis=1).tolist())), trial
        components = [connected_components(csr_matrix((np.ones(len(a)), (a[:, 0], a[:, 1])), shape=(n, n)),
                                           directed=False)[1] for a in (links, np.column_stack([i[ok], j[ok]]))]
        assert np.array_equal(*components)


def test_pair_kernels_end_on_degenerate_parameters():
    from accumcli.pair_kernel import collinear_links, junction_growth

    c = np.array([[0.0, 10.0], [10.0, 0.0]])
    d = np.array([[1.0, 0.0], [0.0, 1.0]])
    ends, normal = np.concatenate([c - 5 * d, c + 7 * d]), np.column_stack([-d[:, 1], d[:, 0]])
    assert len(collinear_links(ends, c, d, normal, 14.0, 0.001, np.cos(np.radians(0.001)), 1.0)) == 0
    assert len(collinear_links(ends, c, d, normal, 14.0, 0.0, 1.0, 1.0)) == 0
    assert len(collinear_links(ends, c, d, normal, 0.0, 2.0, np.cos(np.radians(2.0)), 1.0)) == 0
    assert not junction_growth(ends, np.concatenate([-d, d]), c, d, np.array([0, 1]), np.ones(2, bool), 0.0, 0.0, 0.34,
                               20.0).any()


def test_neighbour_links_join_8_neighbours_whose_gradients_agree_each_pair_once():
    from accumcli.chain_kernel import neighbour_links

    # (row, column): a run along row 2, its right end at the image border, one pixel below-left of
    # the run's start, one with the opposite gradient, one far away
    pixel = np.array([[2, 7], [2, 8], [2, 9], [3, 6], [1, 8], [5, 0]], np.int64)
    g = np.array([[0.0, 9.0], [0.0, 9.0], [0.0, 9.0], [2.0, 9.0], [0.0, -9.0], [0.0, 9.0]])
    links = neighbour_links(pixel, g, np.hypot(g[:, 0], g[:, 1]), 10, 10, np.cos(np.radians(20.0)))
    # right neighbours first (0-1, 1-2), then down-left (0-3); 4 (opposite polarity) and 5 (alone) join nothing
    assert links.tolist() == [[0, 1], [1, 2], [0, 3]]


def test_line_order_is_numpys_lexsort_with_its_ties():
    from accumcli.chain_kernel import line_order

    rng = np.random.default_rng(5)
    for n, lines in ((0, 1), (1, 1), (7, 1), (3000, 150), (3000, 5)):   # groups of ~10 and ~300 (merge sort)
        labels = rng.integers(0, lines, n)
        polarity = rng.choice([-1, 1], n)
        t = np.round(rng.normal(0, 30, n))               # whole numbers: many ties within a line
        assert np.array_equal(line_order(labels, polarity, t), np.lexsort((t, polarity, labels)))


def test_refine_on_gradient_moves_a_segment_onto_a_slanted_step_edge():
    from scipy.special import erf

    from accumcli.lines2d import Gradients, Segments2D, refine_on_gradient

    angle = np.radians(30.0)                                     # the edge's direction
    direction, normal = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    point = np.array([80.3, 60.7])
    v, u = np.mgrid[0:120, 0:160].astype(float)
    across = (u - point[0]) * normal[0] + (v - point[1]) * normal[1]
    image = np.clip(np.round(60 + 50 * (1 + erf(across / np.sqrt(2)))), 0, 255).astype(np.uint8)
    grad = Gradients.of(image)
    turned = np.radians(31.0)                                   # 0.6 px across and 1 deg off
    start = Segments2D(centers=np.array([point + 0.6 * normal]), directions=np.array([[np.cos(turned), np.sin(turned)]]),
                       lengths=np.array([20.0]), polarity=np.array([1], np.int8), contrast=np.array([20.0]),
                       line_id=np.array([0]), t=np.array([0.0]), line_direction=np.array([direction]))
    refined = refine_on_gradient(start, grad.magnitude)
    assert abs((refined.centers[0] - point) @ normal) < 0.1      # on the edge within 0.1 px
    assert np.degrees(np.arccos(min(1.0, abs(refined.directions[0] @ direction)))) < 0.3
    # a cut that would move it more than 1 px keeps the segment where it was
    far = Segments2D(**{**start.__dict__, "centers": np.array([point + 1.6 * normal])})
    assert np.array_equal(refine_on_gradient(far, grad.magnitude).centers, far.centers)
