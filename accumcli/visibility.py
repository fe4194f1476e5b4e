"""The one test of whether 3D points and segments fall inside both rectified images.

Accumulation (``line_model``: which model segments a frame should have shown) and
tracking (``track``: which model segments to measure) both use it, so both mean the
same by "in view": in front of the camera by more than ``MIN_DEPTH_M`` and, in both
the left and the right image, at least ``IMAGE_MARGIN_PX`` inside the outermost pixel
centres (u in [margin, width - 1 - margin], v in [margin, height - 1 - margin]); where raw
images were rectified, also ``WEDGE_MARGIN_PX`` from the black wedges that rectification leaves
(``StereoFrame.border_distance``): their gradients are zero within 3 blur sigmas + 1 px of a
wedge (``Gradients.of``), 4 px at the default blur, and the same margin as at the image border
is added to that.
"""

from __future__ import annotations

import numpy as np

from .geometry import transform_points
from .recording import StereoIntrinsics
from .segments import Segments

IMAGE_MARGIN_PX = 5.0   # an edge this near the border is cut by it or lost by the blur and the search
MIN_DEPTH_M = 0.05      # nearer (or behind the camera) is not in view
WEDGE_MARGIN_PX = 10    # from a rectification wedge: its gradient reach, then IMAGE_MARGIN_PX


def in_both_images(points_camera: np.ndarray, intr: StereoIntrinsics, margin_px: float = IMAGE_MARGIN_PX,
                   min_depth_m: float = MIN_DEPTH_M, border_distance=None) -> np.ndarray:
    """(N,) bool: ``points_camera`` (N, 3), metres, left camera frame, are deeper than
    ``min_depth_m`` and project at least ``margin_px`` inside both images and, given the
    frame's (left, right) ``border_distance`` (``StereoFrame``), ``WEDGE_MARGIN_PX`` from a wedge."""
    uv_left, uv_right, z = intr.project(points_camera)
    ok = z > min_depth_m
    for side, uv in enumerate((uv_left, uv_right)):
        ok &= (uv[:, 0] >= margin_px) & (uv[:, 0] <= intr.width - 1 - margin_px) & (uv[:, 1] >= margin_px) & \
              (uv[:, 1] <= intr.height - 1 - margin_px)
        if border_distance is not None:
            px = np.where(ok[:, None], np.rint(uv), 0).astype(np.int64)
            ok &= border_distance[side][px[:, 1], px[:, 0]] >= WEDGE_MARGIN_PX
    return ok


def segments_in_both_images(segments: Segments, T_camera_segments: np.ndarray, intr: StereoIntrinsics,
                            margin_px: float = IMAGE_MARGIN_PX, border_distance=None) -> np.ndarray:
    """(N,) bool: both endpoints of each segment (in ``segments.frame_id``, placed in the left
    camera frame by ``T_camera_segments``) pass ``in_both_images``."""
    ends = transform_points(T_camera_segments, segments.endpoints().reshape(-1, 3))
    return in_both_images(ends, intr, margin_px, border_distance=border_distance).reshape(-1, 2).all(axis=1)
