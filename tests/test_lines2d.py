"""2D local segments against rendered edges of exactly known position and orientation."""

from __future__ import annotations

import numpy as np
import pytest

from accumcli.lines2d import LineParams, detect_hough, detect_lsd

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


@pytest.mark.parametrize("detector", [detect_hough, detect_lsd])
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
    blurred = cv2.GaussianBlur(image, (0, 0), 1.0)
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
