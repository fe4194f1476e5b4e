"""Stereo matching and triangulation against rendered scenes with exact geometry."""

from __future__ import annotations

import numpy as np

from accumcli.extract import ExtractParams, extract_frame

from .scenes import render_pair, quad, rotated_square


def test_fronto_parallel_edge_at_half_a_metre_within_a_millimetre():
    # a dark rectangle 0.5 m away; its left and right sides are vertical 3D lines at x = -0.04 and x = 0.05
    rect = quad([[-0.04, -0.06, 0.5], [0.05, -0.06, 0.5], [0.05, 0.06, 0.5], [-0.04, 0.06, 0.5]])
    frame = render_pair([rect], seed=1)
    result = extract_frame(frame, ExtractParams())
    seg = result.segments
    for x_edge in (-0.04, 0.05):
        on = (np.abs(seg.centers[:, 0] - x_edge) < 0.005) & (np.abs(seg.centers[:, 1]) < 0.05)
        assert on.sum() >= 4
        errors = np.hypot(seg.centers[on, 0] - x_edge, seg.centers[on, 2] - 0.5)
        print(f"edge x={x_edge}: {on.sum()} segments, max error {1000 * errors.max():.3f} mm")
        assert errors.max() < 0.001
        assert np.all(np.abs(seg.directions[on, 1]) > np.cos(np.radians(2)))


def _sides_along_rows(segments, corners):
    """Masks of the segments on the square's two near-horizontal sides (within 3 mm), and their sides."""
    sides = [(corners[0], corners[1]), (corners[2], corners[3])]
    masks = []
    for a, b in sides:
        u = (b - a) / np.linalg.norm(b - a)
        masks.append(np.linalg.norm(np.cross(segments.centers - a, u), axis=1) < 0.003)
    return masks, sides


def test_edge_along_the_epipolar_lines_is_rejected_as_critical_without_its_ends():
    from dataclasses import replace

    # a square rotated by 3 degrees: its top and bottom sides run almost along image rows
    square, corners = rotated_square((0.0, 0.0), 0.05, 3.0, 0.5)
    frame = render_pair([square], seed=2)
    params = ExtractParams(stereo=replace(ExtractParams().stereo, critical_by_ends=False))
    result = extract_frame(frame, params)
    assert result.counts["critical"] >= 4 and result.counts["critical_3d"] == 0
    near_horizontal = np.abs(result.segments.directions[:, 1]) < 0.3
    assert not near_horizontal.any()
    # the vertical sides are still triangulated
    assert (np.abs(result.segments.directions[:, 1]) > 0.95).sum() >= 4


def test_edge_along_the_epipolar_lines_is_triangulated_from_its_corners():
    square, corners = rotated_square((0.0, 0.0), 0.05, 3.0, 0.5)
    frame = render_pair([square], seed=2)
    result = extract_frame(frame, ExtractParams())
    seg = result.segments
    assert result.counts["critical_3d"] >= 6
    masks, sides = _sides_along_rows(seg, corners)
    for on, (a, b) in zip(masks, sides):
        u = (b - a) / np.linalg.norm(b - a)
        angle = np.degrees(np.arccos(np.clip(np.abs(seg.directions[on] @ u), 0, 1)))
        error = np.linalg.norm(np.cross(seg.centers[on] - a, u), axis=1)
        print(f"side along the rows: {on.sum()} segments, max error {1000 * error.max():.2f} mm, "
              f"max angle {angle.max():.2f} deg, sigma_depth median {1000 * np.median(seg.extra['sigma_depth_m'][on]):.2f} mm")
        assert on.sum() >= 3
        assert error.max() < 0.0015 and angle.max() < 3.0
    # every near-horizontal 3D segment lies on one of the two sides
    near_horizontal = np.abs(seg.directions[:, 1]) < 0.3
    assert np.all(masks[0][near_horizontal] | masks[1][near_horizontal])


def test_an_edge_without_ends_in_view_stays_unmatched():
    # a dark band wider than the view: its long sides run along the rows and never end in the image
    band = quad([[-3.0, -0.02, 0.5], [3.0, -0.02, 0.5], [3.0, 0.03, 0.5], [-3.0, 0.03, 0.5]])
    result = extract_frame(render_pair([band], seed=3), ExtractParams())
    assert result.counts["critical"] >= 10
    assert result.counts["critical_3d"] == 0


