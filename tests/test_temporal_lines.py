"""Line segments triangulated across frames (``accumcli.temporal_lines``), against exact geometry."""

from __future__ import annotations

import numpy as np

from accumcli.geometry import make_transform, transform_points
from accumcli.lines2d import Segments2D
from accumcli.recording import StereoIntrinsics
from accumcli.temporal_lines import TemporalLines, TemporalParams

INTR = StereoIntrinsics(600.0, 600.0, 319.5, 239.5, 0.08, 640, 480)
HALF = 0.03   # a cube 60 mm across, centred on the object frame's origin


def _cube_pieces(step: float = 0.015) -> np.ndarray:
    """(N, 2, 3) pieces of the cube's 12 edges, ``step`` metres long, object frame."""
    corners = np.array([[x, y, z] for x in (-HALF, HALF) for y in (-HALF, HALF) for z in (-HALF, HALF)])
    pieces = []
    for a in range(8):
        for b in range(a + 1, 8):
            if np.sum(corners[a] != corners[b]) == 1:      # an edge: the corners differ on one axis
                t = np.arange(0.0, 2 * HALF - 1e-9, step)
                starts = corners[a] + (corners[b] - corners[a]) * (t / (2 * HALF))[:, None]
                pieces.append(np.stack([starts, starts + (corners[b] - corners[a]) * (step / (2 * HALF))], 1))
    return np.concatenate(pieces)


def _pose(k: int, step_deg: float = 8.0) -> np.ndarray:
    """T_camera_object of frame k: the cube 0.6 m ahead, turned k * step_deg about a tilted axis."""
    import cv2

    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    R = cv2.Rodrigues(axis * np.radians(step_deg * k))[0] @ cv2.Rodrigues(np.array([0.4, 0.3, 0.0]))[0]
    return make_transform(R, np.array([0.0, 0.0, 0.6]))


def _segments_2d(ends: np.ndarray) -> Segments2D:
    """Pieces between image points ``ends`` (N, 2, 2) px."""
    vector = ends[:, 1] - ends[:, 0]
    lengths = np.linalg.norm(vector, axis=1)
    directions = vector / lengths[:, None]
    directions *= np.where(directions[:, 1] < 0, -1.0, 1.0)[:, None]   # angle in [0, 180)
    n = len(ends)
    return Segments2D(ends.mean(axis=1), directions, lengths, np.ones(n, np.int8), np.full(n, 50.0), np.arange(n),
                      np.zeros(n), directions)


def _frames(n: int, noise_px: float = 0.0, clutter: int = 0, seed: int = 0):
    """(pieces 2D, T_camera_object, object pieces (N, 2, 3)) of n frames; the first ``len(object)``
    pieces are the cube's (visible or not: no occlusion), then ``clutter`` pieces fixed in the image."""
    rng = np.random.default_rng(seed)
    cube = _cube_pieces()
    centres = rng.uniform([60, 60], [580, 420], (clutter, 2))
    angles = rng.uniform(0, np.pi, clutter)
    half = 6.0 * np.column_stack([np.cos(angles), np.sin(angles)])
    background = np.stack([centres - half, centres + half], 1)
    for k in range(n):
        T = _pose(k)
        uv, _, _ = INTR.project(transform_points(T, cube.reshape(-1, 3)))
        ends = uv.reshape(-1, 2, 2) + rng.normal(0.0, noise_px, (len(cube), 2, 2)) if noise_px else uv.reshape(-1, 2, 2)
        yield _segments_2d(np.concatenate([ends, background])), T, cube


def _errors(found, T, cube):
    """Per found segment (camera frame): distance of its centre from the true line of the cube edge
    nearest it (metres) and the angle to that line (degrees); True where its piece is the cube's."""
    on_cube = found.extra["piece"] < len(cube)
    edges = transform_points(T, cube[:, 0]), transform_points(T, cube[:, 1])
    direction = edges[1] - edges[0]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    rel = found.centers[on_cube, None] - edges[0][None]                     # (F, pieces, 3)
    distance = np.linalg.norm(rel - np.sum(rel * direction, axis=2, keepdims=True) * direction, axis=2)
    nearest = np.argmin(distance, axis=1)
    cosine = np.abs(np.sum(found.directions[on_cube] * direction[nearest], axis=1))
    return distance[np.arange(len(nearest)), nearest], np.degrees(np.arccos(np.clip(cosine, 0, 1))), on_cube


def _dihedral_deg(cube: np.ndarray, T_a: np.ndarray, T_b: np.ndarray) -> np.ndarray:
    """(N,) degrees between the planes through each piece of ``cube`` and the cameras of poses T_a, T_b."""
    normals = []
    for T in (T_a, T_b):
        camera = -T[:3, :3].T @ T[:3, 3]
        n = np.cross(cube[:, 0] - camera, cube[:, 1] - camera)
        normals.append(n / np.linalg.norm(n, axis=1, keepdims=True))
    return np.degrees(np.arcsin(np.clip(np.linalg.norm(np.cross(*normals), axis=1), 0, 1)))


