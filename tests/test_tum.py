"""Poses as TUM, read by evo itself: evo's APE gives the same medians as accum eval --poses."""

from __future__ import annotations

import numpy as np
import pytest

from accumcli.evaluate import pose_errors
from accumcli.geometry import make_transform
from accumcli.model_io import PoseTrack, read_truth
from accumcli.runs import FrameRange, accumulate_recording, track_recording
from accumcli.tum import write_poses_tum


def test_tum_round_trip_keeps_nanoseconds_and_skips_lost_poses(tmp_path):
    angle = np.radians(30)
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    track = PoseTrack("camera_left", "gripper", np.array([1_700_000_000_123_456_789, 5], np.int64),
                      np.stack([make_transform(R, [0.1, -0.2, 0.5]), np.full((4, 4), np.nan)]), ["tracked", "lost"])
    path = tmp_path / "p.tum"
    assert write_poses_tum(path, track) == 1
    line = [x for x in path.read_text().splitlines() if not x.startswith("#")]
    assert len(line) == 1
    values = line[0].split()
    assert values[0] == "1700000000.123456789"
    np.testing.assert_allclose([float(v) for v in values[1:]], [0.1, -0.2, 0.5, 0, 0, np.sin(angle / 2),
                                                                np.cos(angle / 2)], atol=1e-9)


def test_evo_ape_agrees_with_accum_eval(small_recording, tmp_path):
    evo_metrics = pytest.importorskip("evo.core.metrics")
    from evo.core import sync
    from evo.tools import file_interface

    model = accumulate_recording(small_recording, frames=FrameRange(0, 4)).model
    result = track_recording(model, small_recording, [str(tmp_path / "est.tum")])
    truth = read_truth(small_recording.replace(".mcap", ".truth.json"))
    write_poses_tum(tmp_path / "ref.tum", PoseTrack("camera_left", "gripper", truth.times_ns, truth.poses))
    ours = pose_errors(result.track.times_ns, result.track.poses, result.track.status, truth)
    ref, est = sync.associate_trajectories(file_interface.read_tum_trajectory_file(str(tmp_path / "ref.tum")),
                                           file_interface.read_tum_trajectory_file(str(tmp_path / "est.tum")))
    medians = {}
    for relation in (evo_metrics.PoseRelation.translation_part, evo_metrics.PoseRelation.rotation_angle_deg):
        ape = evo_metrics.APE(relation)
        ape.process_data((ref, est))
        medians[relation] = ape.get_statistic(evo_metrics.StatisticsType.median)
    assert est.num_poses == result.tracked
    assert medians[evo_metrics.PoseRelation.translation_part] * 1000 == pytest.approx(ours["median_translation_mm"],
                                                                                      rel=1e-6, abs=1e-6)
    assert medians[evo_metrics.PoseRelation.rotation_angle_deg] == pytest.approx(ours["median_rotation_deg"],
                                                                                 rel=1e-5, abs=1e-5)
