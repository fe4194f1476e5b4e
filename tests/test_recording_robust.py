"""The reader on damaged and hostile recordings: a RecordingError, a PoseUnavailable or a
warning, never another exception (issue 11). Recordings are built by the fuzzer's builder."""

from __future__ import annotations

import importlib.util
import logging
import re
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform

from accumcli.errors import PoseUnavailable, RecordingError
from accumcli.logs import LimitedWarnings
from accumcli.recording import Recording, TransformTree
from accumcli.recording import tf_tree
from accumcli.recording.messages import DecodeError, decode_image

_spec = importlib.util.spec_from_file_location("fuzz", Path(__file__).parent.parent / "benchmarks" / "fuzz.py")
fuzz = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz)
T0, PERIOD = fuzz.T0, fuzz.PERIOD


@pytest.fixture(autouse=True)
def _warnings(caplog, monkeypatch):
    monkeypatch.setattr(logging.getLogger("accumcli"), "handlers", [])  # the CLI's, if a CLI test ran before
    caplog.set_level(logging.WARNING, logger="accumcli")


def frames_of(path, **kw):
    with Recording(path, **kw) as rec:
        return list(rec.frames())


def chunk_offsets(data: bytes) -> list[int]:
    return [p for p in fuzz.record_offsets(data) if data[p] == 0x06]


