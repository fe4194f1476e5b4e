"""Hand-made recordings for tests: a few frames of a textured scene with
controllable defects (missing topics, corrupt images, bad transforms)."""

from __future__ import annotations

import numpy as np

from accumcli.geometry import make_transform
from accumcli.recording import CameraCalibration, RecordingWriter

T0 = 1_000_000_000
PERIOD = 100_000_000


def calibration(side: str, width=160, height=120, fx=150.0, baseline=0.08) -> CameraCalibration:
    P = np.array([[fx, 0, width / 2, 0], [0, fx, height / 2, 0], [0, 0, 1, 0]], float)
    if side == "right":
        P[0, 3] = -fx * baseline
    return CameraCalibration(width, height, P[:, :3].copy(), np.zeros(5), np.eye(3), P, "plumb_bob",
                             f"camera_{side}")


def image(i: int, width=160, height=120) -> np.ndarray:
    rng = np.random.default_rng(i)
    return rng.integers(0, 255, (height, width), dtype=np.uint8)


def pose(i: int) -> np.ndarray:
    return make_transform(np.eye(3), [0.01 * i, 0.0, 0.5])


def write(path, n=5, *, skip_topics=(), corrupt_left=(), unpaired_right=(), tf_quats=None, tf_times=None,
          encoding="png", images=None) -> str:
    """A small recording; the options break it in the named ways. ``images``: the image of index i
    (the right image of frame i is image i + 100; default ``image``, noise)."""
    image_of = images or image
    with RecordingWriter(path) as w:
        for side in ("left", "right"):
            if f"/stereo/{side}/calibration" not in skip_topics:
                w.calibration(f"/stereo/{side}/calibration", calibration(side), T0)
        if "/tf" not in skip_topics:
            times = tf_times if tf_times is not None else [T0 + i * PERIOD for i in range(n)]
            for j, t in enumerate(times):
                quat = tf_quats[j] if tf_quats is not None else (0.0, 0.0, 0.0, 1.0)
                w.raw_transform("camera_left", "gripper", (0.01 * j, 0.0, 0.5), quat, int(t))
        for i in range(n):
            t = T0 + i * PERIOD
            if "/stereo/left/image" not in skip_topics:
                if i in corrupt_left:
                    from accumcli.recording.messages import image_to_msg

                    msg = image_to_msg(image_of(i), t, "camera_left", "png")
                    msg.data = b"\x89PNG garbage"
                    w._writer.write_message("/stereo/left/image", msg, log_time=t, publish_time=t)
                else:
                    w.image("/stereo/left/image", image_of(i), t, "camera_left", encoding)
            if "/stereo/right/image" not in skip_topics:
                shift = 20_000_000 if i in unpaired_right else 0
                w.image("/stereo/right/image", image_of(i + 100), t + shift, "camera_right", encoding)
    return str(path)


def one_pair(path, *, image_topic="/stereo/{side}/image", calibration_topic="/stereo/{side}/calibration",
             frame_id="camera_{side}", calibrations=None, transforms=(("camera_left", "gripper", (0.0, 0.0, 0.5)),)) -> str:
    """A recording of one stereo pair at ``T0``: each side's calibration (``calibrations``: (left, right),
    else ``calibration(side)``) and image on the topics and frame named with ``{side}``, and the
    ``transforms`` (parent, child, translation; no rotation)."""
    with RecordingWriter(path) as w:
        for k, side in enumerate(("left", "right")):
            cal = calibrations[k] if calibrations is not None else calibration(side)
            w.calibration(calibration_topic.format(side=side), cal, T0)
            w.image(image_topic.format(side=side), image(0), T0, frame_id.format(side=side), "png")
        for parent, child, translation in transforms:
            w.raw_transform(parent, child, translation, (0.0, 0.0, 0.0, 1.0), T0)
    return str(path)
