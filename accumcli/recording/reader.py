"""Streaming reader of stereo recordings (formats.md section 1).

What ``path`` is, is found by content: a folder with ``metadata.yaml`` is a rosbag2 bag, a file
starting with SQLite's magic a bare rosbag2 ``.db3``, one starting with ``#ROSBAG V2.0`` a ROS 1 bag
(all read with ``rosbags``, ``ros2``); any other file must be MCAP, whose channels may each be
Foxglove protobuf or JSON, or ROS 2 CDR (``ros2msg`` schema). ROS messages are converted to the
Foxglove protobuf messages on decoding (``ros2``), so everything below is the same for every form.

``Recording(path)`` reads the MCAP file front to back with accum's own record
parser (``mcap_records``: never trusting a declared length beyond what the file
or the chunk holds; it says why not the mcap library's reader) and raises
``RecordingError`` with one line naming the file and the problem when the whole
recording cannot be used. A first pass indexes the small
messages (calibrations, transforms) and pairs the image timestamps;
``frames()`` then streams the images again, pairs left and right by their
timestamp field within the tolerance, and yields one ``StereoFrame`` at a time,
so memory does not grow with the recording's length (one chunk is held at a
time). A problem confined to one frame (undecodable bytes, a size that is not
the calibration's, an image without a partner, no pose at that time) is a
warning naming the frame, and the other frames go on; repeated warnings of one
kind are summarised (``logs.LimitedWarnings``).

Damage the reader survives, each with one warning:
- a chunk whose CRC does not match, whose compressed data is corrupt or whose
  declared size is a lie or beyond ``mcap_records.MAX_CHUNK_BYTES``: its messages are
  skipped and the chunks after it are read;
- a truncated file (no footer, e.g. a recorder that was killed) or a record
  whose declared length runs past the end of the file: everything before it is
  read and the warning says how many bytes are lost and the last good time;
- a message on an undefined channel, or whose protobuf bytes do not parse, or
  whose timestamp is outside the int64 nanosecond range: skipped.

Choices where formats.md is silent:
- Messages are taken in file order; within a chunk, in log-time order.
- Messages are decoded with the Foxglove protobuf classes accum ships, after
  checking the channel's schema name (a topic carrying another type is a
  ``RecordingError``); the recording's descriptor set is not compiled. CDR
  messages are decoded with the channel's own ros2msg schema (``ros2``).
- Raw images in an encoding that ``messages`` cannot read (``encoding_problem``: e.g. 32FC1 depth)
  are a ``RecordingError`` when the recording opens: every frame would fail alike.
- When a default topic is missing and the recording has ROS 2 image topics with
  CameraInfo siblings, the error proposes the four topic options
  (``ros2.propose_topics``).
- An image or transform whose timestamp field is unset (zero) uses its log time.
- Timestamps may be negative, duplicate or out of order. Images are paired in
  arrival order: an image pairs with a pending image of the other camera within
  the tolerance, the first such one; an image that arrives after its partner has
  been given up (more than the tolerance later on the other topic) is unpaired.
  Transforms are sorted by time (see ``tf_tree``).
- Frames earlier than the first calibration use the first calibration
  (calibrations are normally static; a warning says so once).
- A transform on ``/tf_static`` is static whatever its count of samples. A frame
  with several parents (a cycle) is a warning; lookups take the shortest path.
- No silent empty recording: opening fails when an image topic has no readable
  message, and when images exist on both topics but none pair (with the
  measured typical left/right offset and the tolerance to try).
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import (
    CameraCalibration as CalibrationMsg,
)
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from ..errors import PoseUnavailable, RecordingError
from ..logs import LimitedWarnings
from .calibration import CameraCalibration, StereoIntrinsics, StereoRectifier
from . import ros2
from .mcap_records import MCAP_MAGIC, McapScan
from .messages import (
    DecodeError,
    calibration_from_msg,
    decode_image,
    encoding_problem,
    from_foxglove_json,
    image_encoding,
    image_size,
    sixteen_bit_full_scale,
    stamp_ns,
)
from .tf_tree import TransformTree, frame_name, sample_problem

log = logging.getLogger("accumcli")

MAX_PENDING_IMAGES = 64
OFFSET_SAMPLES = 4096       # left/right offsets kept to measure the typical one

IMAGE_TYPES = {"foxglove.CompressedImage": CompressedImage, "foxglove.RawImage": RawImage}
CALIBRATION_TYPES = {"foxglove.CameraCalibration": CalibrationMsg}
TF_TYPES = {"foxglove.FrameTransform": FrameTransform, "foxglove.FrameTransforms": FrameTransforms}
ROS_TYPES = {"image": ros2.ROS_IMAGE_TYPES, "calibration": (ros2.ROS_CAMERA_INFO,), "tf": (ros2.ROS_TF, ros2.ROS1_TF)}
PROTOBUF_TYPES = {"image": IMAGE_TYPES, "calibration": CALIBRATION_TYPES, "tf": TF_TYPES}


def _is_rect_topic(topic: str) -> bool:
    """A ROS image_proc rectified image topic: .../image_rect, .../image_rect_color (or /compressed of one)."""
    parts = [p for p in topic.split("/") if p]
    if parts and parts[-1] in ("compressed", "compressedDepth"):
        parts = parts[:-1]
    return bool(parts) and parts[-1].startswith("image_rect")


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
    or None with ``pose_problem`` saying why; border_distance: (left, right) (H, W) uint8, px from
    the nearest pixel that rectification did not fill from inside the raw images
    (``StereoRectifier.border_distance``), None when there is none.
    """

    index: int
    timestamp_ns: int
    left: np.ndarray
    right: np.ndarray
    intrinsics: StereoIntrinsics
    T_camera_object: np.ndarray | None
    pose_problem: str | None = None
    border_distance: tuple[np.ndarray, np.ndarray] | None = None


