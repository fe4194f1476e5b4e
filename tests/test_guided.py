"""The right-image search for left pieces whose right partner the detector missed (``guided``)."""

from __future__ import annotations

import numpy as np

from accumcli.extract import ExtractParams, extract_frame
from accumcli.guided import GuidedParams, guided_matches
from accumcli.lines2d import DETECTORS, Gradients
from accumcli.stereo import match

from .scenes import INTRINSICS, quad, render_pair

ON = GuidedParams(enabled=True)
DEPTH = 0.5
RIGHT_SIDE_X = 0.05    # the rectangle's right side, metres (left camera frame)


def _frame(seed=1):
    # 30 px wide: the left side's matched pieces lie within the search's neighbourhood of the right side's
    rect = quad([[0.025, -0.06, DEPTH], [RIGHT_SIDE_X, -0.06, DEPTH], [RIGHT_SIDE_X, 0.06, DEPTH], [0.025, 0.06, DEPTH]])
    return render_pair([rect], seed=seed)


def _column(x: float) -> float:
    """The left image column of a point at ``x`` metres, depth ``DEPTH``."""
    return INTRINSICS.fx * x / DEPTH + INTRINSICS.cx


def _detect(frame, right_image=None):
    params = ExtractParams()
    right_image = frame.right if right_image is None else right_image
    grads = [Gradients.of(image, params.lines) for image in (frame.left, right_image)]
    left, right = (DETECTORS[params.lines.detector](image, params.lines, g, None)
                   for image, g in zip((frame.left, right_image), grads))
    return left, right, grads[1], params


def _without_right_side(frame, right_image=None, reach_px=2.0):
    """2D pieces of both images, the right image's pieces within ``reach_px`` of the rectangle's right
    side removed (a detector's miss), the matches of what is left, and the left pieces on that side."""
    left, right, right_gradients, params = _detect(frame, right_image)
    disparity = INTRINSICS.fx * INTRINSICS.baseline / DEPTH
    on_side_right = np.abs(right.centers[:, 0] - (_column(RIGHT_SIDE_X) - disparity)) < reach_px
    right = right.select(~on_side_right)
    m = match(frame.left, right_image if right_image is not None else frame.right, left, right, INTRINSICS,
              params.stereo)
    side = np.flatnonzero(np.abs(left.centers[:, 0] - _column(RIGHT_SIDE_X)) < 2)
    return left, right, right_gradients, params, m, side


def test_a_missed_right_edge_is_found_at_its_true_disparity():
    frame = _frame()
    left, right, right_gradients, params, m, side = _without_right_side(frame)
    assert len(side) >= 4 and not np.isin(side, m.left).any()     # the side is unmatched without the search
    matches, extended = guided_matches(frame.left, frame.right, left, right, m, right_gradients, INTRINSICS,
                                       params.stereo, ON)
    found = matches
    new = np.isin(found.left, side)
    assert new.sum() >= len(side) - 1
    truth = INTRINSICS.fx * INTRINSICS.baseline / DEPTH
    errors = np.abs(found.disparity[new] - truth)
    print(f"{new.sum()} of {len(side)} pieces found, disparity errors up to {errors.max():.3f} px")
    assert errors.max() < 0.2
    # the found right pieces are appended, on lines of their own; the matches before are kept as they were
    assert len(extended) == len(right) + new.sum()
    assert np.array_equal(found.left[:len(m.left)], m.left) and np.array_equal(found.right[:len(m.right)], m.right)
    assert len(np.unique(extended.line_id[found.right[new]])) == new.sum()
    assert found.unmatched == m.unmatched - new.sum()
    # the new matches name the appended pieces, which lie on the side in the right image
    assert np.array_equal(found.right[len(m.right):], len(right) + np.arange(new.sum()))
    assert np.array_equal(extended.centers[:len(right)], right.centers)
    appended = extended.centers[len(right):, 0]
    assert np.abs(appended - (_column(RIGHT_SIDE_X) - truth)).max() < 0.5


def test_a_piece_is_left_alone_where_a_second_edge_of_its_polarity_lies_beside_the_first():
    frame = _frame()
    disparity = INTRINSICS.fx * INTRINSICS.baseline / DEPTH
    u = int(round(_column(RIGHT_SIDE_X) - disparity))
    right_image = frame.right.copy()
    right_image[:, u + 3:u + 5] = right_image[:, u - 6:u - 4]   # a dark band: another dark-to-bright edge at u + 5
    left, right, right_gradients, params, m, side = _without_right_side(frame, right_image, reach_px=8.0)
    assert not np.isin(side, m.left).any()
    wide = GuidedParams(enabled=True, margin_px=8.0)     # the rival lies within the searched range
    found, _ = guided_matches(frame.left, right_image, left, right, m, right_gradients, INTRINSICS, params.stereo, wide)
    assert not np.isin(found.left, side).any()
    # without the band the same range finds them: the band is what stops it
    left, right, right_gradients, params, m, side = _without_right_side(frame)
    found, _ = guided_matches(frame.left, frame.right, left, right, m, right_gradients, INTRINSICS, params.stereo, wide)
    assert np.isin(found.left, side).sum() >= len(side) - 1


def test_no_search_without_matched_neighbours_or_when_disabled():
    frame = _frame()
    left, right, right_gradients, params, m, side = _without_right_side(frame)
    far = GuidedParams(enabled=True, neighbour_px=0.5)     # no matched piece this near any unmatched one
    found, extended = guided_matches(frame.left, frame.right, left, right, m, right_gradients, INTRINSICS,
                                     params.stereo, far)
    assert found is m and extended is right
    off = GuidedParams(enabled=False)
    assert guided_matches(frame.left, frame.right, left, right, m, right_gradients, INTRINSICS, params.stereo,
                          off)[0] is m


def test_extraction_triangulates_the_found_pieces_on_the_edge(monkeypatch):
    """Through ``extract_frame``, with the right image's detector blind to the rectangle's right side:
    the search finds that side, and its pieces are triangulated on it."""
    import accumcli.extract as extract_module

    frame = _frame(seed=3)
    params = ExtractParams()
    detect = extract_module.DETECTORS[params.lines.detector]
    disparity = INTRINSICS.fx * INTRINSICS.baseline / DEPTH

    def blind(image, *args):
        pieces = detect(image, *args)
        if image is frame.right:
            return pieces.select(np.abs(pieces.centers[:, 0] - (_column(RIGHT_SIDE_X) - disparity)) >= 2)
        return pieces

    monkeypatch.setitem(extract_module.DETECTORS, params.lines.detector, blind)
    without = extract_frame(frame, params)
    with_search = extract_frame(frame, ExtractParams(guided=ON))
    assert without.counts["right_found"] == 0 and with_search.counts["right_found"] >= 4

    def on_side(segments):
        return (np.abs(segments.centers[:, 0] - RIGHT_SIDE_X) < 0.005) & (np.abs(segments.centers[:, 1]) < 0.05)

    assert on_side(without.segments).sum() == 0
    seg = with_search.segments
    on = on_side(seg)
    assert on.sum() >= 4
    assert np.abs(seg.centers[on, 2] - DEPTH).max() < 0.002
    # every 3D segment names a right piece that exists
    assert with_search.right_index.max() < len(with_search.right)
