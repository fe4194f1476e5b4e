"""The single-frame funnel (accumcli.funnel): stages judged against a hand-made truth."""

from __future__ import annotations

import json

import numpy as np

from accumcli.evaluate import EdgeSamples, evaluate_model
from accumcli.funnel import LOSSES, detected_by, frame_funnel, funnel
from accumcli.model_io import Truth, dumps, segments_from_dict, segments_to_dict
from accumcli.segments import Segments

INTR = {"fx": 500.0, "fy": 500.0, "cx": 320.0, "cy": 240.0, "baseline": 0.1, "width": 640, "height": 480}


def _truth(a, b, k=50, times_ns=(), poses=np.zeros((0, 4, 4))) -> Truth:
    return Truth("gripper", "camera_left", np.array([a], float), np.array([b], float), [""],
                 [np.full(k, 5)], np.array([True]), np.asarray(times_ns, np.int64), np.asarray(poses, float), {})


def _edges(a, b, k=50) -> EdgeSamples:
    return EdgeSamples.of(_truth(a, b, k))


def _vertical_segment(y0: float, y1: float, confidence: float = 0.9) -> Segments:
    """One segment on the edge x = 0, z = 1 m of the tests, from y0 to y1 (metres, camera frame)."""
    return Segments("camera_left", np.array([[0.0, (y0 + y1) / 2, 1.0]]), np.array([[0.0, 1.0, 0.0]]),
                    np.array([y1 - y0]), np.array([confidence]), np.array([1]))


def test_a_segment_on_the_projection_detects_its_samples_and_one_beside_it_does_not():
    # a vertical edge at x = 0, z = 1 m, y from -0.05 to 0.05 m: u = 320, v from 215 to 265
    edges = _edges([0, -0.05, 0], [0, 0.05, 0])
    T = np.eye(4)
    T[2, 3] = 1.0
    samples = np.arange(len(edges.points))
    on = np.array([[320.4, 215.0, 320.4, 240.0]])        # covers the upper half, 0.4 px off
    hit, _ = detected_by(on, edges, T, INTR, samples)
    assert 0.45 <= len(np.unique(hit)) / len(samples) <= 0.56
    beside = np.array([[322.5, 215.0, 322.5, 265.0]])    # 2.5 px away: not this edge
    assert len(detected_by(beside, edges, T, INTR, samples)[0]) == 0
    across = np.array([[300.0, 240.0, 340.0, 240.0]])    # through it, but perpendicular
    assert len(detected_by(across, edges, T, INTR, samples)[0]) == 0


def test_stages_follow_critical_and_matched_flags():
    edges = _edges([-0.05, 0, 0], [0.05, 0, 0])          # a horizontal edge: its 2D segment is critical
    T = np.eye(4)
    T[2, 3] = 1.0
    doc = {"intrinsics": INTR, "segments_2d": {"left": [[295.0, 240.0, 345.0, 240.0]], "matched": [0],
                                               "critical_angle_deg": 12.0}}
    counts = frame_funnel(Segments.empty("camera_left"), doc, T, edges, None)
    assert counts["seen"] == 50 and counts["detected_2d"] == 50
    # a critical segment that became 3D (from its edge's ends) counts as matched
    assert counts["not_critical"] == 0 and counts["matched"] == 50 and counts["correct_3d"] == 0
    doc["segments_2d"]["matched"] = []
    assert frame_funnel(Segments.empty("camera_left"), doc, T, edges, None)["matched"] == 0
    doc["segments_2d"]["critical_angle_deg"] = 0.0
    doc["segments_2d"]["matched"] = [0]
    counts = frame_funnel(Segments.empty("camera_left"), doc, T, edges, None)
    assert counts["not_critical"] == 50 and counts["matched"] == 50


def test_correct_twice_counts_the_edge_that_two_frames_got_right():
    # the upper half of the edge right in frames 0 and 1, the lower half only in frame 2
    T = np.eye(4)
    T[2, 3] = 1.0
    truth = _truth([0, -0.05, 0], [0, 0.05, 0], times_ns=[0, 10, 20], poses=[T, T, T])
    frames = [(0, _vertical_segment(-0.05, 0.0), {}), (10, _vertical_segment(-0.05, 0.0), {}),
              (20, _vertical_segment(0.0, 0.05), {})]
    result = funnel(frames, truth)
    assert 0.45 <= result["funnel_correct_twice"] <= 0.55
    assert 0.45 <= result["funnel_correct_3d"] <= 0.55      # half the edge in each frame