def test_an_edge_behind_an_occluder_does_not_take_the_occluders_depth():
    # a dark band at 1 m, whose long sides run along the rows, interrupted by a bar at 0.8 m: the
    # band's run ends at the bar are where the bar is, not where the band ends (taken as ends,
    # they gave 20 segments tilted from 0.97 m to the bar's 0.82 m)
    band = quad([[-0.12, -0.02, 1.0], [0.12, -0.02, 1.0], [0.12, 0.02, 1.0], [-0.12, 0.02, 1.0]])
    bar = quad([[-0.005, -0.08, 0.8], [0.005, -0.08, 0.8], [0.005, 0.08, 0.8], [-0.005, 0.08, 0.8]], albedo=0.6)
    result = extract_frame(render_pair([band, bar], seed=5), ExtractParams())
    seg = result.segments
    along_rows = np.abs(seg.directions[:, 1]) < 0.3
    print(f"{result.counts['critical_3d']} from their ends; depths of those along the rows: "
          f"{np.round(seg.centers[along_rows, 2], 3)}")
    assert result.counts["critical"] >= 10
    assert np.all(np.abs(seg.centers[along_rows, 2] - 1.0) < 0.02)


def test_slanted_edge_direction_from_global_support():
    # a plane tilted 40 degrees about the vertical axis: a horizontal-ish 3D edge recedes in depth
    c, s = np.cos(np.radians(40)), np.sin(np.radians(40))
    corners = np.array([[-0.05 * c, -0.05, 0.5 - 0.05 * s], [0.05 * c, -0.03, 0.5 + 0.05 * s],
                        [0.05 * c, 0.05, 0.5 + 0.05 * s], [-0.05 * c, 0.05, 0.5 - 0.05 * s]])
    frame = render_pair([quad(corners)], seed=4)
    seg = extract_frame(frame, ExtractParams()).segments
    top = corners[1] - corners[0]
    top /= np.linalg.norm(top)
    on_top = np.abs(np.cross(seg.centers - corners[0], top)).max(axis=1) < 0.003
    assert on_top.sum() >= 4
    angle = np.degrees(np.arccos(np.clip(np.abs(seg.directions[on_top] @ top), 0, 1)))
    print(f"receding edge: {on_top.sum()} segments, direction error median {np.median(angle):.2f} deg")
    assert np.median(angle) < 3.0


def test_a_receding_edge_alone_on_its_line_ends_where_its_left_pieces_end():
    """A piece alone on its stretch (no disparity fit along it) keeps one disparity; its 3D ends are
    where the rays through its left piece's ends meet its 3D line, so a piece receding in depth is as
    long in 3D as the image shows it (at one depth it came out 20 to 40 % short, and the samples
    beyond its ends uncovered)."""
    h, c, s = 0.012, np.cos(np.radians(50)), np.sin(np.radians(50))
    corners = np.array([[-h, -h * c, 0.5 - h * s], [h, -h * c, 0.5 - h * s], [h, h * c, 0.5 + h * s],
                        [-h, h * c, 0.5 + h * s]])          # a small square turned 50 degrees about x
    frame = render_pair([quad(corners)], seed=4)
    result = extract_frame(frame, ExtractParams())
    seg, intr = result.segments, frame.intrinsics
    side = (corners[3] - corners[0]) / np.linalg.norm(corners[3] - corners[0])   # its left side recedes
    on = np.linalg.norm(np.cross(seg.centers - corners[0], side), axis=1) < 0.003
    assert on.sum() >= 1
    half = (seg.lengths[on] / 2)[:, None] * seg.directions[on]
    ends = np.stack([seg.centers[on] - half, seg.centers[on] + half], axis=1).reshape(-1, 3)
    pieces = result.left.endpoints()[result.left_index[on]].reshape(-1, 2)
    projected = intr.project(ends)[0]
    gap = np.min([np.linalg.norm(projected - pieces, axis=1),
                  np.linalg.norm(projected - pieces.reshape(-1, 2, 2)[:, ::-1].reshape(-1, 2), axis=1)], axis=0)
    assert gap.max() < 0.5                                 # px: the 3D ends show where the pieces end
    along = (ends - corners[0]) @ side
    off = np.linalg.norm(np.cross(ends - corners[0], side), axis=1)
    assert off.max() < 0.0015 and along.min() > -0.002 and along.max() < np.linalg.norm(corners[3] - corners[0]) + 0.002


