"""ROS 2 recordings in: MCAP with ros2msg/CDR, rosbag2 folders and bare .db3 files give the same models
as the protobuf recording they were converted from."""

from __future__ import annotations

import glob
import shutil

import cv2
import numpy as np
import pytest

from accumcli.errors import RecordingError
from accumcli.model_io import file_kind
from accumcli.extract import ExtractParams
from accumcli.recording import Recording, RecordingWriter, Rosbag2Writer, Topics
from accumcli.recording.mcap_records import _Channel
from accumcli.recording.messages import calibration_from_msg, decode_image
from accumcli.recording.ros2 import (
    ROS_CAMERA_INFO,
    ROS_IMAGE,
    RosMessage,
    convert_to_ros2,
    mcap_cdr_decoder,
    typestore,
)
from accumcli.runs import FrameRange, RecordingOptions, accumulate_recording, describe_recording

from . import helpers

ROS_NAMES = {"/stereo/left/image": "/cam/left/image_raw", "/stereo/right/image": "/cam/right/image_raw",
             "/stereo/left/calibration": "/cam/left/camera_info",
             "/stereo/right/calibration": "/cam/right/camera_info"}
ROS_TOPICS = Topics("/cam/left/image_raw", "/cam/right/image_raw", "/cam/left/camera_info", "/cam/right/camera_info")


class _Renaming:
    """A ROS 2 writer that puts each message on ``names[topic]`` (or ``topic``)."""

    def __init__(self, writer, names):
        self.writer, self.names = writer, names

    def ros_message(self, topic, message, log_time):
        self.writer.ros_message(self.names.get(topic, topic), message, log_time)


def _forms(source: str, directory, names=None) -> dict[str, str]:
    """The protobuf recording ``source`` as ROS 2 MCAP, rosbag2 folder and bare .db3 in ``directory``."""
    names = names or {}
    mcap, folder, bare = directory / "cdr.mcap", directory / "bag", directory / "bare.db3"
    mcap_folder = directory / "mcapbag"
    with RecordingWriter(mcap, ros2=True) as w:
        convert_to_ros2(source, _Renaming(w, names))
    for path, storage in ((folder, "sqlite3"), (mcap_folder, "mcap")):
        with Rosbag2Writer(path, storage) as w:
            convert_to_ros2(source, _Renaming(w, names))
    shutil.copy(glob.glob(str(folder / "*.db3"))[0], bare)
    return {"mcap-cdr": str(mcap), "folder": str(folder), "db3": str(bare), "mcap-folder": str(mcap_folder)}


@pytest.fixture(scope="module")
def ros_forms(small_recording, tmp_path_factory):
    return _forms(small_recording, tmp_path_factory.mktemp("ros2"))


@pytest.fixture(scope="module")
def ros_named_forms(small_recording, tmp_path_factory):
    return _forms(small_recording, tmp_path_factory.mktemp("ros2named"), ROS_NAMES)


def _model_bytes(path, out, options=RecordingOptions()) -> bytes:
    result = accumulate_recording(path, [str(out)], frames=FrameRange(0, 4), options=options)
    assert result.frames == 4
    return out.read_bytes()


def test_ros2_forms_give_byte_identical_models(small_recording, ros_forms, ros_named_forms, tmp_path):
    reference = _model_bytes(small_recording, tmp_path / "protobuf.json")
    assert len(reference) > 1000
    for kind, path in ros_forms.items():
        assert _model_bytes(path, tmp_path / f"{kind}.json") == reference, kind
    ros_options = RecordingOptions(topics=ROS_TOPICS)
    for kind, path in ros_named_forms.items():
        assert _model_bytes(path, tmp_path / f"named-{kind}.json", ros_options) == reference, kind


def test_info_on_each_form(small_recording, ros_forms):
    expected, _ = describe_recording(small_recording)
    for kind, path in ros_forms.items():
        summary, problem = describe_recording(path)
        assert problem is None
        assert summary.stereo_frames == expected.stereo_frames == 6
        assert summary.frames_with_pose == 6 and summary.image_encoding == expected.image_encoding
        assert summary.intrinsics == expected.intrinsics and summary.distortion_model == expected.distortion_model
        types = {topic: schema for topic, schema, _ in summary.topics}
        assert types["/stereo/left/image"] == "sensor_msgs/msg/CompressedImage", kind
        assert types["/stereo/left/calibration"] == ROS_CAMERA_INFO and types["/tf"] == "tf2_msgs/msg/TFMessage"
        assert [n for _, _, n in summary.topics] == [n for _, _, n in expected.topics]


