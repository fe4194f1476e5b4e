"""Pose estimation from a model: refinement, tracking, RANSAC re-acquisition, tracked accumulation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from accumcli.cli import main
from accumcli.evaluate import evaluate_model
from accumcli.geometry import make_transform, pose_error, transform_points
from accumcli.model_io import read_truth
from accumcli.pipeline import AccumulateParams, LineAccumulation
from accumcli.recording import Recording
from accumcli.segments import Segments
from accumcli.track import PoseTracker, ransac_pose, refine_pose


@pytest.fixture(scope="module")
def model_of_exact(noisy_pair) -> Segments:
    """A model accumulated over the exact recording (it knows from where each segment was seen)."""
    acc = LineAccumulation()
    with Recording(noisy_pair[0]) as rec:
        for frame in rec.frames():
            acc.step(frame, frame.T_camera_object)
    return acc.model()


def perturbed(T: np.ndarray, degrees: float, metres: float, seed: int = 0) -> np.ndarray:
    """T turned by ``degrees`` about a random axis through the object's origin and moved by ``metres``
    (as the object moves between frames: it turns about itself, not about the camera)."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    shift = rng.normal(size=3)
    R = Rotation.from_rotvec(np.radians(degrees) * axis / np.linalg.norm(axis)).as_matrix()
    c = T[:3, 3]
    return make_transform(R, c + metres * shift / np.linalg.norm(shift) - R @ c) @ T


def test_refinement_converges_from_a_perturbed_pose(noisy_pair, model_of_exact):
    exact, _ = noisy_pair
    model = model_of_exact
    truth = read_truth(exact.replace(".mcap", ".truth.json"))
    with Recording(exact) as rec:
        for frame in rec.frames(0, 3):
            T_true = truth.pose_at(frame.timestamp_ns)
            estimate = refine_pose(model, frame, perturbed(T_true, 6.0, 0.008, frame.index))
            rotation, translation = pose_error(estimate.T_camera_object, T_true)
            assert estimate.status == "tracked"
            assert rotation < 0.3 and translation < 0.001, (rotation, translation)


def test_tracker_follows_the_sequence_from_the_first_pose_only(noisy_pair, model_of_exact):
    exact, _ = noisy_pair
    truth = read_truth(exact.replace(".mcap", ".truth.json"))
    tracker = PoseTracker(model_of_exact)
    errors = []
    with Recording(exact) as rec:
        for frame in rec.frames():
            estimate = tracker.update(frame, frame.T_camera_object if frame.index == 0 else None)
            assert estimate.status == "tracked"
            errors.append(pose_error(estimate.T_camera_object, truth.pose_at(frame.timestamp_ns)))
    errors = np.array(errors)
    assert np.median(errors[:, 0]) < 0.2 and np.median(errors[:, 1]) < 0.001


def test_ransac_recovers_a_pose_from_3d_segments():
    rng = np.random.default_rng(3)
    n = 120
    d = rng.normal(size=(n, 3))
    model = Segments("o", rng.uniform(-0.06, 0.06, (n, 3)), d / np.linalg.norm(d, axis=1, keepdims=True),
                     np.full(n, 0.012), np.ones(n), np.ones(n, np.int64))
    T_true = make_transform(Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix(), [0.02, -0.01, 0.5])
    keep = rng.random(n) < 0.7
    outliers = 80
    centers = np.vstack([transform_points(T_true, model.centers[keep]), rng.uniform(-0.3, 0.3, (outliers, 3)) +
                         [0, 0, 0.8]])
    dirs = np.vstack([model.directions[keep] @ T_true[:3, :3].T, rng.normal(size=(outliers, 3))])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    observed = Segments("camera", centers, dirs, np.full(len(centers), 0.012), np.ones(len(centers)),
                        np.ones(len(centers), np.int64))
    result = ransac_pose(model, observed, np.random.default_rng(0))
    rotation, translation = pose_error(result.pose, T_true)
    assert result.support >= 0.8 * keep.sum() and rotation < 1.0 and translation < 0.003
    assert result.reason == "" and result.hypotheses[0][1] == result.support


def test_track_command_writes_poses_json_and_mcap(noisy_pair, tmp_path):
    from mcap.reader import make_reader

    exact, _ = noisy_pair
    runner = CliRunner()
    model = tmp_path / "model.json"
    assert runner.invoke(main, ["accumulate", exact, "-o", str(model), "--frames", "0:10"]).exit_code == 0
    poses_json, poses_mcap = tmp_path / "poses.json", tmp_path / "poses.mcap"
    result = runner.invoke(main, ["track", str(model), exact, "-o", str(poses_json), "-o", str(poses_mcap)])
    assert result.exit_code == 0, result.output
    doc = json.loads(poses_json.read_text())
    assert doc["format"] == "accum.poses/1" and doc["child_frame_id"] == "gripper" and len(doc["poses"]) == 16
    with open(poses_mcap, "rb") as f:
        messages = list(make_reader(f).iter_messages(topics=["/tf"]))
    assert len(messages) == sum(p["status"] == "tracked" for p in doc["poses"]) >= 14
    figures = json.loads(runner.invoke(main, ["eval", "--poses", str(poses_json),
                                              exact.replace(".mcap", ".truth.json"), "--json"]).output)
    assert figures["tracked_fraction"] >= 0.85 and figures["median_rotation_deg"] < 0.5
    assert figures["median_translation_mm"] < 2.0
    bad = runner.invoke(main, ["track", str(model), exact, "-o", str(tmp_path / "p.json"), "--init", "1,2,3"])
    assert bad.exit_code == 2 and "x,y,z,qx,qy,qz,qw" in bad.output


def test_tracked_motion_repairs_noisy_gripper_poses(noisy_pair):
    exact, noisy = noisy_pair
    truth = read_truth(exact.replace(".mcap", ".truth.json"))
    scores = {}
    for name, path, motion in (("exact", exact, "gripper"), ("noisy", noisy, "gripper"),
                               ("repaired", noisy, "tracked")):
        acc = LineAccumulation(AccumulateParams(motion=motion))
        with Recording(path) as rec:
            for frame in rec.frames():
                acc.step(frame, frame.T_camera_object)
        scores[name] = evaluate_model(acc.model(), truth)
    print({k: (round(v["precision"], 3), round(v["completeness"], 3)) for k, v in scores.items()})
    assert scores["noisy"]["precision"] < scores["exact"]["precision"] - 0.02
    assert scores["repaired"]["precision"] >= scores["exact"]["precision"] - 0.03
    assert scores["repaired"]["completeness"] >= scores["exact"]["completeness"] - 0.03