@dataclass
class RecordingInfo:
    """What ``accum info`` shows. ``stereo_offset_ms``: the typical (median) time between a
    left image and the nearest right one, milliseconds, None without images on both sides;
    ``pairing_tolerance_ms``: the tolerance that pairs nearly all of them (``_Pairing.covering_tolerance_ms``);
    ``lost_bytes``: bytes of a truncated or damaged file that could not be read."""

    path: str
    topics: list = field(default_factory=list)  # (topic, schema name, readable message count)
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
    stereo_offset_ms: float | None = None
    pairing_tolerance_ms: int | None = None
    lost_bytes: int = 0
    size_problem: str | None = None   # the images' own size differs from their calibration's
    topics_only: bool = False   # the topics accum reads are not all there: only the topics and transforms are known


@dataclass
class _PendingImage:
    t_ns: int
    msg: object


class _Pairing:
    """Pairs left and right image timestamps in arrival order (see the module docstring).

    ``add`` returns the pairs it completes as (left, right) ``_PendingImage``;
    ``unpaired`` is called for each image given up. Measures the offset of each
    pair, and of each image given up to the nearest of the last 8 on the other
    side (``typical_offset_ns``, the median).
    """

    def __init__(self, left_topic: str, tolerance_ns: int, unpaired: Callable):
        self.left_topic, self.tolerance_ns, self.unpaired = left_topic, tolerance_ns, unpaired
        self.pending = {True: deque(), False: deque()}
        self.recent = {True: deque(maxlen=8), False: deque(maxlen=8)}
        self.offsets: list[int] = []
        self.left_gaps: list[int] = []    # between consecutive left stamps: the frame period

    def _offset(self, is_left: bool, t_ns: int) -> None:
        others = self.recent[not is_left]
        if others and len(self.offsets) < OFFSET_SAMPLES:
            self.offsets.append(min(abs(t_ns - o) for o in others))

    def add(self, topic: str, item: _PendingImage) -> list[tuple[_PendingImage, _PendingImage]]:
        is_left = topic == self.left_topic
        last_left = self.recent[True][-1] if self.recent[True] else None
        if is_left and last_left is not None and item.t_ns > last_left and len(self.left_gaps) < OFFSET_SAMPLES:
            self.left_gaps.append(item.t_ns - last_left)
        self.recent[is_left].append(item.t_ns)
        partners = self.pending[not is_left]
        while partners and partners[0].t_ns < item.t_ns - self.tolerance_ns:
            self._give_up(not is_left, partners.popleft())
        match = next((p for p in partners if abs(p.t_ns - item.t_ns) <= self.tolerance_ns), None)
        if match is None:
            mine = self.pending[is_left]
            mine.append(item)
            if len(mine) > MAX_PENDING_IMAGES:
                self._give_up(is_left, mine.popleft())
            return []
        partners.remove(match)
        if len(self.offsets) < OFFSET_SAMPLES:
            self.offsets.append(abs(match.t_ns - item.t_ns))
        return [(item, match) if is_left else (match, item)]

    def _give_up(self, is_left: bool, item: _PendingImage) -> None:
        self._offset(is_left, item.t_ns)
        self.unpaired(is_left, item)

    def finish(self) -> None:
        for is_left in (True, False):
            for item in self.pending[is_left]:
                self._give_up(is_left, item)
            self.pending[is_left].clear()

    @property
    def typical_offset_ns(self) -> float | None:
        return float(np.median(self.offsets)) if self.offsets else None

    @property
    def covering_tolerance_ms(self) -> int | None:
        """Whole milliseconds above the 98th percentile of the offsets under half the frame period (the
        median gap between left stamps): the ``--tolerance-ms`` to propose. The median proposed 5 ms
        for cameras 3 to 5.5 ms apart, which left a quarter of the images unpaired; an image whose
        partner was dropped measures its distance to the next frame's, which proposed a whole frame
        period (30 fps, a tenth of the left images dropped: 30 ms, pairing 62 of 268 images with the
        next frame's)."""
        if not self.offsets:
            return None
        offsets = np.asarray(self.offsets, float)
        if self.left_gaps:
            within = offsets[offsets < float(np.median(self.left_gaps)) / 2]
            offsets = within if len(within) else offsets
        return math.floor(float(np.percentile(offsets, 98)) * 1e-6) + 1