def test_missing_default_topics_propose_the_ros_topics(ros_named_forms):
    """info of a bag with other topic names lists its topics and transforms, then the error with the proposal
    (it printed the error alone)."""
    proposal = ("try --left-topic /cam/left/image_raw --right-topic /cam/right/image_raw "
                "--left-calibration-topic /cam/left/camera_info --right-calibration-topic /cam/right/camera_info")
    for path in ros_named_forms.values():
        summary, problem = describe_recording(path)
        assert isinstance(problem, RecordingError)
        assert "missing topic /stereo/left/image; this recording looks like ROS 2: " + proposal in str(problem)
        assert "/cam/left/camera_info" in str(problem).split("topics found:")[1]
        assert summary.topics_only and ("/cam/left/image_raw", "sensor_msgs/msg/CompressedImage", 6) in summary.topics
        assert summary.tf_frames == ["camera_left", "gripper"]


def test_proposal_prefers_raw_images_and_finds_compressed_ones(tmp_path):
    path = tmp_path / "many.mcap"
    with RecordingWriter(path, ros2=True) as w:
        for side in ("right", "left"):   # right first: the left one is found by its name
            w.calibration(f"/rig/{side}/camera_info", helpers.calibration(side), helpers.T0)
            w.image(f"/rig/{side}/image_rect/compressed", helpers.image(0), helpers.T0, f"camera_{side}")
            w.image(f"/rig/{side}/image_raw/compressed", helpers.image(0), helpers.T0, f"camera_{side}")
        w.image("/mono/image_raw", helpers.image(0), helpers.T0, "mono")   # no CameraInfo sibling
    with pytest.raises(RecordingError, match="try --left-topic /rig/left/image_raw/compressed --right-topic "
                                             "/rig/right/image_raw/compressed --left-calibration-topic "
                                             "/rig/left/camera_info --right-calibration-topic /rig/right/camera_info"):
        Recording(path)


def test_protobuf_recording_gets_no_ros_proposal(tmp_path):
    path = helpers.write(tmp_path / "pb.mcap", skip_topics=("/stereo/left/image",))
    with pytest.raises(RecordingError) as e:
        Recording(path)
    assert "missing topic /stereo/left/image (topics found" in str(e.value) and "ROS 2" not in str(e.value)


def _write_raw_ros(writer, encoding: str, n=3, tf_topic="/tf", pixels=helpers.image):
    """A tiny ROS 2 recording whose images are sensor_msgs/msg/Image in ``encoding`` (written as mono8
    content, ``pixels(i)``, under that name) and with one transform per frame on ``tf_topic`` (one only on
    /tf_static)."""
    from accumcli.recording.messages import image_to_msg
    from accumcli.recording.ros2 import ros_from_foxglove

    for side in ("left", "right"):
        writer.calibration(f"/stereo/{side}/calibration", helpers.calibration(side), helpers.T0)
    for i in range(n):
        t = helpers.T0 + i * helpers.PERIOD
        if tf_topic == "/tf" or i == 0:
            writer.raw_transform("camera_left", "gripper", (0.01 * i, 0.0, 0.5), (0, 0, 0, 1), t, topic=tf_topic)
        for side in ("left", "right"):
            msg = image_to_msg(pixels(i), t, f"camera_{side}", "mono8")
            msg.encoding = encoding
            writer.ros_message(f"/stereo/{side}/image", ros_from_foxglove(msg), t)


