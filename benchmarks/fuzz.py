"""`make fuzz`: mutated recordings through info, extraction and a short accumulation.

Tiny good recordings (160x120, 3 stereo frames; PNG, JPEG, mono8, distorted,
a tf tree, lz4, unchunked, without CRCs) are mutated at the byte level (bit
flips, overwrites, inserts, deletions, truncations, huge record lengths) and
rebuilt structure-aware (lying image sizes, PNG bombs, NaN/inf/zero in
calibration and poses, zero/negative baseline, odd timestamps, tf cycles,
wrong schemas, unpaired cameras). Each input runs ``exercise(path)`` in a forked
worker (2 at a time, 60 s timeout, RLIMIT_AS 2 GiB). A run passes when it ends
normally or with an ``AccumError``; a traceback, a hang, a memory-limit hit or
output that is not accum's is a failure and the input is saved to the crash
folder. Prints the counts by class.

    python benchmarks/fuzz.py [--count N] [--seconds S] [--seed K] [--crashes DIR]
"""

from __future__ import annotations

import os
import shutil

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import functools  # noqa: E402
import logging  # noqa: E402
import resource  # noqa: E402
import select  # noqa: E402
import signal  # noqa: E402
import struct  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
import zlib  # noqa: E402
from collections import Counter, defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration as CalibrationMsg  # noqa: E402
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform  # noqa: E402
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms  # noqa: E402
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage  # noqa: E402
from mcap.writer import CompressionType, Writer  # noqa: E402
from mcap_protobuf.schema import build_file_descriptor_set  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from accumcli.errors import AccumError  # noqa: E402
from accumcli.geometry import make_transform, quat_from_transform  # noqa: E402
from accumcli.recording import CameraCalibration  # noqa: E402
from accumcli.recording.calibration import MAX_PIXELS  # noqa: E402
from accumcli.recording.messages import calibration_to_msg, image_to_msg, to_stamp, transform_to_msg  # noqa: E402

T0 = 1_750_000_000 * 1_000_000_000
PERIOD = 100_000_000
TIMEOUT_S = 60
MEMORY_LIMIT = 2 << 30
LEFT, RIGHT = "/stereo/left/image", "/stereo/right/image"


def pick(rng: np.random.Generator, options):
    """One element of the sequence ``options``, as it is (no conversion to a numpy type)."""
    options = list(options)
    return options[int(rng.integers(len(options)))]


