"""Tracking: frames per second at 640x480 on one thread (model from the first 20 frames of a
simulated 60-frame recording, then all 60 frames tracked from the first pose only).

Target (issue 5): at least 20 stereo frames per second. Re-acquisition by RANSAC (with extraction)
runs only after a loss; it is counted when it happens.
"""

from __future__ import annotations

from common import recording, run_child

TRACK = """
import time, cv2, numpy as np
cv2.setNumThreads(1)
from accumcli.recording import Recording
from accumcli.pipeline import LineAccumulation
from accumcli.track import PoseTracker
from accumcli.extract import extract_frame
with Recording({path!r}) as rec:
    frames = list(rec.frames())
acc = LineAccumulation()
for frame in frames[:20]:
    acc.step(frame, frame.T_camera_object)
tracker = PoseTracker(acc.model())
t0 = time.perf_counter()
status = []
for frame in frames:
    estimate = tracker.update(frame, frame.T_camera_object if frame.index == 0 else None,
                              lambda f=frame: extract_frame(f).segments)
    status.append(estimate.status)
seconds = time.perf_counter() - t0
RESULT = {{'frames': len(frames), 'seconds': seconds, 'tracked': status.count('tracked')}}
"""


def main() -> dict:
    path = recording("track_60", frames=60, width=640, height=480, seed=5)
    r = run_child(TRACK.format(path=path))
    print(f"track       {r['frames'] / r['seconds']:5.1f} stereo frames/s at 640x480, one thread "
          f"({r['tracked']}/{r['frames']} tracked)")
    return r


if __name__ == "__main__":
    main()