def test_a_right_camera_with_another_gain_and_offset_matches_as_well():
    """Real stereo cameras differ in gain and offset (the teabox's right camera: 0.72 times the
    contrast, 52 grey levels up); matching takes the right patches to the left's grey levels."""
    from dataclasses import replace

    rect = quad([[-0.04, -0.06, 0.5], [0.05, -0.06, 0.5], [0.05, 0.06, 0.5], [-0.04, 0.06, 0.5]])
    frame = render_pair([rect], seed=1)
    brighter = np.clip(0.7 * frame.right.astype(float) + 60, 0, 255).astype(np.uint8)
    same, other = (extract_frame(f, ExtractParams()).segments for f in (frame, replace(frame, right=brighter)))
    assert len(same) >= 8
    assert len(other) >= 0.9 * len(same)
    for seg in (same, other):       # the rectangle's sides at x = -0.04 and 0.05, 0.5 m away
        side = np.minimum(np.abs(seg.centers[:, 0] + 0.04), np.abs(seg.centers[:, 0] - 0.05))
        assert np.all(np.hypot(side, seg.centers[:, 2] - 0.5)[np.abs(seg.directions[:, 1]) > 0.9] < 0.001)


def test_extraction_returns_its_gradients_and_reuses_given_ones():
    from accumcli.lines2d import frame_gradients

    square, _ = rotated_square((0.0, 0.0), 0.04, 20.0, 0.5)
    frame = render_pair([square], seed=6)
    first = extract_frame(frame, ExtractParams())
    left, right = first.gradients
    assert left.gx.shape == frame.left.shape and not np.array_equal(left.gx, right.gx)
    given = frame_gradients(frame)
    again = extract_frame(frame, ExtractParams(), gradients=given)
    assert again.gradients[0] is given[0] and again.gradients[1] is given[1]
    assert np.array_equal(again.segments.centers, first.segments.centers) and len(first.segments) >= 8
    flat = tuple(type(g)(np.zeros_like(g.gx), np.zeros_like(g.gy), g.blur_sigma, 3.0, 1.5) for g in given)
    assert len(extract_frame(frame, ExtractParams(), gradients=flat).segments) == 0   # they are used


def test_given_gradients_are_reused_only_as_far_as_the_parameters_match():
    from accumcli.lines2d import Gradients, LineParams

    square, _ = rotated_square((0.0, 0.0), 0.04, 20.0, 0.5)
    image = render_pair([square], seed=6).left
    given = Gradients.of(image, LineParams())
    assert Gradients.of(image, LineParams(), reuse=given) is given
    other_threshold = Gradients.of(image, LineParams(gradient_threshold=1.0), reuse=given)
    assert other_threshold.gx is given.gx and other_threshold.gradient_threshold == 1.0
    assert other_threshold.edges.sum() > given.edges.sum()                 # its own Canny: the noise too
    other_blur = Gradients.of(image, LineParams(blur_sigma=2.0), reuse=given)
    assert other_blur.gx is not given.gx and np.abs(other_blur.gx).max() < np.abs(given.gx).max()


def test_edge_ten_degrees_off_the_rows_is_matched_along_them():
    """The critical angle (8 degrees, ``StereoParams``) lets an edge 10 degrees off the epipolar
    lines be matched along the rows, without its ends: its disparity is defined well enough there
    (within 2 mm and 3 degrees; at 12 degrees the sides are critical and not found)."""
    from dataclasses import replace

    square, corners = rotated_square((0.0, 0.0), 0.05, 10.0, 0.5)
    frame = render_pair([square], seed=2)
    params = ExtractParams(stereo=replace(ExtractParams().stereo, critical_by_ends=False))
    seg = extract_frame(frame, params).segments
    masks, sides = _sides_along_rows(seg, corners)
    for on, (a, b) in zip(masks, sides):
        u = (b - a) / np.linalg.norm(b - a)
        angle = np.degrees(np.arccos(np.clip(np.abs(seg.directions[on] @ u), 0, 1)))
        offset = np.linalg.norm(np.cross(seg.centers[on] - a, u), axis=1)
        print(f"side: {on.sum()} segments, max offset {1000 * offset.max():.2f} mm, {angle.max():.2f} deg")
        assert on.sum() >= 4 and offset.max() < 0.002 and angle.max() < 3.0    # seeds 0-4: up to 1.48 mm


