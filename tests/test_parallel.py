"""Extraction in worker processes (accumcli.runs.parallel): the same bytes whatever the number."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from accumcli.runs import FrameRange, accumulate_recording, extract_recording


def test_two_workers_give_the_same_model_and_frames_bytes(small_recording, tmp_path):
    outputs = {}
    for workers in (1, 2):
        model, frames = tmp_path / f"m{workers}.json", tmp_path / f"f{workers}.jsonl"
        result = accumulate_recording(small_recording, [str(model)], frames=FrameRange(0, 4), workers=workers)
        extract_recording(small_recording, str(frames), frames=FrameRange(0, 4), workers=workers)
        outputs[workers] = (model.read_bytes(), frames.read_bytes(), result.frames, sorted(result.times.seconds))
    assert outputs[1] == outputs[2]
    assert outputs[1][2] == 4 and "lines" in outputs[1][3]


def test_an_extraction_sent_back_without_its_gradients_accumulates_as_with_them():
    """Helpers send extractions back without their gradients (and ``--motion tracked`` replays them
    so); the accumulation's test of what the extraction missed (``line_model.expected``) reads the
    left image's gradients all the same, so the model does not depend on which process extracted."""
    import copy

    from accumcli.pipeline import LineAccumulation
    from accumcli.recording import Recording

    with_them, without = LineAccumulation(), LineAccumulation()
    with Recording(Path(__file__).resolve().parents[1] / "sample_data" / "sim_box.mcap") as rec:
        for frame in rec.frames(0, 12):
            extraction = with_them.extract(frame)
            sent = copy.copy(extraction)
            sent.gradients = None
            with_them.step(frame, frame.T_camera_object, extraction)
            without.step(frame, frame.T_camera_object, sent)
    a, b = with_them.model(), without.model()
    assert len(a) == len(b) and np.array_equal(a.centers, b.centers) and np.array_equal(a.confidence, b.confidence)


def test_this_process_and_a_ready_helper_share_the_frames_and_hand_them_back_in_order(small_recording, monkeypatch):
    from concurrent.futures import wait

    import numpy as np

    from accumcli.extract import ExtractParams, extract_frame
    from accumcli.lines2d import StageTimes
    from accumcli.recording import Recording
    from accumcli.runs import parallel

    submitted = {"ready": [], "frames": 0}
    submit = parallel.ProcessPoolExecutor.submit

    def counting_submit(pool, fn, *args, **kwargs):
        future = submit(pool, fn, *args, **kwargs)
        if fn is parallel._ready:
            submitted["ready"].append(future)
        else:
            submitted["frames"] += 1
        return future

    monkeypatch.setattr(parallel.ProcessPoolExecutor, "submit", counting_submit)
    with Recording(small_recording) as rec:
        frames = list(rec.frames())
    params = ExtractParams()

    def frames_once_the_helper_is_ready():
        yield frames[0]                 # this process extracts it: the helper is starting
        wait(submitted["ready"], timeout=120)
        yield from frames[1:]

    times = StageTimes()
    got = list(parallel.extracted_frames(frames_once_the_helper_is_ready(), params, "camera_left", 2, times))
    assert 1 <= submitted["frames"] <= len(frames) - 1
    assert [frame.index for frame, _ in got] == [frame.index for frame in frames]
    for (_, extraction), frame in zip(got, frames):
        alone = extract_frame(frame, params, "camera_left")
        assert np.array_equal(extraction.segments.centers, alone.segments.centers)
    assert times.seconds["lines"] > 0


def test_auto_workers_use_both_cores_only_for_recordings_long_enough(monkeypatch, caplog):
    import os

    from accumcli.runs.parallel import AUTO_MIN_FRAMES, resolve_workers

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    assert resolve_workers(None, AUTO_MIN_FRAMES) == 2 and resolve_workers(None, AUTO_MIN_FRAMES - 1) == 1
    assert resolve_workers(3, 10) == 3 and not caplog.text
    # a number given is capped at the frames, and at the CPUs with a warning (99999 ran for minutes)
    assert resolve_workers(3, 2) == 2 and not caplog.text
    assert resolve_workers(99999, 100) == 4 and "--workers 99999: this machine gives the run 4 CPUs; using at most 4" in caplog.text
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert resolve_workers(None, 1000) == 1


def test_workers_option_takes_a_count_or_auto(small_recording, tmp_path):
    from click.testing import CliRunner

    from accumcli.cli import main

    runner = CliRunner()
    bad = runner.invoke(main, ["extract", small_recording, "-o", str(tmp_path / "f.jsonl"), "--workers", "0"])
    assert bad.exit_code != 0 and "expected a number of processes (1 or more) or 'auto'" in bad.output
    auto, one = tmp_path / "auto.jsonl", tmp_path / "one.jsonl"
    assert runner.invoke(main, ["extract", small_recording, "-o", str(auto)]).exit_code == 0
    assert runner.invoke(main, ["extract", small_recording, "-o", str(one), "--workers", "1"]).exit_code == 0
    assert auto.read_bytes() == one.read_bytes()


def test_workers_and_frames_given_wrongly_are_input_errors():
    from accumcli.errors import InputError
    from accumcli.runs import FrameRange
    from accumcli.runs.parallel import resolve_workers

    assert resolve_workers("auto", 10) == 1 and resolve_workers(1, 10) == 1
    for workers in (0, -1, "two", 1.5, True):
        with pytest.raises(InputError, match="workers: expected a whole number of at least 1"):
            resolve_workers(workers, 10)
    for start, stop in ((-3, 2), (5, 2), (1.5, None)):
        with pytest.raises(InputError, match="expected whole numbers 0 <= START < STOP"):
            FrameRange(start, stop)
