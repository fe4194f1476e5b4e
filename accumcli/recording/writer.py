"""Writing recordings (simulator output, tracked poses) as MCAP with Foxglove
protobuf schemas, so they open in Foxglove. Written to a path, the file appears
atomically when the writer is closed without error (``atomic.atomic_open``);
or to a binary file opened by an ``outputs.OutputSet``, which then owns it.
With ``ros2=True`` calibrations, images and transforms are ROS 2 messages instead (CDR with
``ros2msg`` schemas, as ``ros2 bag record -s mcap`` writes; ``ros2`` builds them); ``rosbag2``
writes the folder form (``Rosbag2Writer``)."""

from __future__ import annotations

import contextlib
import json

import numpy as np
from mcap_protobuf.writer import Writer

from ..atomic import opened
from ..errors import InputError
from ..geometry import check_transform, quat_from_transform
from .calibration import CameraCalibration
from .messages import calibration_to_msg, image_to_msg, transform_to_msg
from .ros2 import RosMessage, ros_from_foxglove, typestore


class _MessageWriter:
    """Calibrations, images and transforms as Foxglove protobuf messages, handed to ``_put``."""

    def _put(self, topic: str, message, log_time: int) -> None:
        raise NotImplementedError

    def calibration(self, topic: str, calibration: CameraCalibration, t_ns: int) -> None:
        self._put(topic, calibration_to_msg(calibration, _time(t_ns)), _time(t_ns))

    def image(self, topic: str, image: np.ndarray, t_ns: int, frame_id: str, encoding: str = "png") -> None:
        """Write an (H, W) uint8 image (or (H, W, 3) BGR: png and jpeg keep the colour) as png, jpeg or
        mono8; ``InputError`` for anything else (an image that failed to load is None; a float image
        would be written black)."""
        if encoding not in ("png", "jpeg", "mono8"):
            raise InputError(f"{topic}: image encoding {encoding!r}: expected png, jpeg or mono8")
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or not (
                image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3 and encoding != "mono8")) or not image.size:
            what = "None (did the image load?)" if image is None else (
                f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__)
            raise InputError(f"{topic}: expected an (H, W) uint8 image (8 bits: convert first), found {what}")
        self._put(topic, image_to_msg(image, _time(t_ns), frame_id, encoding), _time(t_ns))

    def transform(self, parent: str, child: str, T_parent_child: np.ndarray, t_ns: int, topic: str = "/tf",
                  log_time_ns: int | None = None) -> None:
        """Write ``T_parent_child`` ((4, 4) rigid; ``InputError`` otherwise)."""
        translation, quat = quat_from_transform(check_transform(T_parent_child, f"T {parent} -> {child}"))
        self.raw_transform(parent, child, translation, quat, t_ns, topic, log_time_ns)

    def raw_transform(self, parent: str, child: str, translation, quat_xyzw, t_ns: int, topic: str = "/tf",
                      log_time_ns: int | None = None) -> None:
        """A transform given as translation and quaternion as they are (possibly invalid, for tests)."""
        self._put(topic, transform_to_msg(parent, child, _time(t_ns), translation, quat_xyzw),
                  _time(t_ns if log_time_ns is None else log_time_ns))


def _time(t_ns) -> int:
    """A message time, integer nanoseconds in MCAP's unsigned 64-bit range; ``InputError`` otherwise
    (a float such as 1.75e18 is not exact in nanoseconds)."""
    if isinstance(t_ns, (bool, float)) or not isinstance(t_ns, (int, np.integer)) or not 0 <= int(t_ns) < 1 << 64:
        raise InputError(f"time {t_ns!r}: expected whole nanoseconds (an int, 0 to 2^64 - 1)")
    return int(t_ns)


class RecordingWriter(_MessageWriter):
    """Context manager writing protobuf messages to ``target`` (a path or an open binary
    file); log time = the message time. ``ros2``: calibrations, images and transforms as ROS 2
    messages (CDR, ``ros2.ros_from_foxglove``)."""

    def __init__(self, target, ros2: bool = False):
        self._stack = contextlib.ExitStack()
        self._file = self._stack.enter_context(opened(target, "wb"))
        self._writer = Writer(self._file)
        self._json_channels: dict[str, int] = {}
        self.ros2 = ros2
        self._ros_schemas: dict[str, int] = {}
        self._ros_channels: dict[tuple[str, str], int] = {}

    def _put(self, topic: str, message, log_time: int) -> None:
        if self.ros2:
            self.ros_message(topic, ros_from_foxglove(message), log_time)
        else:
            self._writer.write_message(topic, message, log_time=log_time, publish_time=log_time)

    def ros_message(self, topic: str, message: RosMessage, log_time: int) -> None:
        """A ROS 2 message as CDR on ``topic`` (its schema: the ros2msg text of its type)."""
        raw = self._writer._writer   # the mcap writer under mcap_protobuf's
        if message.msgtype not in self._ros_schemas:
            text = typestore().generate_msgdef(message.msgtype, ros_version=2)[0]
            self._ros_schemas[message.msgtype] = raw.register_schema(message.msgtype, "ros2msg", text.encode())
        key = (topic, message.msgtype)
        if key not in self._ros_channels:
            self._ros_channels[key] = raw.register_channel(topic, "cdr", self._ros_schemas[message.msgtype])
        raw.add_message(self._ros_channels[key], log_time=int(log_time), data=message.cdr,
                        publish_time=int(log_time))

    def message(self, topic: str, message, t_ns: int) -> None:
        """Any protobuf message (e.g. a ``foxglove.SceneUpdate``) on ``topic`` at ``t_ns``."""
        self._writer.write_message(topic, message, log_time=t_ns, publish_time=t_ns)

    def json_message(self, topic: str, schema_name: str, json_schema: dict, doc: dict, t_ns: int) -> None:
        """A JSON message (with its JSON schema, so that Foxglove can plot its fields) on ``topic``."""
        raw = self._writer._writer   # the mcap writer under mcap_protobuf's, for a non-protobuf channel
        if topic not in self._json_channels:
            schema_id = raw.register_schema(schema_name, "jsonschema", json.dumps(json_schema).encode())
            self._json_channels[topic] = raw.register_channel(topic, "json", schema_id)
        raw.add_message(self._json_channels[topic], log_time=t_ns, data=json.dumps(doc).encode(), publish_time=t_ns)

    def metadata(self, name: str, data: dict) -> None:
        self._writer.add_metadata(name, {k: str(v) for k, v in data.items()})

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self._writer.finish()
        self._stack.__exit__(exc_type, exc, tb)


class Rosbag2Writer(_MessageWriter):
    """A rosbag2 folder (``metadata.yaml`` + one ``.db3``, or one ``.mcap`` with ``storage="mcap"``;
    version 9) written with ``rosbags``: the calibrations, images and transforms as ROS 2 messages;
    log time = the message time."""

    def __init__(self, path, storage: str = "sqlite3"):
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as BagWriter

        self._writer = BagWriter(path, version=9, storage_plugin=StoragePlugin[storage.upper()])
        self._writer.open()
        self._connections: dict[tuple[str, str], object] = {}

    def _put(self, topic: str, message, log_time: int) -> None:
        self.ros_message(topic, ros_from_foxglove(message), log_time)

    def ros_message(self, topic: str, message: RosMessage, log_time: int) -> None:
        key = (topic, message.msgtype)
        if key not in self._connections:
            self._connections[key] = self._writer.add_connection(topic, message.msgtype, typestore=typestore())
        self._writer.write(self._connections[key], int(log_time), message.cdr)

    def __enter__(self) -> "Rosbag2Writer":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._writer.close()
