"""The pose figures of ``accum eval`` (a poses file against a truth)."""

from __future__ import annotations

import json

from accumcli.model_io import PoseTrack, read_truth, write_poses
from accumcli.runs import evaluate_file


def test_pose_figures_judge_only_frames_with_truth(small_recording, tmp_path, caplog):
    """A truth of the first half of the frames: the tracked fraction is of that half (it was of all
    frames, 0.5 for a track that follows every frame), and the rest is counted and named."""
    truth_path = small_recording.replace(".mcap", ".truth.json")
    truth = read_truth(truth_path)
    doc = json.loads(open(truth_path).read())
    doc["poses"] = doc["poses"][:3]
    half = tmp_path / "half.truth.json"
    half.write_text(json.dumps(doc))
    poses = tmp_path / "p.json"
    tracked = ["tracked"] * len(truth.times_ns)
    write_poses(poses, PoseTrack("camera_left", "gripper", truth.times_ns, truth.poses, tracked))
    figures = evaluate_file(str(poses), str(half))
    assert len(truth.times_ns) == 6
    assert figures["frames"] == 3 and figures["frames_without_truth"] == 3 and figures["tracked_fraction"] == 1.0
    assert figures["median_rotation_deg"] < 1e-6
    assert "3 of 6 frames have no pose in" in caplog.text
    assert "frames_without_truth" not in evaluate_file(str(poses), truth_path)