def test_a_piece_alone_near_the_rows_is_unsure_of_its_direction():
    """The direction of a piece alone on its stretch comes from its two back-projected planes, which
    nearly coincide for an edge near the epipolar direction: its sigma says so. A square of 14 mm
    at 0.5 m turned 15 degrees (one piece per side): its sides near the rows came out up to 23
    degrees off (a flat 6 degrees claimed before), those across the rows within about 1."""
    square, corners = rotated_square([0.0, 0.0], 0.007, 15.0, 0.5)
    seg = extract_frame(render_pair([square], seed=3), ExtractParams()).segments
    sigma, error = {}, {}
    for i in range(4):
        side = (corners[(i + 1) % 4] - corners[i]) / np.linalg.norm(corners[(i + 1) % 4] - corners[i])
        on = np.linalg.norm(np.cross(seg.centers - corners[i], side), axis=1) < 0.002
        assert on.sum() >= 1
        sigma[i] = np.degrees(seg.extra["sigma_direction_rad"][on])
        error[i] = np.degrees(np.arccos(np.clip(np.abs(seg.directions[on] @ side), 0, 1)))
        print(f"side {i}: sigma {sigma[i].round(1)} deg, error {error[i].round(1)} deg")
        assert np.all(error[i] <= 2 * sigma[i])
    near_rows, across_rows = np.concatenate([sigma[0], sigma[2]]), np.concatenate([sigma[1], sigma[3]])
    assert near_rows.min() > 2.5 * across_rows.max()


def test_a_short_line_alone_is_as_unsure_as_its_fit():
    """A plane is as sure as the line it goes through: a line of n px fitted to edge pixels scattered
    by ``line_fit_sigma_px`` turns by that times sqrt(12) / n rad. The 14 mm square at 0.5 m (sides
    of about 17 px, one piece each) claims for its sides across the rows 0.15 sqrt(12) / 17 rad =
    1.75 degrees of plane error instead of the 1 degree of a long line: their sigma grows by that
    ratio (within the sides' spans, 15 to 20 px). Whether such sigmas are honest is measured on
    the suite's frames (``make uncertainty``), not here."""
    from dataclasses import replace

    square, corners = rotated_square([0.0, 0.0], 0.007, 15.0, 0.5)
    frame = render_pair([square], seed=3)
    sigmas = []
    for fit_px in (0.0, 0.15):
        params = ExtractParams(stereo=replace(ExtractParams().stereo, line_fit_sigma_px=fit_px))
        seg = extract_frame(frame, params).segments
        sigma = []
        for i in (1, 3):   # the sides across the rows
            side = (corners[(i + 1) % 4] - corners[i]) / np.linalg.norm(corners[(i + 1) % 4] - corners[i])
            on = np.linalg.norm(np.cross(seg.centers - corners[i], side), axis=1) < 0.002
            on &= np.abs(seg.directions @ side) > np.cos(np.radians(30))   # not the next side's piece
            assert on.sum() >= 1
            sigma.append(np.degrees(seg.extra["sigma_direction_rad"][on]))
        sigmas.append(np.concatenate(sigma))
    ratio = sigmas[1] / sigmas[0]
    print(f"sigma {sigmas[0].round(2)} -> {sigmas[1].round(2)} deg (x {ratio.round(2)})")
    expected_low, expected_high = np.degrees(0.15 * np.sqrt(12) / np.array([20.0, 15.0]))
    assert np.all((ratio >= expected_low) & (ratio <= expected_high))


def _silhouette_pair(seed: int = 7):
    """A bar 30 px wide at disparity 30 px (grey 90) before a brighter background (140); in the right view
    the background left of it is darker (40: the right camera sees another part of the scene behind it),
    so the bar's left side has opposite polarities in the two images; its right side does not."""
    import cv2

    from accumcli.recording import StereoFrame

    rng = np.random.default_rng(seed)
    left, right = np.full((240, 320), 140.0), np.full((240, 320), 140.0)
    left[40:200, 150:180] = 90.0
    right[:, :120] = 40.0
    right[40:200, 120:150] = 90.0
    images = [np.clip(cv2.GaussianBlur(im, (0, 0), 1.0) + rng.normal(0, 2.0, im.shape), 0, 255).astype(np.uint8)
              for im in (left, right)]
    from .scenes import INTRINSICS
    return StereoFrame(0, 0, images[0], images[1], INTRINSICS, np.eye(4))


