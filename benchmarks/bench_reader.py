"""Streaming reader: throughput and peak memory reading a 600-frame 320x240 recording.

Targets (issue 2): peak memory < 300 MB, >= 200 stereo frames per second.
"""

from __future__ import annotations

from common import recording, run_child

READ = """
import time, cv2
cv2.setNumThreads(1)
from accumcli.recording import Recording
t0 = time.perf_counter()
n = 0
with Recording({path!r}) as rec:
    for frame in rec.frames():
        n += 1
RESULT = {{'frames': n, 'seconds': time.perf_counter() - t0}}
"""


def main() -> dict:
    long = recording("reader_600", frames=600, width=320, height=240, seed=21)
    short = recording("reader_60", frames=60, width=320, height=240, seed=21)
    results = {}
    for name, path in (("600 frames", long), ("60 frames", short)):
        r = run_child(READ.format(path=path))
        results[name] = r
        print(f"reader  {name:>10}: {r['frames'] / r['seconds']:7.1f} stereo frames/s, "
              f"peak memory {r['peak_rss_mb']:6.1f} MB")
    return results


if __name__ == "__main__":
    main()