def test_an_object_turning_in_front_of_the_camera_gives_its_lines_and_the_still_background_none():
    """Exact pieces of a cube turned 8 degrees a frame, among 300 pieces fixed in the image (a
    background that does not move with it): once the buffer is full, nearly every piece of the cube
    whose planes meet a partner frame's at more than the least angle is triangulated exactly onto its
    own line, and a fixed piece only by a
    coincidence of four views (a cube piece's plane and three witnesses): at most 1 in 100 a frame."""
    temporal = TemporalLines(TemporalParams())
    steep_found, steep_total = 0, 0
    for k, (pieces, T, cube) in enumerate(_frames(12, clutter=300)):
        found = temporal.step(pieces, T, INTR, k)
        if k < temporal.params.buffer:
            continue
        distance, angle, on_cube = _errors(found, T, cube)
        assert np.sum(~on_cube) <= 3
        # no occlusion: every piece is shown; those whose planes meet a partner's steeply enough count
        steep = np.zeros(len(cube), bool)
        for back in temporal.params.frames_back:
            steep |= _dihedral_deg(cube, T, _pose(k - back)) >= temporal.params.min_dihedral_deg + 0.5
        steep_total += steep.sum()
        steep_found += np.isin(np.flatnonzero(steep), found.extra["piece"][on_cube]).sum()
        assert np.max(distance) < 2e-3 and np.max(angle) < 2.0        # near a cube edge, every one ...
        assert np.max(found.lengths) < 0.02                              # ... as long as its 15 mm piece
        assert np.mean((distance < 1e-6) & (angle < 0.01)) >= 0.9      # ... and exactly on it, nearly all
    # the rest: shorter than min_length_px in a view, or on an image line that barely moved (``still_px``)
    assert steep_total >= 100 and steep_found >= 0.9 * steep_total


def test_the_direction_sigma_of_a_line_across_frames_is_honest_for_noisy_pieces():
    """With 0.15 px of noise on the pieces' ends, the direction errors over their sigmas have the
    median a calibrated Gaussian's would (0.67), within a factor of 1.5 either way."""
    temporal = TemporalLines(TemporalParams())
    ratios = []
    for k, (pieces, T, cube) in enumerate(_frames(16, noise_px=0.15, seed=1)):
        found = temporal.step(pieces, T, INTR, k)
        if len(found):
            _, angle, on_cube = _errors(found, T, cube)
            ratios.append(np.radians(angle) / found.extra["sigma_direction_rad"][on_cube])
    ratios = np.concatenate(ratios)
    assert len(ratios) > 200
    assert 0.67 / 1.5 < np.median(ratios) < 0.67 * 1.5


def test_with_a_right_camera_that_shows_nothing_the_lines_across_frames_alone_build_the_model():
    """The sample's right images replaced by flat grey: stereo finds nothing, so the model is what the
    lines across frames give from the left images and the recorded motion alone. It holds most of the
    box and nothing else (measured: precision 1.0, completeness 0.80 of what stereo and they together
    reach, 0.97)."""
    import dataclasses
    from pathlib import Path

    from accumcli.evaluate import evaluate_model
    from accumcli.model_io import read_truth
    from accumcli.pipeline import AccumulateParams, LineAccumulation
    from accumcli.runs import RecordingOptions

    sample = Path(__file__).resolve().parents[1] / "sample_data" / "sim_box.mcap"
    figures = {}
    for name, temporal in (("stereo only", None), ("across frames", TemporalParams())):
        with RecordingOptions().open(sample) as recording:
            accumulation = LineAccumulation(AccumulateParams(temporal=temporal), recording.object_frame,
                                            recording.camera_frame)
            for frame in recording.frames(0, None):
                accumulation.step(dataclasses.replace(frame, right=np.full_like(frame.right, 128)), frame.T_camera_object)
        figures[name] = evaluate_model(accumulation.model(), read_truth(sample.with_suffix(".truth.json")))
    assert figures["stereo only"]["accepted"] == 0
    assert figures["across frames"]["precision"] >= 0.95
    assert figures["across frames"]["completeness"] >= 0.6


def test_frames_at_one_pose_give_no_line_and_no_pairs():
    """The gripper holding still: every view's camera is at the same place in the object frame, no two
    planes of one edge meet at the least angle, and no pair is even formed (all pairs of 300 pieces
    were formed before: quadratic in time and memory)."""
    from accumcli import temporal_lines

    pieces, T, _ = next(_frames(1, clutter=300))
    temporal = TemporalLines(TemporalParams())
    formed = []
    real = temporal_lines.pair_hypotheses
    temporal_lines.pair_hypotheses = lambda *args, **kwargs: formed.append(1) or real(*args, **kwargs)
    try:
        found = [temporal.step(pieces, T, INTR, k) for k in range(8)]
    finally:
        temporal_lines.pair_hypotheses = real
    assert all(len(f) == 0 for f in found) and not formed
