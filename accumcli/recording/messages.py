"""Conversions between Foxglove protobuf messages and numpy / library types.

Images become (H, W) uint8 grey arrays: colour is converted with OpenCV's
weights, Bayer demosaiced first, YUV 4:2:2 gives its luma (``RAW_ENCODINGS``); 16-bit data is
scaled to its bit depth (``sixteen_bit_full_scale``; little-endian, as Foxglove's RawImage).
Before any pixel is decoded, ``image_size`` reads the size from the PNG or JPEG
header (or the RawImage fields), so an image larger than ``MAX_SIDE`` /
``MAX_PIXELS`` or of another size than its calibration is refused without
allocating it. Compressed data must be PNG or JPEG by its signature. What the
codecs print (libpng, libjpeg, OpenCV's log) is captured and becomes part of
the ``DecodeError`` or is dropped, never written to the terminal.
"""

from __future__ import annotations

import atexit
import json
import math
import os
import re
import struct
import tempfile
import threading

import cv2
import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import (
    CameraCalibration as CalibrationMsg,
)
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf import json_format
from google.protobuf.timestamp_pb2 import Timestamp

from ..errors import one_line
from .calibration import MAX_PIXELS, MAX_SIDE, CameraCalibration, size_problem  # noqa: F401

_U16 = np.dtype("<u2")
# raw encoding -> (channels, dtype, OpenCV conversion to grey or None): every encoding Foxglove's RawImage
# lists (but 32FC1) and ROS's colour, 16-bit and Bayer ones. Bayer codes as cv_bridge's: OpenCV names a
# pattern by the second row's first two pixels, so ROS's rggb is OpenCV's BG.
RAW_ENCODINGS = {
    "mono8": (1, np.uint8, None), "8UC1": (1, np.uint8, None), "mono16": (1, _U16, None), "16UC1": (1, _U16, None),
    "rgb8": (3, np.uint8, cv2.COLOR_RGB2GRAY), "bgr8": (3, np.uint8, cv2.COLOR_BGR2GRAY),
    "8UC3": (3, np.uint8, cv2.COLOR_BGR2GRAY), "rgba8": (4, np.uint8, cv2.COLOR_RGBA2GRAY),
    "bgra8": (4, np.uint8, cv2.COLOR_BGRA2GRAY), "8UC4": (4, np.uint8, cv2.COLOR_BGRA2GRAY),
    "rgb16": (3, _U16, cv2.COLOR_RGB2GRAY), "bgr16": (3, _U16, cv2.COLOR_BGR2GRAY),
    "rgba16": (4, _U16, cv2.COLOR_RGBA2GRAY), "bgra16": (4, _U16, cv2.COLOR_BGRA2GRAY),
    **{f"bayer_{pattern}{bits}": (1, np.uint8 if bits == 8 else _U16, code)
       for pattern, code in (("rggb", cv2.COLOR_BayerBG2GRAY), ("bggr", cv2.COLOR_BayerRG2GRAY),
                             ("gbrg", cv2.COLOR_BayerGR2GRAY), ("grbg", cv2.COLOR_BayerGB2GRAY)) for bits in (8, 16)},
    "uyvy": (2, np.uint8, cv2.COLOR_YUV2GRAY_UYVY), "yuv422": (2, np.uint8, cv2.COLOR_YUV2GRAY_UYVY),
    "yuyv": (2, np.uint8, cv2.COLOR_YUV2GRAY_YUY2), "yuv422_yuy2": (2, np.uint8, cv2.COLOR_YUV2GRAY_YUY2),
}
SIXTEEN_BIT = tuple(name for name, (_, dtype, _) in RAW_ENCODINGS.items() if dtype == _U16)
YUV422 = ("uyvy", "yuv422", "yuyv", "yuv422_yuy2")


def encoding_problem(msg) -> str | None:
    """Why an image's encoding cannot be read (for an error when the recording opens: every frame would
    fail alike), or None: a compressed image (but a compressedDepth one), or a raw image in an encoding of
    ``RAW_ENCODINGS``."""
    if "compresseddepth" in getattr(msg, "format", "").lower():
        return (f"image format {msg.format!r} is a compressed depth image (ROS compressedDepth); accum needs the "
                "cameras' intensity images: choose their topics")
    encoding = getattr(msg, "encoding", None)
    if encoding in YUV422 and msg.width % 2:
        return f"image encoding {encoding!r} (YUV 4:2:2) needs an even width, found {msg.width} px"
    if encoding is None or encoding in RAW_ENCODINGS:
        return None
    if encoding in ("32FC1", "64FC1"):
        return (f"image encoding {encoding!r} holds floating-point values (a depth or disparity map?); "
                "accum needs the cameras' intensity images: choose their topics")
    return (f"image encoding {encoding!r} is not supported (supported: {', '.join(RAW_ENCODINGS)}); "
            "convert the images to one of them, e.g. with image_proc")


