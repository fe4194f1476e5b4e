"""Streaming reader of stereo recordings (formats.md section 1).

``Recording(path)`` validates the whole file up front (MCAP magic, footer,
topics, calibration, a transform path to the object frame) and raises
``RecordingError`` with one line naming the file and the problem. It indexes
the small messages (calibrations, transforms) in a first pass; ``frames()``
then streams the images, pairs left and right by their timestamp field within
the tolerance, and yields one ``StereoFrame`` at a time, so memory does not grow
with the recording's length. A problem confined to one frame (undecodable
bytes, an image without a partner, no pose at that time) is logged as a
warning naming the frame, and the other frames go on.

Choices where formats.md is silent:
- An image or transform whose timestamp field is unset (zero) uses its log time.
- Frames earlier than the first calibration use the first calibration
  (calibrations are normally static; a warning says so once).
- A transform on ``/tf_static`` is static whatever its count of samples.
"""

from __future__ import annotations

import logging
import os
from collections import deque
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from ..errors import PoseUnavailable, RecordingError
from .calibration import CameraCalibration, StereoIntrinsics, StereoRectifier
from .messages import DecodeError, calibration_from_msg, decode_image, image_encoding, stamp_ns
from .tf_tree import TransformTree

log = logging.getLogger("accumcli")

MCAP_MAGIC = b"\x89MCAP0\r\n"
MAX_PENDING_IMAGES = 64


@dataclass(frozen=True)
class Topics:
    """Topic names of a recording (formats.md defaults)."""

    left_image: str = "/stereo/left/image"
    right_image: str = "/stereo/right/image"
    left_calibration: str = "/stereo/left/calibration"
    right_calibration: str = "/stereo/right/calibration"
    tf: str = "/tf"
    tf_static: str = "/tf_static"


@dataclass(frozen=True)
class StereoFrame:
    """One rectified stereo pair.

    index: position of the pair in the recording (0-based, counting every
    pair, also those skipped); left, right: (H, W) uint8 rectified grey images;
    T_camera_object: (4, 4) pose of the object frame in the left camera frame,
    or None with ``pose_problem`` saying why.
    """

    index: int
    timestamp_ns: int
    left: np.ndarray
    right: np.ndarray
    intrinsics: StereoIntrinsics
    T_camera_object: np.ndarray | None
    pose_problem: str | None = None


@dataclass
class RecordingInfo:
    """What ``accum info`` shows."""

    path: str
    topics: list = field(default_factory=list)  # (topic, schema name, message count)
    stereo_frames: int = 0
    unpaired_images: int = 0
    image_size: tuple | None = None
    image_encoding: str | None = None
    intrinsics: StereoIntrinsics | None = None
    rectified_input: bool | None = None
    distortion_model: str | None = None
    calibrations: int = 0
    frames_with_pose: int = 0
    pose_problems: list = field(default_factory=list)
    first_ns: int | None = None
    last_ns: int | None = None
    tf_frames: list = field(default_factory=list)


@dataclass
class _PendingImage:
    t_ns: int
    msg: object