@pytest.mark.parametrize("form", ["mcap", "folder"])
def test_bayer_bags_are_demosaiced_and_float_images_refused(tmp_path, form):
    """A Bayer bag opens and reads (it was refused): a grey scene's mosaic is the grey image, which
    demosaicing keeps within 2 levels where it is smooth (colour: test_recording); a 32FC1 (depth) image
    topic is refused when the bag opens, naming the encoding."""
    def smooth(i):
        return cv2.GaussianBlur(helpers.image(i), (0, 0), 3)

    images = {}
    for encoding in ("mono8", "bayer_grbg8", "32FC1"):
        path = tmp_path / (f"{encoding}.mcap" if form == "mcap" else encoding)
        with (RecordingWriter(path, ros2=True) if form == "mcap" else Rosbag2Writer(path)) as w:
            _write_raw_ros(w, encoding, pixels=smooth)
        if encoding == "32FC1":
            with pytest.raises(RecordingError, match="/stereo/left/image: image encoding '32FC1' holds floating"):
                Recording(path)
            continue
        with Recording(path) as rec:
            images[encoding] = [f.left.astype(int) for f in rec.frames()]
    assert len(images["bayer_grbg8"]) == 3
    for mono, bayer in zip(images["mono8"], images["bayer_grbg8"]):
        assert np.abs(mono - bayer)[2:-2, 2:-2].max() <= 2


def test_tf_static_is_static_forever(tmp_path):
    path = tmp_path / "static"
    with Rosbag2Writer(path) as w:
        _write_raw_ros(w, "mono8", n=5, tf_topic="/tf_static")
    with Recording(path) as rec:
        frames = list(rec.frames())
        assert len(frames) == 5
        assert all(f.T_camera_object is not None and f.T_camera_object[2, 3] == 0.5 for f in frames)
        assert rec.pose_at(helpers.T0 + 10**12)[2, 3] == 0.5   # 1000 s later: still the static transform
        assert np.array_equal(frames[1].left.shape, (120, 160))


def _cdr_roundtrip(msgtype: str, message):
    """A ROS message serialised with rosbags and decoded by the MCAP-CDR path (mcap_ros2)."""
    text = typestore().generate_msgdef(msgtype, ros_version=2)[0].encode()
    decode = mcap_cdr_decoder(_Channel(1, msgtype, "/t", "cdr", 1, "ros2msg", text))
    return decode(memoryview(RosMessage(msgtype, message).cdr))


def _ros_image(pixels: np.ndarray, encoding: str, bigendian: bool = False):
    T = typestore().types
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=3, nanosec=5), frame_id="c")
    data = pixels.astype(pixels.dtype.newbyteorder(">" if bigendian else "<")).tobytes()
    return T[ROS_IMAGE](header=header, height=pixels.shape[0], width=pixels.shape[1], encoding=encoding,
                        is_bigendian=int(bigendian), step=len(data) // pixels.shape[0],
                        data=np.frombuffer(data, np.uint8))


def test_image_encodings_through_the_cdr_decoder():
    rng = np.random.default_rng(4)
    rgb = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    grey_of_rgb = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    msg = _cdr_roundtrip(ROS_IMAGE, _ros_image(rgb, "rgb8"))
    assert msg.timestamp.seconds == 3 and msg.timestamp.nanos == 5 and msg.frame_id == "c"
    assert np.array_equal(decode_image(msg), grey_of_rgb)
    assert np.array_equal(decode_image(_cdr_roundtrip(ROS_IMAGE, _ros_image(rgb[:, :, ::-1].copy(), "bgr8"))),
                          grey_of_rgb)
    mono = rng.integers(0, 256, (7, 9), dtype=np.uint8)
    assert np.array_equal(decode_image(_cdr_roundtrip(ROS_IMAGE, _ros_image(mono, "mono8"))), mono)
    deep = mono.astype(np.uint16) * 257   # 16-bit value v*257 scales back to exactly v
    for bigendian in (False, True):
        got = decode_image(_cdr_roundtrip(ROS_IMAGE, _ros_image(deep, "mono16", bigendian)))
        assert np.array_equal(got, mono), bigendian


@pytest.mark.parametrize("model,d", [("plumb_bob", [0.1, -0.05, 0.001, 0.002, 0.01]),
                                     ("rational_polynomial", [0.1, -0.05, 0.001, 0.002, 0.01, 0.3, -0.2, 0.05])])
