"""A small z-buffer renderer for convex planar polygons (numpy + OpenCV).

Polygons are filled with ``cv2.fillConvexPoly`` at ``supersample`` times the
image resolution; each covered pixel gets the depth of the polygon's plane
along its ray, and the nearest polygon wins (a true depth test, not only a
painter's order, so that the depth buffer can decide what the cameras saw).
Shading is Lambertian with one directional light; the image is then reduced
with area averaging, which anti-aliases edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..geometry import transform_points
from .scene import Polygon, _clip_convex

NEAR_M = 0.05
DECAL_BIAS_M = 3e-4
# cv2.fillConvexPoly fills every pixel within about half a pixel of the polygon
# (measured: 0.5 px for axis-aligned edges, 0.4 px at 45 degrees); polygons are
# shrunk by this much so that coverage, and so the anti-aliased edge, is unbiased.
FILL_DILATION_PX = 0.47


@dataclass(frozen=True)
class PinholeCamera:
    """Rectified pinhole camera: intrinsics in pixels of the (width, height) image."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def with_margin(self, margin: int) -> "PinholeCamera":
        return PinholeCamera(self.fx, self.fy, self.cx + margin, self.cy + margin, self.width + 2 * margin,
                             self.height + 2 * margin)


@dataclass
class Layer:
    """Supersampled colour (float32, 0..1 before gain) and depth (float32, metres) buffers."""

    color: np.ndarray
    depth: np.ndarray


def empty_layer(camera: PinholeCamera, supersample: int) -> Layer:
    shape = (camera.height * supersample, camera.width * supersample)
    return Layer(np.zeros(shape, np.float32), np.full(shape, np.inf, np.float32))


def shade(normal: np.ndarray, albedo: float, light: np.ndarray) -> float:
    """Lambertian grey level in [0, 1] of a face with outward unit ``normal`` (camera frame)."""
    return float(albedo * (0.35 + 0.65 * max(0.0, float(normal @ light))))


def rasterize(layer: Layer, polygons: list[Polygon], T_camera_part: np.ndarray, camera: PinholeCamera,
              supersample: int, light: np.ndarray) -> None:
    """Draw ``polygons`` (in a part's frame) into ``layer`` in place, with depth test."""
    S = supersample
    H, W = layer.depth.shape
    R = T_camera_part[:3, :3]
    for polygon in polygons:
        vertices = transform_points(T_camera_part, polygon.vertices)
        normal = R @ polygon.normal
        if polygon.cull and normal @ vertices.mean(axis=0) >= 0:
            continue
        if vertices[:, 2].min() < NEAR_M:
            vertices = _clip_convex(vertices, np.array([0.0, 0.0, -1.0]), -NEAR_M)
            if len(vertices) < 3:
                continue
        u = ((camera.fx * vertices[:, 0] / vertices[:, 2] + camera.cx) + 0.5) * S - 0.5
        v = ((camera.fy * vertices[:, 1] / vertices[:, 2] + camera.cy) + 0.5) * S - 0.5
        x0, y0 = max(int(np.floor(u.min())), 0), max(int(np.floor(v.min())), 0)
        x1, y1 = min(int(np.ceil(u.max())) + 1, W), min(int(np.ceil(v.max())) + 1, H)
        if x0 >= x1 or y0 >= y1:
            continue
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        shrunk = _shrink(np.column_stack([u - x0, v - y0]), FILL_DILATION_PX)
        if shrunk is None:
            continue
        points = np.round(shrunk * 16).astype(np.int32)
        cv2.fillConvexPoly(mask, points, 1, cv2.LINE_8, 4)
        ys, xs = np.nonzero(mask)
        if ys.size == 0:
            continue
        ys += y0
        xs += x0
        ray_x = ((xs + 0.5) / S - 0.5 - camera.cx) / camera.fx
        ray_y = ((ys + 0.5) / S - 0.5 - camera.cy) / camera.fy
        denominator = normal[0] * ray_x + normal[1] * ray_y + normal[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (normal @ vertices[0]) / denominator
        z = np.where(denominator != 0, z, np.inf).astype(np.float32)
        if polygon.decal:
            z = z - DECAL_BIAS_M
            closer = z <= layer.depth[ys, xs]
        else:
            closer = z < layer.depth[ys, xs]
        layer.depth[ys[closer], xs[closer]] = z[closer]
        layer.color[ys[closer], xs[closer]] = shade(normal, polygon.albedo, light)


def _shrink(points: np.ndarray, distance: float) -> np.ndarray | None:
    """Offset every edge of a convex (K, 2) polygon inward by ``distance``; None if it vanishes."""
    edges = np.roll(points, -1, axis=0) - points
    area2 = np.sum(points[:, 0] * np.roll(points[:, 1], -1) - np.roll(points[:, 0], -1) * points[:, 1])
    length = np.hypot(edges[:, 0], edges[:, 1])
    keep = length > 1e-9
    if area2 == 0 or keep.sum() < 3:
        return None
    points, edges, length = points[keep], edges[keep], length[keep]
    outward = np.sign(area2) * np.column_stack([edges[:, 1], -edges[:, 0]]) / length[:, None]
    offsets = np.sum(outward * points, axis=1) - distance
    # vertex i is where edge i-1 and edge i meet
    n_prev, c_prev = np.roll(outward, 1, axis=0), np.roll(offsets, 1)
    det = n_prev[:, 0] * outward[:, 1] - n_prev[:, 1] * outward[:, 0]
    if np.any(np.abs(det) < 1e-9):
        return points
    x = (c_prev * outward[:, 1] - n_prev[:, 1] * offsets) / det
    y = (n_prev[:, 0] * offsets - c_prev * outward[:, 0]) / det
    shrunk = np.column_stack([x, y])
    new_area2 = np.sum(shrunk[:, 0] * np.roll(shrunk[:, 1], -1) - np.roll(shrunk[:, 0], -1) * shrunk[:, 1])
    return shrunk if np.sign(new_area2) == np.sign(area2) else None


def reduce(layer: Layer, supersample: int) -> np.ndarray:
    """Area-averaged (H, W) float32 image of a supersampled layer's colour, 0..1."""
    h, w = layer.color.shape
    return cv2.resize(layer.color, (w // supersample, h // supersample), interpolation=cv2.INTER_AREA)


def finish_image(image: np.ndarray, gain: float, blur_sigma: float, noise_sigma: float,
                 rng: np.random.Generator) -> np.ndarray:
    """Sensor: gain, optical blur, Gaussian noise (grey levels), 8-bit quantisation."""
    out = cv2.GaussianBlur(image * (255.0 * gain), (0, 0), blur_sigma) if blur_sigma > 0 else image * (255.0 * gain)
    out = out + rng.normal(0.0, noise_sigma, out.shape).astype(np.float32)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)
