"""Precision judged by surface (accumcli.surface) on a hand-made box."""

from __future__ import annotations

import numpy as np

from accumcli.segments import Segments
from accumcli.surface import Face, on_body, surface_scores


def _box_faces() -> list[Face]:
    """The faces of a 0.1 x 0.1 x 0.1 m box with a corner at the origin (bottom: z = 0)."""
    faces = []
    for axis in range(3):
        for side in (0.0, 0.1):
            square = np.array([[0, 0], [0.1, 0], [0.1, 0.1], [0, 0.1]])
            vertices = np.insert(square, axis, side, axis=1)
            normal = np.zeros(3)
            normal[axis] = 1.0 if side else -1.0
            faces.append(Face(vertices, normal))
    return faces


def _segments(centers, directions) -> Segments:
    n = len(centers)
    return Segments("object", np.array(centers, float), np.array(directions, float), np.full(n, 0.01),
                    np.full(n, 0.9), np.ones(n, np.int64))


def test_print_on_a_face_is_on_the_body_and_the_floor_is_not():
    faces = _box_faces()
    segments = _segments([[0.05, 0.05, 0.102],     # print on the top face, 2 mm off: on
                          [0.05, 0.05, 0.11],      # 10 mm above the top: off
                          [0.05, 0.05, 0.1],       # on the top face plane but pointing out of it: off
                          [0.2, 0.05, 0.1],        # in the top face's plane, outside the face: off
                          [0.25, 0.05, 0.0]],      # on the bottom plane 0.2 m away (the board)
                         [[1, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0]])
    bottom = 4     # axis 2 (z), side 0
    assert on_body(segments, faces).tolist() == [True, False, False, False, False]
    assert on_body(segments, faces, support_face=bottom).tolist() == [True, False, False, False, True]
    scores = surface_scores(segments, faces, support_face=bottom)
    assert scores["surface_precision"] == 0.4 and abs(scores["surface_background"] - 0.6) < 1e-12


def test_a_support_face_that_faces_the_cameras_is_named_and_the_hidden_one_proposed():
    """Cameras 0.5 m above the box, looking down at it from 0 to 40 degrees off vertical: the
    bottom (face 4) is hidden in every pose, the top (face 5) faces them in every one."""
    from scipy.spatial.transform import Rotation

    from accumcli.geometry import invert, make_transform
    from accumcli.surface import facing_camera, support_face_problem

    faces, poses = _box_faces(), []
    for tilt in (0.0, 20.0, 40.0):
        R_object_camera = Rotation.from_euler("x", 180 - tilt, degrees=True).as_matrix()   # optical axis down
        eye = np.array([0.05, 0.05, 0.05]) - 0.5 * R_object_camera[:, 2]
        poses.append(invert(make_transform(R_object_camera, eye)))
    poses = np.array(poses)
    assert np.all(facing_camera(faces[4], poses) < -0.7) and np.all(facing_camera(faces[5], poses) > 0.7)
    assert support_face_problem(faces, 4, poses) is None
    problem = support_face_problem(faces, 5, poses)
    assert "support face 5 faces the cameras in 100%" in problem and "try --support-face 4" in problem
    assert support_face_problem(faces, 5, np.zeros((0, 4, 4))) is None
