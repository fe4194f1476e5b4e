"""ROS 2 recordings: MCAP with ``ros2msg`` schemas and CDR messages, rosbag2 folders and bare ``.db3``
files, read into the same Foxglove protobuf messages the protobuf path decodes, so that everything
after decoding (``reader``, ``messages``) is one code path.

Conversions (ROS 2 message -> Foxglove protobuf message):
- ``sensor_msgs/msg/Image`` -> ``foxglove.RawImage`` (width, height, encoding, step, data). 16-bit
  data with ``is_bigendian`` set is byte-swapped to the little-endian RawImage layout. The encodings
  read (colour, 16-bit, Bayer, YUV 4:2:2) are ``messages.RAW_ENCODINGS``; others are refused when the
  recording opens (``messages.encoding_problem``).
- ``sensor_msgs/msg/CompressedImage`` -> ``foxglove.CompressedImage`` (format, data; PNG or JPEG by
  signature, as for protobuf).
- ``sensor_msgs/msg/CameraInfo`` -> ``foxglove.CameraCalibration``: d, k, r, p to D, K, R, P (K, P and
  the size those of the binned, cropped images where binning or a region of interest is set);
  distortion_model as written (``calibration`` takes plumb_bob, rational_polynomial and the fisheye
  model, equidistant, and refuses others with a ``RecordingError``).
- ``tf2_msgs/msg/TFMessage`` -> ``foxglove.FrameTransforms``: header.frame_id is the parent.
- Every timestamp is ``header.stamp``; a zero stamp is left unset, so the reader uses the log time
  (as for an unset protobuf timestamp); a nanosec beyond int32 makes the message undecodable.

MCAP-CDR messages are decoded by ``mcap_ros2``'s decoder from the file's own ``ros2msg`` schema;
rosbag2 messages by ``rosbags``' typestore (``Stores.ROS2_HUMBLE``; the four message types are the
same in every ROS 2 distribution), since a ``.db3`` need not carry its message definitions.
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import (
    CameraCalibration as CalibrationMsg,
)
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from google.protobuf.timestamp_pb2 import Timestamp

from ..errors import RecordingError, one_line
from .mcap_records import _Channel, _Message
from .messages import SIXTEEN_BIT

ROS_IMAGE, ROS_COMPRESSED = "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"
ROS_CAMERA_INFO, ROS_TF = "sensor_msgs/msg/CameraInfo", "tf2_msgs/msg/TFMessage"
ROS_IMAGE_TYPES = (ROS_IMAGE, ROS_COMPRESSED)
ROS1_TF = "tf/msg/tfMessage"       # ROS 1's tf (before tf2), the same fields
SQLITE_MAGIC = b"SQLite format 3\x00"
ROSBAG1_MAGIC = b"#ROSBAG V2.0\n"

log = logging.getLogger("accumcli")


def _stamp(header) -> Timestamp | None:
    sec, nanosec = int(header.stamp.sec), int(header.stamp.nanosec)
    return None if sec == 0 and nanosec == 0 else Timestamp(seconds=sec, nanos=nanosec)


def _with_stamp(msg, header):
    stamp = _stamp(header)
    if stamp is not None:
        msg.timestamp.CopyFrom(stamp)
    return msg


def image_from_ros(m) -> RawImage:
    data = bytes(m.data)
    encoding = str(m.encoding)
    if m.is_bigendian and encoding in SIXTEEN_BIT:
        data = np.frombuffer(data[:len(data) // 2 * 2], ">u2").astype("<u2").tobytes()
    return _with_stamp(RawImage(frame_id=m.header.frame_id, width=int(m.width), height=int(m.height),
                                encoding=encoding, step=int(m.step), data=data), m.header)


def compressed_from_ros(m) -> CompressedImage:
    return _with_stamp(CompressedImage(frame_id=m.header.frame_id, format=str(m.format), data=bytes(m.data)),
                       m.header)


def calibration_from_ros(m) -> CalibrationMsg:
    """CameraInfo -> CameraCalibration of the images published: with binning or a region of interest
    (REP 104: K, P, width and height are the full sensor's) those of the binned, cropped images
    (``_reduced``); ROS 1's D, K, R, P as ROS 2's d, k, r, p."""
    d, k, r, p = (getattr(m, name) if hasattr(m, name) else getattr(m, name.upper()) for name in "dkrp")  # ROS 1: D...
    width, height, K, P = int(m.width), int(m.height), np.array(k, float), np.array(p, float)
    binning = (max(int(getattr(m, "binning_x", 0)), 1), max(int(getattr(m, "binning_y", 0)), 1))
    roi = getattr(m, "roi", None)
    offset = (int(roi.x_offset), int(roi.y_offset)) if roi is not None else (0, 0)
    size = (int(roi.width), int(roi.height)) if roi is not None else (0, 0)
    if binning != (1, 1) or any(offset) or any(size):
        width, height, K, P = _reduced(width, height, K, P, binning, offset, size)
    return _with_stamp(CalibrationMsg(
        frame_id=m.header.frame_id, width=width, height=height,
        distortion_model=str(m.distortion_model), D=[float(v) for v in d], K=[float(v) for v in K],
        R=[float(v) for v in r], P=[float(v) for v in P]), m.header)


def _reduced(width, height, K, P, binning, offset, size):
    """(width, height, K, P) of the images a camera publishes from the region ``offset`` (x, y) px and
    ``size`` (width, height; 0: to the sensor's edge) of its sensor, binned by ``binning`` (x, y):
    binned pixel u' covers sensor pixels u' b .. u' b + b - 1, so a sensor coordinate u is
    u' = (u - x_offset - (b - 1) / 2) / b; K and P (flattened 3x3, 3x4) map to u' row by row. The
    distortion D and rectification R are of normalised coordinates and stay."""
    (bx, by), (x0, y0) = binning, offset
    w = size[0] or width - x0
    h = size[1] or height - y0
    reduced = []
    for M, columns in ((K, 3), (P, 4)):
        M = M.reshape(3, columns).copy()
        M[0] = (M[0] - (x0 + (bx - 1) / 2) * M[2]) / bx
        M[1] = (M[1] - (y0 + (by - 1) / 2) * M[2]) / by
        reduced.append(M.ravel())
    return w // bx, h // by, reduced[0], reduced[1]


def transforms_from_ros(m) -> FrameTransforms:
    out = FrameTransforms()
    for tf in m.transforms:
        msg = _with_stamp(FrameTransform(parent_frame_id=tf.header.frame_id, child_frame_id=tf.child_frame_id),
                          tf.header)
        t, q = tf.transform.translation, tf.transform.rotation
        msg.translation.x, msg.translation.y, msg.translation.z = float(t.x), float(t.y), float(t.z)
        msg.rotation.x, msg.rotation.y, msg.rotation.z, msg.rotation.w = float(q.x), float(q.y), float(q.z), float(q.w)
        out.transforms.append(msg)
    return out


CONVERTERS: dict[str, Callable] = {ROS_IMAGE: image_from_ros, ROS_COMPRESSED: compressed_from_ros,
                                   ROS_CAMERA_INFO: calibration_from_ros, ROS_TF: transforms_from_ros,
                                   ROS1_TF: transforms_from_ros}


def mcap_cdr_decoder(channel: _Channel) -> Callable[[memoryview], object]:
    """bytes -> Foxglove protobuf message for an MCAP channel of CDR messages with a ros2msg schema;
    raises ValueError when the schema cannot be used."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    if channel.schema_encoding != "ros2msg":
        raise ValueError(f"schema encoding {channel.schema_encoding or 'none'!r}, expected ros2msg")
    schema = Schema(id=channel.schema_id, name=channel.schema_name, encoding=channel.schema_encoding,
                    data=channel.schema_data)
    try:
        decode = DecoderFactory().decoder_for("cdr", schema)
    except Exception as e:  # the ros2msg parser raises its own error types
        raise ValueError(f"its ros2msg schema cannot be parsed ({one_line(e)})") from None
    if decode is None:
        raise ValueError("no CDR decoder for its schema")
    convert = CONVERTERS[channel.schema_name]
    return lambda data: convert(decode(_uncompressed(data)))


ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


def _uncompressed(data) -> bytes:
    """A CDR message's bytes; ValueError naming the cause for a zstd frame (a rosbag2 bag's file with
    message compression, given without its folder, whose metadata.yaml says so)."""
    data = bytes(data)
    if data[:4] == ZSTD_MAGIC:
        raise ValueError("the message is zstd-compressed (a rosbag2 bag with message compression): give the "
                         "bag's folder")
    return data


_TYPESTORE = None


def typestore():
    """The rosbags typestore of the standard ROS 2 messages (built once)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
    return _TYPESTORE


def split_bag_files(folder: str) -> list[str]:
    """The ROS 1 bags of a folder (``rosbag record --split`` writes name_0.bag, name_1.bag, ...), in the
    order of their numbers; [] if it holds none, or rosbag2 storage files beside them."""
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    if any(n.endswith((".db3", ".mcap")) for n in names):
        return []
    bags = [n for n in names if n.endswith(".bag") and not n.endswith(".orig.bag")   # rosbag reindex's backup
            and os.path.isfile(os.path.join(folder, n))]
    def order(name):   # by the number before .bag, then by name
        found = re.search(r"(\d+)\.bag$", name)
        return (int(found.group(1)) if found else -1, name)

    return [os.path.join(folder, n) for n in sorted(bags, key=order)]


def unfinished_bag_files(folder: str) -> list[str]:
    """A split bag folder's files that a killed recorder left (name.bag.active: no index), not read."""
    try:
        return sorted(n for n in os.listdir(folder) if n.endswith(".bag.active")) if os.path.isdir(folder) else []
    except OSError:
        return []


def bag_kind(path: str) -> str | None:
    """'rosbag2' for a folder with metadata.yaml, 'db3' for an SQLite file, 'rosbag1' for a ROS 1 bag,
    None otherwise."""
    if os.path.isdir(path):
        if os.path.isfile(os.path.join(path, "metadata.yaml")):
            return "rosbag2"
        return "rosbag1" if split_bag_files(path) else None
    try:
        with open(path, "rb") as f:
            head = f.read(max(len(SQLITE_MAGIC), len(ROSBAG1_MAGIC)))
    except OSError:
        return None
    return "db3" if head.startswith(SQLITE_MAGIC) else "rosbag1" if head.startswith(ROSBAG1_MAGIC) else None


class RosbagScan:
    """One pass over a rosbag2 folder or ``.db3``, or a ROS 1 ``.bag`` (``kind`` 'rosbag1'), with
    ``rosbags``, with ``McapScan``'s interface: ``messages()`` yields ``_Message`` in the bag's time
    order, ``channels`` fills as the bag opens; ``decoder(channel)`` gives bytes -> Foxglove protobuf
    message. A bag ``rosbags`` cannot open is a ``RecordingError``; one damaged further on (a bad
    compressed chunk, a damaged storage file) is read up to the damage: ``footer`` False and ``broken``
    the reason, as ``McapScan`` says it. ROS 1 messages are decoded with the Noetic types and the
    definitions the bag carries (its connections'), ``tf/tfMessage`` as ``tf2_msgs/TFMessage``, and
    CameraInfo's ``D, K, R, P`` as ROS 2's ``d, k, r, p``."""

    lost_bytes, broken, footer, last_time_ns = 0, None, True, None

    def __init__(self, path: str, channels: dict, kind: str = "rosbag2"):
        self.path, self.channels, self.kind = path, channels, kind
        self.name = "ROS 1 bag" if kind == "rosbag1" else "rosbag2 bag"
        self.store = None   # ROS 1: the Noetic types with the bag's own definitions

    def _open(self):
        if self.kind == "rosbag1" and os.path.isdir(self.path):   # a split bag's files, merged in time order
            from rosbags.highlevel import AnyReader

            reader = AnyReader([Path(p) for p in split_bag_files(self.path)])
        elif self.kind == "rosbag1":
            from rosbags.rosbag1 import Reader

            reader = Reader(self.path)
        else:
            from rosbags.rosbag2 import Reader

            reader = Reader(self.path)
        reader.open()
        return reader

    def messages(self) -> Iterator[_Message]:
        try:
            reader = self._open()
        except Exception as e:  # rosbags raises its own errors, and sqlite3 / yaml ones through it
            hint = ("; a bag cut short (a .bag.active of a recorder that was killed) needs 'rosbag reindex' first"
                    if self.kind == "rosbag1" and "index" in str(e).lower() else "")
            raise RecordingError(f"{self.path}: cannot be read as a {self.name} ({one_line(e)}){hint}") from None
        try:
            connections = list(reader.connections)
            if self.kind == "rosbag1":
                self.store = _ros1_typestore([(c.topic, c.msgtype, getattr(c.msgdef, "data", c.msgdef))
                                              for c in connections])
            number = {id(c): k for k, c in enumerate(connections)}   # the files of a split bag number theirs alike
            for k, c in enumerate(connections):
                encoding = "ros1" if self.kind == "rosbag1" else getattr(c.ext, "serialization_format", "cdr")
                self.channels[k] = _Channel(k, c.msgtype, c.topic, encoding)
            messages = iter(reader.messages())
            while True:
                try:
                    c, timestamp, data = next(messages)
                except StopIteration:
                    break
                except Exception as e:   # rosbags' reading (its own, sqlite3's, the codecs' errors): read up to
                    self.footer, self.broken = False, f"{type(e).__name__}: {one_line(e)}"   # the damage, as an
                    break                                                               # MCAP is (the reader warns)
                self.last_time_ns = timestamp
                yield _Message(number[id(c)], int(timestamp), memoryview(data))
        finally:
            reader.close()

    def decoder(self, channel: _Channel) -> Callable[[memoryview], object]:
        if self.kind == "rosbag1":
            return _ros1_decoder(self.store, channel.schema_name)
        convert, name, store = CONVERTERS[channel.schema_name], channel.schema_name, typestore()
        return lambda data: convert(store.deserialize_cdr(bytes(data), name))


def _ros1_typestore(definitions):
    """The ROS 1 Noetic typestore with the message definitions ((topic, msgtype, text) of a bag's
    connections or an MCAP channel's ros1msg schema) of the types accum reads (Noetic's store lacks
    tf2_msgs; a recording of another distribution carries its own)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    for topic, msgtype, text in definitions:
        if msgtype in CONVERTERS and msgtype not in store.types:
            try:
                store.register(get_types_from_msg(text, msgtype))
            except Exception as e:  # rosbags' parser raises its own error types
                raise RecordingError(f"{topic}: the recording's definition of {msgtype} cannot be parsed "
                                     f"({one_line(e)})") from None
    return store


def mcap_ros1_decoder(channel: _Channel) -> Callable[[memoryview], object]:
    """bytes -> Foxglove protobuf message for an MCAP channel of ROS 1 messages with a ros1msg schema
    (``mcap convert`` of a ROS 1 bag writes them), decoded as a ROS 1 bag's; raises ValueError when the
    schema cannot be used."""
    if channel.schema_encoding != "ros1msg":
        raise ValueError(f"schema encoding {channel.schema_encoding or 'none'!r}, expected ros1msg")
    try:
        store = _ros1_typestore([(channel.topic, channel.schema_name, bytes(channel.schema_data).decode())])
    except (RecordingError, UnicodeDecodeError) as e:
        raise ValueError(f"its ros1msg schema cannot be parsed ({one_line(e)})") from None
    return _ros1_decoder(store, channel.schema_name)


def _ros1_decoder(store, name: str) -> Callable[[memoryview], object]:
    """bytes -> Foxglove protobuf message for ROS 1 messages of type ``name`` in ``store``."""
    convert = CONVERTERS[name]
    return lambda data: convert(store.deserialize_ros1(bytes(data), name))


def propose_topics(channels: dict[str, _Channel], image_types=ROS_IMAGE_TYPES,
                   calibration_types=(ROS_CAMERA_INFO,), raw_image=ROS_IMAGE) -> str | None:
    """'--left-topic ... --right-calibration-topic ...' from the message types, or None.

    Image (or CompressedImage) topics with a CameraInfo topic in their namespace or the one above
    (/cam/left/image_raw or /cam/left/image_raw/compressed with /cam/left/camera_info). Per camera
    the raw image is preferred (accum rectifies), then an uncompressed one, then the shortest name;
    the camera whose namespace names "left" (else the first by name) is the left one. The schema
    names are ROS 2's unless given (a Foxglove recording's: foxglove.RawImage and
    foxglove.CompressedImage with foxglove.CameraCalibration).
    """
    infos = {t.rsplit("/", 1)[0]: t for t, c in channels.items() if c.schema_name in calibration_types}
    cameras: dict[str, list] = {}
    for topic, c in channels.items():
        if c.schema_name not in image_types:
            continue
        ns = topic.rsplit("/", 1)[0]
        owner = ns if ns in infos else ns.rsplit("/", 1)[0] if ns.rsplit("/", 1)[0] in infos else None
        if owner is not None:
            rank = ("image_raw" not in topic, c.schema_name != raw_image, len(topic), topic)
            cameras.setdefault(owner, []).append((rank, topic))
    if len(cameras) < 2:
        return None
    names = sorted(cameras, key=lambda ns: ("left" not in ns.lower(), ns))
    left = names[0]
    right = next((ns for ns in names[1:] if "right" in ns.lower()), names[1])
    pick = {ns: min(cameras[ns])[1] for ns in (left, right)}
    return (f"--left-topic {pick[left]} --right-topic {pick[right]} --left-calibration-topic {infos[left]} "
            f"--right-calibration-topic {infos[right]}")


# -- writing ------------------------------------------------------------------------------------
@dataclass
class RosMessage:
    """A ROS 2 message ready to write: its type name, the rosbags object, and its CDR bytes."""

    msgtype: str
    message: object

    @property
    def cdr(self) -> bytes:
        return bytes(typestore().serialize_cdr(self.message, self.msgtype))


def _header(stamp, frame_id: str):
    T = typestore().types
    return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(stamp.seconds),
                                                                          nanosec=int(stamp.nanos)),
                                    frame_id=frame_id)


def _bytes(data: bytes) -> np.ndarray:
    return np.frombuffer(data, np.uint8)


def ros_from_foxglove(msg) -> RosMessage:
    """The ROS 2 message of a Foxglove protobuf image, calibration or transform(s) message: the inverse
    of the conversions in the module docstring (an unset timestamp becomes a zero stamp)."""
    T = typestore().types
    name = msg.DESCRIPTOR.full_name
    if name == "foxglove.CompressedImage":
        return RosMessage(ROS_COMPRESSED, T[ROS_COMPRESSED](header=_header(msg.timestamp, msg.frame_id),
                                                            format=msg.format, data=_bytes(msg.data)))
    if name == "foxglove.RawImage":
        return RosMessage(ROS_IMAGE, T[ROS_IMAGE](header=_header(msg.timestamp, msg.frame_id), height=msg.height,
                                                  width=msg.width, encoding=msg.encoding, is_bigendian=0,
                                                  step=msg.step, data=_bytes(msg.data)))
    if name == "foxglove.CameraCalibration":
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        R = list(msg.R) if len(msg.R) == 9 else [1.0, 0, 0, 0, 1, 0, 0, 0, 1]
        return RosMessage(ROS_CAMERA_INFO, T[ROS_CAMERA_INFO](
            header=_header(msg.timestamp, msg.frame_id), height=msg.height, width=msg.width,
            distortion_model=msg.distortion_model, d=np.array(msg.D, float), k=np.array(msg.K, float),
            r=np.array(R, float), p=np.array(msg.P, float), binning_x=0, binning_y=0, roi=roi))
    if name in ("foxglove.FrameTransform", "foxglove.FrameTransforms"):
        stamped = []
        for tf in (msg.transforms if name == "foxglove.FrameTransforms" else [msg]):
            t, q = tf.translation, tf.rotation
            stamped.append(T["geometry_msgs/msg/TransformStamped"](
                header=_header(tf.timestamp, tf.parent_frame_id), child_frame_id=tf.child_frame_id,
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=t.x, y=t.y, z=t.z),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=q.x, y=q.y, z=q.z, w=q.w))))
        return RosMessage(ROS_TF, T[ROS_TF](transforms=stamped))
    raise ValueError(f"no ROS 2 message for {name}")


def convert_to_ros2(path: str, writer, topics=None) -> int:
    """Write the calibration, image and transform messages of the protobuf MCAP ``path`` to ``writer``
    (a ``RecordingWriter(..., ros2=True)`` or ``Rosbag2Writer``) as ROS 2 messages, same topics, same
    log times, same bytes of image data; returns the number of messages written. ``topics``: the
    ``reader.Topics`` (default names)."""
    from ..logs import LimitedWarnings
    from .reader import Recording, Topics

    recording = Recording.__new__(Recording)  # only its scan: no validation of what is converted
    recording.path, recording.topics, recording.bag = str(path), topics or Topics(), None
    count = 0
    with LimitedWarnings(log) as warn:
        for topic, log_time, msg in recording._scan(warn, set(recording._roles())):
            writer.ros_message(topic, ros_from_foxglove(msg), log_time)
            count += 1
    return count