def _folder_problem(path: str) -> str:
    """What to do with a folder that is not a rosbag2 bag (no metadata.yaml): name the files in it that are."""
    try:
        names = sorted(os.listdir(path))
    except OSError as e:
        return f"a folder that cannot be listed ({e.strerror or e})"
    storage = [n for n in names if n.endswith((".db3", ".mcap"))]
    if storage:
        return (f"a folder without metadata.yaml, holding {', '.join(storage[:3])}: a rosbag2 recording that was "
                f"killed leaves none: run 'ros2 bag reindex {path}', or give {storage[0]} itself")
    return "a folder with neither a rosbag2 bag (metadata.yaml) nor the .bag files of a split ROS 1 bag"


DITHER_SHARE = 0.1   # of the pixels that ``dithered`` moves by one grey level


def dithered(image: np.ndarray, seed) -> np.ndarray:
    """(H, W) uint8 ``image`` with a tenth of its pixels (``DITHER_SHARE``), drawn by ``seed`` (anything
    ``numpy.random.default_rng`` takes), one grey level up or down (clipped to 0..255): a new pattern
    of noise of 0.3 grey levels RMS, below any camera's, that changes which pixels Canny keeps and
    every sub-pixel fit a little, as a second recording of the same scene would."""
    rng = np.random.default_rng(seed)
    step = np.where(rng.random(image.shape) < DITHER_SHARE, rng.integers(0, 2, image.shape, np.int16) * 2 - 1, 0)
    return np.clip(image.astype(np.int16) + step, 0, 255).astype(np.uint8)