def test_completeness_any_confidence_counts_what_is_not_accepted():
    truth = _truth([0, -0.05, 1], [0, 0.05, 1])
    upper, lower = _vertical_segment(-0.05, 0.0, 0.9), _vertical_segment(0.0, 0.05, 0.3)
    model = Segments("gripper", np.concatenate([upper.centers, lower.centers]),
                     np.concatenate([upper.directions, lower.directions]),
                     np.concatenate([upper.lengths, lower.lengths]), np.array([0.9, 0.3]), np.array([3, 1]))
    scores = evaluate_model(model, truth)
    assert scores["accepted"] == 1 and 0.45 <= scores["completeness"] <= 0.55
    assert scores["completeness_any_confidence"] >= 0.98


def test_completeness_with_held_counts_the_confident_segments_held_back_for_their_direction():
    """Three quarters of an edge: the upper quarter accepted, the next held back for its direction
    (confident, written at 0.49), the third found once and never confirmed: with held adds the
    second quarter only; a model without the column gives no such figure."""
    truth = _truth([0, -0.05, 1], [0, 0.05, 1])
    parts = [_vertical_segment(-0.05, -0.025), _vertical_segment(-0.025, 0.0), _vertical_segment(0.0, 0.025)]
    model = Segments("gripper", np.concatenate([p.centers for p in parts]), np.concatenate([p.directions for p in parts]),
                     np.concatenate([p.lengths for p in parts]), np.array([0.9, 0.49, 0.3]), np.array([5, 6, 1]),
                     {"direction_held": np.array([False, True, False])})
    scores = evaluate_model(model, truth)
    assert 0.2 <= scores["completeness"] <= 0.3
    assert 0.45 <= scores["completeness_with_held"] <= 0.55
    assert 0.7 <= scores["completeness_any_confidence"] <= 0.8
    written = segments_from_dict(json.loads(dumps(segments_to_dict(model))), "model")   # true / false -> 1.0 / 0.0
    assert evaluate_model(written, truth)["completeness_with_held"] == scores["completeness_with_held"]
    model.extra.clear()
    assert "completeness_with_held" not in evaluate_model(model, truth)


def test_completeness_by_part_where_the_truth_names_parts():
    """Two edges, the object's (x = 0) and the gripper's (x = 0.05 m), the model on the first only: the object's
    part complete, the gripper's not; a truth without parts gives no such figures."""
    two = Truth("gripper", "camera_left", np.array([[0, -0.05, 1], [0.05, -0.05, 1]], float),
                np.array([[0, 0.05, 1], [0.05, 0.05, 1]], float), ["", ""], [np.full(50, 5), np.full(50, 5)],
                np.array([True, True]), np.zeros(0, np.int64), np.zeros((0, 4, 4)), {}, {}, ["object", "gripper"])
    model = _vertical_segment(-0.05, 0.05)
    scores = evaluate_model(model, two)
    assert scores["completeness_object"] >= 0.98 and scores["completeness_gripper"] == 0.0
    assert 0.45 <= scores["completeness"] <= 0.55
    assert "completeness_object" not in evaluate_model(model, _truth([0, -0.05, 1], [0, 0.05, 1]))


def test_the_truths_seen_bits_are_those_of_the_pose_it_chose_within_the_tolerance():
    """A frame 0.5 ms from its truth pose takes that pose's bits (10 of 50 samples seen, a segment on 5
    of them: 0.5), not the projection of every sample (0.1) under the bits' label."""
    import base64

    from accumcli.geometry import make_transform

    T = make_transform(np.eye(3), [0, 0, 0.5])
    bits = np.zeros(50, bool)
    bits[:10] = True
    truth = Truth("o", "c", np.array([[0, -0.05, 0.0]]), np.array([[0, 0.05, 0.0]]), ["crease"], [np.full(50, 5)],
                  np.array([True]), np.array([0], np.int64), T[None], {},
                  {0: base64.b64encode(np.packbits(bits).tobytes()).decode()})
    intrinsics = dict(fx=800.0, fy=800.0, cx=320.0, cy=240.0, baseline=0.1, width=640, height=480)
    segment = Segments("cam", np.array([[0, -0.045, 0.5]]), np.array([[0, 1.0, 0]]), np.array([0.01]), np.ones(1),
                       np.ones(1, np.int64))
    for t_ns in (0, 500_000):
        result = funnel([(t_ns, segment, {"intrinsics": intrinsics})], truth)
        assert result["funnel_correct_3d"] == 0.5 and result["funnel_seen_from"] == "truth per-frame bits", t_ns


def _losses_sum(result: dict) -> float:
    return result["funnel_correct_twice"] + sum(result[f"funnel_{name}"] for name in LOSSES)


def _frame_2d(t_ns: int, segments: Segments, left: list, matched: list) -> tuple:
    return t_ns, segments, {"intrinsics": INTR, "segments_2d": {"left": left, "matched": matched,
                                                                "critical_angle_deg": 8.0}}


