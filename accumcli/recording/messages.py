"""Conversions between Foxglove protobuf messages and numpy / library types.

Images become (H, W) uint8 grey arrays: colour is converted with OpenCV's
weights, mono16 is scaled by 255/65535 (little-endian, as Foxglove's RawImage).
"""

from __future__ import annotations

import cv2
import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration as CalibrationMsg
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf.timestamp_pb2 import Timestamp

from .calibration import CameraCalibration

RAW_ENCODINGS = {"mono8": (1, np.uint8), "8UC1": (1, np.uint8), "rgb8": (3, np.uint8), "bgr8": (3, np.uint8),
                 "mono16": (1, np.dtype("<u2")), "16UC1": (1, np.dtype("<u2"))}


class DecodeError(ValueError):
    """An image message whose bytes cannot be turned into an image."""


def stamp_ns(stamp) -> int:
    """Integer nanoseconds of a protobuf Timestamp."""
    return int(stamp.seconds) * 1_000_000_000 + int(stamp.nanos)


def to_stamp(t_ns: int) -> Timestamp:
    return Timestamp(seconds=int(t_ns) // 1_000_000_000, nanos=int(t_ns) % 1_000_000_000)


def image_encoding(msg) -> str:
    """'png', 'jpeg', or the raw encoding name, for summaries."""
    return msg.format if hasattr(msg, "format") else msg.encoding


def decode_image(msg) -> np.ndarray:
    """(H, W) uint8 grey image of a CompressedImage or RawImage; raises ``DecodeError``."""
    if hasattr(msg, "format"):
        buffer = np.frombuffer(msg.data, np.uint8)
        image = cv2.imdecode(buffer, cv2.IMREAD_UNCHANGED) if buffer.size else None
        if image is None:
            raise DecodeError(f"cannot decode {msg.format or 'compressed'} image bytes ({len(msg.data)} bytes)")
    else:
        if msg.encoding not in RAW_ENCODINGS:
            raise DecodeError(f"raw image encoding {msg.encoding!r} is not supported "
                              f"(expected one of {', '.join(RAW_ENCODINGS)})")
        channels, dtype = RAW_ENCODINGS[msg.encoding]
        row_bytes = msg.width * channels * np.dtype(dtype).itemsize
        step = msg.step or row_bytes
        if msg.width == 0 or msg.height == 0 or step < row_bytes or len(msg.data) < step * (msg.height - 1) + row_bytes:
            raise DecodeError(f"raw {msg.encoding} image {msg.width}x{msg.height} (step {step}) "
                              f"does not fit its {len(msg.data)} data bytes")
        rows = np.lib.stride_tricks.as_strided(
            np.frombuffer(msg.data, np.uint8), shape=(msg.height, row_bytes), strides=(step, 1))
        image = rows.copy().view(dtype).reshape(msg.height, msg.width, channels)
        if msg.encoding == "rgb8":
            image = image[:, :, ::-1]
    if image.ndim == 3:
        image = image[:, :, 0] if image.shape[2] == 1 else cv2.cvtColor(
            image, cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if image.dtype == np.uint16:
        image = cv2.convertScaleAbs(image, alpha=255.0 / 65535.0)
    return np.ascontiguousarray(image, dtype=np.uint8)


def calibration_from_msg(msg) -> CameraCalibration:
    """``CameraCalibration`` of a foxglove.CameraCalibration; raises ValueError if malformed."""
    if len(msg.K) != 9 or len(msg.P) != 12:
        raise ValueError(f"expected K with 9 and P with 12 values, found {len(msg.K)} and {len(msg.P)}")
    R = np.array(msg.R, float).reshape(3, 3) if len(msg.R) == 9 else np.eye(3)
    return CameraCalibration(
        width=int(msg.width), height=int(msg.height), K=np.array(msg.K, float).reshape(3, 3),
        D=np.array(msg.D, float), R=R, P=np.array(msg.P, float).reshape(3, 4),
        distortion_model=msg.distortion_model, frame_id=msg.frame_id)


def calibration_to_msg(cal: CameraCalibration, t_ns: int) -> CalibrationMsg:
    return CalibrationMsg(
        timestamp=to_stamp(t_ns), frame_id=cal.frame_id, width=cal.width, height=cal.height,
        distortion_model=cal.distortion_model, D=list(map(float, cal.D)), K=list(cal.K.ravel()),
        R=list(cal.R.ravel()), P=list(cal.P.ravel()))


def image_to_msg(image: np.ndarray, t_ns: int, frame_id: str, encoding: str = "png"):
    """A CompressedImage (``png``/``jpeg``) or RawImage (``mono8``) of an (H, W) uint8 image."""
    if encoding == "mono8":
        return RawImage(timestamp=to_stamp(t_ns), frame_id=frame_id, width=image.shape[1], height=image.shape[0],
                        encoding="mono8", step=image.shape[1], data=np.ascontiguousarray(image).tobytes())
    params = [cv2.IMWRITE_JPEG_QUALITY, 92] if encoding == "jpeg" else [cv2.IMWRITE_PNG_COMPRESSION, 6]
    ok, data = cv2.imencode(".jpg" if encoding == "jpeg" else ".png", image, params)
    assert ok
    return CompressedImage(timestamp=to_stamp(t_ns), frame_id=frame_id, format=encoding, data=data.tobytes())


def transform_to_msg(parent: str, child: str, t_ns: int, translation, quat_xyzw) -> FrameTransform:
    msg = FrameTransform(timestamp=to_stamp(t_ns), parent_frame_id=parent, child_frame_id=child)
    msg.translation.x, msg.translation.y, msg.translation.z = map(float, translation)
    msg.rotation.x, msg.rotation.y, msg.rotation.z, msg.rotation.w = map(float, quat_xyzw)
    return msg