def test_camera_info_lower_case_fields(model, d):
    T = typestore().types
    K = [500.0, 0, 320, 0, 510, 240, 0, 0, 1]
    R = [1.0, 0, 0, 0, 1, 0, 0, 0, 1]
    P = [505.0, 0, 322, -40.4, 0, 505, 241, 0, 0, 0, 1, 0]
    info = T[ROS_CAMERA_INFO](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="cam"),
        height=480, width=640, distortion_model=model, d=np.array(d), k=np.array(K), r=np.array(R), p=np.array(P),
        binning_x=0, binning_y=0,
        roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
    msg = _cdr_roundtrip(ROS_CAMERA_INFO, info)
    assert not msg.HasField("timestamp")   # a zero stamp: the reader uses the log time
    cal = calibration_from_msg(msg)
    assert (cal.width, cal.height, cal.distortion_model, cal.frame_id) == (640, 480, model, "cam")
    assert np.array_equal(cal.D, d) and np.array_equal(cal.K.ravel(), K) and np.array_equal(cal.P.ravel(), P)


def test_a_topic_with_another_ros_type_is_an_error(tmp_path):
    path = tmp_path / "wrong.mcap"
    with RecordingWriter(path, ros2=True) as w:
        _write_raw_ros(w, "mono8")
        w.calibration("/stereo/left/image", helpers.calibration("left"), helpers.T0 + 10**9)
    with pytest.raises(RecordingError, match="topic /stereo/left/image carries sensor_msgs/msg/CameraInfo"):
        Recording(path)


def test_directory_without_metadata_is_a_clear_error(tmp_path):
    with pytest.raises(RecordingError, match=r"a folder with neither a rosbag2 bag \(metadata.yaml\) nor the .bag files "
                                             "of a split ROS 1 bag"):
        Recording(tmp_path)


