"""Precision judged by surface, for objects that carry lines of their own (print, texture) that no
list of edges holds, as a user with a CAD model of the object would judge a model.

A segment is on the object when its centre lies within ``tol.position_tol`` of one of the truth's
``faces`` (inside the face polygon, grown by the same margin) and its direction lies in that face's
plane within ``tol.angle_tol_deg``. With a ``support_face`` (the face the object stands on, e.g. a
box on a board that moves with it), a segment in that face's plane within ``support_radius`` of
the object also counts as on the moving body. Everything else is background.

The face an object stands on is hidden from a camera above its support in every frame, so the
truth's poses can check a given support face (``facing_camera``): the teabox's README names face 0
(normal (0, -1, 0)) the bottom, but by its own poses that face turns towards the cameras in all 80
frames (cosine 0.49 to 0.53) while face 1 (normal (0, 0, -1)) turns away in all of them (-0.82 to
-0.86); judged with face 0, a vertical plane through the box's front counted as the board. Face 2
(the back) is hidden in every frame too, less squarely (-0.63 to -0.59); judged with it, the teabox
model's surface precision is 0.318 against 0.372 with face 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .evaluate import Tolerances
from .geometry import invert
from .segments import Segments


@dataclass(frozen=True)
class Face:
    """A planar convex face: vertices (K, 3) metres in the object frame, outward unit normal (3,)."""

    vertices: np.ndarray
    normal: np.ndarray


def faces_of(doc: dict) -> list[Face]:
    """The ``faces`` of a truth document (vertex lists and outward normals); [] when it has none."""
    faces = []
    for face in doc.get("faces", []) or []:
        vertices = np.asarray(face["vertices"], float).reshape(-1, 3)
        normal = np.asarray(face["normal"], float)
        faces.append(Face(vertices, normal / np.linalg.norm(normal)))
    return faces


def _in_plane(segments: Segments, face: Face, tol: Tolerances) -> np.ndarray:
    """(N,) bool: centre within the distance of the face's plane and direction within the angle of it."""
    distance = np.abs((segments.centers - face.vertices[0]) @ face.normal)
    out_of_plane = np.abs(segments.directions @ face.normal)
    return (distance <= tol.position_tol) & (out_of_plane <= np.sin(np.radians(tol.angle_tol_deg)))


def _inside(points: np.ndarray, face: Face, margin: float) -> np.ndarray:
    """(N,) bool: points (projected on the plane) inside the convex polygon grown by ``margin``."""
    ring = face.vertices
    centroid = ring.mean(axis=0)
    inside = np.ones(len(points), bool)
    for a, b in zip(ring, np.roll(ring, -1, axis=0)):
        outward = np.cross(b - a, face.normal)
        outward /= np.linalg.norm(outward)
        if (centroid - a) @ outward > 0:      # vertices listed the other way round
            outward = -outward
        inside &= (points - a) @ outward <= margin
    return inside


def on_body(segments: Segments, faces: list[Face], tol: Tolerances = Tolerances(), support_face: int | None = None,
            support_radius: float = 0.3) -> np.ndarray:
    """(N,) bool: segments (object frame) on a face, or on the support face's plane near the object."""
    result = np.zeros(len(segments), bool)
    for face in faces:
        result |= _in_plane(segments, face, tol) & _inside(segments.centers, face, tol.position_tol)
    if support_face is not None:
        face = faces[support_face]
        centre = np.concatenate([f.vertices for f in faces]).mean(axis=0)
        near = np.linalg.norm(segments.centers - centre, axis=1) <= support_radius
        result |= _in_plane(segments, face, tol) & near
    return result


def facing_camera(face: Face, poses: np.ndarray) -> np.ndarray:
    """(P,) the cosine between the face's outward normal and the direction from its centre to the
    camera, per pose (``poses``: (P, 4, 4) T_camera_object): > 0 where the camera sees its outside."""
    centre = poses[:, :3, :3] @ face.vertices.mean(axis=0) + poses[:, :3, 3]           # (P, 3) camera frame
    normal = poses[:, :3, :3] @ face.normal
    return -np.sum(normal * centre, axis=1) / np.linalg.norm(centre, axis=1)


def support_face_problem(faces: list[Face], support_face: int, poses: np.ndarray) -> str | None:
    """Why ``support_face`` cannot be the face the object stands on (it faces the camera in most of
    the truth's ``poses``, (P, 4, 4) T_camera_object), naming the face turned away the most (a
    suggestion: of several hidden faces the one the cameras look at most squarely from behind);
    None if it can."""
    if not len(poses):
        return None
    share = float(np.mean(facing_camera(faces[support_face], poses) > 0))   # the other faces: ``hidden_face``
    if share <= 0.5:
        return None
    problem = f"support face {support_face} faces the cameras in {share:.0%} of the truth's poses, so the object " \
              "cannot stand on it"
    hidden = hidden_face(faces, poses)
    if hidden is None or hidden == support_face:
        return problem + " (and no face of the truth faces away from them)"
    return problem + f"; face {hidden} faces away the most (try --support-face {hidden})"


def hidden_face(faces: list[Face], poses: np.ndarray) -> int | None:
    """The face turned away from the cameras the most over the truth's ``poses`` (median facing
    cosine below 0), or None: what an object standing on a board would stand on."""
    if not len(poses) or not faces:
        return None
    facing = np.median(np.array([facing_camera(face, poses) for face in faces]), axis=1)
    return int(np.argmin(facing)) if facing.min() < 0 else None


def surface_scores(model: Segments, faces: list[Face], tol: Tolerances = Tolerances(),
                   support_face: int | None = None) -> dict:
    """Of the accepted segments: the share on the body (``surface_precision``) and the rest
    (``surface_background``)."""
    accepted = model.select(model.accepted)
    if len(accepted) == 0:
        return {"surface_precision": float("nan"), "surface_background": float("nan")}
    share = float(on_body(accepted, faces, tol, support_face).mean())
    return {"surface_precision": share, "surface_background": 1.0 - share}


def frame_surface_scores(frames, truth, faces: list[Face], tol: Tolerances = Tolerances(),
                         support_face: int | None = None) -> dict:
    """Single-frame figures by surface over ``frames`` (iterable of (timestamp_ns, Segments in the
    camera frame)), each placed by the truth's pose at its time (frames without one are skipped):
    ``surface_segments_per_frame``, the mean number of a frame's 3D segments on the body (``on_body``),
    and ``surface_precision_frames``, their share of all the frames' segments. Why: on an object with
    print or texture, the segments a stereo pair gives on the body, not only on its edges, are what a
    tracker or a model can use (issue 9 asks 300 a pair on the real teabox)."""
    on, total, counted = 0, 0, 0
    for t_ns, segments in frames:
        T = truth.pose_at(int(t_ns))
        if T is None:
            continue
        counted += 1
        total += len(segments)
        if len(segments):
            on += int(on_body(segments.transformed(invert(T), segments.frame_id), faces, tol, support_face).sum())
    return {"surface_segments_per_frame": on / counted if counted else float("nan"),
            "surface_precision_frames": on / total if total else float("nan")}