# -- building recordings ------------------------------------------------------------------------
def scene(i: int, side: str, width: int = 160, height: int = 120) -> np.ndarray:
    """(H, W) uint8: a bright box on a grey ramp, shifted by frame and by 8 px disparity on the right."""
    image = np.tile(np.linspace(60, 110, width, dtype=np.uint8), (height, 1))
    x = width // 3 + 3 * i - (8 if side == "right" else 0)
    image[height // 4: 3 * height // 4, x: x + width // 4] = 210
    image[height // 3: height // 2, x + 6: x + 14] = 30
    return image


def calibration(side: str, width: int = 160, height: int = 120, fx: float = 150.0, baseline: float = 0.08,
                raw: bool = False) -> CameraCalibration:
    P = np.array([[fx, 0, width / 2, 0], [0, fx, height / 2, 0], [0, 0, 1, 0]], float)
    if side == "right":
        P[0, 3] = -fx * baseline
    K, D = P[:, :3].copy(), np.zeros(5)
    if raw:
        K[0, 0] *= 1.02
        D = np.array([-0.1, 0.02, 0.0, 0.0, 0.0])
    return CameraCalibration(width, height, K, D, np.eye(3), P, "plumb_bob", f"camera_{side}")


class Builder:
    """Writes an MCAP with protobuf Foxglove messages, any schema on any topic, raw bytes allowed."""

    def __init__(self, path, chunk_size=4096, compression=CompressionType.ZSTD, chunked=True, crcs=True):
        self.file = open(path, "wb")
        self.w = Writer(self.file, chunk_size=chunk_size, compression=compression, use_chunking=chunked,
                        enable_crcs=crcs)
        self.w.start(profile="", library="accum-fuzz")
        self.channels: dict = {}

    def message(self, topic: str, msg, t_ns: int, schema_name: str | None = None, schema_data: bytes | None = None,
                encoding: str = "protobuf") -> None:
        key = (topic, schema_name or msg.DESCRIPTOR.full_name, schema_data, encoding)
        if key not in self.channels:
            data = schema_data if schema_data is not None else \
                build_file_descriptor_set(type(msg)).SerializeToString()
            schema = self.w.register_schema(name=key[1], encoding="protobuf", data=data)
            self.channels[key] = self.w.register_channel(topic=topic, message_encoding=encoding, schema_id=schema)
        payload = msg if isinstance(msg, bytes) else msg.SerializeToString()
        log_time = min(max(int(t_ns), 0), (1 << 64) - 1)
        self.w.add_message(self.channels[key], log_time=log_time, data=payload, publish_time=log_time)

    def close(self) -> None:
        self.w.finish()
        self.file.close()


def build(path, *, n=3, width=160, height=120, encoding="png", raw=False, tf_tree=False, compression="zstd",
          chunked=True, crcs=True, chunk_size=4096, left_cal=None, right_cal=None, cal_edit=None, image_edit=None,
          left_times=None, right_times=None, tf=None, tf_edit=None, extra=()) -> str:
    """A small good recording; the keyword arguments change it (the fuzzer's structure-aware mutations).

    cal_edit(side, msg), image_edit(side, i, msg) -> msg | bytes, tf_edit(msg) edit messages in place or
    return replacements; tf: list of (parent, child, t_ns, translation, quat) replacing the default
    camera_left -> gripper poses; extra: (topic, message, t_ns, schema_name, schema_data, encoding) tuples.
    """
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    b = Builder(path, chunk_size, comp, chunked, crcs)
    for side in ("left", "right"):
        cal = (left_cal if side == "left" else right_cal) or calibration(side, width, height, raw=raw)
        msg = calibration_to_msg(cal, T0)
        if cal_edit:
            msg = cal_edit(side, msg) or msg
        b.message(f"/stereo/{side}/calibration", msg, T0)
    if tf is None:
        tf = []
        for i in range(n):
            T = make_transform(np.eye(3), [0.01 * i, 0.0, 0.5])
            if tf_tree:
                tf.append(("world", "gripper", T0 + i * PERIOD, T[:3, 3], quat_from_transform(T)[1]))
            else:
                tf.append(("camera_left", "gripper", T0 + i * PERIOD, T[:3, 3], quat_from_transform(T)[1]))
        if tf_tree:
            b.message("/tf_static", transform_to_msg("world", "camera_left", T0, (0, 0, 0), (0, 0, 0, 1)), T0)
    for parent, child, t_ns, translation, quat in tf:
        msg = FrameTransform(parent_frame_id=parent, child_frame_id=child)
        if 0 <= t_ns < 1 << 63:
            msg.timestamp.CopyFrom(to_stamp(t_ns))
        else:
            msg.timestamp.seconds, msg.timestamp.nanos = int(t_ns // 1_000_000_000), int(t_ns % 1_000_000_000)
        msg.translation.x, msg.translation.y, msg.translation.z = map(float, translation)
        msg.rotation.x, msg.rotation.y, msg.rotation.z, msg.rotation.w = map(float, quat)
        if tf_edit:
            msg = tf_edit(msg) or msg
        b.message("/tf", msg, min(max(t_ns, 0), 1 << 62))
    for i in range(n):
        for side, topic, times in (("left", LEFT, left_times), ("right", RIGHT, right_times)):
            t = times[i] if times is not None else T0 + i * PERIOD
            msg = image_to_msg(scene(i, side, width, height), 0, f"camera_{side}", encoding)
            if 0 <= t < 1 << 63:
                msg.timestamp.CopyFrom(to_stamp(t))
            else:
                msg.timestamp.seconds, msg.timestamp.nanos = int(t // 1_000_000_000), int(t % 1_000_000_000)
            if image_edit:
                msg = image_edit(side, i, msg) or msg
            b.message(topic, msg, min(max(t, 0), 1 << 62), "foxglove.CompressedImage" if isinstance(msg, bytes)
                      else None, b"" if isinstance(msg, bytes) else None)
    for topic, msg, t_ns, schema_name, schema_data, enc in extra:
        b.message(topic, msg, t_ns, schema_name, schema_data, enc)
    b.close()
    return str(path)


SEEDS = {
    "png": {}, "jpeg": {"encoding": "jpeg"}, "mono8": {"encoding": "mono8"}, "raw": {"raw": True},
    "tftree": {"tf_tree": True}, "lz4": {"compression": "lz4"}, "unchunked": {"chunked": False},
    "nocrc": {"crcs": False}, "nocompression": {"compression": "none", "crcs": False},
}


# -- structure-aware mutations ------------------------------------------------------------------
def png_with_size(msg, width: int, height: int):
    """The PNG ``msg`` with its IHDR claiming width x height (CRC fixed, so only the size lies)."""
    data = bytearray(msg.data)
    data[16:24] = struct.pack(">II", width, height)
    data[29:33] = struct.pack(">I", zlib.crc32(bytes(data[12:29])))
    msg.data = bytes(data)
    return msg


@functools.lru_cache(maxsize=8)
def png_bomb(width: int, height: int) -> bytes:
    """A valid grey PNG of width x height zeros (highly compressible: a decompression bomb when large)."""
    row = b"\x00" * (width + 1)
    z = zlib.compressobj(9)
    idat = b"".join(z.compress(row) for _ in range(height)) + z.flush()

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)) + \
        chunk(b"IDAT", idat) + chunk(b"IEND", b"")


BAD_FLOATS = [float("nan"), float("inf"), -float("inf"), 0.0, -1.0, 1e200, -1e300, 1e-320, 1e20]


def structure_mutation(rng: np.random.Generator, path: str) -> str:
    """Builds a recording with one to three random defects; returns their names."""
    kw: dict = dict(SEEDS[pick(rng, list(SEEDS))])
    names = []
    for _ in range(int(rng.integers(1, 4))):
        name = str(pick(rng, list(STRUCTURE)))
        names.append(name)
        STRUCTURE[name](rng, kw)
    if kw.get("encoding") == "mono8" and "lying_png" in names + ["png_bomb"] * ("png_bomb" in names):
        kw["encoding"] = "png"
    build(path, **kw)
    return "+".join(names)


def _chain(kw, key, fn):
    previous = kw.get(key)

    def both(*args):
        msg = previous(*args) if previous else None
        return fn(*args[:-1], msg if msg is not None else args[-1])
    kw[key] = both


def m_lying_png(rng, kw):
    kw["encoding"] = "png"
    w, h = (int(pick(rng, [0, 1, 161, 100000, 65536, 1 << 31, (1 << 32) - 1])) for _ in range(2))
    _chain(kw, "image_edit", lambda side, i, msg: png_with_size(msg, w, h)
           if rng.random() < 0.7 and getattr(msg, "format", "") == "png" else msg)


def m_png_bomb(rng, kw):
    size = [(20000, 20000), (16384, 1024), (4000, 4000), (5000, 5000), (160, 120)][int(rng.integers(5))]
    data = png_bomb(*size)
    kw["encoding"] = "png"
    if rng.random() < 0.3 and size[0] * size[1] <= MAX_PIXELS:
        kw["width"], kw["height"] = size  # the calibration agrees: a large but legal image
    _chain(kw, "image_edit", lambda side, i, msg: (setattr(msg, "data", data), msg)[1]
           if hasattr(msg, "format") else msg)


def m_lying_raw(rng, kw):
    kw["encoding"] = "mono8"

    def edit(side, i, msg):
        if hasattr(msg, "format"):
            return msg
        field = ["width", "height", "step"][int(rng.integers(3))]
        setattr(msg, field, int(pick(rng, [0, 1, 159, 100000, (1 << 32) - 1])))
        if rng.random() < 0.3:
            msg.encoding = str(pick(rng, ["rgb8", "mono16", "yuv422", ""]))
        return msg
    _chain(kw, "image_edit", edit)


def m_garbage_image(rng, kw):
    def edit(side, i, msg):
        data = bytearray(getattr(msg, "data"))
        for _ in range(int(rng.integers(1, 20))):
            if data:
                data[int(rng.integers(len(data)))] = int(rng.integers(256))
        msg.data = bytes(data[: int(rng.integers(len(data) + 1))] if rng.random() < 0.3 else data)
        return msg
    _chain(kw, "image_edit", edit)


def m_calibration_values(rng, kw):
    def edit(side, msg):
        field = str(pick(rng, ["K", "P", "D", "R"]))
        values = list(getattr(msg, field))
        if values:
            values[int(rng.integers(len(values)))] = float(pick(rng, BAD_FLOATS))
        del getattr(msg, field)[:]
        getattr(msg, field).extend(values)
        return msg
    _chain(kw, "cal_edit", edit)


def m_intrinsics(rng, kw):
    fx = float(pick(rng, [1e-300, 1e-6, 1e6, 1e200, 1e300, 150.0]))
    baseline = float(pick(rng, [1e-300, 1e-9, 0.08, 1e6, 1e300]))
    w, h = kw.get("width", 160), kw.get("height", 120)
    kw["left_cal"] = calibration("left", w, h, fx=fx, raw=kw.get("raw", False))
    kw["right_cal"] = calibration("right", w, h, fx=fx, baseline=baseline, raw=kw.get("raw", False))


def m_lying_jpeg(rng, kw):
    kw["encoding"] = "jpeg"
    w, h = (int(pick(rng, [0, 1, 161, 65535, 16384])) for _ in range(2))

    def edit(side, i, msg):
        data = bytearray(msg.data)
        at = bytes(data).find(b"\xff\xc0")
        if at > 0 and rng.random() < 0.8:
            data[at + 5:at + 9] = struct.pack(">HH", h, w)
        elif data:
            data[int(rng.integers(2, len(data)))] = int(rng.integers(256))
        msg.data = bytes(data)
        return msg
    _chain(kw, "image_edit", lambda side, i, msg: edit(side, i, msg) if getattr(msg, "format", "") == "jpeg"
           else msg)


def m_frame_transforms(rng, kw):
    many = FrameTransforms()
    for i in range(int(rng.integers(0, 4))):
        t = many.transforms.add(parent_frame_id=str(pick(rng, ["camera_left", "world", ""])),
                                child_frame_id=str(pick(rng, ["gripper", "world", ""])))
        t.timestamp.CopyFrom(to_stamp(T0 + i * PERIOD))
        t.rotation.w = float(pick(rng, [1.0, 0.0, float("nan")]))
    extra = list(kw.get("extra", ()))
    extra.append(("/tf", many, T0, None, None, "protobuf"))
    kw["extra"] = extra


def m_calibration_shape(rng, kw):
    def edit(side, msg):
        choice = int(rng.integers(4))
        if choice == 0:
            del msg.D[:]
            msg.D.extend([0.01] * int(pick(rng, [1, 3, 6, 11, 15, 40])))
        elif choice == 1:
            msg.width = int(pick(rng, [0, 65536, 20000, (1 << 31), 16384]))
        elif choice == 2:
            msg.height = int(pick(rng, [0, 65536, 20000, (1 << 31) - 1]))
        else:
            msg.distortion_model = str(pick(rng, ["equidistant", "fisheye", ""]))
        return msg
    _chain(kw, "cal_edit", edit)


def m_baseline(rng, kw):
    b = float(pick(rng, [0.0, -0.08, float("nan"), float("inf"), 1e-300, 1e300]))
    kw["right_cal"] = calibration("right", kw.get("width", 160), kw.get("height", 120), baseline=b,
                                  raw=kw.get("raw", False))


def m_pose_values(rng, kw):
    def edit(msg):
        if rng.random() < 0.5:
            setattr(msg.rotation, str(pick(rng, list("xyzw"))), float(pick(rng, BAD_FLOATS)))
        else:
            setattr(msg.translation, str(pick(rng, list("xyz"))), float(pick(rng, BAD_FLOATS)))
        return msg
    kw["tf_edit"] = edit


def m_timestamps(rng, kw):
    n = kw.get("n", 3)
    if n == 0:
        return
    base = [T0 + i * PERIOD for i in range(n)]
    kind = int(rng.integers(5))
    if kind == 0:
        times = [-t for t in base]
    elif kind == 1:
        times = [base[0]] * n
    elif kind == 2:
        times = base[::-1]
    elif kind == 3:
        times = [(1 << 63) - 1 - i for i in range(n)]
    else:
        times = [int(x) for x in rng.integers(-(1 << 62), 1 << 62, n)]
    key = str(pick(rng, ["left_times", "right_times", "both", "tf"]))
    if key == "both":
        kw["left_times"] = kw["right_times"] = times
    elif key == "tf":
        kw["tf"] = [("camera_left", "gripper", t, (0.01 * i, 0, 0.5), (0, 0, 0, 1)) for i, t in enumerate(times)]
    else:
        kw[key] = times


def m_offset(rng, kw):
    offset = int(pick(rng, [2_000_000, 5_000_000, 50_000_000, 999_999]))
    kw["right_times"] = [T0 + i * PERIOD + offset for i in range(kw.get("n", 3))]


def m_tf_cycle(rng, kw):
    q = (0, 0, 0, 1)
    kw["tf"] = [("camera_left", "gripper", T0, (0, 0, 0.5), q), ("gripper", "camera_left", T0, (0, 0, -0.4), q),
                ("gripper", "gripper", T0, (0, 0, 0), q), ("a", "b", T0, (0, 0, 0), q),
                ("b", "a", T0 + 1, (1, 0, 0), q), ("world", "gripper", T0, (0, 0, 0), q)]
    if rng.random() < 0.5:
        kw["tf"] = kw["tf"][1:]


def m_wrong_schema(rng, kw):
    topic = str(pick(rng, [LEFT, RIGHT, "/stereo/left/calibration", "/tf"]))
    kind = int(rng.integers(4))
    msg = [CalibrationMsg(width=160, height=120), FrameTransform(), RawImage(width=3, height=2, encoding="mono8"),
           FrameTransforms()][kind]
    schema_name = str(pick(rng, ["", "foxglove.CameraCalibration", "foxglove.CompressedImage", "x.Y"]))
    schema_data = bytes(rng.integers(0, 256, int(rng.integers(0, 40)), dtype=np.uint8)) if rng.random() < 0.5 \
        else None
    encoding = "protobuf" if rng.random() < 0.8 else "json"
    extra = list(kw.get("extra", ()))
    extra.append((topic, msg, T0, schema_name or None, schema_data, encoding))
    kw["extra"] = extra


def m_missing(rng, kw):
    kw["n"] = int(pick(rng, [0, 1]))


STRUCTURE = {f.__name__[2:]: f for f in (m_lying_png, m_png_bomb, m_lying_raw, m_garbage_image, m_calibration_values,
                                          m_calibration_shape, m_baseline, m_pose_values, m_timestamps, m_offset,
                                          m_tf_cycle, m_wrong_schema, m_missing, m_intrinsics, m_lying_jpeg,
                                          m_frame_transforms)}


# -- byte-level mutations -------------------------------------------------------------------------
def record_offsets(data: bytes) -> list[int]:
    """Byte offsets of the top-level MCAP records of a good file."""
    pos, out = 8, []
    while pos + 9 <= len(data) - 8:
        out.append(pos)
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
    return out


def byte_mutation(rng: np.random.Generator, data: bytes) -> tuple[str, bytes]:
    data = bytearray(data)
    kind = str(pick(rng, ["flip", "overwrite", "insert", "delete", "truncate", "length", "duplicate"]))
    n = len(data)
    if kind == "flip":
        for _ in range(int(rng.integers(1, 5))):
            i = int(rng.integers(n))
            data[i] ^= 1 << int(rng.integers(8))
    elif kind == "overwrite":
        i = int(rng.integers(n))
        data[i:i + 8] = bytes(rng.integers(0, 256, 8, dtype=np.uint8))
    elif kind == "insert":
        i = int(rng.integers(n))
        data[i:i] = bytes(rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8))
    elif kind == "delete":
        i = int(rng.integers(n))
        del data[i:i + int(rng.integers(1, 256))]
    elif kind == "truncate":
        del data[int(rng.integers(n)):]
    elif kind == "duplicate":
        i = int(rng.integers(n))
        data[i:i] = data[i:i + int(rng.integers(1, 512))]
    else:  # a record's length (or a length inside it) made huge or small
        offsets = record_offsets(bytes(data))
        pos = int(pick(rng, offsets)) if offsets else 8
        field_at = pos + 1 + (0 if rng.random() < 0.5 else 9 + 8 * int(rng.integers(0, 4)))
        value = [0, 1, 1 << 31, (1 << 63) - 1, (1 << 64) - 1, n][int(rng.integers(6))]
        data[field_at:field_at + 8] = struct.pack("<Q", value)[: max(0, min(8, len(data) - field_at))]
    return kind, bytes(data)


# -- regression corpus -----------------------------------------------------------------------------
def _patch(path: str, edit) -> str:
    data = bytearray(Path(path).read_bytes())
    edit(data, [p for p in record_offsets(bytes(data))])
    Path(path).write_bytes(bytes(data))
    return path


def _chunks(data, offsets):
    return [p for p in offsets if data[p] == 0x06]


def _set(data, at, fmt, value):
    data[at:at + struct.calcsize(fmt)] = struct.pack(fmt, value)


def _cal(field, value, side="right"):
    def edit(s, msg):
        if s == side:
            if field == "size":
                msg.width, msg.height = value
            else:
                del getattr(msg, field)[:]
                getattr(msg, field).extend(value)
        return msg
    return edit


def _image(i_bad, fn):
    return lambda side, i, msg: fn(msg) if i == i_bad else msg


def _corrupt_png(msg):
    data = bytearray(msg.data)
    data[60] ^= 0xFF
    msg.data = bytes(data)
    return msg


def _bomb(msg):
    msg.data = png_bomb(4000, 4000)
    return msg


def _big_msg(msg):
    return png_with_size(msg, 20000, 20000)


def _tf(**changes):
    rows = [("camera_left", "gripper", T0 + i * PERIOD, (0.01 * i, 0, 0.5), (0, 0, 0, 1)) for i in range(3)]
    for i, row in changes.items():
        rows[int(i[1:])] = row
    return rows


CORPUS = {  # name: (class, expected outcome, how to make it)
    "undefined_channel": ("1 KeyError: message on an undefined channel id", "warning: on undefined channel id 999",
                          lambda p: _patch(build(p, chunked=False), lambda d, o: _set(
                              d, [x for x in o if d[x] == 0x05][-1] + 9, "<H", 999))),
    "huge_record_length": ("1 MemoryError/OverflowError: a record length of 2^64-1",
                           "warning: declares 18446744073709551615 bytes",
                           lambda p: _patch(build(p, chunk_size=1), lambda d, o: _set(
                               d, _chunks(d, o)[-1] + 1, "<Q", (1 << 64) - 1))),
    "lying_string_length": ("1 struct.error: a string length beyond its record", "error: missing calibration",
                            lambda p: _patch(build(p, chunked=False), lambda d, o: _set(
                                d, [x for x in o if d[x] == 0x04][0] + 13, "<I", 0xFFFFFFFF))),
    "corrupt_zstd": ("1 ZstdError: a corrupt zstd chunk", "warning: zstd data corrupt",
                     lambda p: _patch(build(p, chunk_size=1), lambda d, o: _set(
                         d, _chunks(d, o)[-1] + 9 + 40 + 8, "<I", 0))),
    "corrupt_lz4": ("1 lz4 RuntimeError: a corrupt lz4 chunk", "warning: lz4 data corrupt",
                    lambda p: _patch(build(p, chunk_size=1, compression="lz4"), lambda d, o: _set(
                        d, _chunks(d, o)[-1] + 9 + 39 + 8, "<I", 0x12345678))),
    "lying_chunk_size": ("1 MemoryError: a chunk declaring 2^62 uncompressed bytes", "warning: (limit 256 MiB)",
                         lambda p: _patch(build(p, chunk_size=1), lambda d, o: _set(
                             d, _chunks(d, o)[-1] + 25, "<Q", 1 << 62))),
    "crc_mismatch": ("CRC damage (was never detected)", "warning: damaged (CRC mismatch): its 1 messages skipped",
                     lambda p: _patch(build(p, chunk_size=1, compression="none"), lambda d, o: d.__setitem__(
                         _chunks(d, o)[-2] + 60, d[_chunks(d, o)[-2] + 60] ^ 1))),
    "truncated": ("truncated file (was refused)", "warning: truncated recording (no MCAP footer)",
                  lambda p: Path(p).write_bytes(Path(build(p, chunk_size=1)).read_bytes()[:-1200]) and p),
    "broken_descriptor": ("2 protobuf DecodeError: a broken schema descriptor set", "ok",
                          lambda p: build(p, extra=[("/stereo/left/calibration", calibration_to_msg(
                              calibration("left"), T0), T0, "foxglove.CameraCalibration", b"\x0a\xff!", "protobuf")])),
    "wrong_type": ("3 AttributeError: a topic carrying another message type",
                   "error: topic /stereo/right/calibration carries foxglove.FrameTransform",
                   lambda p: build(p, extra=[("/stereo/right/calibration", FrameTransform(), T0 + 1, None, None,
                                              "protobuf")])),
    "huge_quaternion": ("4 scipy zero norm: a quaternion of 1e200 parts", "ok",
                        lambda p: build(p, tf=_tf(r1=("camera_left", "gripper", T0 + PERIOD, (0, 0, 0.5),
                                                      (0, 0, 1e200, 1e200))))),
    "timestamp_int64_limit": ("5 OverflowError: timestamps near 2^63 ns", "ok",
                              lambda p: build(p, left_times=[(1 << 63) - 3 + i for i in range(3)],
                                              right_times=[(1 << 63) - 3 + i for i in range(3)],
                                              tf=[("camera_left", "gripper", (1 << 63) - 3 + i, (0, 0, 0.5),
                                                   (0, 0, 0, 1)) for i in range(3)])),
    "timestamp_beyond_int64": ("5 OverflowError: a timestamp of 2^70 ns", "warning: outside the int64 nanosecond",
                               lambda p: build(p, left_times=[T0, 1 << 70, T0 + 2 * PERIOD])),
    "calibration_65536": ("6 16 GiB remap tables: a 65536 x 65536 calibration", "error: outside 1..16384 pixels",
                          lambda p: build(p, raw=True, cal_edit=_cal("size", (65536, 65536), "left"))),
    "calibration_D11": ("6 OpenCV assertion: 11 distortion coefficients", "error: D has 11 coefficients",
                        lambda p: build(p, raw=True, cal_edit=_cal("D", [0.01] * 11))),
    "calibration_nan_K": ("6 NaN in K (exit 0, 0 segments)", "error: K holds NaN",
                          lambda p: build(p, raw=True, cal_edit=_cal("K", [float("nan")] + [0.0] * 8))),
    "baseline_negative": ("6 negative baseline", "error: has the wrong sign",
                          lambda p: build(p, right_cal=calibration("right", baseline=-0.08))),
    "baseline_zero": ("6 zero baseline", "error: the baseline is 0 m",
                      lambda p: build(p, right_cal=calibration("right", baseline=0.0))),
    "baseline_nan": ("6 NaN baseline (info said baseline nan mm)", "error: P holds NaN",
                     lambda p: build(p, right_cal=calibration("right", baseline=float("nan")))),
    "png_header_100000": ("7 a PNG header declaring 100000 x 100000", "warning: size 100000x100000 is outside",
                          lambda p: build(p, image_edit=_image(1, lambda m: png_with_size(m, 100000, 100000)))),
    "png_bomb": ("7 a PNG bomb (16 Mpx of zeros in 16 KB)", "warning: image header: size 4000x4000 exceeds the limit",
                 lambda p: build(p, image_edit=_image(1, _bomb))),
    "corrupt_png": ("7 libpng error on the terminal", "warning: libpng error",
                    lambda p: build(p, image_edit=_image(2, _corrupt_png))),
    "huge_image_and_calibration": ("8 out of memory: 20000 x 20000 images matching their calibration",
                                   "error: size 20000x20000 is outside 1..16384 pixels",
                                   lambda p: build(p, cal_edit=lambda s, m: _cal("size", (20000, 20000), s)(s, m),
                                                   image_edit=lambda s, i, m: _big_msg(m))),
    "image_size_mismatch": ("8 image not of its calibration's size (every frame skipped: nothing done)",
                            "error: no stereo frame could be read in frames 0:3",
                            lambda p: build(p, cal_edit=lambda s, m: _cal("size", (320, 240), s)(s, m))),
    "tf_translation_1e20": ("/tf translation of 1e20 (NaN in the model)", "warning: invalid translation (beyond",
                            lambda p: build(p, tf=_tf(r1=("camera_left", "gripper", T0 + PERIOD, (1e20, 0, 0),
                                                          (0, 0, 0, 1))))),
    "stereo_offset_5ms": ("no pair within 1 ms (exit 0, empty model)",
                          "error: left and right images are 5.0 ms apart; try --tolerance-ms 6",
                          lambda p: build(p, right_times=[T0 + i * PERIOD + 5_000_000 for i in range(3)])),
    "no_object_frame": ("extract refused without the object frame (extract runs; accumulate needs the frame)",
                        "error: no transform path from 'camera_left' to 'gripper'",
                        lambda p: build(p, tf=[("world", "board", T0, (0, 0, 1), (0, 0, 0, 1))])),
    "odd_timestamps": ("negative, duplicate and out-of-order timestamps", "ok",
                       lambda p: build(p, left_times=[-PERIOD, -2 * PERIOD, -2 * PERIOD],
                                       right_times=[-PERIOD, -2 * PERIOD, -2 * PERIOD],
                                       tf=[("camera_left", "gripper", t, (0, 0, 0.5), (0, 0, 0, 1))
                                           for t in (-2 * PERIOD, -PERIOD, -2 * PERIOD)])),
    "object_behind_camera": ("a pose putting the object 1 m behind the camera (a numpy RuntimeWarning on the "
                             "terminal, 2026-12-07)", "ok",
                             lambda p: build(p, tf=_tf(r2=("camera_left", "gripper", T0 + 2 * PERIOD, (0.02, 0, -1),
                                                           (0, 0, 0, 1))))),
    "tf_cycle": ("a cycle in the tf tree", "warning: has several parents",
                 lambda p: build(p, tf=[("camera_left", "gripper", T0, (0, 0, 0.5), (0, 0, 0, 1)),
                                        ("gripper", "camera_left", T0, (0, 0, -0.4), (0, 0, 0, 1)),
                                        ("world", "gripper", T0, (1, 0, 0), (0, 0, 0, 1))])),
}


def write_corpus(folder) -> None:
    """The regression inputs and their index ("name | class | expected outcome" per line)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lines = []
    for name, (cls, outcome, make) in CORPUS.items():
        make(str(folder / f"{name}.mcap"))
        lines.append(f"{name}.mcap | {cls} | {outcome}")
    (folder / "index.txt").write_text("\n".join(lines) + "\n")


# -- running ------------------------------------------------------------------------------------
def exercise(path: str) -> None:
    """The library runs behind ``accum info``, ``extract`` and ``accumulate`` (first 3 frames, outputs
    into a scratch folder), each tried; the first AccumError is raised at the end. Only AccumError
    may escape."""
    from accumcli.runs import FrameRange, accumulate_recording, describe_recording, extract_recording

    out = tempfile.mkdtemp(prefix="accum-fuzz-")
    errors = []
    stages = (lambda: describe_recording(path),
              lambda: extract_recording(path, os.path.join(out, "f.jsonl"), frames=FrameRange(0, 3)),
              lambda: accumulate_recording(path, [os.path.join(out, "m.json"), os.path.join(out, "m.ply")],
                                           frames=FrameRange(0, 3)))
    try:
        for stage in stages:
            try:
                stage()
            except AccumError as e:
                errors.append(e)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    if errors:
        raise errors[0]


def _child(path: str, out_fd: int) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    sink = os.open(path + ".out", os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(sink, 1)
    os.dup2(sink, 2)
    logger = logging.getLogger("accumcli")
    logger.handlers[:] = [logging.NullHandler()]
    logger.propagate = False
    try:
        exercise(path)
        result = "ok"
    except AccumError:
        result = "accum error"
    except MemoryError:
        result = "memory limit\n" + traceback.format_exc()
    except BaseException as e:  # noqa: BLE001 - classifying every escape is the point
        result = f"traceback {type(e).__name__}\n" + traceback.format_exc()
    sys.stdout.flush()
    sys.stderr.flush()
    os.write(out_fd, result.encode()[:60000])
    os._exit(0)


class Run:
    """One forked run of ``exercise(path)`` under the limits."""

    def __init__(self, path: str, kind: str):
        self.path, self.kind, self.data = path, kind, Path(path).read_bytes()
        self.fd, write_fd = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:
            os.close(self.fd)
            _child(path, write_fd)
        os.close(write_fd)
        self.deadline = time.monotonic() + TIMEOUT_S
        self.chunks: list[bytes] = []

    def read(self) -> bool:
        """Read what the child sent; True when it has finished."""
        data = os.read(self.fd, 65536)
        self.chunks.append(data)
        return not data

    def result(self, hung: bool = False) -> tuple[str, str]:
        if hung:
            os.kill(self.pid, signal.SIGKILL)
        os.close(self.fd)
        _, status = os.waitpid(self.pid, 0)
        if hung:
            return "hang", f"no result within {TIMEOUT_S} s"
        text = b"".join(self.chunks).decode("utf-8", "replace")
        if not text:
            return "signal", f"child ended with status {status}"
        cls, _, detail = text.partition("\n")
        output = Path(self.path + ".out").read_text(errors="replace").strip()
        if cls in ("ok", "accum error") and output:
            return "foreign output", output[:2000]
        return cls, detail


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--count", type=int, default=10000)
    ap.add_argument("--seconds", type=float, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--crashes", default=str(ROOT / "out" / "fuzz_crashes"))
    ap.add_argument("--write-corpus", metavar="DIR", help="write the regression corpus to DIR and stop")
    args = ap.parse_args(argv)
    if args.write_corpus:
        write_corpus(args.write_corpus)
        return 0
    rng = np.random.default_rng(args.seed)
    work = Path(tempfile.mkdtemp(prefix="accum-fuzz-"))
    crashes = Path(args.crashes)
    seeds = {name: Path(build(work / f"seed_{name}.mcap", **kw)).read_bytes() for name, kw in SEEDS.items()}
    start = time.monotonic()
    counts, failures, running = Counter(), [], []
    by_family: dict = defaultdict(Counter)  # mutation family -> outcome counts
    started = done = 0

    def make_input() -> tuple[str, str]:
        path = str(work / f"in_{started % 64}.mcap")
        if rng.random() < 0.5:
            seed = str(pick(rng, list(seeds)))
            kind, data = byte_mutation(rng, seeds[seed])
            Path(path).write_bytes(data)
            return path, f"bytes:{kind}:{seed}"
        try:
            return path, "structure:" + structure_mutation(rng, path)
        except Exception as e:  # noqa: BLE001 - a combination the builder cannot write: counted, not run
            counts["builder error"] += 1
            print(f"  builder error: {type(e).__name__}: {e}", flush=True)
            kind, data = byte_mutation(rng, seeds["png"])
            Path(path).write_bytes(data)
            return path, f"bytes:{kind}:png"

    def finish(run: Run, hung: bool = False) -> None:
        nonlocal done
        cls, detail = run.result(hung)
        done += 1
        outcome = cls.split()[0] if cls.startswith("traceback") else cls
        counts[outcome] += 1
        family = run.kind.split(":")[1] if run.kind.startswith("bytes") else "structure"
        by_family[family][outcome] += 1
        if cls not in ("ok", "accum error"):
            crashes.mkdir(parents=True, exist_ok=True)
            name = crashes / f"{cls.split()[0]}_{args.seed}_{done:05d}.mcap"
            name.write_bytes(run.data)
            name.with_suffix(".txt").write_text(f"{run.kind}\n{cls}\n{detail}\n")
            last = detail.strip().splitlines()[-1] if detail.strip() else ""
            failures.append((cls, run.kind, last))
        if done % 500 == 0:
            print(f"  {done} inputs, {time.monotonic() - start:.0f} s, failures {len(failures)}", flush=True)

    while True:
        out_of_time = args.seconds is not None and time.monotonic() - start > args.seconds
        while len(running) < args.workers and started < args.count and not out_of_time:
            path, kind = make_input()
            started += 1
            running.append(Run(path, kind))
        if not running:
            break
        timeout = max(0.0, min(r.deadline for r in running) - time.monotonic())
        ready, _, _ = select.select([r.fd for r in running], [], [], timeout)
        for run in list(running):
            if run.fd in ready and run.read():
                running.remove(run)
                finish(run)
            elif run.fd not in ready and time.monotonic() > run.deadline:
                running.remove(run)
                finish(run, hung=True)
    elapsed = time.monotonic() - start
    print(f"inputs run   {done} in {elapsed:.0f} s ({done / max(elapsed, 1e-9):.1f}/s, {args.workers} workers, "
          f"{TIMEOUT_S} s timeout, RLIMIT_AS {MEMORY_LIMIT >> 30} GiB)")
    for cls in ("ok", "accum error", "traceback", "hang", "memory limit", "signal", "foreign output",
                "builder error"):
        print(f"  {cls:<15} {counts.get(cls, 0)}")
    print("by mutation: " + "; ".join(f"{family} {sum(c.values())} ({c['ok']} ok, {c['accum error']} AccumError)"
                                      for family, c in sorted(by_family.items())))
    for cls, kind, last in failures[:40]:
        print(f"  FAIL {cls} [{kind}] {last}")
    if failures:
        print(f"failing inputs saved in {crashes}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