# -- 1. MCAP-level damage --------------------------------------------------------------------------
def test_message_on_undefined_channel_is_a_warning(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", chunked=False)
    data = bytearray(Path(path).read_bytes())
    message = [p for p in fuzz.record_offsets(bytes(data)) if data[p] == 0x05][-1]
    data[message + 9:message + 11] = struct.pack("<H", 999)
    Path(path).write_bytes(bytes(data))
    with Recording(path, require_pose=False) as rec:
        rec.info()
    assert f"message at {(T0 + 2 * PERIOD) * 1e-9:.3f} s on undefined channel id 999: skipped" in caplog.text


def test_record_length_beyond_the_file_keeps_what_came_before(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", compression="none", chunk_size=1)
    data = bytearray(Path(path).read_bytes())
    last_chunk = chunk_offsets(bytes(data))[-1]
    data[last_chunk + 1:last_chunk + 9] = struct.pack("<Q", (1 << 64) - 1)
    Path(path).write_bytes(bytes(data))
    frames = frames_of(path)
    assert [f.index for f in frames] == [0, 1]
    assert f"the record at byte {last_chunk} declares {(1 << 64) - 1} bytes" in caplog.text


def test_corrupt_zstd_chunk_is_skipped_with_a_warning(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", chunk_size=1)
    data = bytearray(Path(path).read_bytes())
    chunk = chunk_offsets(bytes(data))[-1]
    start = chunk + 9 + 8 * 3 + 4 + 4 + 4 + 8  # opcode/length, times, size, crc, "zstd", data length
    data[start:start + 4] = b"\x00\x00\x00\x00"
    Path(path).write_bytes(bytes(data))
    assert [f.index for f in frames_of(path)] == [0, 1]
    assert f"chunk at byte {chunk} damaged (zstd data corrupt" in caplog.text


def test_lying_uncompressed_size_is_refused_before_allocation(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", chunk_size=1)
    data = bytearray(Path(path).read_bytes())
    chunk = chunk_offsets(bytes(data))[-1]
    data[chunk + 25:chunk + 33] = struct.pack("<Q", 1 << 62)
    Path(path).write_bytes(bytes(data))
    assert len(frames_of(path)) == 2
    assert f"chunk at byte {chunk} damaged (it declares {1 << 62} uncompressed bytes (limit 256 MiB))" in caplog.text


def test_crc_mismatch_skips_that_chunk_only(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", compression="none", chunk_size=1)
    data = bytearray(Path(path).read_bytes())
    chunk = chunk_offsets(bytes(data))[-2]
    length = struct.unpack_from("<Q", data, chunk + 1)[0]
    data[chunk + 9 + length - 40] ^= 0x01
    Path(path).write_bytes(bytes(data))
    frames = frames_of(path)
    assert len(frames) == 2
    assert f"chunk at byte {chunk} damaged (CRC mismatch): its 1 messages skipped" in caplog.text
    assert caplog.text.count("damaged") == 1


def test_truncated_recording_is_read_as_far_as_it_goes(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", chunk_size=1)
    data = Path(path).read_bytes()
    cut = chunk_offsets(data)[-1] + 20
    Path(path).write_bytes(data[:cut])
    with Recording(path) as rec:
        frames = list(rec.frames())
        info = rec.info()
    assert [f.index for f in frames] == [0, 1]
    lost = cut - chunk_offsets(data)[-1]
    assert (f"truncated recording (no MCAP footer): read up to byte {cut - lost} of {cut}, {lost} bytes lost; "
            f"last message read at {(T0 + 2 * PERIOD) * 1e-9:.3f} s") in caplog.text
    assert "mcap recover" not in caplog.text
    assert info.lost_bytes == lost and info.stereo_frames == 2


def test_nothing_readable_is_a_recording_error(tmp_path):
    path = fuzz.build(tmp_path / "r.mcap", chunk_size=1 << 20)
    data = Path(path).read_bytes()
    (chunk,) = chunk_offsets(data)
    Path(path).write_bytes(data[:chunk + 100])
    with pytest.raises(RecordingError, match=rf"truncated MCAP file: no readable channel in its {chunk + 100} bytes "
                                             rf"\(the record at byte {chunk} declares \d+ bytes, 91 remain\)"):
        Recording(path)


# -- 2, 3. schemas ---------------------------------------------------------------------------------
def test_broken_descriptor_set_does_not_matter(tmp_path):
    path = fuzz.build(tmp_path / "r.mcap", extra=[
        ("/stereo/left/calibration", fuzz.calibration_to_msg(fuzz.calibration("left"), T0), T0,
         "foxglove.CameraCalibration", b"\x0a\xff garbage", "protobuf")])
    assert len(frames_of(path)) == 3


def test_topic_with_the_wrong_message_type(tmp_path):
    path = fuzz.build(tmp_path / "r.mcap", extra=[("/stereo/right/calibration", FrameTransform(), T0 + 1, None,
                                                   None, "protobuf")])
    with pytest.raises(RecordingError, match="topic /stereo/right/calibration carries foxglove.FrameTransform "
                                             r"\(protobuf encoding\), expected protobuf or json foxglove.CameraCalibration or cdr or ros1"):
        frames_of(path)


def test_json_channel_of_other_bytes_is_skipped_with_a_warning(tmp_path, caplog):
    """A JSON channel (Foxglove's JSON encoding is read) whose message is not JSON: skipped, said once."""
    path = fuzz.build(tmp_path / "r.mcap", extra=[("/tf", FrameTransform(child_frame_id="x"), T0, None, None, "json")])
    with caplog.at_level(logging.WARNING, logger="accumcli"):
        assert len(frames_of(path)) == 3
    assert "message on /tf at" in caplog.text and "cannot be decoded" in caplog.text


# -- 4, 5, 7. transforms and time ------------------------------------------------------------------
def tf_samples(quats=None, translations=None, times=None, n=3):
    quats = quats or [(0, 0, 0, 1)] * n
    translations = translations or [(0.01 * i, 0, 0.5) for i in range(n)]
    times = times or [T0 + i * PERIOD for i in range(n)]
    return [("camera_left", "gripper", t, tr, q) for t, tr, q in zip(times, translations, quats)]


def test_huge_finite_quaternion_is_normalised(tmp_path):
    path = fuzz.build(tmp_path / "r.mcap", tf=tf_samples(quats=[(0, 0, 1e200, 1e200)] * 3))
    frames = frames_of(path)
    assert np.allclose(frames[1].T_camera_object[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    assert frames[1].pose_problem is None


@pytest.mark.parametrize("translation, problem", [((1e20, 0, 0), r"invalid translation \(beyond 10000 m\)"),
                                                  ((np.inf, 0, 0), r"invalid translation \(not finite\)")])
def test_far_or_infinite_translation_is_an_invalid_sample(tmp_path, caplog, translation, problem):
    path = fuzz.build(tmp_path / "r.mcap", tf=tf_samples(translations=[(0, 0, 0.5), translation, (0, 0, 0.5)]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frames = frames_of(path)
    assert frames[1].T_camera_object is None
    assert pytest.approx(frames[0].T_camera_object[2, 3]) == 0.5
    assert "at 1750000000.100 s has an invalid translation" in frames[1].pose_problem
    assert len(re.findall(problem, caplog.text)) == 1


def test_timestamps_near_int64_limits(tmp_path, caplog):
    times = [(1 << 63) - 3, (1 << 63) - 2, (1 << 63) - 1]
    path = fuzz.build(tmp_path / "r.mcap", tf=tf_samples(times=times), left_times=times, right_times=times)
    frames = frames_of(path)
    assert [f.timestamp_ns for f in frames] == times
    assert all(f.T_camera_object is not None for f in frames)
    beyond = fuzz.build(tmp_path / "b.mcap", left_times=[T0, 1 << 70, T0 + 2 * PERIOD])
    with Recording(beyond) as rec:
        assert rec.frame_count_hint == 2
    assert f"timestamp {(1 << 70) // 10**9} s is outside the int64 nanosecond range: skipped" in caplog.text


def test_negative_duplicate_and_out_of_order_timestamps(tmp_path, caplog):
    times = [-PERIOD, -2 * PERIOD, -2 * PERIOD]
    tf = tf_samples(times=[-2 * PERIOD, -PERIOD, -2 * PERIOD], translations=[(0, 0, 0.4), (0, 0, 0.6), (0, 0, 0.5)])
    path = fuzz.build(tmp_path / "r.mcap", tf=tf, left_times=times, right_times=times)
    frames = frames_of(path)
    # left and right pair in arrival order; the duplicate pairs with the duplicate, and that frame is
    # skipped (both would be placed by the one pose of that time)
    assert [f.timestamp_ns for f in frames] == times[:2]
    assert "has the stamp of the frame before it" in caplog.text
    # of the two transform samples at -0.2 s the last one received (z = 0.5) holds
    assert [round(f.T_camera_object[2, 3], 9) for f in frames] == [0.6, 0.5]


def test_cycle_in_the_tf_tree_is_a_warning(tmp_path, caplog):
    q = (0, 0, 0, 1)
    tf = [("camera_left", "gripper", T0, (0, 0, 0.5), q), ("gripper", "camera_left", T0, (0, 0, -0.4), q),
          ("world", "gripper", T0, (1, 0, 0), q), ("gripper", "gripper", T0, (0, 0, 0), q)]
    frames = frames_of(fuzz.build(tmp_path / "r.mcap", tf=tf))
    assert len(frames) == 3 and frames[0].T_camera_object[2, 3] == 0.5
    assert "frame 'gripper' has several parents ('camera_left', 'world')" in caplog.text
    assert "frame 'camera_left' has several parents" not in caplog.text
    assert "transform from 'gripper' to itself at 1750000000.000 s: skipped" in caplog.text


def test_tree_lookup_of_static_invalid_sample():
    tree = TransformTree()
    tree.add("a", "b", 0, (0, 0, 0), (0, 0, 0, 0))
    with pytest.raises(PoseUnavailable, match=r"a -> b: the static transform has an invalid quaternion \(zero\)"):
        tree.lookup("a", "b", 5)
    assert not hasattr(tf_tree, "EdgeSamples") and tree._edge(("a", "b")).__class__.__name__ == "TransformSamples"


def test_normalised_quats_without_overflow():
    q = tf_tree.normalised_quats(np.array([[1e308, 1e308, 0, 0], [1e-320, 0, 0, 0], [0, 0, 0, 0.0]]))
    assert np.allclose(q[0], [np.sqrt(0.5), np.sqrt(0.5), 0, 0]) and np.allclose(q[1], [1, 0, 0, 0])
    assert not q[2].any()


# -- 6. calibration --------------------------------------------------------------------------------
def cal_edit(field, value, side="right"):
    def edit(s, msg):
        if s == side:
            if field == "size":
                msg.width, msg.height = value
            elif field in ("width", "height", "distortion_model"):
                setattr(msg, field, value)
            else:
                del getattr(msg, field)[:]
                getattr(msg, field).extend(value)
        return msg
    return edit


@pytest.mark.parametrize("field, value, message", [
    ("width", 65536, r"right calibration: size 65536x120 is outside 1..16384 pixels"),
    ("width", 0, r"right calibration: size 0x120 is outside 1..16384 pixels"),
    ("size", (8192, 4096), r"right calibration: size 8192x4096 exceeds the limit of 8.3 Mpx"),
    ("D", [0.01] * 11, r"right calibration: D has 11 coefficients \(expected 0, 4, 5, 8, 12, 14\)"),
    ("K", [np.nan] + [0.0] * 8, r"right calibration: K holds NaN or infinite values"),
    ("P", [150.0, 0, 80, -12, 0, np.inf, 60, 0, 0, 0, 1, 0], r"right calibration: P holds NaN or infinite"),
    ("R", [0.0] * 9, r"right calibration: R is not a rotation \(R R\^T = I, det \+1\), so the images cannot be"),
    ("R", [1.0, 0, 0, 0, 1, 0, 0, 0, -1], r"right calibration: R is not a rotation"),
    ("K", [150.0, 0, 80, 0, 150, 60, 0, 0, 0], r"right calibration: K \(its 3x3 part\) is singular"),
    ("P", [150.0, 0, 80, -12, 0, 150, 60, 0, 0, 0, 0, 0], r"right calibration: P \(its 3x3 part\) is singular"),
])
def test_calibration_checked_before_any_table(tmp_path, field, value, message):
    path = fuzz.build(tmp_path / "r.mcap", cal_edit=cal_edit(field, value), raw=True)
    with pytest.raises(RecordingError, match=message):
        Recording(path)


@pytest.mark.parametrize("baseline, message", [
    (-0.08, r"right calibration: P\[0,3\] = 12 has the wrong sign \(expected -fx \* baseline < 0, a baseline "
            r"of 0.08 m; are left and right swapped\?\)"),
    (0.0, r"stereo calibration: the baseline is 0 m"),
    (np.nan, r"right calibration: P holds NaN")])
def test_baseline_must_be_finite_and_positive(tmp_path, baseline, message):
    path = fuzz.build(tmp_path / "r.mcap", right_cal=fuzz.calibration("right", baseline=baseline))
    with pytest.raises(RecordingError, match=message):
        Recording(path)


# -- 7, 8. images ------------------------------------------------------------------------------------
def test_lying_png_header_is_refused_before_decoding(tmp_path, caplog, capfd):
    edit = lambda side, i, msg: fuzz.png_with_size(msg, 100000, 100000) if i == 1 else msg  # noqa: E731
    frames = frames_of(fuzz.build(tmp_path / "r.mcap", image_edit=edit))
    assert [f.index for f in frames] == [0, 2]
    assert "frame 1 (1750000000.100 s): image header: size 100000x100000 is outside 1..16384 pixels: skipped" \
        in caplog.text
    assert capfd.readouterr().err == ""


def test_png_bomb_is_refused_by_its_header():
    msg = fuzz.image_to_msg(np.zeros((2, 2), np.uint8), 0, "cam", "png")
    msg.data = fuzz.png_bomb(5000, 5000)
    assert len(msg.data) < 30_000
    with pytest.raises(DecodeError, match=r"image header: size 5000x5000 exceeds the limit of 8.3 Mpx"):
        decode_image(msg)
    msg.data = fuzz.png_bomb(3000, 2000)
    with pytest.raises(DecodeError, match="image size 3000x2000 differs from the calibration's 160x120"):
        decode_image(msg, (160, 120))


def test_image_of_another_size_than_its_calibration(tmp_path, caplog):
    def edit(side, i, msg):
        if side == "left" and i == 0:
            msg.data = fuzz.image_to_msg(np.zeros((60, 80), np.uint8), 0, "cam", "png").data
        return msg
    assert [f.index for f in frames_of(fuzz.build(tmp_path / "r.mcap", image_edit=edit))] == [1, 2]
    assert "frame 0 (1750000000.000 s): image size 80x60 differs from the calibration's 160x120: skipped" \
        in caplog.text


def test_corrupt_png_data_is_a_warning_and_prints_nothing(tmp_path, caplog, capfd):
    def edit(side, i, msg):
        if i == 2:
            data = bytearray(msg.data)
            data[60] ^= 0xFF
            msg.data = bytes(data)
        return msg
    frames = frames_of(fuzz.build(tmp_path / "r.mcap", image_edit=edit))
    assert [f.index for f in frames] == [0, 1]
    assert "frame 2 (1750000000.200 s): cannot decode png image bytes" in caplog.text
    assert "libpng error" in caplog.text
    assert capfd.readouterr().err == ""


def test_compressed_image_that_is_neither_png_nor_jpeg():
    msg = fuzz.image_to_msg(np.zeros((2, 2), np.uint8), 0, "cam", "png")
    msg.data = b"BM" + b"x" * 50
    with pytest.raises(DecodeError, match=r"cannot decode png image bytes \(52 bytes\): neither PNG nor JPEG"):
        decode_image(msg)


def test_jpeg_size_is_read_from_its_header():
    msg = fuzz.image_to_msg(fuzz.scene(0, "left"), 0, "cam", "jpeg")
    with pytest.raises(DecodeError, match="image size 160x120 differs from the calibration's 161x120"):
        decode_image(msg, (161, 120))
    assert decode_image(msg, (160, 120)).shape == (120, 160)


# -- 5, 6. no silent empty results; no object frame ---------------------------------------------------
def test_no_stereo_pair_names_the_offset_and_the_tolerance(tmp_path):
    path = fuzz.build(tmp_path / "r.mcap", right_times=[T0 + i * PERIOD + 5_000_000 for i in range(3)])
    with pytest.raises(RecordingError, match=r"no stereo pair within 1.0 ms: left and right images are 5.0 ms apart; "
                                             r"try --tolerance-ms 6"):
        Recording(path)
    with Recording(path, tolerance_ns=6_000_000) as rec:
        assert len(list(rec.frames())) == 3
        assert rec.info().stereo_offset_ms == pytest.approx(5.0)


def test_the_proposed_tolerance_pairs_cameras_whose_offset_varies(tmp_path):
    """Right images 3 to 5.5 ms after the left (no hardware sync): the proposal covers the largest
    offsets, not the median (which proposed 5 ms and left a quarter of the images unpaired)."""
    offsets = [3_000_000 + (i % 6) * 500_000 for i in range(12)]
    path = fuzz.build(tmp_path / "r.mcap", n=12, right_times=[T0 + i * PERIOD + d for i, d in enumerate(offsets)])
    with pytest.raises(RecordingError, match=r"try --tolerance-ms 6$"):
        Recording(path)
    with Recording(path, tolerance_ns=6_000_000) as rec:
        assert len(list(rec.frames())) == 12 and rec.info().unpaired_images == 0



def test_a_dropped_partner_does_not_stretch_the_proposed_tolerance():
    """At 30 frames/s with a tenth of the left images dropped, their right partners measure the 33 ms
    to the next left image: the proposal stays at the cameras' own 3 to 5.5 ms (it proposed 30)."""
    from accumcli.recording.reader import _Pairing

    pairing = _Pairing("/left", 1_000_000, lambda *args: None)
    pairing.offsets = [3_000_000 + (i % 6) * 500_000 for i in range(270)] + [28_000_000] * 30
    pairing.left_gaps = [33_333_333] * 100
    assert pairing.covering_tolerance_ms == 6
    pairing.offsets = [0] * 60 + [3_000_000] * 40   # synchronised cameras and a jitter of 3 ms: 4, not 1
    assert pairing.covering_tolerance_ms == 4


def test_unpaired_warnings_are_summarised(tmp_path, caplog):
    n = 12
    right = [T0 + i * PERIOD + (20_000_000 if i % 2 else 0) for i in range(n)]
    frames = frames_of(fuzz.build(tmp_path / "r.mcap", n=n, right_times=right,
                                  tf=tf_samples(n=n)))
    assert len(frames) == 6
    assert caplog.text.count("has no partner") == 5
    assert "... and 7 more such warnings (unpaired image)" in caplog.text


def test_limited_warnings(caplog):
    logger = logging.getLogger("accumcli")
    with LimitedWarnings(logger, limit=2, prefix="rec: ") as warn:
        for i in range(5):
            warn("kind a", "a %d", i)
        warn("kind b", "b")
        assert warn.suppressed() == 3
    assert [r.getMessage() for r in caplog.records] == ["a 0", "a 1", "b", "rec: ... and 3 more such warnings (kind a)"]


def test_without_the_object_frame_frames_carry_no_pose(tmp_path):
    path = fuzz.build(tmp_path / "r.mcap", tf=[("world", "board", T0, (0, 0, 1), (0, 0, 0, 1))])
    with pytest.raises(RecordingError, match="no transform path from 'camera_left' to 'gripper'"):
        Recording(path)
    frames = frames_of(path, require_pose=False)
    assert len(frames) == 3 and all(f.T_camera_object is None for f in frames)
    assert frames[0].pose_problem == "no path from camera_left to gripper in the transform tree"


def test_info_counts_do_not_depend_on_earlier_passes(tmp_path):
    path = fuzz.build(tmp_path / "r.mcap", n=4, tf=tf_samples(n=4))
    with Recording(path) as rec:
        next(rec.frames())
        info = rec.info()
    assert dict((t, c) for t, _, c in info.topics) == {
        "/stereo/left/calibration": 1, "/stereo/left/image": 4, "/stereo/right/calibration": 1,
        "/stereo/right/image": 4, "/tf": 4}
    assert info.stereo_frames == 4 and info.stereo_offset_ms == 0.0 and info.lost_bytes == 0


def test_an_image_topic_without_readable_images(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", compression="none", chunk_size=1)
    data = bytearray(Path(path).read_bytes())
    for chunk in chunk_offsets(bytes(data))[-5::2]:  # the chunks of the three right images
        data[chunk + 9 + struct.unpack_from("<Q", data, chunk + 1)[0] - 40] ^= 0x01
    Path(path).write_bytes(bytes(data))
    with pytest.raises(RecordingError, match=r"r.mcap: no readable image on /stereo/right/image$"):
        Recording(path, require_pose=False)
    assert caplog.text.count("(CRC mismatch): its 1 messages skipped") == 3


def test_no_pair_because_the_images_of_one_camera_do_not_parse(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", image_edit=lambda side, i, msg: b"\xff\xff" if side == "left" else msg)
    with pytest.raises(RecordingError, match="no stereo pair: the images of one camera cannot be read"):
        Recording(path, require_pose=False)
    assert caplog.text.count("message on /stereo/left/image at") == 3


def test_no_pair_because_one_camera_cannot_be_read(tmp_path, caplog):
    path = fuzz.build(tmp_path / "r.mcap", right_times=[1 << 70] * 3)
    with pytest.raises(RecordingError, match="no stereo pair: the images of one camera cannot be read"):
        Recording(path)
    assert caplog.text.count("outside the int64 nanosecond range") == 3


def test_a_record_longer_than_any_chunk_is_not_read(tmp_path, caplog, monkeypatch):
    from accumcli.recording import mcap_records
    path = fuzz.build(tmp_path / "r.mcap", chunk_size=1)
    first = chunk_offsets(Path(path).read_bytes())[0]
    monkeypatch.setattr(mcap_records, "MAX_RECORD_BYTES", 100)  # the chunks (and schemas) are now "too long"
    with pytest.raises(RecordingError, match="topic /stereo/left/image carries no schema, expected"):
        Recording(path)
    assert re.search(rf"record at byte {first} declares \d+ bytes \(limit 100\): skipped", caplog.text)


def test_unreadable_file(tmp_path, monkeypatch):
    from accumcli.recording import reader
    path = fuzz.build(tmp_path / "r.mcap")

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")
    monkeypatch.setattr(reader, "open", denied, raising=False)
    with pytest.raises(RecordingError, match=r"r.mcap: cannot be read \(Permission denied\)$"):
        Recording(path)


def test_corrupt_jpeg_that_still_decodes_is_refused_and_prints_nothing(capfd):
    msg = fuzz.image_to_msg(fuzz.scene(0, "left"), 0, "cam", "jpeg")
    data = bytearray(msg.data)
    data[335] ^= 0x55  # libjpeg: "Corrupt JPEG data: premature end of data segment", yet an image, part grey
    msg.data = bytes(data)
    with pytest.raises(DecodeError, match="damaged jpeg image data"):   # it was used: edges that are not there
        decode_image(msg, (160, 120))
    assert capfd.readouterr().err == ""


def test_a_repeated_image_stamp_is_skipped_with_a_warning(tmp_path, caplog):
    """Two frames with one stamp would both be placed by the pose of that time (a driver that repeats
    a stamp put a frame at its neighbour's pose without a word)."""
    from accumcli.recording import Recording, RecordingWriter

    from .helpers import T0, calibration, image

    path = tmp_path / "dup.mcap"
    with RecordingWriter(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", calibration(side), T0)
        stamps = [T0, T0 + 100_000_000, T0 + 100_000_000, T0 + 200_000_000]
        for j, t in enumerate(stamps):
            w.raw_transform("camera_left", "gripper", (0.01 * j, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0), t)
            w.image("/stereo/left/image", image(j), t, "camera_left")
            w.image("/stereo/right/image", image(j + 100), t, "camera_right")
    with Recording(path) as rec:
        frames = list(rec.frames())
    assert [f.timestamp_ns for f in frames] == [T0, T0 + 100_000_000, T0 + 200_000_000]
    assert "has the stamp of the frame before it" in caplog.text and "skipped" in caplog.text


def test_tracking_starts_at_the_first_frame_with_a_recorded_pose(tmp_path):
    """Transforms that begin after the images (tf started late): the frames before them are 'lost' with
    the reason and tracking starts at the first with a pose (it refused the run, asking for --init);
    with no pose anywhere the run is refused in one line."""
    from accumcli.errors import AccumError
    from accumcli.model_io import read_poses, write_model
    from accumcli.runs import track_recording
    from accumcli.segments import Segments

    model = tmp_path / "m.json"
    write_model(model, Segments("gripper", np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]]),
                                np.eye(3), np.full(3, 0.01), np.ones(3), np.full(3, 3, np.int64)))
    late = fuzz.build(tmp_path / "late.mcap", n=5,
                      tf=[("camera_left", "gripper", T0 + i * PERIOD, (0, 0, 0.5), (0, 0, 0, 1)) for i in (2, 3, 4)])
    track_recording(str(model), str(late), [str(tmp_path / "p.json")], reacquire=False)
    poses = read_poses(str(tmp_path / "p.json"))
    assert len(poses.status) == 5 and list(poses.status[:2]) == ["lost", "lost"]
    reasons = [row.get("reason", "") for row in poses.extra[:2]]
    assert all(r.startswith("no recorded pose to start from") for r in reasons), reasons
    none = fuzz.build(tmp_path / "none.mcap", n=3, tf=[("camera_left", "gripper", T0 + i * PERIOD, (0, 0, 0.5),
                                                         (0, 0, 0, 1)) for i in (10, 11)])   # after every frame
    with pytest.raises(AccumError, match="no frame has a recorded pose to start from .*; give one with --init"):
        track_recording(str(model), str(none), [str(tmp_path / "q.json")], reacquire=False)
