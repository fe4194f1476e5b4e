"""The simulated world: a polyhedral object with painted stripes held by a
two-finger gripper, a static cluttered background, and the object's motion.

Everything here is geometry in metres; rendering is in ``render.py``.
Frames: the object frame is the gripper frame (origin at the object's centre,
fingers along +-x, palm towards -y); the world frame is the rectified left
camera frame unless a separate world is asked for.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from ..geometry import make_transform

SHAPES = ("box", "prism", "house")


@dataclass
class Polygon:
    """A planar convex polygon. vertices: (K, 3) metres, counter-clockwise seen
    from outside; normal: (3,) outward unit; albedo in [0, 1]. ``decal`` polygons
    are painted on another polygon's surface and win its depth test; ``cull``
    polygons are invisible from behind (faces of closed solids). Only the triangle
    renderer (``raster.py``) draws non-convex polygons and ``texture``."""

    vertices: np.ndarray
    normal: np.ndarray
    albedo: float
    cull: bool = True
    decal: bool = False
    texture: object = None  # raster.Texture (random scenes only)


@dataclass
class Part:
    """Polygons and true straight edges (a, b) of one rigid part of the scene."""

    polygons: list = field(default_factory=list)
    edges: list = field(default_factory=list)  # (a (3,), b (3,), kind)


def _prism(section: np.ndarray, z0: float, z1: float, albedo: float, kind: str) -> Part:
    """Extrude a convex (K, 2) counter-clockwise polygon of the xy plane from z0 to z1."""
    k = len(section)
    back = np.column_stack([section, np.full(k, z1)])
    front = np.column_stack([section, np.full(k, z0)])
    part = Part()
    part.polygons.append(Polygon(front[::-1].copy(), np.array([0.0, 0.0, -1.0]), albedo))
    part.polygons.append(Polygon(back.copy(), np.array([0.0, 0.0, 1.0]), albedo))
    for i in range(k):
        j = (i + 1) % k
        quad = np.array([front[i], front[j], back[j], back[i]])
        d = section[j] - section[i]
        normal = np.array([d[1], -d[0], 0.0]) / np.hypot(*d)
        part.polygons.append(Polygon(quad, normal, albedo))
        part.edges += [(front[i], front[j], kind), (back[i], back[j], kind), (front[i], back[i], kind)]
    return part


def _box(center, size, albedo: float, kind: str) -> Part:
    cx, cy, cz = center
    sx, sy, sz = np.asarray(size) / 2
    section = np.array([[cx - sx, cy - sy], [cx + sx, cy - sy], [cx + sx, cy + sy], [cx - sx, cy + sy]])
    return _prism(section, cz - sz, cz + sz, albedo, kind)


def _clip_convex(vertices: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Keep the part of a convex polygon with ``vertices @ normal <= offset`` (Sutherland-Hodgman)."""
    out = []
    n = len(vertices)
    for i in range(n):
        p, q = vertices[i], vertices[(i + 1) % n]
        dp, dq = p @ normal - offset, q @ normal - offset
        if dp <= 0:
            out.append(p)
        if dp * dq < 0:
            out.append(p + (q - p) * dp / (dp - dq))
    return np.array(out)


def _stripe(face: Polygon, across: np.ndarray, lo: float, hi: float, albedo: float,
            kind: str = "stripe") -> tuple[Polygon, list]:
    """A painted band ``lo <= x . across <= hi`` on a face, and its two boundary edges (of ``kind``)."""
    band = _clip_convex(_clip_convex(face.vertices, across, hi), -across, -lo)
    edges = []
    for level in (lo, hi):
        on = band[np.abs(band @ across - level) < 1e-9]
        if len(on) >= 2:
            edges.append((on[0], on[-1], kind))
    return Polygon(band, face.normal, albedo, cull=True, decal=True), edges


def make_object(shape: str, rng: np.random.Generator) -> tuple[Part, float]:
    """The object (object frame, centred at the origin) and its half-width along x."""
    if shape == "box":
        half = 0.05
        section = np.array([[-half, -0.035], [half, -0.035], [half, 0.035], [-half, 0.035]])
        depth = 0.06
    elif shape == "prism":
        r = 0.052
        angles = np.radians(np.arange(-30, 330, 60))
        section = np.column_stack([r * np.cos(angles), r * np.sin(angles)])
        half = r * np.cos(np.radians(30))
        depth = 0.07
    elif shape == "house":
        half = 0.045
        section = np.array([[-half, 0.04], [-half, -0.01], [0.0, -0.045], [half, -0.01], [half, 0.04]])
        depth = 0.065
    else:
        raise ValueError(f"unknown shape {shape!r} (expected one of {', '.join(SHAPES)})")
    if _area(section) < 0:
        section = section[::-1]
    part = _prism(section, -depth / 2, depth / 2, 0.78, "object")
    # Painted stripes: a diagonal band on the front and back caps and one on a side face.
    for index, albedo in ((0, 0.22), (1, 0.25), (2 + int(rng.integers(0, len(section))), 0.2)):
        face = part.polygons[index]
        in_plane = np.cross(face.normal, [0.0, 0.0, 1.0] if abs(face.normal[2]) < 0.9 else [0.0, 1.0, 0.0])
        angle = rng.uniform(20, 70) * rng.choice([-1, 1])
        across = Rotation.from_rotvec(np.radians(angle) * face.normal).apply(in_plane / np.linalg.norm(in_plane))
        centre = face.vertices.mean(axis=0) @ across + rng.uniform(-0.01, 0.01)
        width = rng.uniform(0.010, 0.016)
        polygon, edges = _stripe(face, across, centre - width / 2, centre + width / 2, albedo)
        part.polygons.append(polygon)
        part.edges += edges
    return part, half