class Recording:
    """A stereo recording opened for streaming. Use as a context manager.

    With ``require_pose=False`` a recording without /tf or without a path to the
    object frame opens, and its frames carry ``T_camera_object = None``.
    After opening: ``time_span_ns`` (first, last) the image timestamps (None: no image);
    ``frame_count_hint`` is the number of stereo pairs (counted
    in the first pass, exact), ``stereo_offset_ns`` the typical left/right
    offset (ns, or None), ``lost_bytes`` the bytes of a truncated or damaged
    file that could not be read.

    ``dither``: 0 streams the images as recorded; another number is the seed of one more noise
    pattern (``dithered``) added to every rectified image, for robustness studies: ``make suite
    --repeats`` tells a change's effect from the scatter that one noise pattern of a recording gives.
    """

    def __init__(self, path, topics: Topics = Topics(), camera_frame: str = "camera_left",
                 object_frame: str = "gripper", tolerance_ns: int = 1_000_000, require_pose: bool = True,
                 time_offset_ns: int = 0, dither: int = 0):
        self.path = str(path)
        self.dither = int(dither)
        self.time_offset_ns = int(time_offset_ns)   # poses are looked up this long after an image's stamp
        self.topics = topics
        self.camera_frame = frame_name(camera_frame)
        self.object_frame = frame_name(object_frame)
        self.tolerance_ns = int(tolerance_ns)
        self._check_file()
        self.tree = TransformTree()
        self.calibrations: dict[str, list[tuple[int, CameraCalibration]]] = {"left": [], "right": []}
        self._rectifiers: dict = {}
        self._warned_early_calibration = False
        self._warned_rect_topic = False
        self._full_scale: int | None = None   # of 16-bit images (``messages.sixteen_bit_full_scale``)
        self.undecodable: dict[str, int] = {}   # frames skipped while streaming: reason -> count
        # ROS's image_rect (and image_rect_color) topics hold rectified images, beside the raw camera's
        # camera_info: rectifying them again with its D and R gave a model of precision 0.014
        self.images_rectified = all(_is_rect_topic(t) for t in (topics.left_image, topics.right_image))
        self._index()
        try:
            self._check_topics(require_pose)
        except RecordingError as e:   # what the recording holds, for ``accum info`` to show beside the error
            e.info = RecordingInfo(path=self.path, topics=self._topic_counts(), tf_frames=sorted(self.tree.frames),
                                   topics_only=True)
            raise
        self._check_calibrations()
        self._check_image_frame()
        if require_pose:
            self._check_pose_path()
        log.info("%s: %d stereo frames, %d calibration message(s), transform frames: %s", self.path,
                 self.frame_count_hint, len(self.calibrations["left"]), ", ".join(sorted(self.tree.frames)) or "none")

    # -- opening and validation ---------------------------------------------------------
    def _fail(self, problem: str) -> RecordingError:
        return RecordingError(f"{self.path}: {problem}")

    def _check_file(self) -> None:
        if not os.path.exists(self.path):
            raise self._fail("no such file")
        self.bag = ros2.bag_kind(self.path)
        self.bag_damage = None   # what a damaged bag lost (``_index``)
        if self.bag is not None:
            self.size, self.truncated = 0, False
            active = ros2.unfinished_bag_files(self.path) if self.bag == "rosbag1" else []
            if active:
                log.warning("%s: %s is a recording cut short, not read: run 'rosbag reindex' on it and drop its "
                            "'.active' to read its frames too", self.path, active[0])
            return
        if not os.path.isfile(self.path):
            raise self._fail(_folder_problem(self.path))
        self.size = os.path.getsize(self.path)
        if self.size == 0:
            raise self._fail("empty file")
        try:
            with open(self.path, "rb") as f:
                head = f.read(len(MCAP_MAGIC))
                f.seek(max(self.size - len(MCAP_MAGIC), 0))
                self.truncated = f.read() != MCAP_MAGIC or self.size < 2 * len(MCAP_MAGIC)
        except OSError as e:
            raise self._fail(f"cannot be read ({e.strerror or e})") from None
        if head != MCAP_MAGIC:
            raise self._fail("not an MCAP file (wrong magic bytes), nor a ROS 1 bag or rosbag2 .db3: give an MCAP "
                             "recording, a rosbag2 folder or a ROS 1 .bag")

    def _roles(self) -> dict[str, str]:
        t = self.topics
        return {t.left_image: "image", t.right_image: "image", t.left_calibration: "calibration",
                t.right_calibration: "calibration", t.tf: "tf", t.tf_static: "tf"}

    @staticmethod
    def _expected(role: str) -> str:
        return (f"protobuf or json {' or '.join(PROTOBUF_TYPES[role])} or cdr or ros1 {' or '.join(ROS_TYPES[role])}")

    def _decoder(self, scan, channel, role: str) -> Callable:
        """bytes -> Foxglove protobuf message for ``channel`` in its ``role``; raises RecordingError."""
        protobuf = PROTOBUF_TYPES[role].get(channel.schema_name)
        if protobuf is not None and channel.message_encoding == "protobuf":
            return lambda data: protobuf.FromString(bytes(data))
        if protobuf is not None and channel.message_encoding == "json":
            return lambda data: from_foxglove_json(protobuf, data)
        if channel.schema_name in ROS_TYPES[role] and channel.message_encoding in ("cdr", "ros1"):
            if isinstance(scan, ros2.RosbagScan):
                return scan.decoder(channel)
            try:
                return (ros2.mcap_cdr_decoder if channel.message_encoding == "cdr" else ros2.mcap_ros1_decoder)(channel)
            except ValueError as e:
                raise self._fail(f"topic {channel.topic} carries {channel.schema_name}: {e}") from None
        raise self._fail(f"topic {channel.topic} carries {channel.schema_name or 'no schema'} "
                         f"({channel.message_encoding or 'no'} encoding), expected {self._expected(role)}")

    def _scan(self, warn: LimitedWarnings, wanted: set[str],
              first: bool = False) -> Iterator[tuple[str, int, object]]:
        """(topic, log_time_ns, decoded message) of the ``wanted`` topics, in file order.

        The ``first`` pass also counts the messages per channel and keeps the channels and the scan's
        damage report (``_first_scan``).
        """
        channels, schemas, roles, decoders = {}, {}, self._roles(), {}
        scan = ros2.RosbagScan(self.path, channels, self.bag) if self.bag else McapScan(self.path, warn, channels,
                                                                                        schemas)
        counts: dict[int, int] = {}
        if first:
            self._first_scan, self.message_counts, self._channels_seen = scan, counts, channels
        for message in scan.messages():
            channel = channels.get(message.channel_id)
            if channel is None:
                warn("undefined channel", "%s: message at %.3f s on undefined channel id %d: skipped", self.path,
                     message.log_time * 1e-9, message.channel_id)
                continue
            counts[channel.id] = counts.get(channel.id, 0) + 1
            if channel.topic not in wanted:
                continue
            decode = decoders.get(channel.id)
            if decode is None:
                decode = decoders[channel.id] = self._decoder(scan, channel, roles[channel.topic])
            try:
                decoded = decode(message.data)
            except Exception as e:  # protobuf and the CDR decoders raise their own error types
                warn("undecodable message", "%s: message on %s at %.3f s cannot be decoded (%s): skipped",
                     self.path, channel.topic, message.log_time * 1e-9, e)
                continue
            yield channel.topic, message.log_time, decoded

    def _stamp(self, msg, log_time: int, warn: LimitedWarnings, topic: str) -> int | None:
        if not msg.HasField("timestamp"):
            return log_time
        try:
            return stamp_ns(msg.timestamp)
        except ValueError as e:
            warn("bad timestamp", "%s: message on %s at log time %.3f s: %s: skipped", self.path, topic,
                 log_time * 1e-9, e)
            return None

    def _index(self) -> None:
        """First pass: calibrations and transforms, image pairing on timestamps, message counts."""
        t = self.topics
        sides = {t.left_calibration: "left", t.right_calibration: "right"}
        self.frame_count_hint, unpaired, unstamped = 0, {"count": 0}, {}
        self.time_span_ns: tuple[int, int] | None = None
        self.image_frame_id = ""   # the left images' frame_id (the first one given)

        def count_unpaired(is_left, item):
            unpaired["count"] += 1

        pairing = _Pairing(t.left_image, self.tolerance_ns, count_unpaired)
        wanted = set(self._roles())
        with LimitedWarnings(log, prefix=f"{self.path}: ") as warn:
            for topic, log_time, msg in self._scan(warn, wanted, first=True):
                if topic in (t.left_image, t.right_image):
                    refused = encoding_problem(msg)
                    if refused:
                        raise self._fail(f"{topic}: {refused}")
                    t_ns = self._stamp(msg, log_time, warn, topic)
                    if not msg.HasField("timestamp"):
                        unstamped[topic] = unstamped.get(topic, 0) + 1
                    if topic == t.left_image and not self.image_frame_id:
                        self.image_frame_id = frame_name(getattr(msg, "frame_id", "") or "")
                    if t_ns is not None:
                        self.frame_count_hint += len(pairing.add(topic, _PendingImage(t_ns, None)))
                        span = self.time_span_ns or (t_ns, t_ns)
                        self.time_span_ns = (min(span[0], t_ns), max(span[1], t_ns))
                    continue
                if topic in sides:
                    try:
                        cal = calibration_from_msg(msg)
                    except ValueError as e:
                        warn("bad calibration", "%s: calibration on %s at %.3f s is malformed (%s): skipped",
                             self.path, topic, log_time * 1e-9, e)
                        continue
                    stamp = self._stamp(msg, log_time, warn, topic)
                    if stamp is not None:
                        self.calibrations[sides[topic]].append((stamp, cal))
                    continue
                for tf in (msg.transforms if hasattr(msg, "transforms") else [msg]):
                    t_ns = self._stamp(tf, log_time, warn, topic)
                    if t_ns is None:
                        continue
                    if frame_name(tf.parent_frame_id) == frame_name(tf.child_frame_id):
                        warn("self transform", "%s: transform from %r to itself at %.3f s: skipped", self.path,
                             tf.parent_frame_id, t_ns * 1e-9)
                        continue
                    r, q = tf.translation, tf.rotation
                    translation, quat = (r.x, r.y, r.z), (q.x, q.y, q.z, q.w)
                    problem = sample_problem(translation, quat)
                    if problem:
                        warn("invalid transform", "%s: transform %s -> %s at %.3f s has an %s: frames that "
                             "need it have no pose", self.path, tf.parent_frame_id, tf.child_frame_id,
                             t_ns * 1e-9, problem)
                    self.tree.add(tf.parent_frame_id, tf.child_frame_id, t_ns, translation, quat,
                                  static=topic == t.tf_static)
            pairing.finish()
            for topic, count in sorted(unstamped.items()):
                log.warning("%s: %d image(s) on %s carry no time stamp (header.stamp zero): their log times are "
                            "used, which lag the capture by the recorder's delay, so their poses may not match "
                            "them", self.path, count, topic)
            for child, parents in self.tree.ambiguous_frames().items():
                warn("several parents", "%s: frame %r has several parents (%s) in the transform tree: lookups "
                     "take the shortest path", self.path, child, ", ".join(map(repr, parents)))
        scan = self._first_scan
        self.lost_bytes = scan.lost_bytes
        self.unpaired_count = unpaired["count"]
        self.stereo_offset_ns = pairing.typical_offset_ns
        self.pairing_tolerance_ms = pairing.covering_tolerance_ms
        self._channels = {c.topic: c for c in self._channels_seen.values()}
        if not self._channels and self.bag:
            raise self._fail("ROS bag without any topic")
        if not self._channels:
            how = "truncated" if self.truncated else "corrupt"
            raise self._fail(f"{how} MCAP file: no readable channel in its {self.size} bytes"
                             + (f" ({scan.broken})" if scan.broken else ""))
        last = f"{scan.last_time_ns * 1e-9:.3f} s" if scan.last_time_ns is not None else "none"
        if not scan.footer and self.bag:
            self.bag_damage = f"damaged after {last} ({scan.broken})"
            log.warning("%s: damaged bag (%s): read up to its last message before the damage, at %s; the rest "
                        "is lost", self.path, scan.broken, last)
        elif not scan.footer:
            what = "truncated recording (no MCAP footer)" if self.truncated else f"damaged recording ({scan.broken})"
            log.warning("%s: %s: read up to byte %d of %d, %d bytes lost; last message read at %s", self.path,
                        what, self.size - scan.lost_bytes, self.size, scan.lost_bytes, last)

    def _lost(self) -> str:
        if self.bag_damage:
            return f" (the bag is {self.bag_damage})"
        return f" (the file is truncated or damaged: {self.lost_bytes} of its {self.size} bytes unreadable)" \
            if self.lost_bytes else ""

    def _check_topics(self, require_pose: bool) -> None:
        t = self.topics
        available = ", ".join(sorted(self._channels)) or "none"
        for topic in (t.left_image, t.right_image, t.left_calibration, t.right_calibration):
            if topic not in self._channels:
                proposal = ros2.propose_topics(self._channels)
                version = 1 if any(c.message_encoding == "ros1" for c in self._channels.values()) else 2
                hint = f"; this recording looks like ROS {version}: try {proposal}" if proposal else ""
                if not proposal:
                    proposal = ros2.propose_topics(self._channels, tuple(IMAGE_TYPES), tuple(CALIBRATION_TYPES),
                                                   "foxglove.RawImage")
                    hint = f"; the stereo pair looks like: try {proposal}" if proposal else ""
                raise self._fail(f"missing topic {topic}{hint} (topics found: {available}){self._lost()}")
        for topic, role in self._roles().items():
            channel = self._channels.get(topic)
            if channel is not None and (channel.schema_name not in PROTOBUF_TYPES[role]
                                        and channel.schema_name not in ROS_TYPES[role]):
                raise self._fail(f"topic {topic} carries {channel.schema_name or 'no schema'}, expected "
                                 f"{self._expected(role)}")
        if require_pose and t.tf not in self._channels and t.tf_static not in self._channels:
            raise self._fail(f"missing topic {t.tf}: no transforms, so no pose of {self.object_frame!r} "
                             f"(topics found: {available})")
        for topic in (t.left_image, t.right_image):
            if not self._message_count(topic):
                raise self._fail(f"no readable image on {topic}{self._lost()}")
        if self.frame_count_hint == 0:
            if self.stereo_offset_ns is None:
                raise self._fail("no stereo pair: the images of one camera cannot be read (see the warnings)")
            offset_ms = self.stereo_offset_ns * 1e-6
            raise self._fail(f"no stereo pair within {self.tolerance_ns * 1e-6:.1f} ms: left and right images are "
                             f"{offset_ms:.1f} ms apart; try --tolerance-ms {self.pairing_tolerance_ms}")

    def _check_calibrations(self) -> None:
        t = self.topics
        for side, topic in (("left", t.left_calibration), ("right", t.right_calibration)):
            if not self.calibrations[side]:
                raise self._fail(f"missing calibration: no valid message on {topic}{self._lost()}")
            self.calibrations[side].sort(key=lambda item: item[0])
        self.calibration_at(self.calibrations["left"][0][0])

    def _check_pose_path(self) -> None:
        if self.tree.path(self.camera_frame, self.object_frame) is None:
            frames = ", ".join(sorted(self.tree.frames)) or "none"
            raise self._fail(f"no transform path from {self.camera_frame!r} to {self.object_frame!r} "
                             f"(frames in the transform tree: {frames}); {self.pose_path_hint()}")

    def pose_path_hint(self) -> str:
        """What to try when no transform path joins the camera and the object frame."""
        frames = self.tree.frames
        if not frames:
            return f"the recording holds no transform (on {self.topics.tf} or {self.topics.tf_static})"
        if self.camera_frame not in frames:
            if self.image_frame_id in frames:
                return f"the images' frame is {self.image_frame_id!r}: try --camera-frame {self.image_frame_id}"
            if self.image_frame_id == self.camera_frame:   # the right frame, whose transforms are missing
                return f"no transform names {self.camera_frame!r}, the images' own frame{self._static_hint()}"
            return "choose the left camera's optical frame with --camera-frame"
        if self.object_frame not in frames:
            return "choose the object's frame with --object-frame"
        return "the two frames are in separate transform trees"

    def _static_hint(self) -> str:
        """Why the static transforms (a camera's mounting, usually) may be missing."""
        static = self.topics.tf_static
        others = sorted(topic for topic in self._channels if topic.endswith("tf_static") and topic != static)
        if others:
            return f"; the recording has {others[0]}: try --tf-static-topic {others[0]}"
        if not self._message_count(static):
            return (f"; {static} has no message here (a split bag records it in its first file only: give the "
                    + "bag's folder, which holds all its files)")
        return ""

    def _check_image_frame(self) -> None:
        """Warn when the left images name a frame of the transform tree other than the camera frame:
        poses are looked up for the camera frame, so a wrong one (the right camera's, a body frame
        instead of the optical one) gives a wrong model without any other sign."""
        image, camera = self.image_frame_id, self.camera_frame
        if image and image != camera and image in self.tree.frames and camera in self.tree.frames:
            log.warning("%s: the left images are in frame %r (their frame_id), poses are looked up for %r "
                        "(--camera-frame): if %r is the left camera's optical frame, give --camera-frame %s",
                        self.path, image, camera, image, image)

    # -- streaming ----------------------------------------------------------------------
    def _pairs(self, warn: LimitedWarnings | None = None) -> Iterator[tuple[int, int, object, object]]:
        """(index, t_ns, left message, right message) for each stereo pair, in arrival order."""
        t = self.topics
        quiet = LimitedWarnings(log, limit=0)

        def unpaired(is_left: bool, item: _PendingImage) -> None:
            if warn is not None:
                warn("unpaired image", "%s: image on %s at %.3f s has no partner within %.3f ms: skipped",
                     self.path, t.left_image if is_left else t.right_image, item.t_ns * 1e-9,
                     self.tolerance_ns * 1e-6)

        pairing = _Pairing(t.left_image, self.tolerance_ns, unpaired)
        index = 0
        for topic, log_time, msg in self._scan(quiet, {t.left_image, t.right_image}):
            t_ns = self._stamp(msg, log_time, quiet, topic)
            if t_ns is None:
                continue
            for left, right in pairing.add(topic, _PendingImage(t_ns, msg)):
                yield index, left.t_ns, left.msg, right.msg
                index += 1
        pairing.finish()

    def calibration_at(self, t_ns: int) -> StereoRectifier:
        """The rectifier of the latest calibrations at or before ``t_ns``."""
        chosen = []
        if self.images_rectified and not self._warned_rect_topic and not all(
                self.calibrations[side][0][1].is_rectified for side in ("left", "right")):
            log.warning("%s: %s is a rectified image topic (ROS's image_rect): its images are used as they are, "
                        "with the calibration's P (not rectified again)", self.path, self.topics.left_image)
            self._warned_rect_topic = True
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
                self._rectifiers[key] = StereoRectifier(*chosen, images_rectified=self.images_rectified)
            except RecordingError as e:
                raise self._fail(str(e)) from None
            baseline = self._rectifiers[key].intrinsics.baseline
            if not 0.005 <= baseline <= 2.0:   # a stereo rig's, in metres: P[0,3] in other units?
                log.warning("%s: the stereo baseline is %.4g m: the right P[0,3] must be -fx times the baseline "
                            "in metres (in other units every depth is off by that factor)", self.path, baseline)
        return self._rectifiers[key]

    def pose_at(self, t_ns: int) -> np.ndarray:
        """``T_camera_object`` for an image stamped ``t_ns``: the transforms at ``t_ns`` plus the
        recording's ``time_offset_ns`` (``--time-offset-ms``: a camera clock apart from the robot's);
        raises ``PoseUnavailable``."""
        return self.tree.lookup(self.camera_frame, self.object_frame, t_ns + self.time_offset_ns, self.tolerance_ns)

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[StereoFrame]:
        """Stream the stereo frames with index in [start, stop). A frame with the stamp of the frame
        before it is skipped with a warning: both would be placed by the one pose of that time (a
        driver that repeats a stamp put a frame at its neighbour's pose, silently)."""
        previous_ns = None
        self._full_scale = None   # each pass decodes a frame as the first pass did (the scale grows within one)
        with LimitedWarnings(log, prefix=f"{self.path}: ") as warn:
            for index, t_ns, left_msg, right_msg in self._pairs(warn):
                repeated, previous_ns = t_ns == previous_ns, t_ns
                if index < start:
                    continue
                if stop is not None and index >= stop:
                    break
                where = f"{self.path}: frame {index} ({t_ns * 1e-9:.3f} s)"
                if repeated:
                    warn("repeated stamp", "%s: has the stamp of the frame before it (the images' stamps repeat; "
                         "check the camera driver): skipped", where)
                    continue
                rectifier = self.calibration_at(t_ns)
                size = (rectifier.intrinsics.width, rectifier.intrinsics.height)
                try:
                    if self._full_scale is None:   # of 16-bit data: its bit depth, from the first frame
                        self._full_scale = max(sixteen_bit_full_scale(m) or 0 for m in (left_msg, right_msg)) or 65535
                        if self._full_scale < 65535:
                            log.warning("%s: the 16-bit images use %d bits (the first frame's largest value "
                                        "needs them): scaled by 255/%d", self.path,
                                        self._full_scale.bit_length(), self._full_scale)
                    elif self._full_scale < 65535:   # a brighter frame needs more bits: the scale grows
                        needed = max(sixteen_bit_full_scale(m) or 0 for m in (left_msg, right_msg))
                        if needed > self._full_scale:
                            self._full_scale = needed
                            log.warning("%s: from it on, the 16-bit images use %d bits: scaled by 255/%d (a "
                                        "first frame darker than the rest gave too few)", where,
                                        needed.bit_length(), needed)
                    left, right = (decode_image(m, size, self._full_scale) for m in (left_msg, right_msg))
                except DecodeError as e:
                    warn("undecodable frame", "%s: %s: skipped", where, e)
                    reason = f"cannot be decoded ({e})"
                    self.undecodable[reason] = self.undecodable.get(reason, 0) + 1
                    continue
                left, right = rectifier.rectify(left, right)
                if self.dither:
                    left, right = dithered(left, (self.dither, index, 0)), dithered(right, (self.dither, index, 1))
                try:
                    T, problem = self.pose_at(t_ns), None
                except PoseUnavailable as e:
                    T, problem = None, str(e)
                yield StereoFrame(index, t_ns, left, right, rectifier.intrinsics, T, problem, rectifier.border_distance)

    # -- summary --------------------------------------------------------------------------
    def _message_count(self, topic: str) -> int:
        """Messages on ``topic`` over all its channels (a ROS 1 bag has one per publisher: two /tf
        broadcasters, a restarted driver)."""
        return sum(self.message_counts.get(c.id, 0) for c in self._channels_seen.values() if c.topic == topic)

    def _topic_counts(self) -> list[tuple[str, str, int]]:
        """(topic, schema name, messages) of every topic, by name."""
        return [(c.topic, c.schema_name, self._message_count(c.topic))
                for c in sorted(self._channels.values(), key=lambda c: c.topic)]

    def info(self) -> RecordingInfo:
        """Scan the recording (no pixel decoding) for ``accum info``."""
        info = RecordingInfo(path=self.path, stereo_offset_ms=None if self.stereo_offset_ns is None
                             else self.stereo_offset_ns * 1e-6, pairing_tolerance_ms=self.pairing_tolerance_ms,
                             lost_bytes=self.lost_bytes)
        info.topics = self._topic_counts()
        info.tf_frames = sorted(self.tree.frames)
        info.calibrations = len(self.calibrations["left"])
        info.unpaired_images = self.unpaired_count
        problems: dict[str, int] = {}
        for _, t_ns, left_msg, _ in self._pairs():
            info.stereo_frames += 1
            info.first_ns = t_ns if info.first_ns is None else info.first_ns
            info.last_ns = t_ns
            if info.image_encoding is None:
                info.image_encoding = image_encoding(left_msg)
                rectifier = self.calibration_at(t_ns)
                info.intrinsics = rectifier.intrinsics
                info.image_size = (rectifier.intrinsics.width, rectifier.intrinsics.height)
                info.rectified_input = rectifier.rectified_input
                left_cal = self.calibrations["left"][0][1]
                info.distortion_model = left_cal.distortion_model or (   # unnamed: OpenCV's by its coefficients
                    f"unnamed: {len(left_cal.D)} coefficients" if np.any(left_cal.D) else "none")
                try:
                    declared = image_size(left_msg)
                except DecodeError:
                    declared = info.image_size
                if declared != info.image_size:
                    info.size_problem = (f"the images are {declared[0]}x{declared[1]}, their calibration is for "
                                         f"{info.image_size[0]}x{info.image_size[1]}: every frame would be refused; "
                                         "give the calibration of these images")
            try:
                self.pose_at(t_ns)
                info.frames_with_pose += 1
            except PoseUnavailable as e:
                reason = re.sub(r"time -?[0-9.]+ s (is )?", "", str(e))   # one reason for all the frames it holds for
                problems[reason] = problems.get(reason, 0) + 1
        info.pose_problems = sorted(problems.items())
        return info

    def close(self) -> None:
        """Nothing to release: each pass opens and closes the file itself."""

    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
