"""A triangle z-buffer for planar polygons, convex or not, flat or textured (numpy + OpenCV).

Every polygon is triangulated once (ear clipping in its plane). A triangle
covers the supersampled pixels whose centres lie inside it or on its boundary
(per row, the span of columns where its three edge functions are >= 0; the
pixels of all spans at once, vectorised); each covered pixel gets the
depth of the triangle's plane along its ray (1/z is affine in the image), and
the nearest surface wins. Coverage is exact at pixel centres, so neighbouring
triangles of one face leave no seam and the area-averaged image is unbiased.
Besides colour and depth the buffer keeps, per pixel, the index of the polygon
that won, from which the simulator decides exactly what each camera saw.

Pixel convention: supersampled pixel (column j, row i) has its centre at image
point (u, v) = ((j + 0.5) / S - 0.5, (i + 0.5) / S - 0.5), S the supersampling.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .render import DECAL_BIAS_M, NEAR_M, PinholeCamera
from .scene import Polygon, _clip_convex

SPAN_EPS = 1e-6  # px: a pixel centre on an edge shared by two triangles is covered by both


@dataclass
class Texture:
    """An albedo image on a polygon's plane: ``image`` (h, w) float32 in [0, 1]; texel (column c, row r)
    sits at ``origin + c * axes[0] + r * axes[1]`` (part frame, metres); it repeats beyond its borders."""

    image: np.ndarray
    origin: np.ndarray
    axes: np.ndarray


@dataclass
class Mesh:
    """Polygons of one rigid part as triangles: ``triangles`` (T, 3, 3) metres in the part frame,
    ``face`` (T,) the polygon of each; per polygon (P,): normals (P, 3), plane offsets ``normals . x``,
    albedo, cull, decal, texture (or None)."""

    triangles: np.ndarray
    face: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    albedo: np.ndarray
    cull: np.ndarray
    decal: np.ndarray
    textures: list
    first_id: int = 0

    @classmethod
    def of(cls, polygons: list[Polygon], first_id: int = 0) -> "Mesh":
        """Triangulate ``polygons``; polygon j gets the buffer id ``first_id + j``."""
        triangles, face = [], []
        for j, polygon in enumerate(polygons):
            for tri in triangulate(polygon.vertices, polygon.normal):
                triangles.append(polygon.vertices[tri])
                face.append(j)
        normals = np.array([p.normal for p in polygons], float).reshape(-1, 3)
        return cls(np.array(triangles, float).reshape(-1, 3, 3), np.array(face, int), normals,
                   np.array([p.normal @ p.vertices[0] for p in polygons]), np.array([p.albedo for p in polygons]),
                   np.array([p.cull for p in polygons], bool), np.array([p.decal for p in polygons], bool),
                   [getattr(p, "texture", None) for p in polygons], first_id)


def triangulate(vertices: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(K - 2, 3) vertex indices of triangles covering a simple planar polygon (K, 3), by ear clipping."""
    k = len(vertices)
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    p = np.column_stack([vertices @ e1, vertices @ e2])
    if _area2(p) < 0:
        order = list(range(k))[::-1]
    else:
        order = list(range(k))
    out = []
    while len(order) > 3:
        n = len(order)
        for i in range(n):
            a, b, c = order[i - 1], order[i], order[(i + 1) % n]
            if _cross(p[a], p[b], p[c]) <= 1e-15:
                continue  # reflex or degenerate corner
            others = [m for m in order if m not in (a, b, c)]
            if others and np.any(_inside(p[others], p[a], p[b], p[c])):
                continue
            out.append((a, b, c))
            order.pop(i)
            break
        else:  # numerically degenerate remainder: fan it
            out += [(order[0], order[m], order[m + 1]) for m in range(1, len(order) - 1)]
            order = []
    if len(order) == 3:
        out.append(tuple(order))
    return np.array(out, int).reshape(-1, 3)


def _area2(p: np.ndarray) -> float:
    return float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


def _cross(a, b, c) -> float:
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _inside(q: np.ndarray, a, b, c) -> np.ndarray:
    """(N,) bool: points q (N, 2) inside or on the counter-clockwise triangle a, b, c."""
    def side(p0, p1):
        return (p1[0] - p0[0]) * (q[:, 1] - p0[1]) - (p1[1] - p0[1]) * (q[:, 0] - p0[0])
    return (side(a, b) >= -1e-15) & (side(b, c) >= -1e-15) & (side(c, a) >= -1e-15)


@dataclass
class Buffers:
    """Supersampled colour (float32, shaded albedo), depth (float32, metres along z, inf where empty)
    and id (int32, winning polygon id, -1 where empty) of one camera."""

    color: np.ndarray
    depth: np.ndarray
    ids: np.ndarray

    @classmethod
    def empty(cls, camera: PinholeCamera, supersample: int) -> "Buffers":
        shape = (camera.height * supersample, camera.width * supersample)
        return cls(np.zeros(shape, np.float32), np.full(shape, np.inf, np.float32), np.full(shape, -1, np.int32))

    def copy(self) -> "Buffers":
        return Buffers(self.color.copy(), self.depth.copy(), self.ids.copy())