def test_unusable_ros2msg_schema_is_a_one_line_error(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "badschema.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema(ROS_CAMERA_INFO, "ros2msg", b"float64[9 k\nnot a field\n")
        channel = w.register_channel("/stereo/left/calibration", "cdr", schema)
        w.add_message(channel, log_time=1, data=b"\x00\x01\x00\x00", publish_time=1)
        w.finish()
    with pytest.raises(RecordingError) as e:
        Recording(path)
    assert "topic /stereo/left/calibration carries sensor_msgs/msg/CameraInfo: its ros2msg schema cannot be " \
           "parsed" in str(e.value) and "\n" not in str(e.value)


def test_damaged_bags_are_one_line_errors(ros_forms, tmp_path):
    folder = tmp_path / "bag"
    shutil.copytree(ros_forms["folder"], folder)
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    with pytest.raises(RecordingError, match="cannot be read as a rosbag2 bag") as e:
        Recording(folder)
    assert "\n" not in str(e.value)
    half = tmp_path / "half.db3"
    data = open(ros_forms["db3"], "rb").read()
    half.write_bytes(data[:len(data) // 2])
    with pytest.raises(RecordingError, match="half.db3: cannot be read as a rosbag2 bag"):
        Recording(half)


def _namespaced_bag(path, static_topic: str | None):
    """A ROS 2 bag whose camera mount (base -> camera_left) is on ``static_topic`` (None: nowhere) and
    whose gripper moves on /robot/tf."""
    from accumcli.recording.messages import image_to_msg
    from accumcli.recording.ros2 import ros_from_foxglove

    with Rosbag2Writer(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", helpers.calibration(side), helpers.T0)
        if static_topic:
            w.raw_transform("base", "camera_left", (0.0, 0.0, -0.5), (0, 0, 0, 1), helpers.T0, topic=static_topic)
        for i in range(3):
            t = helpers.T0 + i * helpers.PERIOD
            w.raw_transform("base", "gripper", (0.01 * i, 0.0, 0.0), (0, 0, 0, 1), t, topic="/robot/tf")
            for side in ("left", "right"):
                w.ros_message(f"/stereo/{side}/image",
                              ros_from_foxglove(image_to_msg(helpers.image(i), t, "camera_left", "mono8")), t)


def test_a_namespaced_transform_tree_is_read_with_its_own_static_topic(tmp_path):
    """--tf-topic /robot/tf reads /robot/tf_static too (--tf-static-topic's default); with the static
    topic left at /tf_static the error names the one the bag has, and without any static transform it
    says that none arrived (a split bag's later file)."""
    from click.testing import CliRunner

    from accumcli.cli import main

    path = tmp_path / "robot"
    _namespaced_bag(path, "/robot/tf_static")
    info = CliRunner().invoke(main, ["info", str(path), "--tf-topic", "/robot/tf"])
    assert info.exit_code == 0 and "poses        gripper in camera_left: 3/3 frames" in info.output, info.output
    with pytest.raises(RecordingError, match="the recording has /robot/tf_static: try --tf-static-topic "
                                             "/robot/tf_static"):
        Recording(path, Topics(tf="/robot/tf"))
    with Recording(path, Topics(tf="/robot/tf", tf_static="/robot/tf_static")) as rec:
        assert [round(f.T_camera_object[2, 3], 6) for f in rec.frames()] == [0.5, 0.5, 0.5]
    bare = tmp_path / "bare"
    _namespaced_bag(bare, None)
    with pytest.raises(RecordingError, match="no transform names 'camera_left', the images' own frame; /tf_static "
                                             "has no message here"):
        Recording(bare, Topics(tf="/robot/tf"))


TF2_MSG = "geometry_msgs/TransformStamped[] transforms"


class _Ros1BagWriter:
    """A ROS 1 bag (rosbags' writer, Noetic types; tf2_msgs/TFMessage from its definition) taking the ROS 2
    messages ``convert_to_ros2`` gives: the same fields, CameraInfo's d, k, r, p as D, K, R, P, headers with
    a seq."""

    def __init__(self, path, **writer_options):
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.store = get_typestore(Stores.ROS1_NOETIC)
        self.store.register(get_types_from_msg(TF2_MSG, "tf2_msgs/msg/TFMessage"))
        self.connections = {}
        self._open(path, **writer_options)

    def _open(self, path, compression=None, chunk_bytes=None):
        from rosbags.rosbag1 import Writer

        self.writer = Writer(path)
        if compression:
            self.writer.set_compression(Writer.CompressionFormat[compression])
        if chunk_bytes:
            self.writer.chunk_threshold = chunk_bytes
        self.writer.open()

    def _ros1(self, value, msgtype):
        cls = self.store.types[msgtype]
        fields = {}
        for name, field in cls.__dataclass_fields__.items():
            if name == "__msgtype__":
                continue
            source = getattr(value, name) if hasattr(value, name) else getattr(value, name.lower(), 0)
            node, detail = dict(self.store.fielddefs[msgtype][1])[name]
            if node == 2:   # a message
                source = self._ros1(source, detail)
            elif node in (3, 4) and detail[0][0] == 2:   # an array or sequence of messages
                source = [self._ros1(v, detail[0][1]) for v in source]
            fields[name] = source
        return cls(**fields)

    def ros_message(self, topic, message, log_time):
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(topic, message.msgtype, typestore=self.store)
        ros1 = self._ros1(message.message, message.msgtype)
        self.writer.write(self.connections[topic], log_time, self.store.serialize_ros1(ros1, message.msgtype))

    def close(self):
        self.writer.close()


class _Ros1McapWriter(_Ros1BagWriter):
    """The same ROS 1 messages in an MCAP file with ros1msg schemas named pkg/Type, as ``mcap convert``
    writes a ROS 1 bag."""

    def _open(self, path):
        from mcap.writer import Writer

        self.file = open(path, "wb")
        self.writer = Writer(self.file)
        self.writer.start()

    def ros_message(self, topic, message, log_time):
        if topic not in self.connections:
            text = self.store.generate_msgdef(message.msgtype, ros_version=1)[0]
            schema = self.writer.register_schema(message.msgtype.replace("/msg/", "/"), "ros1msg", text.encode())
            self.connections[topic] = self.writer.register_channel(topic, "ros1", schema)
        data = self.store.serialize_ros1(self._ros1(message.message, message.msgtype), message.msgtype)
        self.writer.add_message(self.connections[topic], log_time=log_time, data=bytes(data), publish_time=log_time)

    def close(self):
        self.writer.finish()
        self.file.close()


@pytest.mark.parametrize("writer_class", [_Ros1BagWriter, _Ros1McapWriter], ids=["bag", "mcap-ros1"])
def test_ros1_recordings_give_the_protobuf_recordings_model(small_recording, tmp_path, writer_class):
    """A ROS 1 bag (rosbags' rosbag1, sensor_msgs with ROS 1's CameraInfo D, K, R, P, tf2_msgs/TFMessage
    defined by the bag), and the same messages in an MCAP with ros1msg schemas, give the model of the
    protobuf recording they were converted from, byte for byte."""
    path = tmp_path / ("run.bag" if writer_class is _Ros1BagWriter else "run.mcap")
    writer = writer_class(path)
    convert_to_ros2(small_recording, writer)
    writer.close()
    assert _model_bytes(str(path), tmp_path / "ros1.json") == _model_bytes(small_recording, tmp_path / "pb.json")
    summary, problem = describe_recording(str(path))
    assert problem is None and summary.stereo_frames == 6 and summary.frames_with_pose == 6
    assert {schema for _, schema, _ in summary.topics} >= {ROS_CAMERA_INFO, "tf2_msgs/msg/TFMessage"}
    assert file_kind(path) == "recording"   # view took a .bag for "a binary file"


def test_a_ros1_bag_cut_short_asks_for_reindex(small_recording, tmp_path):
    bag = tmp_path / "run.bag"
    writer = _Ros1BagWriter(bag)
    convert_to_ros2(small_recording, writer)
    writer.close()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bag.read_bytes()[:len(bag.read_bytes()) * 2 // 3])
    with pytest.raises(RecordingError, match="cannot be read as a ROS 1 bag .*needs 'rosbag reindex' first"):
        Recording(cut)


def test_a_damaged_ros1_bag_is_read_up_to_the_damage(small_recording, tmp_path, caplog):
    """A bad compressed chunk in the middle of a ROS 1 bag: the frames before it are read, one warning says
    where the damage began (the whole bag was refused)."""
    bag = tmp_path / "run.bag"
    writer = _Ros1BagWriter(bag, compression="BZ2", chunk_bytes=100_000)
    convert_to_ros2(small_recording, writer)
    writer.close()
    data = bytearray(bag.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = bytes(b ^ 0x5A for b in data[middle:middle + 64])
    damaged = tmp_path / "damaged.bag"
    damaged.write_bytes(bytes(data))
    with caplog.at_level("WARNING", logger="accumcli"), Recording(damaged) as rec:
        read = len(list(rec.frames()))
    assert 0 < read < 6
    assert caplog.text.count("damaged bag") == 1 and "the rest is lost" in caplog.text


def test_a_message_compressed_bag_file_and_a_killed_bag_folder_say_what_to_give(tmp_path):
    text = typestore().generate_msgdef(ROS_IMAGE, ros_version=2)[0].encode()
    decode = mcap_cdr_decoder(_Channel(1, ROS_IMAGE, "/t", "cdr", 1, "ros2msg", text))
    with pytest.raises(ValueError, match="zstd-compressed .*give the bag's folder"):
        decode(memoryview(b"\x28\xb5\x2f\xfd" + bytes(20)))
    killed = tmp_path / "killed"
    killed.mkdir()
    (killed / "run_0.db3").write_bytes(b"SQLite format 3\x00")
    with pytest.raises(RecordingError, match="holding run_0.db3: a rosbag2 recording that was killed leaves none: "
                                             "run 'ros2 bag reindex"):
        Recording(killed)


class _BinnedCropped:
    """A ROS 2 writer passing on ``convert_to_ros2``'s messages with every image cut to the sensor region
    ``offset``/``size`` and binned by ``binning`` (averaged), its CameraInfo saying so (K, P and size kept
    as the full sensor's, REP 104)."""

    def __init__(self, writer, binning, offset, size):
        self.writer, self.binning, self.offset, self.size = writer, binning, offset, size

    def ros_message(self, topic, message, log_time):
        m = message.message
        (x0, y0), (w, h), b = self.offset, self.size, self.binning
        if message.msgtype == ROS_CAMERA_INFO:
            m.binning_x = m.binning_y = b
            m.roi.x_offset, m.roi.y_offset, m.roi.width, m.roi.height = x0, y0, w, h
        elif message.msgtype == "sensor_msgs/msg/CompressedImage":
            image = cv2.imdecode(np.frombuffer(bytes(m.data), np.uint8), cv2.IMREAD_GRAYSCALE)[y0:y0 + h, x0:x0 + w]
            image = image.reshape(h // b, b, w // b, b).mean(axis=(1, 3)).round().astype(np.uint8)
            m.format, m.data = "png", np.frombuffer(cv2.imencode(".png", image)[1].tobytes(), np.uint8)
        self.writer.ros_message(topic, message, log_time)


def test_binned_and_cropped_images_use_their_reduced_calibration(raw_recording, tmp_path):
    """A camera publishing a region of its sensor, binned (CameraInfo binning and roi set, K and P the full
    sensor's; raw, distorted images): the frames' intrinsics are those of the images published, and a frame's
    3D segments lie where the full images put them (the images' size disagreed with the calibration: every
    frame refused)."""
    from accumcli.evaluate import _point_edge_distance
    from accumcli.extract import extract_frame

    path = tmp_path / "binned.mcap"
    with RecordingWriter(path, ros2=True) as w:
        convert_to_ros2(raw_recording, _BinnedCropped(w, 2, (80, 60), (480, 360)))
    with Recording(raw_recording) as full, Recording(path) as reduced:
        a, b = next(iter(full.frames(2, 3))), next(iter(reduced.frames(2, 3)))
    assert b.left.shape == (180, 240)
    assert b.intrinsics.fx == pytest.approx(a.intrinsics.fx / 2)
    assert b.intrinsics.cx == pytest.approx((a.intrinsics.cx - 80 - 0.5) / 2)
    assert b.intrinsics.baseline == pytest.approx(a.intrinsics.baseline)
    ours = extract_frame(b, ExtractParams(), "camera_left").segments
    theirs = extract_frame(a, ExtractParams(), "camera_left").segments
    ends = theirs.endpoints()
    off = _point_edge_distance(ours.centers, ends[:, 0], ends[:, 1]).min(axis=1)
    assert len(ours) > 20 and np.median(off) < 0.002   # metres: the same edges, at half the resolution


class _SplitBags:
    """ROS 1 messages written to name_0.bag, name_1.bag, ... in ``folder``, a new file every ``per_file``
    stereo frames' worth of log time, as ``rosbag record --split`` does."""

    def __init__(self, folder, period_ns, frames_per_file):
        self.folder, self.span, self.writers = folder, period_ns * frames_per_file, {}
        self.start = None

    def ros_message(self, topic, message, log_time):
        self.start = log_time if self.start is None else self.start
        part = (log_time - self.start) // self.span
        if part not in self.writers:
            self.writers[part] = _Ros1BagWriter(self.folder / f"run_{part}.bag")
        self.writers[part].ros_message(topic, message, log_time)

    def close(self):
        for w in self.writers.values():
            w.close()


def test_a_split_ros1_bag_is_read_from_its_folder(small_recording, tmp_path, caplog):
    """A folder of a split ROS 1 bag's files (run_0.bag, run_1.bag) is one recording, in time order, and gives
    the protobuf recording's model (only one file could be read, and the hint named the folder in vain);
    rosbag reindex's .orig.bag backup is left out, a .bag.active named in a warning."""
    with Recording(small_recording) as rec:
        times = [f.timestamp_ns for f in rec.frames()]
    folder = tmp_path / "split"
    folder.mkdir()
    writer = _SplitBags(folder, times[1] - times[0], 3)
    convert_to_ros2(small_recording, writer)
    writer.close()
    assert sorted(p.name for p in folder.iterdir()) == ["run_0.bag", "run_1.bag"]
    assert file_kind(folder) == "recording"
    (folder / "run_0.orig.bag").write_bytes((folder / "run_0.bag").read_bytes()[:3000])   # rosbag reindex's backup
    (folder / "run_2.bag.active").write_bytes(b"#ROSBAG V2.0\n")   # a killed recorder's last file
    with caplog.at_level("WARNING", logger="accumcli"):
        assert _model_bytes(str(folder), tmp_path / "split.json") == _model_bytes(small_recording,
                                                                                  tmp_path / "pb.json")
    assert "run_2.bag.active is a recording cut short, not read" in caplog.text