class Recording:
    """A stereo recording opened for streaming. Use as a context manager."""

    def __init__(self, path, topics: Topics = Topics(), camera_frame: str = "camera_left",
                 object_frame: str = "gripper", tolerance_ns: int = 1_000_000, require_pose: bool = True):
        self.path = str(path)
        self.topics = topics
        self.camera_frame = camera_frame
        self.object_frame = object_frame
        self.tolerance_ns = int(tolerance_ns)
        self._check_file()
        self._file = open(self.path, "rb")
        try:
            self._reader = make_reader(self._file)
            self._summary = self._read_summary()
            self._channels = {c.topic: c for c in self._summary.channels.values()}
            self._schemas = self._summary.schemas
            self._check_topics(require_pose)
            self.tree = TransformTree()
            self.calibrations: dict[str, list[tuple[int, CameraCalibration]]] = {"left": [], "right": []}
            self._index_small_messages()
            if require_pose:
                self._check_pose_path()
        except Exception:
            self._file.close()
            raise
        self._rectifiers: dict = {}
        self._warned_early_calibration = False
        log.info("%s: about %d stereo frames, %d calibration message(s), transform frames: %s", self.path,
                 self.frame_count_hint, len(self.calibrations["left"]), ", ".join(sorted(self.tree.frames)) or "none")

    # -- opening and validation ---------------------------------------------------------
    def _fail(self, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: {problem}")

    def _check_file(self) -> None:
        if not os.path.exists(self.path):
            raise self._fail("no such file")
        if not os.path.isfile(self.path):
            raise self._fail("not a file")
        size = os.path.getsize(self.path)
        if size == 0:
            raise self._fail("empty file")
        with open(self.path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
            f.seek(max(size - len(MCAP_MAGIC), 0))
            tail = f.read()
        if head != MCAP_MAGIC:
            raise self._fail("not an MCAP file (wrong magic bytes)")
        if tail != MCAP_MAGIC or size < 2 * len(MCAP_MAGIC) + 20:
            raise self._fail("truncated MCAP file (no footer); `mcap recover` may save what it holds")

    def _read_summary(self):
        try:
            summary = self._reader.get_summary()
        except (McapError, ValueError, EOFError, OSError, KeyError) as e:
            raise self._fail(f"corrupt MCAP summary ({e})") from None
        if summary is None or not summary.channels:
            raise self._fail("the MCAP file has no summary or no channels (was it finished?)")
        return summary

    def _check_topics(self, require_pose: bool) -> None:
        t = self.topics
        available = ", ".join(sorted(self._channels)) or "none"
        required = [t.left_image, t.right_image, t.left_calibration, t.right_calibration]
        for topic in required:
            if topic not in self._channels:
                raise self._fail(f"missing topic {topic} (topics found: {available})")
        if require_pose and t.tf not in self._channels and t.tf_static not in self._channels:
            raise self._fail(f"missing topic {t.tf}: no transforms, so no pose of {self.object_frame!r} "
                             f"(topics found: {available})")

    def _messages(self, topics: list[str]) -> Iterator[tuple[str, int, object]]:
        """(topic, log_time_ns, decoded message) in log-time order; undecodable messages are warned about."""
        decoders = {}
        factory = DecoderFactory()
        try:
            for schema, channel, message in self._reader.iter_messages(topics=topics, log_time_order=True):
                if channel.id not in decoders:
                    decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
                    if decoders[channel.id] is None:
                        raise self._fail(f"topic {channel.topic}: cannot decode {channel.message_encoding!r} "
                                         f"messages with schema {schema.name if schema else None!r} "
                                         "(expected protobuf Foxglove schemas)")
                try:
                    decoded = decoders[channel.id](message.data)
                except Exception as e:  # protobuf raises its own DecodeError types
                    log.warning("%s: message on %s at %.3f s cannot be decoded (%s): skipped",
                                self.path, channel.topic, message.log_time * 1e-9, e)
                    continue
                yield channel.topic, message.log_time, decoded
        except McapError as e:
            raise self._fail(f"corrupt or truncated MCAP data ({e})") from None
        except (EOFError, ValueError) as e:
            raise self._fail(f"corrupt or truncated MCAP data ({type(e).__name__}: {e})") from None

    def _index_small_messages(self) -> None:
        t = self.topics
        sides = {t.left_calibration: "left", t.right_calibration: "right"}
        topics = [name for name in (*sides, t.tf, t.tf_static) if name in self._channels]
        for topic, log_time, msg in self._messages(topics):
            if topic in sides:
                try:
                    cal = calibration_from_msg(msg)
                except ValueError as e:
                    log.warning("%s: calibration on %s at %.3f s is malformed (%s): skipped",
                                self.path, topic, log_time * 1e-9, e)
                    continue
                self.calibrations[sides[topic]].append((stamp_ns(msg.timestamp), cal))
                continue
            for tf in (msg.transforms if hasattr(msg, "transforms") else [msg]):
                t_ns = stamp_ns(tf.timestamp) if tf.HasField("timestamp") else log_time
                r, q = tf.translation, tf.rotation
                self.tree.add(tf.parent_frame_id, tf.child_frame_id, t_ns, (r.x, r.y, r.z), (q.x, q.y, q.z, q.w),
                              static=topic == t.tf_static)
        for side, topic in (("left", t.left_calibration), ("right", t.right_calibration)):
            if not self.calibrations[side]:
                raise self._fail(f"missing calibration: no valid message on {topic}")
            self.calibrations[side].sort(key=lambda item: item[0])

    def _check_pose_path(self) -> None:
        if self.tree.path(self.camera_frame, self.object_frame) is None:
            frames = ", ".join(sorted(self.tree.frames)) or "none"
            raise self._fail(f"no transform path from {self.camera_frame!r} to {self.object_frame!r} "
                             f"(frames in the transform tree: {frames})")

    # -- streaming ----------------------------------------------------------------------
    @property
    def frame_count_hint(self) -> int:
        """Number of stereo frames, from the message counts (exact unless images are unpaired)."""
        stats = self._summary.statistics
        counts = stats.channel_message_counts if stats else {}
        return min(counts.get(self._channels[self.topics.left_image].id, 0),
                   counts.get(self._channels[self.topics.right_image].id, 0))

    def _pairs(self, warn: bool = True, counter: dict | None = None) -> Iterator[tuple[int, int, object, object]]:
        """(index, t_ns, left message, right message) for each stereo pair, in time order.

        Images on one topic are assumed to arrive in timestamp order; an image
        whose partner can no longer arrive is reported as unpaired.
        """
        t = self.topics
        pending = {t.left_image: deque(), t.right_image: deque()}
        other = {t.left_image: t.right_image, t.right_image: t.left_image}
        index = 0

        def unpaired(topic: str, item: _PendingImage) -> None:
            if counter is not None:
                counter["unpaired"] = counter.get("unpaired", 0) + 1
            if warn:
                log.warning("%s: image on %s at %.3f s has no partner within %.3f ms: skipped",
                            self.path, topic, item.t_ns * 1e-9, self.tolerance_ns * 1e-6)

        for topic, log_time, msg in self._messages([t.left_image, t.right_image]):
            item = _PendingImage(stamp_ns(msg.timestamp) if msg.HasField("timestamp") else log_time, msg)
            partners = pending[other[topic]]
            while partners and partners[0].t_ns < item.t_ns - self.tolerance_ns:
                unpaired(other[topic], partners.popleft())
            match = next((p for p in partners if abs(p.t_ns - item.t_ns) <= self.tolerance_ns), None)
            if match is None:
                pending[topic].append(item)
                if len(pending[topic]) > MAX_PENDING_IMAGES:
                    unpaired(topic, pending[topic].popleft())
                continue
            partners.remove(match)
            left, right = (item, match) if topic == t.left_image else (match, item)
            yield index, left.t_ns, left.msg, right.msg
            index += 1
        for topic, items in pending.items():
            for item in items:
                unpaired(topic, item)

    def calibration_at(self, t_ns: int) -> StereoRectifier:
        """The rectifier of the latest calibrations at or before ``t_ns``."""
        chosen = []
        for side in ("left", "right"):
            items = self.calibrations[side]
            i = int(np.searchsorted([s for s, _ in items], t_ns, side="right")) - 1
            if i < 0:
                if not self._warned_early_calibration:
                    log.warning("%s: frames before the first calibration (%.3f s) use it",
                                self.path, items[0][0] * 1e-9)
                    self._warned_early_calibration = True
                i = 0
            chosen.append(items[i][1])
        key = (chosen[0].key(), chosen[1].key())
        if key not in self._rectifiers:
            try:
                self._rectifiers[key] = StereoRectifier(*chosen)
            except RecordingError as e:
                raise self._fail(str(e)) from None
        return self._rectifiers[key]

    def pose_at(self, t_ns: int) -> np.ndarray:
        """``T_camera_object`` at ``t_ns``; raises ``PoseUnavailable``."""
        return self.tree.lookup(self.camera_frame, self.object_frame, t_ns, self.tolerance_ns)

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[StereoFrame]:
        """Stream the stereo frames with index in [start, stop)."""
        for index, t_ns, left_msg, right_msg in self._pairs():
            if index < start:
                continue
            if stop is not None and index >= stop:
                break
            where = f"{self.path}: frame {index} ({t_ns * 1e-9:.3f} s)"
            try:
                left, right = decode_image(left_msg), decode_image(right_msg)
            except DecodeError as e:
                log.warning("%s: %s: skipped", where, e)
                continue
            rectifier = self.calibration_at(t_ns)
            size = (rectifier.intrinsics.width, rectifier.intrinsics.height)
            if left.shape[::-1] != size or right.shape[::-1] != size:
                log.warning("%s: image sizes %s and %s differ from the calibration's %dx%d: skipped", where,
                            "x".join(map(str, left.shape[::-1])), "x".join(map(str, right.shape[::-1])), *size)
                continue
            left, right = rectifier.rectify(left, right)
            try:
                T, problem = self.pose_at(t_ns), None
            except PoseUnavailable as e:
                T, problem = None, str(e)
            yield StereoFrame(index, t_ns, left, right, rectifier.intrinsics, T, problem)

    # -- summary --------------------------------------------------------------------------
    def info(self) -> RecordingInfo:
        """Scan the recording (no pixel decoding) for ``accum info``."""
        stats = self._summary.statistics
        counts = stats.channel_message_counts if stats else {}
        info = RecordingInfo(path=self.path)
        for channel in sorted(self._summary.channels.values(), key=lambda c: c.topic):
            schema = self._schemas.get(channel.schema_id)
            info.topics.append((channel.topic, schema.name if schema else "", counts.get(channel.id)))
        info.tf_frames = sorted(self.tree.frames)
        info.calibrations = len(self.calibrations["left"])
        counter: dict = {}
        problems: dict[str, int] = {}
        for _, t_ns, left_msg, _ in self._pairs(warn=False, counter=counter):
            info.stereo_frames += 1
            info.first_ns = t_ns if info.first_ns is None else info.first_ns
            info.last_ns = t_ns
            if info.image_encoding is None:
                info.image_encoding = image_encoding(left_msg)
                rectifier = self.calibration_at(t_ns)
                info.intrinsics = rectifier.intrinsics
                info.image_size = (rectifier.intrinsics.width, rectifier.intrinsics.height)
                info.rectified_input = rectifier.rectified_input
                info.distortion_model = self.calibrations["left"][0][1].distortion_model or "none"
            try:
                self.pose_at(t_ns)
                info.frames_with_pose += 1
            except PoseUnavailable as e:
                reason = str(e).split(": time")[0] if ": time" in str(e) else str(e)
                problems[reason] = problems.get(reason, 0) + 1
        info.unpaired_images = counter.get("unpaired", 0)
        info.pose_problems = sorted(problems.items())
        return info

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
