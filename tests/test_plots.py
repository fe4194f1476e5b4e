"""Curves over frames (accumcli.plots): accumulate --plot and eval FRAMES --plot write real PNGs."""

from __future__ import annotations

import cv2
import numpy as np

from accumcli.runs import FrameRange, accumulate_recording, evaluate_file, extract_recording


def _coloured_pixels(path) -> int:
    image = cv2.imread(str(path))
    assert image is not None and image.shape[0] >= 300 and image.shape[1] >= 500
    spread = image.max(axis=2).astype(int) - image.min(axis=2).astype(int)
    return int((spread > 80).sum())


def test_accumulate_plot_draws_counts_and_scores(small_recording, tmp_path):
    truth = small_recording.replace(".mcap", ".truth.json")
    accumulate_recording(small_recording, frames=FrameRange(0, 4), truth=truth, plot=str(tmp_path / "h.png"))
    wide = cv2.imread(str(tmp_path / "h.png")).shape[1]
    assert _coloured_pixels(tmp_path / "h.png") > 500
    accumulate_recording(small_recording, frames=FrameRange(0, 4), plot=str(tmp_path / "counts.png"))
    assert cv2.imread(str(tmp_path / "counts.png")).shape[1] < wide   # no truth: only the counts panel


def test_eval_plot_of_a_frames_file(small_recording, tmp_path):
    frames = tmp_path / "f.jsonl"
    extract_recording(small_recording, str(frames), frames=FrameRange(0, 3))
    figures = evaluate_file(str(frames), small_recording.replace(".mcap", ".truth.json"), plot=str(tmp_path / "f.png"))
    assert figures["frames"] == 3 and np.isfinite(figures["single_frame_completeness"])
    assert _coloured_pixels(tmp_path / "f.png") > 300


def test_eval_plot_numbers_frames_as_the_recording_does(small_recording, tmp_path, monkeypatch):
    """A frames file of the recording's frames 2 and 3 is drawn at 2 and 3, not at its lines 0 and 1."""
    import accumcli.plots
    from accumcli.runs import evaluate_file, extract_recording
    from accumcli.runs.base import FrameRange

    frames = tmp_path / "f.jsonl"
    extract_recording(small_recording, [str(frames)], frames=FrameRange(2, 4))
    drawn = []
    monkeypatch.setattr(accumcli.plots, "plot_frames", lambda target, rows, title: drawn.extend(rows))
    evaluate_file(str(frames), small_recording.replace(".mcap", ".truth.json"), plot=str(tmp_path / "p.png"))
    assert [r["frame_index"] for r in drawn] == [2, 3]
