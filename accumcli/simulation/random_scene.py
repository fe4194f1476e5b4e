"""The random scene (``SimulationOptions(scene="random")``): objects, backgrounds, clutter, motion.

Geometry in metres. The object frame is the gripper frame: the object's profile
lies in the xy plane (centred on its bounding box), extruded along z; the
fingers clamp it at x = +-half its width, the palm and wrist are towards -y.
Static things are in the left camera frame (x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from ..geometry import make_transform, unit
from .raster import Texture
from .scene import GripperSize, Polygon, _box, _stripe, make_gripper

# Profiles in the xy plane, counter-clockwise in a unit box [-0.5, 0.5]^2 (x, y), y down.
PROFILES = {
    "box": [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)],
    "prism": [(0.5 * np.cos(a), 0.5 * np.sin(a)) for a in np.radians(np.arange(0, 360, 60))],
    "wedge": [(-0.5, 0.5), (-0.5, -0.5), (0.5, 0.5)],
    "trapezoid": [(-0.5, 0.5), (-0.25, -0.5), (0.25, -0.5), (0.5, 0.5)],
    "house": [(-0.5, 0.5), (-0.5, -0.1), (0.0, -0.5), (0.5, -0.1), (0.5, 0.5)],
    "L": [(-0.5, -0.5), (-0.1, -0.5), (-0.1, 0.15), (0.5, 0.15), (0.5, 0.5), (-0.5, 0.5)],
    "T": [(-0.5, -0.5), (0.5, -0.5), (0.5, -0.15), (0.17, -0.15), (0.17, 0.5), (-0.17, 0.5), (-0.17, -0.15),
          (-0.5, -0.15)],
    "U": [(-0.5, -0.5), (-0.2, -0.5), (-0.2, 0.15), (0.2, 0.15), (0.2, -0.5), (0.5, -0.5), (0.5, 0.5),
          (-0.5, 0.5)],
    "steps": [(-0.5, -0.5), (-0.17, -0.5), (-0.17, -0.17), (0.17, -0.17), (0.17, 0.17), (0.5, 0.17), (0.5, 0.5),
              (-0.5, 0.5)],
    "cross": [(-0.17, -0.5), (0.17, -0.5), (0.17, -0.17), (0.5, -0.17), (0.5, 0.17), (0.17, 0.17), (0.17, 0.5),
              (-0.17, 0.5), (-0.17, 0.17), (-0.5, 0.17), (-0.5, -0.17), (-0.17, -0.17)],
}
RANDOM_SHAPES = tuple(PROFILES)
CONVEX = ("box", "prism", "wedge", "trapezoid", "house")
BACKGROUNDS = ("texture", "planes", "lines")


@dataclass
class Solid:
    """Polygons and true edges (a (3,), b (3,), kind) with kind 'crease' or 'paint'."""

    polygons: list = field(default_factory=list)
    edges: list = field(default_factory=list)


def _signed_area(section: np.ndarray) -> float:
    x, y = section[:, 0], section[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def extrude(section: np.ndarray, z0: float, z1: float, albedos, cull: bool = True) -> Solid:
    """A closed solid: the simple (K, 2) polygon ``section`` of the xy plane (convex or not) from z0 to z1.

    ``albedos`` (K + 2,): front cap (z0), back cap (z1), then the side from vertex i to i + 1.
    Its true edges are the 3K creases."""
    section = np.asarray(section, float)
    if _signed_area(section) < 0:
        section = section[::-1]
    k = len(section)
    front = np.column_stack([section, np.full(k, z0)])
    back = np.column_stack([section, np.full(k, z1)])
    solid = Solid()
    solid.polygons.append(Polygon(front[::-1].copy(), np.array([0.0, 0.0, -1.0]), float(albedos[0]), cull))
    solid.polygons.append(Polygon(back.copy(), np.array([0.0, 0.0, 1.0]), float(albedos[1]), cull))
    for i in range(k):
        j = (i + 1) % k
        d = section[j] - section[i]
        normal = np.array([d[1], -d[0], 0.0]) / np.hypot(*d)
        solid.polygons.append(Polygon(np.array([front[i], front[j], back[j], back[i]]), normal,
                                      float(albedos[2 + i]), cull))
        solid.edges += [(front[i], front[j], "crease"), (back[i], back[j], "crease"),
                        (front[i], back[i], "crease")]
    return solid


def profile(shape: str, width: float, height: float) -> np.ndarray:
    """(K, 2) profile of ``shape`` scaled to width x height metres (x, y)."""
    if shape not in PROFILES:
        raise ValueError(f"unknown shape {shape!r} (expected one of {', '.join(RANDOM_SHAPES)})")
    return np.array(PROFILES[shape], float) * [width, height]


def make_random_object(shape: str, size: float, base_albedo: float, rng: np.random.Generator) -> tuple[Solid, float]:
    """The object, its largest dimension ``size`` metres, and its half-width along x.

    Width (x) : height (y) : depth (z) ratios are drawn (height 0.55 to 1, depth 0.35 to 1 of the width,
    then scaled so that the largest is ``size``); each face's albedo is ``base_albedo`` times 0.8 to 1.2;
    0 to 4 painted marks (bands across a side face, or windows inside one) of albedo base +- 0.15 to 0.4.
    """
    ratios = np.array([1.0, rng.uniform(0.55, 1.0), rng.uniform(0.35, 1.0)])
    w, h, d = ratios / ratios.max() * size
    section = profile(shape, w, h)
    k = len(section)
    albedos = np.clip(base_albedo * rng.uniform(0.8, 1.2, k + 2), 0.03, 0.97)
    solid = extrude(section, -d / 2, d / 2, albedos)
    sides = list(range(2, 2 + k))
    candidates = sides + ([0, 1] if shape in CONVEX else [])
    for _ in range(int(rng.integers(0, 5))):
        face = solid.polygons[int(rng.choice(candidates))]
        sign = rng.choice([-1.0, 1.0]) if 0.15 < base_albedo < 0.85 else (1.0 if base_albedo < 0.5 else -1.0)
        albedo = float(np.clip(face.albedo + sign * rng.uniform(0.15, 0.4), 0.03, 0.97))
        if rng.uniform() < 0.5:
            polygon, edges = _band(face, rng, albedo)
        else:
            polygon, edges = _window(face, rng, albedo)
        if polygon is not None:
            solid.polygons.append(polygon)
            solid.edges += edges
    return solid, w / 2


def _face_axes(face: Polygon) -> tuple[np.ndarray, np.ndarray]:
    e1 = unit((face.vertices[1] - face.vertices[0])[None])[0]
    return e1, np.cross(face.normal, e1)


def _band(face: Polygon, rng: np.random.Generator, albedo: float):
    """A painted band across a convex face at an angle, and its two boundary edges."""
    e1, e2 = _face_axes(face)
    angle = np.radians(rng.uniform(-60, 60))
    across = np.cos(angle) * e1 + np.sin(angle) * e2
    levels = face.vertices @ across
    span = levels.max() - levels.min()
    width = span * rng.uniform(0.12, 0.3)
    centre = levels.min() + span * rng.uniform(0.3, 0.7)
    polygon, edges = _stripe(face, across, centre - width / 2, centre + width / 2, albedo, "paint")
    return (polygon, edges) if len(polygon.vertices) >= 3 else (None, [])


def _window(face: Polygon, rng: np.random.Generator, albedo: float):
    """A painted rectangle inside a convex face (aligned with its first edge), and its four edges."""
    e1, e2 = _face_axes(face)
    c = face.vertices.mean(axis=0)
    s1, s2 = (face.vertices - c) @ e1, (face.vertices - c) @ e2
    # a rectangle around the centroid that fits: shrink until all corners are inside the face
    half1, half2 = (s1.max() - s1.min()) * rng.uniform(0.1, 0.3), (s2.max() - s2.min()) * rng.uniform(0.1, 0.3)
    offset = c
    for _ in range(6):
        corners = np.array([offset + sa * half1 * e1 + sb * half2 * e2 for sa, sb in
                            ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        if _inside_convex(face, corners):
            break
        half1, half2 = half1 * 0.7, half2 * 0.7
    else:
        return None, []
    if min(half1, half2) < 0.002:
        return None, []
    if np.cross(corners[1] - corners[0], corners[2] - corners[1]) @ face.normal < 0:
        corners = corners[::-1].copy()
    edges = [(corners[i], corners[(i + 1) % 4], "paint") for i in range(4)]
    return Polygon(corners, face.normal, albedo, cull=True, decal=True), edges


def _inside_convex(face: Polygon, points: np.ndarray) -> bool:
    v = face.vertices
    for i in range(len(v)):
        inward = np.cross(face.normal, v[(i + 1) % len(v)] - v[i])
        if np.any((points - v[i]) @ inward < 1e-6):
            return False
    return True


def make_random_gripper(obj: Solid, half_width: float, rng: np.random.Generator) -> Solid:
    """The fingers, palm and wrist of ``scene.make_gripper`` sized to the object ``obj`` (fingers 0.15 of its
    size thick, reaching 60 % down its height; palm and wrist up to the classic gripper's), with grey levels
    U(0.15, 0.8); every edge of kind 'crease'."""
    vertices = np.concatenate([p.vertices for p in obj.polygons])
    top, bottom = vertices[:, 1].min(), vertices[:, 1].max()
    size = float(np.ptp(vertices, axis=0).max())
    depth = float(np.ptp(vertices[:, 2]))
    clip = lambda x, lo, hi: float(np.clip(x, lo, hi))  # noqa: E731
    dims = GripperSize(finger=clip(0.15 * size, 0.005, 0.012), finger_depth=clip(0.5 * depth, 0.008, 0.026),
                       reach=top + 0.6 * (bottom - top), gap=clip(0.25 * size, 0.01, 0.025),
                       palm=clip(0.3 * size, 0.01, 0.024), palm_depth=clip(depth, 0.015, 0.05),
                       wrist=clip(0.5 * size, 0.02, 0.05))
    part = make_gripper(half_width, top, albedos=tuple(rng.uniform(0.15, 0.8, 3)), size=dims)
    return Solid(part.polygons, [(a, b, "crease") for a, b, _ in part.edges])


# -- textures ----------------------------------------------------------------------------------------------------
def noise_texture(rng: np.random.Generator, mean: float, amplitude: float, size: int = 256) -> np.ndarray:
    """(size, size) float32 albedo: periodic smooth blotches at two scales (white noise low-passed by a
    Gaussian of about 10 and 1.3 texels), ``mean`` +- ``amplitude`` (standard deviation), in [0.02, 0.98]."""
    f = np.fft.fftfreq(size)
    radius2 = f[:, None] ** 2 + f[None, :] ** 2
    out = np.zeros((size, size))
    for cutoff, weight in ((1 / 16, 0.75), (1 / 2, 0.25)):
        spectrum = np.fft.fft2(rng.normal(0.0, 1.0, (size, size))) * np.exp(-radius2 / (2 * (cutoff / 4) ** 2))
        layer = np.fft.ifft2(spectrum).real
        out += weight * layer / (layer.std() + 1e-12)
    return np.clip(mean + amplitude * out / (out.std() + 1e-12), 0.02, 0.98).astype(np.float32)


def line_texture(rng: np.random.Generator, mean: float, amplitude: float, size: int = 512) -> np.ndarray:
    """(size, size) float32 albedo rich in straight lines: tiles, grain and random strokes."""
    image = noise_texture(rng, mean, amplitude * 0.3, size)
    style = int(rng.integers(0, 3))
    shade = float(np.clip(mean + rng.choice([-1, 1]) * amplitude, 0.02, 0.98))
    if style == 0:  # tiles
        step = int(rng.integers(48, 128))
        for x in range(0, size, step):
            cv2.line(image, (x, 0), (x, size), shade, int(rng.integers(1, 4)), cv2.LINE_AA)
            cv2.line(image, (0, x), (size, x), shade, int(rng.integers(1, 4)), cv2.LINE_AA)
    elif style == 1:  # grain: near-parallel lines
        y = 0.0
        while y < size:
            y += rng.uniform(4, 24)
            dy = rng.uniform(-8, 8)
            cv2.line(image, (0, int(y)), (size, int(y + dy)), float(np.clip(mean + rng.normal(0, amplitude), 0, 1)),
                     1, cv2.LINE_AA)
    for _ in range(int(rng.integers(10, 40))):  # strokes
        p = rng.uniform(0, size, 2)
        q = p + rng.normal(0, size / 4, 2)
        cv2.line(image, tuple(int(x) for x in p), tuple(int(x) for x in q),
                 float(np.clip(mean + rng.normal(0, amplitude * 1.5), 0, 1)), int(rng.integers(1, 6)), cv2.LINE_AA)
    return image


def _textured_quad(corners: np.ndarray, normal: np.ndarray, image: np.ndarray, texel_m: float) -> Polygon:
    e1 = unit((corners[1] - corners[0])[None])[0]
    e2 = np.cross(normal, e1)
    polygon = Polygon(corners, normal, float(image.mean()), cull=False)
    polygon.texture = Texture(image, corners[0].copy(), np.array([e1, e2]) * texel_m)
    return polygon


def _plane_quad(center, normal, up_hint, half_w, half_h) -> tuple[np.ndarray, np.ndarray]:
    normal = unit(np.asarray(normal, float)[None])[0]
    e1 = unit(np.cross(up_hint, normal)[None])[0]
    e2 = np.cross(normal, e1)
    c = np.asarray(center, float)
    corners = np.array([c - half_w * e1 - half_h * e2, c + half_w * e1 - half_h * e2, c + half_w * e1 + half_h * e2,
                        c - half_w * e1 + half_h * e2])
    if np.cross(corners[1] - corners[0], corners[2] - corners[1]) @ normal < 0:
        corners = corners[::-1].copy()
    return corners, normal


def _posed_box(center, size, albedo, R) -> list:
    box = _box((0.0, 0.0, 0.0), size, albedo, "background")
    for polygon in box.polygons:
        polygon.vertices = polygon.vertices @ R.T + center
        polygon.normal = R @ polygon.normal
    return box.polygons


def make_random_background(kind: str, rng: np.random.Generator, mean: float, near: float, floor_min: float,
                           tan_half: tuple[float, float]) -> list:
    """Static polygons (camera frame) behind depth ``near`` metres, mean albedo about ``mean``; a floor
    lies at y >= ``floor_min`` (below the moving parts). Solids or planes drawn nearer than ``near`` are
    pushed back along z until they are not.

    ``texture``: a blotchy wall at 1.3 to 3 m and often a floor; ``planes``: the wall and 2 to 4 textured
    planes at random depths and tilts; ``lines``: a wall and floor with tiles, grain or strokes and 3 to 9
    thin rods at random angles. All kinds add 0 to 4 boxes. ``tan_half``: the image's half field of view
    (x, y) as tangents, which the wall and floor cover.
    """
    if kind not in BACKGROUNDS:
        raise ValueError(f"unknown background {kind!r} (expected one of {', '.join(BACKGROUNDS)})")
    polygons = []
    amplitude = rng.uniform(0.04, 0.18)
    wall_z = max(near + 0.2, rng.uniform(1.3, 3.0))
    texture = line_texture if kind == "lines" else noise_texture
    hw, hh = 1.6 * tan_half[0] * wall_z, 1.6 * tan_half[1] * wall_z
    wall = np.array([[-hw, -hh, wall_z], [hw, -hh, wall_z], [hw, hh, wall_z], [-hw, hh, wall_z]])[::-1].copy()
    polygons.append(_textured_quad(wall, np.array([0.0, 0.0, -1.0]), texture(rng, mean, amplitude, 512),
                                   2 * hw / 512))
    if kind == "lines" or rng.uniform() < 0.6:  # a floor y = h below the camera, from the near edge to the wall
        floor_y = max(rng.uniform(0.18, 0.4), floor_min)
        floor = np.array([[-hw, floor_y, 0.2], [hw, floor_y, 0.2], [hw, floor_y, wall_z], [-hw, floor_y, wall_z]])
        floor_tex = line_texture(rng, float(np.clip(mean + rng.normal(0, 0.12), 0.1, 0.9)), amplitude, 512)
        polygon = _textured_quad(floor, np.array([0.0, -1.0, 0.0]), floor_tex, 2 * hw / 512)
        polygons.append(polygon)
    if kind == "planes":
        for _ in range(int(rng.integers(2, 5))):
            z = rng.uniform(near + 0.1, wall_z - 0.05)
            center = (rng.uniform(-1, 1) * tan_half[0] * z, rng.uniform(-1, 1) * tan_half[1] * z, z)
            normal = Rotation.from_euler("xy", rng.uniform(-50, 50, 2), degrees=True).apply([0.0, 0.0, -1.0])
            corners, normal = _plane_quad(center, normal, [0.0, 1.0, 0.0], *(rng.uniform(0.08, 0.4, 2) * z))
            tex = (line_texture if rng.uniform() < 0.4 else noise_texture)(
                rng, float(np.clip(mean + rng.normal(0, 0.2), 0.05, 0.95)), amplitude)
            polygons += _behind([_textured_quad(corners, normal, tex, np.linalg.norm(corners[1] - corners[0]) / 256)],
                                near)
    if kind == "lines":
        for _ in range(int(rng.integers(3, 10))):
            z = rng.uniform(near + 0.05, wall_z - 0.05)
            center = np.array([rng.uniform(-1, 1) * tan_half[0] * z, rng.uniform(-1, 1) * tan_half[1] * z, z])
            R = Rotation.from_euler("zy", [rng.uniform(0, 180), rng.uniform(-40, 40)], degrees=True).as_matrix()
            thick = rng.uniform(0.004, 0.02)
            polygons += _behind(_posed_box(center, (3.0 * z, thick, thick), float(rng.uniform(0.05, 0.95)), R), near)
    for _ in range(int(rng.integers(0, 5))):
        z = rng.uniform(near + 0.1, wall_z - 0.1)
        size = rng.uniform(0.05, 0.25, 3)
        center = np.array([rng.uniform(-1, 1) * tan_half[0] * z, rng.uniform(-1, 1) * tan_half[1] * z, z])
        R = Rotation.from_euler("y", rng.uniform(-40, 40), degrees=True).as_matrix()
        polygons += _behind(_posed_box(center, size, float(rng.uniform(0.05, 0.95)), R), near)
    return polygons


def _behind(polygons: list, near: float) -> list:
    """``polygons`` moved along +z so that none of their vertices is nearer than ``near`` (in place)."""
    shift = near - min(p.vertices[:, 2].min() for p in polygons)
    if shift > 0:
        for polygon in polygons:
            polygon.vertices = polygon.vertices + [0.0, 0.0, shift]
            if polygon.texture is not None:
                polygon.texture.origin = polygon.texture.origin + [0.0, 0.0, shift]
    return polygons


def make_clutter(rng: np.random.Generator, distance: float, moving_boxes: np.ndarray, tan_half, mean: float) -> list:
    """Static solids (a list of polygon lists, camera frame) at the object's depth (``distance`` +- 0.12 m)
    beside, above and below its path.

    ``moving_boxes`` (F, 2, 3): per frame the axis-aligned box (min, max corners, camera frame) around the
    object and gripper; a solid whose box comes within 5 mm of any of them is drawn again (40 draws per
    wanted solid in all, so a crowded path may get fewer). Solids: boxes and extruded profiles 30 to 150 mm,
    and rails (long bars above or below the path).
    """
    lo, hi = moving_boxes[:, 0].min(axis=0), moving_boxes[:, 1].max(axis=0)
    polygons, placed = [], 0
    wanted = int(rng.integers(4, 9))
    for _ in range(40 * wanted):
        if placed == wanted:
            break
        z = distance + rng.uniform(-0.12, 0.12)
        where = rng.choice(["left", "right", "above", "below"])
        sx, sy, sz = rng.uniform(0.03, 0.15, 3)
        x_span, y_span = tan_half[0] * z, tan_half[1] * z
        if where in ("left", "right"):
            x = (lo[0] - rng.uniform(0, 0.1) - sx / 2) if where == "left" else (hi[0] + rng.uniform(0, 0.1) + sx / 2)
            y = rng.uniform(-y_span, y_span)
        else:
            x = rng.uniform(-x_span, x_span)
            y = (lo[1] - rng.uniform(0, 0.1) - sy / 2) if where == "above" else (hi[1] + rng.uniform(0, 0.1) + sy / 2)
        rail = where in ("above", "below") and rng.uniform() < 0.35
        if rail:
            sx, sy, sz = 2.5 * x_span, rng.uniform(0.008, 0.03), rng.uniform(0.008, 0.03)
            x = 0.0
        yaw = 0.0 if rail else rng.uniform(-45, 45)
        R = Rotation.from_euler("y", yaw, degrees=True).as_matrix()
        center = np.array([x, y, z])
        half = np.abs(R) @ (np.array([sx, sy, sz]) / 2) + 0.005
        if np.any(np.all((center - half <= moving_boxes[:, 1]) & (center + half >= moving_boxes[:, 0]), axis=1)):
            continue
        albedo = float(np.clip(mean + rng.normal(0, 0.25), 0.05, 0.95))
        if rail or rng.uniform() < 0.5:
            polygons.append(_posed_box(center, (sx, sy, sz), albedo, R))
        else:
            shape = str(rng.choice(RANDOM_SHAPES))
            solid = extrude(profile(shape, sx, sy), -sz / 2, sz / 2, np.full(len(PROFILES[shape]) + 2, albedo))
            for polygon in solid.polygons:
                polygon.vertices = polygon.vertices @ R.T + center
                polygon.normal = R @ polygon.normal
            polygons.append(solid.polygons)
        placed += 1
    return polygons


# -- motion and light --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Motion:
    """A smooth path: centre (3,) metres, translation amplitudes (3,) metres, rotation amplitudes
    (yaw, pitch, roll) degrees, pitch offset degrees, the turn per frame in degrees and phases (4,);
    ``approach_deg`` turns the object about its x axis first (-90: the wrist points away from the camera)."""

    center: tuple
    amplitude_m: tuple
    amplitude_deg: tuple
    pitch_offset_deg: float
    per_frame_deg: float
    phases: tuple
    approach_deg: float = 0.0


def draw_motion(rng: np.random.Generator, distance: float, size: float, per_frame_deg: float,
                tan_half) -> Motion:
    """Yaw +-35 to 65 deg, pitch +-10 to 25 deg about -15 to 5, roll +-15 to 40 deg; the centre sways
    within the part of the view the object leaves free (10 to 50 % of it across, 10 to 40 % up and down)
    and +-0 to 50 mm in depth. The gripper comes from above (approach -20 to 10 deg) or, half of the
    time, from behind the object (approach -100 to -60 deg)."""
    free_x = max(distance * tan_half[0] - 0.6 * size - 0.03, 0.0)
    free_y = max(distance * tan_half[1] - 0.6 * size - 0.03, 0.0)
    amplitude = (free_x * rng.uniform(0.1, 0.5), free_y * rng.uniform(0.1, 0.4), rng.uniform(0.0, 0.05))
    center = (rng.uniform(-0.3, 0.3) * (free_x - amplitude[0]), rng.uniform(-0.1, 0.4) * (free_y - amplitude[1]),
              distance)
    return Motion(center, amplitude, (rng.uniform(35, 65), rng.uniform(10, 25), rng.uniform(15, 40)),
                  rng.uniform(-15, 5), per_frame_deg, tuple(rng.uniform(0, 2 * np.pi, 4)),
                  rng.uniform(-100, -60) if rng.uniform() < 0.5 else rng.uniform(-20, 10))


def random_trajectory(k: np.ndarray, m: Motion) -> np.ndarray:
    """(len(k), 4, 4) poses ``T_camera_object`` at frame times ``k`` (fractional allowed)."""
    omega = np.radians(m.per_frame_deg) / np.radians(m.amplitude_deg[0])
    k = np.asarray(k, float)
    p = m.phases
    angles = np.radians(np.column_stack([m.amplitude_deg[0] * np.sin(omega * k + p[0]),
                                         m.amplitude_deg[1] * np.cos(0.7 * omega * k + p[1]) + m.pitch_offset_deg,
                                         m.amplitude_deg[2] * np.sin(0.45 * omega * k + p[2])]))
    rotations = Rotation.from_euler("yxz", angles).as_matrix() @ Rotation.from_euler(
        "x", m.approach_deg, degrees=True).as_matrix()
    translations = np.asarray(m.center) + np.column_stack([
        m.amplitude_m[0] * np.sin(0.5 * omega * k + p[3]), m.amplitude_m[1] * np.cos(0.41 * omega * k + p[3]),
        m.amplitude_m[2] * np.sin(0.29 * omega * k + p[1])])
    return np.stack([make_transform(R, t) for R, t in zip(rotations, translations)])


@dataclass(frozen=True)
class Lighting:
    """Per frame: the unit direction towards the light (camera frame), ambient share, gain and offset
    (grey levels) of the exposure."""

    light: np.ndarray
    ambient: float
    gain: np.ndarray
    offset: np.ndarray


def draw_lighting(rng: np.random.Generator, frames: int, drift: float) -> Lighting:
    """A light from the camera's side (azimuth +-45 deg, from above by 10 to 60 deg), ambient 0.3 to 0.6;
    over the sequence the light turns by up to 200 * ``drift`` deg, the gain drifts by +-``drift``
    (relative) and the offset by +-30 * ``drift`` grey levels, along smooth random curves."""
    azimuth, elevation = np.radians(rng.uniform(-45, 45)), np.radians(rng.uniform(10, 60))
    turn = np.radians(rng.uniform(-1, 1, 2) * 200.0 * drift)
    s = np.linspace(0.0, 1.0, frames)
    az, el = azimuth + turn[0] * s, elevation + turn[1] * s
    light = unit(np.column_stack([np.sin(az) * np.cos(el), -np.sin(el), -np.cos(az) * np.cos(el)]))
    phase = rng.uniform(0, 2 * np.pi, 2)
    rate = rng.uniform(0.5, 2.0, 2) * 2 * np.pi
    gain = 1.0 + drift * np.sin(rate[0] * s + phase[0])
    offset = 30.0 * drift * np.sin(rate[1] * s + phase[1])
    return Lighting(light, float(rng.uniform(0.3, 0.6)), gain, offset)