UPPER, LOWER = [320.0, 215.0, 320.0, 239.0], [320.0, 241.0, 320.0, 265.0]   # the vertical edge's halves in 2D


def test_the_edge_no_two_frames_got_right_is_charged_to_the_stage_where_it_was_lost():
    """A vertical edge (not critical) in three frames: its upper half matched in all three but never
    triangulated right (lost in 3D), its lower half detected but matched in one frame only (lost
    unmatched); then a horizontal edge whose critical segment nothing triangulated (lost critical), one
    whose critical segment was triangulated (from its ends) twice but wrong (lost in 3D), and one no
    frame detected (lost in 2D). The losses and the share right twice sum to 1."""
    T = np.eye(4)
    T[2, 3] = 1.0
    vertical = _truth([0, -0.05, 0], [0, 0.05, 0], times_ns=[0, 10, 20], poses=[T, T, T])
    frames = [_frame_2d(t, Segments.empty("camera_left"), [UPPER, LOWER], [0, 1] if t == 0 else [0])
              for t in (0, 10, 20)]
    result = funnel(frames, vertical)
    assert result["funnel_correct_twice"] == 0.0
    assert result["funnel_lost_2d"] == result["funnel_lost_critical"] == result["funnel_lost_unseen"] == 0.0
    assert 0.45 <= result["funnel_lost_3d"] <= 0.55 and 0.45 <= result["funnel_lost_unmatched"] <= 0.55
    assert abs(_losses_sum(result) - 1.0) < 1e-9

    horizontal = _truth([-0.05, 0, 0], [0.05, 0, 0], times_ns=[0, 10], poses=[T, T])
    empty = Segments.empty("camera_left")
    for matched, lost in (([], "funnel_lost_critical"), ([0], "funnel_lost_3d")):
        result = funnel([_frame_2d(t, empty, [[295.0, 240.0, 345.0, 240.0]], matched) for t in (0, 10)], horizontal)
        assert result[lost] == 1.0 and abs(_losses_sum(result) - 1.0) < 1e-9, matched
    result = funnel([_frame_2d(t, empty, [], []) for t in (0, 10)], horizontal)
    assert result["funnel_lost_2d"] == 1.0 and result["funnel_correct_twice"] == 0.0


def test_the_share_right_twice_is_not_charged_and_uncounted_samples_are_left_out():
    """The upper half right in two frames (not lost), the lower half matched in both but never right
    (lost in 3D); a second edge the truth does not count for completeness, never detected, is in no share."""
    T = np.eye(4)
    T[2, 3] = 1.0
    two = Truth("gripper", "camera_left", np.array([[0, -0.05, 0], [0.02, -0.05, 0]], float),
                np.array([[0, 0.05, 0], [0.02, 0.05, 0]], float), ["", ""], [np.full(50, 5), np.full(50, 5)],
                np.array([True, False]), np.array([0, 10], np.int64), np.array([T, T]), {})
    frames = [_frame_2d(t, _vertical_segment(-0.05, 0.0), [UPPER, LOWER], [0, 1]) for t in (0, 10)]
    result = funnel(frames, two)
    assert 0.45 <= result["funnel_correct_twice"] <= 0.55 and 0.45 <= result["funnel_lost_3d"] <= 0.55
    assert result["funnel_lost_2d"] == 0.0 and abs(_losses_sum(result) - 1.0) < 1e-9


def test_losses_need_every_frame_with_2d_segments_and_two_frames_showing_a_sample():
    """A frame without 2D segments among those judged: no losses (its samples would look undetected);
    a single frame judged: every counted sample shown fewer than twice (lost unseen)."""
    T = np.eye(4)
    T[2, 3] = 1.0
    truth = _truth([0, -0.05, 0], [0, 0.05, 0], times_ns=[0, 10], poses=[T, T])
    empty = Segments.empty("camera_left")
    mixed = [_frame_2d(0, empty, [UPPER, LOWER], [0, 1]), (10, _vertical_segment(-0.05, 0.05), {"intrinsics": INTR})]
    assert "funnel_lost_3d" not in funnel(mixed, truth)
    result = funnel([_frame_2d(0, empty, [UPPER, LOWER], [0, 1])], truth)
    assert result["funnel_lost_unseen"] == 1.0 and abs(_losses_sum(result) - 1.0) < 1e-9
def test_a_frames_file_without_2d_segments_gives_no_losses():
    T = np.eye(4)
    T[2, 3] = 1.0
    truth = _truth([0, -0.05, 0], [0, 0.05, 0], times_ns=[0, 10], poses=[T, T])
    result = funnel([(0, _vertical_segment(-0.05, 0.05), {}), (10, _vertical_segment(-0.05, 0.05), {})], truth)
    assert result["funnel_correct_twice"] >= 0.98 and "funnel_lost_3d" not in result
