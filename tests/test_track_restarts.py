"""Restarts of a frame nothing verified in (``TrackParams.restart_deg``), on the independent
renderer's dev_steps_track (skipped without ../shared/data/devset)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from accumcli.geometry import pose_error
from accumcli.model_io import read_truth
from accumcli.runs import FrameRange, accumulate_recording, track_recording
from accumcli.track import TrackParams

DEVSET = Path(__file__).resolve().parents[2] / "shared" / "data" / "devset"


@pytest.mark.skipif(not (DEVSET / "dev_steps_track.mcap").exists(), reason="needs ../shared/data/devset")
def test_frames_whose_refinement_stops_off_the_truth_are_found_by_restarts():
    """From frame 27, some of frames 29 to 32 (the object turns up to 8 degrees a frame; which ones
    moves with the model) end off the truth from the prediction and the last pose; without restarts
    the tracker says 'lost' there (two or more), with them it tracks more of them, every tracked
    frame within a degree and 2 mm (the default model, with view planes; frame 30 stays 'lost' with
    the model of now, as in the whole run of the tracking scoreboard)."""
    model = accumulate_recording(str(DEVSET / "dev_steps.mcap")).model
    truth = read_truth(str(DEVSET / "dev_steps_track.truth.json"))

    def run(restart_deg):
        track = track_recording(model, str(DEVSET / "dev_steps_track.mcap"), frames=FrameRange(27, 34),
                                params=TrackParams(restart_deg=restart_deg)).track
        errors = [pose_error(T, truth.pose_at(int(t))) if s == "tracked" else None
                  for t, T, s in zip(track.times_ns, track.poses, track.status)]
        return track.status, errors

    status, _ = run(None)
    assert status[:2] == ["tracked"] * 2 and status[2:6].count("lost") >= 2
    without = status.count("tracked")
    status, errors = run(5.0)
    assert status[:2] == ["tracked"] * 2 and status.count("tracked") > without
    tracked = [e for e in errors if e is not None]
    assert max(e[0] for e in tracked) < 1.0 and max(e[1] for e in tracked) < 0.002
