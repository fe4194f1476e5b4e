"""Tracking: frames per second at 640x480 on one thread (model from the first 20 frames of a
simulated 60-frame recording, then all 60 frames tracked from the first pose only; the whole
library run, reading and decoding included).

Target (issue 5): at least 20 stereo frames per second. Re-acquisition by RANSAC (with extraction)
runs only after a loss; it is counted when it happens.
"""

from __future__ import annotations

from common import recording, run_child

TRACK = """
import cv2
cv2.setNumThreads(1)
from accumcli.runs import FrameRange, accumulate_recording, track_recording
model = accumulate_recording({path!r}, frames=FrameRange(0, 20)).model
result = track_recording(model, {path!r})
RESULT = {{'frames': result.frames, 'seconds': result.seconds, 'tracked': result.tracked}}
"""


def main() -> dict:
    path = recording("track_60", frames=60, width=640, height=480, seed=5)
    r = run_child(TRACK.format(path=path))
    print(f"track       {r['frames'] / r['seconds']:5.1f} stereo frames/s at 640x480, one thread "
          f"({r['tracked']}/{r['frames']} tracked)")
    return r


if __name__ == "__main__":
    main()