def draw(buffers: Buffers, mesh: Mesh, T_camera_part: np.ndarray, camera: PinholeCamera, supersample: int,
         light: np.ndarray, ambient: float) -> None:
    """Rasterise ``mesh`` posed at ``T_camera_part`` into ``buffers`` in place, with the depth test.

    Shading is Lambertian: albedo * (ambient + (1 - ambient) * max(0, n . light)), ``light`` the unit
    direction towards the light in the camera frame. Back faces of ``cull`` polygons are skipped; decal
    polygons win the depth test against the surface they are painted on.
    """
    S = supersample
    H, W = buffers.depth.shape
    R, t = T_camera_part[:3, :3], T_camera_part[:3, 3]
    normals = mesh.normals @ R.T
    offsets = mesh.offsets + normals @ t
    shades = (mesh.albedo * (ambient + (1.0 - ambient) * np.maximum(0.0, normals @ light))).astype(np.float32)
    front = ~mesh.cull | (offsets < 0)  # the camera centre is on the outer side of the plane
    tris = mesh.triangles @ R.T + t
    keep = front[mesh.face]
    for tri, f in zip(tris[keep], mesh.face[keep]):
        if tri[:, 2].min() < NEAR_M:
            poly = _clip_convex(tri, np.array([0.0, 0.0, -1.0]), -NEAR_M)
            pieces = [poly[[0, m, m + 1]] for m in range(1, len(poly) - 1)]
        else:
            pieces = [tri]
        for piece in pieces:
            _fill(buffers, piece, int(f), normals[f], offsets[f], shades[f], mesh, R, t, camera, S, W, H)


def _fill(buffers: Buffers, tri: np.ndarray, f: int, normal, offset, shade, mesh: Mesh, R, t,
          camera: PinholeCamera, S: int, W: int, H: int) -> None:
    if abs(offset) < 1e-12:
        return  # seen edge-on
    u = ((camera.fx * tri[:, 0] / tri[:, 2] + camera.cx) + 0.5) * S - 0.5
    v = ((camera.fy * tri[:, 1] / tri[:, 2] + camera.cy) + 0.5) * S - 0.5
    area = (u[1] - u[0]) * (v[2] - v[0]) - (v[1] - v[0]) * (u[2] - u[0])
    y0, y1 = max(int(np.ceil(v.min())), 0), min(int(np.floor(v.max())), H - 1)
    if area == 0 or y0 > y1:
        return
    # per row of pixel centres, the span of columns inside all three edges (edge function >= 0)
    sign = 1.0 if area > 0 else -1.0
    ys = np.arange(y0, y1 + 1, dtype=np.float64)
    lo, hi = np.zeros_like(ys), np.full_like(ys, W - 1.0)
    for i in range(3):
        j = (i + 1) % 3
        a, b = -sign * (v[j] - v[i]), sign * (u[j] - u[i])  # a x + b y + c >= 0 on the inner side of i -> j
        c = -(a * u[i] + b * v[i])
        if a > 0:
            lo = np.maximum(lo, -(b * ys + c) / a - SPAN_EPS)
        elif a < 0:
            hi = np.minimum(hi, -(b * ys + c) / a + SPAN_EPS)
        else:
            hi = np.where(b * ys + c >= -SPAN_EPS, hi, -1.0)
    first, last = np.ceil(lo).astype(np.int64), np.floor(hi).astype(np.int64)
    counts = np.maximum(last - first + 1, 0)
    n = int(counts.sum())
    if n == 0:
        return
    rows = np.repeat(np.arange(y0, y1 + 1, dtype=np.int64), counts)
    cols = np.arange(n, dtype=np.int64) - np.repeat(np.cumsum(counts) - counts - first, counts)
    index = rows * W + cols
    # depth along the ray (x, y, 1) of each pixel centre: 1/z = (n . ray) / offset
    ray_x = ((cols + 0.5) / S - 0.5 - camera.cx) / camera.fx
    ray_y = ((rows + 0.5) / S - 0.5 - camera.cy) / camera.fy
    z = (offset / (normal[0] * ray_x + normal[1] * ray_y + normal[2])).astype(np.float32)
    depth = buffers.depth.reshape(-1)
    if mesh.decal[f]:
        z = z - np.float32(DECAL_BIAS_M)
        closer = z <= depth[index]
    else:
        closer = z < depth[index]
    index, z = index[closer], z[closer]
    if index.size == 0:
        return
    depth[index] = z
    buffers.ids.reshape(-1)[index] = mesh.first_id + f
    texture = mesh.textures[f]
    if texture is None:
        buffers.color.reshape(-1)[index] = shade
        return
    # texel coordinates of each pixel's surface point: (p_part - origin) @ M.T, with p_part = R.T (p_cam - t)
    M = np.linalg.solve(texture.axes @ texture.axes.T, texture.axes) @ R.T
    origin = t + R @ texture.origin
    px, py, pz = ray_x[closer] * z - origin[0], ray_y[closer] * z - origin[1], z - origin[2]
    st = [M[k, 0] * px + M[k, 1] * py + M[k, 2] * pz for k in (0, 1)]
    buffers.color.reshape(-1)[index] = sample_wrap(texture.image, st[0], st[1]) * (shade / max(mesh.albedo[f],
                                                                                            1e-6))


def sample_wrap(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(N,) float32: ``image`` (h, w) interpolated bilinearly at columns x, rows y (N,), repeating the image."""
    h, w = image.shape
    n = len(x)
    width = 4096  # cv2.remap wants maps under 32767 on a side
    rows = -(-n // width)
    maps = []
    for values, period in ((x, w), (y, h)):
        m = np.zeros(rows * width, np.float32)
        m[:n] = np.mod(values, period)
        maps.append(m.reshape(rows, width))
    return cv2.remap(image, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP).reshape(-1)[:n]
