"""Tiny rendered stereo scenes with exactly known edges, for unit tests of extraction."""

from __future__ import annotations

import numpy as np

from accumcli.recording import StereoFrame, StereoIntrinsics
from accumcli.simulation.render import PinholeCamera, empty_layer, finish_image, rasterize, reduce
from accumcli.simulation.scene import Polygon

FX, WIDTH, HEIGHT, BASELINE = 600.0, 320, 240, 0.08
CAMERA = PinholeCamera(FX, FX, (WIDTH - 1) / 2, (HEIGHT - 1) / 2, WIDTH, HEIGHT)
INTRINSICS = StereoIntrinsics(FX, FX, CAMERA.cx, CAMERA.cy, BASELINE, WIDTH, HEIGHT)


def render_pair(polygons: list[Polygon], seed: int = 0, noise: float = 2.0) -> StereoFrame:
    """A rectified stereo frame of ``polygons`` (left camera frame, metres) on a mid-grey wall at 2 m."""
    wall = Polygon(np.array([[-5, -5, 2.0], [5, -5, 2.0], [5, 5, 2.0], [-5, 5, 2.0]]), np.array([0, 0, -1.0]),
                   0.5, cull=False)
    rng = np.random.default_rng(seed)
    images = []
    for shift in (0.0, -BASELINE):
        T = np.eye(4)
        T[0, 3] = shift
        layer = empty_layer(CAMERA, 4)
        rasterize(layer, [wall, *polygons], T, CAMERA, 4, np.array([0.0, 0.0, -1.0]))
        images.append(finish_image(reduce(layer, 4), 1.0, 0.6, noise, rng))
    return StereoFrame(0, 0, images[0], images[1], INTRINSICS, np.eye(4))


def quad(corners, albedo: float = 0.15) -> Polygon:
    """A flat dark quadrilateral facing the camera; corners (4, 3) metres."""
    return Polygon(np.asarray(corners, float), np.array([0.0, 0.0, -1.0]), albedo, cull=False, decal=True)


def rotated_square(center, half: float, angle_deg: float, depth: float) -> tuple[Polygon, np.ndarray]:
    """A square on the plane z = depth rotated by ``angle_deg``, and its corners (4, 3)."""
    a = np.radians(angle_deg)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    corners2 = np.array([[-half, -half], [half, -half], [half, half], [-half, half]]) @ R.T + center
    corners = np.column_stack([corners2, np.full(4, depth)])
    return quad(corners), corners
