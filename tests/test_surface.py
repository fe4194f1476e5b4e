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
