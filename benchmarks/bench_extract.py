"""Extraction throughput at 640x480 on one thread, with the per-stage breakdown.

Target (issue 3): at least 15 stereo pairs per second (reading excluded: the frames are decoded
first), stages: gradients, Hough, local segments, matching, triangulation.
"""

from __future__ import annotations

from common import ROOT, run_child

EXTRACT = """
import time, cv2
cv2.setNumThreads(1)
from accumcli.recording import Recording
from accumcli.extract import ExtractParams, extract_frame
from accumcli.lines2d import LineParams, StageTimes
with Recording({path!r}) as rec:
    frames = list(rec.frames())
params = ExtractParams(LineParams(detector={detector!r}))
extract_frame(frames[0], params)          # warm-up
times = StageTimes()
t0 = time.perf_counter()
segments = 0
for frame in frames:
    segments += len(extract_frame(frame, params, times=times).segments)
seconds = time.perf_counter() - t0
RESULT = {{'frames': len(frames), 'seconds': seconds, 'segments': segments,
          'stages_ms': {{k: 1000 * v / len(frames) for k, v in times.seconds.items()}}}}
"""


def main() -> dict:
    sample = str(ROOT / "sample_data" / "sim_box.mcap")
    results = {}
    for detector in ("chains", "hough", "lsd"):
        r = run_child(EXTRACT.format(path=sample, detector=detector))
        results[detector] = r
        stages = ", ".join(f"{k} {v:.1f}" for k, v in r["stages_ms"].items())
        print(f"extract     {detector:>5}: {r['frames'] / r['seconds']:5.1f} stereo pairs/s at 640x480, one thread, "
              f"{r['segments'] / r['frames']:.0f} segments/frame; ms per pair: {stages}")
    return results


if __name__ == "__main__":
    main()