def _area(section: np.ndarray) -> float:
    x, y = section[:, 0], section[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


@dataclass(frozen=True)
class GripperSize:
    """Gripper dimensions in metres (object frame): finger thickness (x) and depth (z), how far below the
    object's centre the fingers reach (y), the gap from the object's top to the palm, the palm's height
    and depth, the wrist's width, depth and length. The defaults are the classic scene's."""

    finger: float = 0.012
    finger_depth: float = 0.026
    reach: float = 0.012
    gap: float = 0.025
    palm: float = 0.024
    palm_depth: float = 0.05
    wrist: float = 0.05
    wrist_length: float = 0.2


def make_gripper(half_width: float, object_top: float, albedos: tuple = (0.35, 0.5, 0.6),
                 size: GripperSize = GripperSize()) -> Part:
    """Two fingers clamping the object at x = +-half_width, a palm and a wrist above it (towards -y);
    ``albedos`` of the fingers, the palm and the wrist."""
    part = Part()
    g = size
    palm_y = object_top - g.gap
    for sign in (-1, 1):
        finger = _box((sign * (half_width + g.finger / 2), (palm_y + g.reach) / 2, 0.0),
                      (g.finger, g.reach - palm_y, g.finger_depth), albedos[0], "gripper")
        part.polygons += finger.polygons
        part.edges += finger.edges
    palm = _box((0.0, palm_y - g.palm / 2, 0.0), (2 * half_width + 3 * g.finger, g.palm, g.palm_depth), albedos[1],
                "gripper")
    wrist = _box((0.0, palm_y - g.palm - g.wrist_length / 2, 0.0), (g.wrist, g.wrist_length, g.wrist), albedos[2],
                 "gripper")
    for piece in (palm, wrist):
        part.polygons += piece.polygons
        part.edges += piece.edges
    return part


def make_background(rng: np.random.Generator, fov_half_width: float) -> Part:
    """A wall at 1.1 m covered with rectangles of other grey levels, and boxes standing in front of it.

    Coordinates are in the world (= left camera) frame; nothing here moves.
    """
    part = Part()
    wall_z = 1.1
    extent = fov_half_width * wall_z * 1.6
    wall = np.array([[-extent, -extent, wall_z], [extent, -extent, wall_z], [extent, extent, wall_z],
                     [-extent, extent, wall_z]])
    part.polygons.append(Polygon(wall[::-1].copy(), np.array([0.0, 0.0, -1.0]), 0.55, cull=False))
    for _ in range(40):
        w, h = rng.uniform(0.03, 0.25, size=2)
        cx, cy = rng.uniform(-extent * 0.6, extent * 0.6, size=2)
        angle = rng.choice([0.0, rng.uniform(-40, 40)])
        rot = Rotation.from_euler("z", angle, degrees=True).as_matrix()[:2, :2]
        corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2 @ rot.T + [cx, cy]
        verts = np.column_stack([corners, np.full(4, wall_z)])[::-1]
        part.polygons.append(Polygon(verts.copy(), np.array([0.0, 0.0, -1.0]), float(rng.uniform(0.1, 0.95)),
                                     cull=False, decal=True))
    for _ in range(5):
        side = rng.choice([-1, 1])
        center = (side * rng.uniform(0.18, 0.35), rng.uniform(-0.1, 0.2), rng.uniform(0.75, 1.0))
        size = rng.uniform(0.06, 0.16, size=3)
        box = _box(center, size, float(rng.uniform(0.2, 0.9)), "background")
        yaw = Rotation.from_euler("y", rng.uniform(-35, 35), degrees=True).as_matrix()
        for polygon in box.polygons:
            polygon.vertices = (polygon.vertices - center) @ yaw.T + center
            polygon.normal = yaw @ polygon.normal
        part.polygons += box.polygons
    return part


def trajectory(k: np.ndarray, phase: float, per_frame_deg: float = 10.0) -> np.ndarray:
    """(len(k), 4, 4) poses ``T_camera_object`` at frame times ``k`` (frame units,
    fractional allowed; ``phase`` in radians picks the recording's start).

    The object, about 0.5 m in front of the camera, swings about its vertical
    axis (+-55 deg), tilts (+-25 deg) and rolls (+-30 deg, so that edges leave
    the critical plane), moving 5 to 15 degrees between frames; the aspects
    repeat about every 30 frames.
    """
    omega = np.radians(per_frame_deg) / np.radians(45.0)
    k = np.asarray(k, float)
    yaw = np.radians(55.0) * np.sin(omega * k + phase)
    pitch = np.radians(25.0) * np.cos(omega * k + phase) - np.radians(10.0)
    roll = np.radians(45.0) * np.sin(0.45 * omega * k + 2.0 * phase)
    rotations = Rotation.from_euler("yxz", np.column_stack([yaw, pitch, roll])).as_matrix()
    translations = np.column_stack([0.03 * np.sin(0.5 * omega * k), 0.02 * np.cos(0.41 * omega * k) + 0.01,
                                    0.5 + 0.04 * np.sin(0.29 * omega * k)])
    return np.stack([make_transform(R, t) for R, t in zip(rotations, translations)])
