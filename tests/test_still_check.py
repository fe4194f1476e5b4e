"""The images' check of which part of a model moves with the object (``still_check``, ``accum check``)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from accumcli.cli import main
from accumcli.geometry import invert, make_transform
from accumcli.lines2d import Gradients
from accumcli.recording import StereoIntrinsics
from accumcli.segments import Segments
from accumcli.still_check import still_check

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data" / "sim_box.mcap"
INTRINSICS = StereoIntrinsics(400.0, 400.0, 160.0, 120.0, 0.08, 320, 240)


def _segments(centers, directions, lengths) -> Segments:
    n = len(centers)
    return Segments("gripper", np.asarray(centers, float), np.asarray(directions, float), np.asarray(lengths, float),
                    np.ones(n), np.ones(n, np.int64))


def _draw(image: np.ndarray, segments: Segments, T_camera_object: np.ndarray) -> None:
    ends = segments.endpoints().reshape(-1, 3)
    uv = INTRINSICS.project(ends @ T_camera_object[:3, :3].T + T_camera_object[:3, 3])[0].reshape(-1, 2, 2)
    for a, b in uv:
        cv2.line(image, tuple(int(round(x)) for x in a), tuple(int(round(x)) for x in b), 255, 2)


def _views(poses, moving: Segments, still_camera: Segments):
    """Images of ``moving`` (object frame) at each pose and of ``still_camera`` (camera frame) always
    at the same place, with their gradients."""
    views = []
    for T in poses:
        image = np.full((240, 320), 60, np.uint8)
        _draw(image, moving, T)
        _draw(image, still_camera, np.eye(4))
        views.append((Gradients.of(image), T))
    return views


def test_a_segment_on_the_object_moves_and_one_held_still_in_the_view_stays_still():
    turn = [make_transform(Rotation.from_euler("y", 4 * k, degrees=True).as_matrix(), [0.004 * k, 0.0, 0.5])
            for k in range(6)]
    on_object = _segments([[0.0, 0.0, 0.0], [-0.03, 0.02, 0.0]], [[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]], [0.05, 0.04])
    background = _segments([[0.05, -0.03, 0.55]], [[0.0, 1.0, 0.0]], [0.05])     # camera frame
    # the model holds the background where the first frame saw it: in the object frame by its pose
    model_background = background.transformed(invert(turn[0]), "gripper")
    model = _segments(np.vstack([on_object.centers, model_background.centers]),
                      np.vstack([on_object.directions, model_background.directions]),
                      np.concatenate([on_object.lengths, model_background.lengths]))
    check = still_check(model, _views(turn, on_object, background), INTRINSICS)
    assert check.moving.tolist() == [True, True, False]
    assert check.still.tolist() == [False, False, True]
    assert check.shares()["still_share"] == pytest.approx(0.05 / 0.14)


def test_without_motion_nothing_is_told():
    still = [make_transform(np.eye(3), [0.0, 0.0, 0.5])] * 4
    on_object = _segments([[0.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]], [0.05])
    check = still_check(on_object, _views(still, on_object, on_object.select([])), INTRINSICS)
    assert check.moving_votes.tolist() == [0] and check.still_votes.tolist() == [0]
    assert check.shares()["undecided_share"] == 1.0


def test_a_frames_own_segments_split_into_the_object_moving_and_the_background_still():
    """One frame's extracted segments hold object and background: placed in the object frame by
    its pose, the truth's edges say which is which, and the other frames' images must agree."""
    from accumcli.evaluate import EdgeSamples, classify
    from accumcli.extract import extract_frame
    from accumcli.model_io import read_truth
    from accumcli.recording import Recording
    from accumcli.still_check import sampled_frames

    truth = read_truth(SAMPLE.with_suffix(".truth.json"))
    with Recording(SAMPLE) as rec:
        wanted = set(sampled_frames(rec.frame_count_hint, 12).tolist())
        views, seen = [], None
        for frame in rec.frames():
            if seen is None:
                seen = extract_frame(frame).segments.transformed(invert(frame.T_camera_object), "gripper")
            if frame.index in wanted:
                views.append((Gradients.of(frame.left), frame.T_camera_object))
                intrinsics = frame.intrinsics
    distance = classify(seen, EdgeSamples.of(truth))[0]
    check = still_check(seen, views, intrinsics)
    on_edge, background = distance <= 0.004, distance > 0.02
    assert on_edge.sum() > 50 and background.sum() > 50
    share = lambda verdict, part: seen.lengths[verdict & part].sum() / seen.lengths[part].sum()  # noqa: E731
    assert share(check.moving, on_edge) >= 0.95
    assert share(check.still, background) >= 0.85 and share(check.moving, background) <= 0.05


def test_accum_check_prints_the_shares_and_refuses_a_model_with_nothing_accepted(tmp_path, small_recording):
    runner = CliRunner()
    model = tmp_path / "model.json"
    assert runner.invoke(main, ["-q", "accumulate", small_recording, "-o", str(model)]).exit_code == 0
    result = runner.invoke(main, ["check", str(model), small_recording, "--json"])
    assert result.exit_code == 0, result.output
    import json

    figures = json.loads(result.output)
    assert figures["moving_share"] + figures["still_share"] + figures["undecided_share"] == pytest.approx(1.0)
    assert figures["frames_checked"] >= 2
    doc = json.loads(model.read_text())
    for s in doc["segments"]:
        s["confidence"] = 0.2
    model.write_text(json.dumps(doc))
    result = runner.invoke(main, ["check", str(model), small_recording])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert result.output.strip().splitlines()[-1].endswith("the model has no accepted segment (confidence >= 0.5) "
                                                           "to check")
