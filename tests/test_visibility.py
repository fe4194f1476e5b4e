"""The one in-view test, shared by accumulation and tracking."""

from __future__ import annotations

import cv2
import numpy as np

from accumcli.geometry import make_transform
from accumcli.line_model import FrameContext, LineSegmentType
from accumcli.segments import Segments
from accumcli.track import visible
from accumcli.visibility import IMAGE_MARGIN_PX, MIN_DEPTH_M, WEDGE_MARGIN_PX, in_both_images, segments_in_both_images

from .scenes import INTRINSICS as INTR  # 320 x 240, fx 600, baseline 0.08 m

Z = 1.0
DISPARITY = INTR.fx * INTR.baseline / Z   # 48 px at 1 m


def _at(u, v, z=Z):
    """The point (left camera frame) that projects to left pixel (u, v) at depth z."""
    return np.array([[(u - INTR.cx) * z / INTR.fx, (v - INTR.cy) * z / INTR.fy, z]])


def test_margin_is_five_pixels_inside_both_images():
    assert IMAGE_MARGIN_PX == 5.0
    u_mid, v_mid = INTR.cx + DISPARITY / 2, INTR.cy
    assert in_both_images(_at(u_mid, v_mid), INTR)[0]
    assert in_both_images(_at(u_mid, 5.0), INTR)[0]                      # on the margin: in
    assert not in_both_images(_at(u_mid, 4.9), INTR)[0]                  # 4.9 px from the top: out
    assert in_both_images(_at(u_mid, INTR.height - 1 - 5.0), INTR)[0]
    assert not in_both_images(_at(u_mid, INTR.height - 1 - 4.9), INTR)[0]
    assert in_both_images(_at(u_mid, 4.0), INTR, margin_px=4.0)[0]       # the margin is a parameter


def test_outside_either_image_or_behind_the_camera_is_out():
    # inside the left image but its right-image projection (u - 48) is left of the right image
    assert not in_both_images(_at(30.0, INTR.cy), INTR)[0]
    assert in_both_images(_at(30.0 + DISPARITY, INTR.cy), INTR)[0]
    # inside the right image (u - 48 = 270) but right of the left image
    assert not in_both_images(_at(318.0, INTR.cy), INTR)[0]
    assert not in_both_images(-_at(INTR.cx, INTR.cy), INTR)[0]           # behind the camera
    assert not in_both_images(_at(INTR.cx + 24, INTR.cy, MIN_DEPTH_M * 0.99), INTR)[0]
    assert in_both_images(_at(INTR.cx + 24, INTR.cy, 0.5), INTR)[0]


def test_a_segment_is_in_view_only_with_both_endpoints():
    ends_in = np.vstack([_at(150.0, 100.0), _at(150.0, 140.0)])
    one_out = np.vstack([_at(150.0, 100.0), _at(150.0, 2.0)])
    segments = Segments("object", np.stack([ends_in.mean(0), one_out.mean(0)]),
                        np.tile([0.0, 1.0, 0.0], (2, 1)),
                        np.array([np.ptp(ends_in[:, 1]), np.ptp(one_out[:, 1])]), np.ones(2), np.ones(2, np.int64))
    assert segments_in_both_images(segments, np.eye(4), INTR).tolist() == [True, False]
    moved = make_transform(np.eye(3), [0.0, 0.0, 1.0])                 # 2 m away: both in
    assert segments_in_both_images(segments, moved, INTR).tolist() == [True, True]


def test_accumulation_and_tracking_agree_on_the_margin():
    """A vertical segment whose top is 4.5 px from the border: out for both (they had 5 and 4 px)."""
    top, bottom = _at(170.0, 4.5), _at(170.0, 60.0)
    segment = Segments("gripper", (top + bottom) / 2, np.array([[0.0, 1.0, 0.0]]),
                       np.array([float(bottom[0, 1] - top[0, 1])]), np.ones(1), np.ones(1, np.int64),
                       {"sigma_depth_m": np.array([0.001])})
    kind = LineSegmentType()
    context = FrameContext(np.eye(4), INTR)
    model = kind.observe(segment, context)
    assert not kind.expected(model, context)[0]
    assert not visible(segment, np.eye(4), INTR, 25.0)[0]
    inside = make_transform(np.eye(3), [0.0, 0.002, 0.0])             # 1.2 px lower: in for both
    assert kind.expected(model, FrameContext(inside, INTR))[0] and visible(segment, inside, INTR, 25.0)[0]


def test_a_rectification_wedge_is_out_of_view():
    """Pixels near a black wedge that rectification left (``border_distance``) are not in view: a
    wedge over the left image's right third, and one over the right image's top rows."""
    left, right = np.full((INTR.height, INTR.width), 255, np.uint8), np.full((INTR.height, INTR.width), 255, np.uint8)
    left[:, 220:], right[:30, :] = 0, 0
    border = tuple(np.minimum(cv2.distanceTransform((b > 0).view(np.uint8), cv2.DIST_C, 3), 255).astype(np.uint8)
                   for b in (left, right))
    u_mid, v_mid = INTR.cx + DISPARITY / 2, INTR.cy
    assert in_both_images(_at(u_mid, v_mid), INTR, border_distance=border)[0]
    assert in_both_images(_at(219.0 - WEDGE_MARGIN_PX, v_mid), INTR, border_distance=border)[0]
    assert not in_both_images(_at(221.0 - WEDGE_MARGIN_PX, v_mid), INTR, border_distance=border)[0]
    assert in_both_images(_at(221.0 - WEDGE_MARGIN_PX, v_mid), INTR)[0]          # no wedge given: in
    assert not in_both_images(_at(u_mid, 30.0 + WEDGE_MARGIN_PX - 2), INTR, border_distance=border)[0]
    assert in_both_images(_at(u_mid, 30.0 + WEDGE_MARGIN_PX), INTR, border_distance=border)[0]
    # accumulation's expected view agrees
    top, bottom = _at(230.0, 100.0), _at(230.0, 140.0)
    segment = Segments("gripper", (top + bottom) / 2, np.array([[0.0, 1.0, 0.0]]),
                       np.array([float(bottom[0, 1] - top[0, 1])]), np.ones(1), np.ones(1, np.int64),
                       {"sigma_depth_m": np.array([0.001])})
    kind = LineSegmentType()
    model = kind.observe(segment, FrameContext(np.eye(4), INTR))
    assert kind.expected(model, FrameContext(np.eye(4), INTR))[0]
    assert not kind.expected(model, FrameContext(np.eye(4), INTR, border))[0]