INT64_MIN, INT64_MAX = -(1 << 63), (1 << 63) - 1
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_SOI = b"\xff\xd8"


class DecodeError(ValueError):
    """An image message whose bytes cannot be turned into an image."""


def stamp_ns(stamp) -> int:
    """Integer nanoseconds of a protobuf Timestamp; ValueError outside the int64 range."""
    t = int(stamp.seconds) * 1_000_000_000 + int(stamp.nanos)
    if not INT64_MIN <= t <= INT64_MAX:
        raise ValueError(f"timestamp {int(stamp.seconds)} s is outside the int64 nanosecond range")
    return t


def _jpeg_size(data: bytes) -> tuple[int, int]:
    """(width, height) from the first SOF marker of JPEG ``data``; raises DecodeError."""
    i, n = 2, len(data)
    while i + 4 <= n:
        if data[i] != 0xFF:
            raise DecodeError("JPEG data has a broken marker structure")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0x01, *range(0xD0, 0xD8)):
            i += 2
            continue
        (length,) = struct.unpack_from(">H", data, i + 2)
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            if i + 9 > n:
                break
            height, width = struct.unpack_from(">HH", data, i + 5)
            return width, height
        if marker in (0xD9, 0xDA) or length < 2:
            break
        i += 2 + length
    raise DecodeError("JPEG data has no frame header (SOF)")


def image_size(msg) -> tuple[int, int]:
    """(width, height) pixels an image message declares, read from its header without decoding."""
    if not hasattr(msg, "format"):
        return int(msg.width), int(msg.height)
    data = msg.data
    try:
        if data[:8] == PNG_SIGNATURE:
            if len(data) < 24 or data[12:16] != b"IHDR":
                raise DecodeError("PNG data has no IHDR header")
            return struct.unpack_from(">II", data, 16)
        if data[:2] == JPEG_SOI:
            return _jpeg_size(data)
        raise DecodeError("neither PNG nor JPEG by its signature")
    except (DecodeError, struct.error) as e:
        raise DecodeError(f"cannot decode {msg.format or 'compressed'} image bytes ({len(data)} bytes): {e}") from None


class _CapturedStderr:
    """Redirects file descriptor 2 into a temporary file while codecs run (one thread at a time)."""

    _lock = threading.Lock()
    _file = None

    def __enter__(self) -> "_CapturedStderr":
        self._lock.acquire()
        if _CapturedStderr._file is None:
            _CapturedStderr._file = tempfile.TemporaryFile()
            atexit.register(_CapturedStderr._file.close)
        self._file.seek(0)
        self._file.truncate()
        self._saved = os.dup(2)
        os.dup2(self._file.fileno(), 2)
        return self

    def __exit__(self, *exc) -> None:
        os.dup2(self._saved, 2)
        os.close(self._saved)
        self._file.seek(0)
        self.text = self._file.read(2000).decode("utf-8", "replace").strip()
        self._lock.release()


