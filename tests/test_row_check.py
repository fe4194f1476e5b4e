"""The rows' check (``row_check``): a right image a fraction of a pixel too low is found from the
edges' junctions, named in a warning with the offset to try, and ``row_offset_px`` corrects it."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from accumcli.evaluate import evaluate_model
from accumcli.extract import ExtractParams, extract_frame
from accumcli.model_io import read_truth
from accumcli.pipeline import AccumulateParams
from accumcli.recording.calibration import StereoRectifier
from accumcli.runs import accumulate_recording, extract_recording
from accumcli.stereo import StereoParams

SAMPLE = Path(__file__).resolve().parent.parent / "sample_data" / "sim_box.mcap"
SHIFT_PX = 0.4


@pytest.fixture
def right_image_low(monkeypatch):
    """Rectified right images moved ``SHIFT_PX`` down (bilinear), as a calibration a little off leaves them."""
    rectify = StereoRectifier.rectify

    def shifted(self, left, right):
        left, right = rectify(self, left, right)
        move = np.float32([[1, 0, 0], [0, 1, SHIFT_PX]])
        return left, cv2.warpAffine(right, move, (right.shape[1], right.shape[0]), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REPLICATE)

    monkeypatch.setattr(StereoRectifier, "rectify", shifted)


def test_junction_samples_measure_the_row_offset():
    """Two squares at 0.55 and 0.45 m, the nearer over the farther: their L-corners, in four noisy
    renderings, put a right image moved down by 0.5 px at 0.52 (median of 15), an unmoved one at
    0.03 (16)."""
    from dataclasses import replace

    from accumcli.row_check import junction_samples

    from .scenes import render_pair, rotated_square

    back, _ = rotated_square([0.0, 0.0], 0.04, 25.0, 0.55)
    front, _ = rotated_square([0.03, 0.03], 0.03, -20.0, 0.45)
    for shift in (0.0, 0.5):
        samples = []
        for seed in range(4):
            frame = render_pair([back, front], seed=seed)
            moved = cv2.warpAffine(frame.right, np.float32([[1, 0, 0], [0, 1, shift]]), frame.right.shape[::-1],
                                   flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            frame = replace(frame, right=moved)
            samples.append(junction_samples(extract_frame(frame, ExtractParams()), frame.intrinsics)[0])
        samples = np.concatenate(samples)
        assert len(samples) >= 10 and abs(np.median(samples) - shift) < 0.06


def _suggested(warning: str) -> float:
    return float(re.search(r"--row-offset (-?\d+\.\d+)", warning).group(1))


def _precision(offset_px: float) -> float:
    params = AccumulateParams(extract=ExtractParams(stereo=StereoParams(row_offset_px=offset_px)))
    model = accumulate_recording(str(SAMPLE), params=params).model
    return evaluate_model(model, read_truth(str(SAMPLE.with_suffix(".truth.json"))))["precision"]


def test_rows_that_agree_give_no_warning(tmp_path):
    assert extract_recording(str(SAMPLE), str(tmp_path / "frames.jsonl")).row_warning is None


def test_a_right_image_too_low_is_named_and_corrected(tmp_path, right_image_low):
    """0.4 px: the junctions put it at 0.38; the box's precision falls from 0.988 to 0.77 and the
    suggested --row-offset gives back 0.976."""
    warning = extract_recording(str(SAMPLE), str(tmp_path / "frames.jsonl")).row_warning
    assert warning is not None and "below" in warning
    suggested = _suggested(warning)
    assert abs(suggested - SHIFT_PX) < 0.08
    uncorrected, corrected = _precision(0.0), _precision(suggested)
    print(f"precision {uncorrected:.3f} uncorrected, {corrected:.3f} with --row-offset {suggested}")
    assert uncorrected < 0.9 and corrected > 0.96


def test_the_command_line_warns_and_takes_the_offset(tmp_path, right_image_low):
    from click.testing import CliRunner

    from accumcli.cli import main

    frames = tmp_path / "frames.jsonl"
    result = CliRunner().invoke(main, ["extract", str(SAMPLE), "-o", str(frames), "-q"])
    assert result.exit_code == 0, result.output
    assert "rows disagree" in result.output and "--row-offset" in result.output
    suggested = _suggested(result.output)
    result = CliRunner().invoke(main, ["extract", str(SAMPLE), "-o", str(frames), "-q", "--row-offset", str(suggested)])
    assert result.exit_code == 0 and "rows disagree" not in result.output



def test_few_samples_decide_only_from_many_places(monkeypatch):
    """Under MIN_SAMPLES, samples decide where their junctions lie at many places in the camera's frame
    and in the object's (a real offset: every junction says it); one junction seen again and again
    (background the object passes: one place in the camera's frame) does not, however well it agrees."""
    import accumcli.row_check as rc
    from accumcli.geometry import make_transform

    def run(offset, camera_point_of_frame):
        check = rc.RowCheck()
        for k in range(12):
            point = camera_point_of_frame(k)
            monkeypatch.setattr(rc, "junction_samples", lambda *_: (np.array([offset]), point[None, :]))
            check.add(None, None, make_transform(np.eye(3), [0.01 * k, 0.0, 0.5]))   # the object moves 1 cm a frame
        return check

    spread_out = run(1.0, lambda k: np.array([0.01 * k, 0.003 * k, 0.5]))
    assert spread_out.places() == 12 and "lie 1.00 px below" in spread_out.warning()
    one_place = run(-1.5, lambda k: np.array([0.02, 0.01, 0.5]))
    assert one_place.places() == 1 and one_place.estimate() is None and one_place.warning() is None
