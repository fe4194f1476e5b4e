"""Accumulation: one update step (model 5,000 segments, frame 1,000 segments; extraction
excluded), end-to-end `accumulate` throughput on the sample, and memory of long runs.

Targets (issue 4): a step in at most 5 ms; >= 12 stereo pairs per second end to end;
peak memory of a 600-frame run at most 1.2 times that of a 60-frame run.
"""

from __future__ import annotations

import copy
import time

import numpy as np
from common import ROOT, recording, run_child


def synthetic_step(n_model: int = 5000, n_new: int = 1000, repeats: int = 30) -> dict:
    import cv2

    cv2.setNumThreads(1)
    from accumcli.geometry import make_transform
    from accumcli.line_model import FrameContext
    from accumcli.pipeline import AccumulateParams, LineAccumulation
    from accumcli.recording import StereoIntrinsics
    from accumcli.segments import Segments

    rng = np.random.default_rng(0)
    intr = StereoIntrinsics(600.0, 600.0, 319.5, 239.5, 0.08, 640, 480)
    T = make_transform(np.eye(3), [0.0, 0.0, 0.5])

    def segments(n, spread=0.1):
        d = rng.normal(size=(n, 3))
        return Segments("camera_left", rng.uniform(-spread, spread, (n, 3)) + [0, 0, 0.5],
                        d / np.linalg.norm(d, axis=1, keepdims=True), np.full(n, 0.0125), np.full(n, 0.9),
                        np.ones(n, np.int64), {"sigma_depth_m": np.full(n, 0.001)})

    acc = LineAccumulation(AccumulateParams())
    core = acc.core
    core.update(segments(n_model), np.linalg.inv(T), FrameContext(T, intr))   # model of n_model segments
    times = []
    for _ in range(repeats):
        state = copy.deepcopy({k: v for k, v in vars(core).items() if k not in ("entity_type", "rule")})
        new = segments(n_new)
        new.centers[: n_new // 2] = core.entities.centers[: n_new // 2] + [0.0, 0.0, 0.5] - \
            [0, 0, 0] + rng.normal(0, 0.0005, (n_new // 2, 3))  # half of them re-observe the model
        new.directions[: n_new // 2] = core.entities.directions[: n_new // 2]
        t0 = time.perf_counter()
        core.update(new, np.linalg.inv(T), FrameContext(T, intr))
        times.append(time.perf_counter() - t0)
        vars(core).update(state)
    return {"model": n_model, "new": n_new, "median_ms": 1000 * float(np.median(times))}


END_TO_END = """
import time, cv2
cv2.setNumThreads(1)
from accumcli.runs import accumulate_recording
result = accumulate_recording({path!r})
RESULT = {{'frames': result.frames, 'seconds': result.seconds, 'model': len(result.model)}}
"""


def main() -> dict:
    step = synthetic_step()
    print(f"accumulate  one step, model {step['model']} + frame {step['new']} segments: {step['median_ms']:.2f} ms "
          "(median of 30, extraction excluded)")
    sample = str(ROOT / "sample_data" / "sim_box.mcap")
    e2e = run_child(END_TO_END.format(path=sample))
    print(f"accumulate  end to end on the sample (640x480, {e2e['frames']} frames): "
          f"{e2e['frames'] / e2e['seconds']:.1f} stereo pairs/s")
    memory = {}
    for name, frames in (("60", 60), ("600", 600)):
        path = recording(f"reader_{frames}", frames=frames, width=320, height=240, seed=21)
        memory[name] = run_child(END_TO_END.format(path=path))
        print(f"accumulate  {frames:>3} frames of 320x240: peak memory {memory[name]['peak_rss_mb']:.1f} MB, "
              f"final model {memory[name]['model']} segments")
    print(f"accumulate  peak memory ratio 600/60 frames: "
          f"{memory['600']['peak_rss_mb'] / memory['60']['peak_rss_mb']:.3f}")
    return {"step": step, "end_to_end": e2e, "memory": memory}


if __name__ == "__main__":
    main()