def to_stamp(t_ns: int) -> Timestamp:
    return Timestamp(seconds=int(t_ns) // 1_000_000_000, nanos=int(t_ns) % 1_000_000_000)


def image_encoding(msg) -> str:
    """'png', 'jpeg', or the raw encoding name, for summaries."""
    return msg.format if hasattr(msg, "format") else msg.encoding


def sixteen_bit_full_scale(msg) -> int | None:
    """The full scale of a 16-bit image's data, raw (mono16) or a 16-bit PNG (2^b - 1, b the even
    number of bits from 10 to 16 its largest value needs), or None for other images. Why: many
    industrial drivers publish 10- or 12-bit data as 16 bits; scaled by 255/65535 a 12-bit image keeps
    16 grey levels and its edges are lost (completeness 0.09 instead of 0.91 on the sample; a 16-bit
    PNG of 12-bit data gave an empty model)."""
    data = getattr(msg, "data", b"")
    if getattr(msg, "encoding", None) in SIXTEEN_BIT and data:
        values = np.frombuffer(data[:len(data) // 2 * 2], "<u2")
        if RAW_ENCODINGS[msg.encoding][0] == 4:   # an opaque alpha (65535) says nothing of the colours' bits
            values = values[:len(values) // 4 * 4].reshape(-1, 4)[:, :3]
        largest = int(values.max(initial=0))
    elif hasattr(msg, "format") and data[:8] == PNG_SIGNATURE and len(data) > 24 and data[24] == 16:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)   # the IHDR says 16 bits
        if image is None or image.dtype != np.uint16:
            return None
        largest = int(image.max())
    else:
        return None
    bits = min(16, max(10, largest.bit_length() + largest.bit_length() % 2))
    return (1 << bits) - 1


def decode_image(msg, expected_size: tuple[int, int] | None = None, full_scale: int = 65535) -> np.ndarray:
    """(H, W) uint8 grey image of a CompressedImage or RawImage; raises ``DecodeError``. 16-bit
    images are scaled by 255 / ``full_scale`` (``sixteen_bit_full_scale``), saturating above it.

    The header's size is checked first, against the limits and ``expected_size``
    (width, height) if given, so a refused image is never allocated.
    """
    width, height = image_size(msg)
    problem = size_problem(width, height)
    if problem:
        raise DecodeError(f"image header: {problem}")
    if expected_size is not None and (width, height) != tuple(expected_size):
        raise DecodeError(f"image size {width}x{height} differs from the calibration's "
                          f"{expected_size[0]}x{expected_size[1]}")
    if hasattr(msg, "format"):
        buffer = np.frombuffer(msg.data, np.uint8)
        with _CapturedStderr() as captured:
            try:
                image = cv2.imdecode(buffer, cv2.IMREAD_UNCHANGED)
            except cv2.error:
                image = None
        said = one_line(captured.text, 200)
        if image is None:
            raise DecodeError(f"cannot decode {msg.format or 'compressed'} image bytes ({len(msg.data)} bytes)"
                              + (f": {said}" if said else ""))
        if _damaged(captured.text, msg.data):   # libjpeg decodes what it can and fills the rest grey
            raise DecodeError(f"damaged {msg.format or 'compressed'} image data ({said})")
        if image.shape[1] != width or image.shape[0] != height:
            raise DecodeError(f"decoded image is {image.shape[1]}x{image.shape[0]}, its header said {width}x{height}")
        source = msg.format.split(";")[0].strip()   # ROS image_transport: "bayer_rggb8; png compressed "
        if source.startswith("bayer_") and source in RAW_ENCODINGS and image.ndim == 2:
            image = cv2.cvtColor(image, RAW_ENCODINGS[source][2])   # the mosaic itself, compressed
    else:
        problem = encoding_problem(msg)
        if problem:
            raise DecodeError(problem)
        channels, dtype, to_grey = RAW_ENCODINGS[msg.encoding]
        row_bytes = msg.width * channels * np.dtype(dtype).itemsize
        step = msg.step or row_bytes
        if msg.width == 0 or msg.height == 0 or step < row_bytes or len(msg.data) < step * (msg.height - 1) + row_bytes:
            raise DecodeError(f"raw {msg.encoding} image {msg.width}x{msg.height} (step {step}) "
                              f"does not fit its {len(msg.data)} data bytes")
        rows = np.lib.stride_tricks.as_strided(
            np.frombuffer(msg.data, np.uint8), shape=(msg.height, row_bytes), strides=(step, 1))
        image = rows.copy().view(dtype).reshape(msg.height, msg.width, channels)
        image = image[:, :, 0] if to_grey is None else _to_grey(image, to_grey, msg)
    if image.ndim == 3:
        image = image[:, :, 0] if image.shape[2] == 1 else cv2.cvtColor(
            image, cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if image.dtype == np.uint16:
        image = cv2.convertScaleAbs(image, alpha=255.0 / full_scale)
    return np.ascontiguousarray(image, dtype=np.uint8)


_EXTRANEOUS = re.compile(r"corrupt jpeg data: (\d+) extraneous bytes before marker 0xd9$")


def _damaged(codec_said: str, data: bytes) -> bool:
    """A codec's warning that the image it still returned is partly made up: libjpeg's corrupt or cut
    data (filled grey from there on). Its one note of a few extraneous bytes before the final end marker
    is not: some cameras pad their JPEGs so, and no pixel is lost; but libjpeg says the same after it
    lost its way in corrupt data, so more than 2 such bytes count only if they are padding (0x00 or
    0xff)."""
    said = [line.strip().lower() for line in codec_said.splitlines() if line.strip()]
    if not said:
        return False
    padded = _EXTRANEOUS.match(said[0]) if len(said) == 1 else None
    if padded and bytes(data[-2:]) == b"\xff\xd9":
        n = int(padded.group(1))
        return n > 2 and bytes(data[-2 - n:-2]).strip(b"\x00\xff") != b""
    return any("premature end" in line or "corrupt jpeg data" in line or "huffman" in line for line in said)


def _to_grey(image: np.ndarray, code: int, msg) -> np.ndarray:
    """(H, W) grey of a raw colour, Bayer or YUV 4:2:2 ``image`` (H, W, channels) by OpenCV's ``code``.
    Bayer is demosaiced (bilinear) before the grey, never read as grey: a raw pattern's pixels alternate
    between the filters' responses, a grid of edges. YUV 4:2:2's grey is its luma (an odd width is refused
    when the recording opens: ``encoding_problem``)."""
    if msg.encoding.startswith("bayer_") and (msg.width < 2 or msg.height < 2):
        raise DecodeError(f"{msg.encoding} image {msg.width}x{msg.height}: a Bayer pattern needs 2x2 pixels")
    return cv2.cvtColor(image if image.shape[2] > 1 else image[:, :, 0], code)


def from_foxglove_json(cls, data):
    """A message of protobuf class ``cls`` from its Foxglove JSON encoding (an MCAP channel with message
    encoding ``json``, as Foxglove's SDKs and bridges write the same schemas): times are
    ``{"sec", "nsec"}`` objects, bytes base64 strings, unknown fields ignored. Raises ValueError.
    Why by hand: protobuf's JSON parser takes the rest as it is, but wants times as RFC 3339 text."""
    doc = json.loads(bytes(data))
    if not isinstance(doc, dict):
        raise ValueError("the message is not a JSON object")
    try:
        return json_format.ParseDict(_times_as_text(doc), cls(), ignore_unknown_fields=True)
    except (json_format.ParseError, ValueError, OverflowError) as e:
        raise ValueError(one_line(e, 200)) from None


def _times_as_text(value):
    """``value`` with every Foxglove time object ({"sec": s, "nsec": n}) as protobuf's RFC 3339 text.
    A fractional ``sec`` (some writers' float seconds) keeps its fraction (as exactly as the float
    holds it: 0.1 us at today's times), and ``nsec`` beyond a second carries into ``sec``: cut to whole seconds, consecutive frames
    shared a stamp and were dropped."""
    if isinstance(value, dict):
        if value and set(value) <= {"sec", "nsec"}:
            sec, nsec = value.get("sec", 0), value.get("nsec", 0)
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (sec, nsec)):
                raise ValueError(f"a time's sec and nsec must be numbers, found {value!r}")
            if isinstance(sec, int) and isinstance(nsec, int):
                total = sec * 1_000_000_000 + nsec
            elif math.isfinite(sec) and math.isfinite(nsec):   # the fraction alone times 1e9: exact to 1 ns
                whole = math.floor(sec)
                total = int(whole) * 1_000_000_000 + round((sec - whole) * 1e9) + round(nsec)
            else:
                raise ValueError(f"a time's sec and nsec must be finite, found {value!r}")
            seconds, nanos = divmod(total, 1_000_000_000)
            return Timestamp(seconds=seconds, nanos=nanos).ToJsonString()
        return {k: _times_as_text(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_times_as_text(v) for v in value]
    return value


def calibration_from_msg(msg) -> CameraCalibration:
    """``CameraCalibration`` of a foxglove.CameraCalibration; raises ValueError if malformed.

    Only the shapes are checked here; ``calibration.check_calibration`` checks the values.
    """
    if len(msg.K) != 9 or len(msg.P) != 12:
        raise ValueError(f"expected K with 9 and P with 12 values, found {len(msg.K)} and {len(msg.P)}")
    if len(msg.R) not in (0, 9):
        raise ValueError(f"expected R with 9 values, found {len(msg.R)}")
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
