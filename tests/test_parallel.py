"""Extraction in worker processes (accumcli.runs.parallel): the same bytes whatever the number."""

from __future__ import annotations

from accumcli.runs import FrameRange, accumulate_recording, extract_recording


def test_two_workers_give_the_same_model_and_frames_bytes(small_recording, tmp_path):
    outputs = {}
    for workers in (1, 2):
        model, frames = tmp_path / f"m{workers}.json", tmp_path / f"f{workers}.jsonl"
        result = accumulate_recording(small_recording, [str(model)], frames=FrameRange(0, 4), workers=workers)
        extract_recording(small_recording, str(frames), frames=FrameRange(0, 4), workers=workers)
        outputs[workers] = (model.read_bytes(), frames.read_bytes(), result.frames, sorted(result.times.seconds))
    assert outputs[1] == outputs[2]
    assert outputs[1][2] == 4 and "hough" in outputs[1][3]   # stage times come back from the workers
