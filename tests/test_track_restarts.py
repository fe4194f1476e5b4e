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


needs_devset = pytest.mark.skipif(not (DEVSET / "dev_steps_track.mcap").exists(), reason="needs ../shared/data/devset")


@pytest.fixture(scope="module")
def dev_steps_model():
    return accumulate_recording(str(DEVSET / "dev_steps.mcap")).model


@needs_devset
def test_frames_whose_refinement_stops_off_the_truth_are_found_by_restarts(dev_steps_model):
    """From frame 27, some of frames 29 to 32 (the object turns up to 8 degrees a frame; which ones
    moves with the model) end off the truth from the prediction and the last pose; without restarts
    the tracker says 'lost' there (two or more), with them it tracks more of them, every tracked
    frame within a degree and 2 mm (the default model, with view planes; frame 30 stays 'lost' with
    the model of now, as in the whole run of the tracking scoreboard). With 5 Gauss-Newton steps a
    level, the default before: with the 10 of now frame 29 converges without one, and the restarts
    change nothing in these frames."""
    model = dev_steps_model
    truth = read_truth(str(DEVSET / "dev_steps_track.truth.json"))

    def run(restart_deg):
        track = track_recording(model, str(DEVSET / "dev_steps_track.mcap"), frames=FrameRange(27, 34),
                                params=TrackParams(restart_deg=restart_deg, iterations_per_level=5)).track
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


@needs_devset
def test_the_frame_after_an_ambiguous_one_restarts(dev_steps_model, monkeypatch):
    """Frame 23 of dev_steps_track is 'ambiguous' with the default model (a pose 4 degrees away covers
    as much); in frame 24 the prediction's refinement stops 3.5 degrees off, where it verifies, and
    the refinement carried from the right pose slides off. The restarts run in the frame after an
    ambiguous one (``PoseTracker.update``) and find the truth, so no frame of 20 to 27 is tracked
    more than 3 degrees or 5 mm off."""
    import accumcli.track as track_module

    restarted = []
    original = track_module.PoseTracker._restarts

    def spy(self, candidates, frame, *args, **kwargs):
        restarted.append(frame.index)
        return original(self, candidates, frame, *args, **kwargs)

    monkeypatch.setattr(track_module.PoseTracker, "_restarts", spy)
    truth = read_truth(str(DEVSET / "dev_steps_track.truth.json"))
    track = track_recording(dev_steps_model, str(DEVSET / "dev_steps_track.mcap"), frames=FrameRange(20, 28)).track
    ambiguous = [20 + k for k, s in enumerate(track.status) if s == "ambiguous"]
    assert ambiguous and all(k + 1 in restarted for k in ambiguous if k + 1 < 28)
    for t, T, s in zip(track.times_ns, track.poses, track.status):
        if s == "tracked":
            rotation, translation = pose_error(T, truth.pose_at(int(t)))
            assert rotation <= 3.0 and translation <= 0.005
