"""Block matching at the ends of critical edges (accumcli.critical) on hand-made image pairs."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from accumcli.critical import _block_match, _peak_trusted
from accumcli.stereo import StereoParams


def _box_pair(textured: bool = True, seed: int = 0):
    """Left and right (240, 320) images of a box's front face (grey 150) (rows 100-159, columns 120-219
    in the left image) at disparity 40, its dark left side face (60) 12 px wide in the left image and
    2 px in the right one (the cameras see it at different angles), over a background at
    disparity 10 (textured, or a uniform grey)."""
    rng = np.random.default_rng(seed)
    texture = cv2.GaussianBlur(rng.uniform(40, 160, (240, 700)).astype(np.float32), (0, 0), 1.5)
    if not textured:
        texture[:] = 100.0
    left, right = texture[:, 300:620].copy(), texture[:, 310:630].copy()
    left[100:160, 108:120] = 60.0
    right[100:160, 78:80] = 60.0
    left[100:160, 120:220] = 150.0
    right[100:160, 80:180] = 150.0
    return left.astype(np.uint8), right.astype(np.uint8)


def test_a_window_beside_a_silhouette_corner_matches_better_than_the_centred_one():
    left, right = _box_pair()
    params = StereoParams()
    corner = np.array([[119.5, 99.5]])                 # the top edge's left end, where the side face begins
    d, best, second = _block_match(left, right, corner, 5, 120, params.end_window_px)
    print(f"centred window: d {d[0]:.2f}, NCC {best[0]:.3f}, best 3 px away {second[0]:.3f}")
    beside = corner + np.array([[1.0, 0.0]]) * params.end_window_px   # on the top edge's side
    d_in, best_in, second_in = _block_match(left, right, beside, 5, 120, params.end_window_px)
    print(f"window beside it: d {d_in[0]:.2f}, NCC {best_in[0]:.3f}, best 3 px away {second_in[0]:.3f}")
    # the centred window holds the side face, which the right camera sees 2 px wide instead of 12
    assert best[0] < 0.9 < best_in[0]
    assert _peak_trusted(best_in, second_in, params)[0] and abs(d_in[0] - 40) < 0.2


def test_a_window_on_an_edge_that_only_runs_along_the_row_is_not_trusted():
    left, right = _box_pair(textured=False)
    params = StereoParams()
    middle = np.array([[170.0, 99.5]])                 # halfway along the top edge, nothing else in view
    d, best, second = _block_match(left, right, middle, 5, 120, params.end_window_px)
    print(f"along the top edge: NCC {best[0]:.3f}, 3 px away {second[0]:.3f}")
    assert best[0] > 0.95 and not _peak_trusted(best, second, params)[0]


def test_a_disparity_range_too_narrow_for_the_peak_test_gives_no_segments_and_no_error():
    # a baseline of 0.1 mm leaves 0 to 1 px of disparity in the depth range (a fuzzed calibration)
    from dataclasses import replace

    from accumcli.extract import ExtractParams, extract_frame

    from .scenes import render_pair, rotated_square

    square, _ = rotated_square((0.0, 0.0), 0.05, 3.0, 0.5)
    frame = render_pair([square], seed=2)
    assert extract_frame(frame, ExtractParams()).counts["critical_3d"] >= 6
    tiny = replace(frame, intrinsics=replace(frame.intrinsics, baseline=1e-4))
    assert extract_frame(tiny, ExtractParams()).counts["critical_3d"] == 0


def test_row_ncc_is_the_normalized_cross_correlation_of_each_shift():
    from accumcli.ncc_kernel import row_ncc

    rng = np.random.default_rng(7)
    left = rng.integers(0, 256, (40, 60)).astype(np.uint8)
    right = np.roll(left, -9, axis=1)                    # disparity 9 everywhere
    right[:, :4] = 128                                   # flat: windows there correlate 0
    row, column = np.array([20, 3]), np.array([30, 40])  # the second window reaches past the top
    ncc = row_ncc(left, right, row, column, 2, 20, 3)
    assert ncc.shape == (2, 19)
    for m in range(2):
        rows = np.clip(np.arange(row[m] - 3, row[m] + 4), 0, 39)
        a = left[rows][:, column[m] - 3:column[m] + 4].astype(float).ravel()
        for k in range(19):
            c = column[m] - 20 + k
            b = right[rows][:, c - 3:c + 4].astype(float).ravel()
            assert ncc[m, k] == pytest.approx(np.corrcoef(a, b)[0, 1], abs=1e-12)
        assert 20 - np.argmax(ncc[m]) == 9 and ncc[m].max() == pytest.approx(1.0)
    flat = row_ncc(np.full((20, 20), 7, np.uint8), right[:20, :20], np.array([10]), np.array([15]), 1, 8, 2)
    assert (flat == 0).all()


def test_ends_on_lines_finds_the_nearest_parallel_end_on_either_side():
    from accumcli.ncc_kernel import ends_on_lines

    # a segment along x at the origin, 10 px long; ends at x = -20, -9, 12, 30 on its line, one at
    # x = -7 beside it (3 px across), one at x = 8 on a crossing line, one at x = 1 inside the segment (within gap_px of its ends counts as beyond them)
    ends = np.array([[-20.0, 0.0], [-9.0, 0.5], [12.0, 0.0], [30.0, 0.0], [-7.0, 3.0], [8.0, 0.0], [1.0, 0.0]])
    end_direction = np.array([[1.0, 0.0]] * 4 + [[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    e0, e1, t0, t1 = ends_on_lines(ends, np.zeros((1, 2)), np.array([[1.0, 0.0]]), end_direction, np.array([5.0]),
                                   1.5, 3.0, np.cos(np.radians(3.0)))
    assert (e0[0], e1[0], t0[0], t1[0]) == (1, 2, -9.0, 12.0)
    none = ends_on_lines(ends[:1], np.zeros((1, 2)), np.array([[0.0, 1.0]]), end_direction[:1], np.array([5.0]),
                         1.5, 3.0, np.cos(np.radians(3.0)))
    assert (none[0][0], none[1][0], none[2][0], none[3][0]) == (0, 0, -np.inf, np.inf)
