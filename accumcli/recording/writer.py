"""Writing recordings (simulator output, tracked poses) as MCAP with Foxglove
protobuf schemas, so they open in Foxglove. Written to a path, the file appears
atomically when the writer is closed without error (``atomic.atomic_open``);
or to a binary file opened by an ``outputs.OutputSet``, which then owns it."""

from __future__ import annotations

import contextlib
import json

import numpy as np
from mcap_protobuf.writer import Writer

from ..atomic import opened
from ..geometry import quat_from_transform
from .calibration import CameraCalibration
from .messages import calibration_to_msg, image_to_msg, transform_to_msg


class RecordingWriter:
    """Context manager writing protobuf messages to ``target`` (a path or an open binary
    file); log time = the message time."""

    def __init__(self, target):
        self._stack = contextlib.ExitStack()
        self._file = self._stack.enter_context(opened(target, "wb"))
        self._writer = Writer(self._file)
        self._json_channels: dict[str, int] = {}

    def calibration(self, topic: str, calibration: CameraCalibration, t_ns: int) -> None:
        self._writer.write_message(topic, calibration_to_msg(calibration, t_ns), log_time=t_ns, publish_time=t_ns)

    def image(self, topic: str, image: np.ndarray, t_ns: int, frame_id: str, encoding: str = "png") -> None:
        """Write an (H, W) uint8 image as png, jpeg or mono8."""
        self._writer.write_message(topic, image_to_msg(image, t_ns, frame_id, encoding), log_time=t_ns,
                                   publish_time=t_ns)

    def transform(self, parent: str, child: str, T_parent_child: np.ndarray, t_ns: int, topic: str = "/tf",
                  log_time_ns: int | None = None) -> None:
        translation, quat = quat_from_transform(T_parent_child)
        self.raw_transform(parent, child, translation, quat, t_ns, topic, log_time_ns)

    def raw_transform(self, parent: str, child: str, translation, quat_xyzw, t_ns: int, topic: str = "/tf",
                      log_time_ns: int | None = None) -> None:
        """A transform given as translation and quaternion as they are (possibly invalid, for tests)."""
        log_time = t_ns if log_time_ns is None else log_time_ns
        self._writer.write_message(topic, transform_to_msg(parent, child, t_ns, translation, quat_xyzw),
                                   log_time=log_time, publish_time=log_time)

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