def test_a_silhouette_whose_polarity_flips_between_the_views_is_matched_in_the_second_round():
    """The first round pairs same-polarity gradients only; the second (``flipped_fallback``) pairs
    the left segments it left unmatched with unused right ones of opposite polarity, by the
    occluder's side: the bar's left side gets its depth (disparity 30 px), and nothing else changes."""
    from dataclasses import replace

    from .scenes import BASELINE, FX

    frame = _silhouette_pair()
    depth = FX * BASELINE / 30.0
    u = (np.array([149.5, 179.5]) - frame.intrinsics.cx) / FX * depth   # the bar's sides, metres (x)
    found = {}
    for fallback in (False, True):
        params = ExtractParams(stereo=replace(ExtractParams().stereo, flipped_fallback=fallback))
        seg = extract_frame(frame, params).segments
        vertical = np.abs(seg.directions[:, 1]) > 0.95
        found[fallback] = [vertical & (np.abs(seg.centers[:, 0] - x) < 0.002) for x in u]
        for side in found[fallback]:
            assert np.all(np.abs(seg.centers[side, 2] - depth) < 0.003)
        assert np.all(found[fallback][0] | found[fallback][1] | ~vertical)    # no vertical segment elsewhere
    assert found[False][0].sum() == 0 and found[False][1].sum() >= 4          # the flipped side unmatched ...
    assert found[True][0].sum() >= 4 and found[True][1].sum() == found[False][1].sum()   # ... until the second round


def _pieces(centers, directions, lengths):
    from accumcli.lines2d import Segments2D

    centers, directions = np.asarray(centers, float), np.asarray(directions, float)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    n = len(centers)
    return Segments2D(centers, directions, np.asarray(lengths, float), np.ones(n, np.int8), np.full(n, 20.0),
                      np.arange(n), np.zeros(n), directions)


def test_crowding_is_the_distance_to_the_nearest_edge_running_beside_a_piece():
    from accumcli.stereo import crowding

    pieces = _pieces([[50, 50], [53, 50], [62, 50],     # three vertical pieces 3 and 9 px apart
                      [50, 62],                         # the first one's continuation on its own line
                      [100, 50], [100, 53],             # a crossing pair: not beside each other
                      [150, 50], [153, 70]],            # parallel, 3 px apart, but not overlapping along
                     [[0, 1], [0, 1], [0, 1], [0, 1], [1, 0], [0, 1], [0, 1], [0, 1]], [15] * 8)
    c = crowding(pieces)
    assert c[0] == 3.0 and c[1] == 3.0
    assert c[2] == np.inf                  # 9 px away: beyond the reach of 8 px
    assert c[3] == 3.0                     # beside the second piece, which it overlaps by 3 px along
    assert np.all(c[4:] == np.inf)


def test_a_piece_beside_another_edge_claims_the_place_and_disparity_that_crowding_leaves_it():
    """Two edges 3 px apart blur into each other and their pieces are placed less surely: on the
    suite's frames (12 rows), pieces with a parallel neighbour within 3.5 px were off across their
    line by a median of 0.5-0.7 px (0.1 px with none within 5 px), and their disparity by 0.26 px at
    the 90th percentile over 1.645 (0.09 px), while they claimed the same as the others. A dark bar
    3 px wide and one 40 px wide at 0.5 m: the thin bar's side pieces claim hypot(0.3, 1.0) px
    across and a disparity sigma of at least 0.25 px, the wide bar's 0.3 px and under 0.25 px."""
    from accumcli.stereo import StereoParams

    p = StereoParams()
    z, px = 0.5, 0.5 / 600.0
    thin = quad([[-0.04, -0.05, z], [-0.04 + 3 * px, -0.05, z], [-0.04 + 3 * px, 0.05, z], [-0.04, 0.05, z]])
    wide = quad([[0.01, -0.05, z], [0.01 + 40 * px, -0.05, z], [0.01 + 40 * px, 0.05, z], [0.01, 0.05, z]])
    seg = extract_frame(render_pair([thin, wide], seed=4), ExtractParams()).segments
    vertical = (np.abs(seg.directions[:, 1]) > 0.95) & (np.abs(seg.centers[:, 1]) < 0.04)
    depth_per_px = z ** 2 / (600.0 * 0.08)
    for lo, hi, crowded in ((-0.041, -0.036, True), (0.009, 0.046, False)):
        on = vertical & (seg.centers[:, 0] > lo) & (seg.centers[:, 0] < hi)
        assert on.sum() >= 6
        lateral = seg.extra["sigma_lateral_px"][on]
        disparity = seg.extra["sigma_depth_m"][on] / depth_per_px
        print(f"crowded {crowded}: lateral {np.unique(lateral.round(3))} px, disparity {disparity.round(3)} px")
        if crowded:
            assert np.allclose(lateral, np.hypot(p.lateral_sigma_px, p.crowded_lateral_px))
            assert np.all(disparity >= p.crowded_disparity_px * 0.99)
        else:
            assert np.allclose(lateral, p.lateral_sigma_px) and np.all(disparity < p.crowded_disparity_px)
