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


def _cameras_above() -> np.ndarray:
    """(3, 4, 4) T_camera_object of cameras 0.5 m above the box of ``_box_faces``, looking down at it
    from 0 to 40 degrees off vertical."""
    from scipy.spatial.transform import Rotation

    from accumcli.geometry import invert, make_transform

    poses = []
    for tilt in (0.0, 20.0, 40.0):
        R_object_camera = Rotation.from_euler("x", 180 - tilt, degrees=True).as_matrix()   # optical axis down
        eye = np.array([0.05, 0.05, 0.05]) - 0.5 * R_object_camera[:, 2]
        poses.append(invert(make_transform(R_object_camera, eye)))
    return np.array(poses)


def test_a_support_face_that_faces_the_cameras_is_named_and_the_hidden_one_proposed():
    """The bottom (face 4) is hidden from cameras above in every pose, the top (face 5) faces them."""
    from accumcli.surface import facing_camera, support_face_problem

    faces, poses = _box_faces(), _cameras_above()
    assert np.all(facing_camera(faces[4], poses) < -0.7) and np.all(facing_camera(faces[5], poses) > 0.7)
    assert support_face_problem(faces, 4, poses) is None
    problem = support_face_problem(faces, 5, poses)
    assert "support face 5 faces the cameras in 100%" in problem and "try --support-face 4" in problem
    assert support_face_problem(faces, 5, np.zeros((0, 4, 4))) is None
    # a truth whose only face faces the cameras proposes nothing
    assert "no face of the truth faces away" in support_face_problem(faces[5:], 0, poses)


def _box_truth(path, faces, poses) -> str:
    """A truth sidecar of the box of ``_box_faces`` with ``poses`` (K, 4, 4) at 0 .. K-1 ns."""
    import json

    from accumcli.geometry import quat_from_transform

    path.write_text(json.dumps({
        "format": "accum.truth/1", "object_frame": "object", "camera_frame": "camera_left",
        "edges": [{"a": [0, 0, 0.1], "b": [0.1, 0, 0.1]}],
        "faces": [{"vertices": f.vertices.tolist(), "normal": f.normal.tolist()} for f in faces],
        "poses": [{"timestamp_ns": k, "translation": t.tolist(), "rotation_xyzw": q.tolist()}
                  for k, (t, q) in enumerate(map(quat_from_transform, poses))]}))
    return str(path)


def test_single_frames_are_judged_by_surface_in_each_frames_pose(tmp_path):
    """Per frame, the segments (camera frame) are placed by the truth's pose at the frame's time: print
    on the top face counts, the floor does not, the board's plane only with its support face; a frame
    without a truth pose is not counted."""
    from accumcli.model_io import read_truth
    from accumcli.surface import frame_surface_scores

    faces, poses = _box_faces(), _cameras_above()
    truth = read_truth(_box_truth(tmp_path / "box.truth.json", faces, poses))
    body = _segments([[0.05, 0.05, 0.102], [0.05, 0.3, -0.2], [0.25, 0.05, 0.0]],   # print, floor, board
                     [[1, 0, 0], [1, 0, 0], [0, 1, 0]])
    frames = [(k, body.transformed(T, "camera_left")) for k, T in enumerate(poses)]
    frames.append((10**9, body.transformed(poses[0], "camera_left")))    # no truth pose at 1 s
    plain = frame_surface_scores(frames, truth, faces)
    assert plain["surface_segments_per_frame"] == 1.0 and abs(plain["surface_precision_frames"] - 1 / 3) < 1e-12
    board = frame_surface_scores(frames, truth, faces, support_face=4)
    assert board["surface_segments_per_frame"] == 2.0 and abs(board["surface_precision_frames"] - 2 / 3) < 1e-12
    # segments 20 mm deeper than the truth's pose put the print off the top face
    far = poses[1].copy()
    far[2, 3] += 0.02
    shifted = frame_surface_scores([(1, body.transformed(far, "camera_left"))], truth, faces)
    assert shifted["surface_segments_per_frame"] == 0.0


def test_eval_warns_of_a_support_face_that_faces_the_cameras(tmp_path, caplog):
    from accumcli.model_io import write_model
    from accumcli.runs import evaluate_file

    faces, poses = _box_faces(), _cameras_above()
    model = tmp_path / "model.json"
    write_model(model, _segments([[0.05, 0.05, 0.1]], [[1, 0, 0]]))
    truth = _box_truth(tmp_path / "box.truth.json", faces, poses)
    with caplog.at_level("WARNING", logger="accumcli"):
        figures = evaluate_file(str(model), str(truth), support_face=5)
    assert figures["surface_precision"] == 1.0
    assert "support face 5 faces the cameras in 100%" in caplog.text and "try --support-face 4" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="accumcli"):
        evaluate_file(str(model), str(truth), support_face=4)
    assert "support face" not in caplog.text
    with caplog.at_level("WARNING", logger="accumcli"):   # none given: the hidden face is proposed
        evaluate_file(str(model), str(truth))
    assert "surface figures count the object's faces only" in caplog.text and "--support-face 4" in caplog.text
