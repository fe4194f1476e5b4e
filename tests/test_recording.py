"""The recording reader against simulated ground truth and hand-broken files."""

from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest

from accumcli.errors import RecordingError
from accumcli.geometry import make_transform, transform_from_quat, transform_points
from accumcli.model_io import read_truth
from accumcli.recording import Recording, RecordingWriter, TransformTree
from accumcli.recording.calibration import CameraCalibration, check_calibration
from accumcli.recording.messages import RAW_ENCODINGS, decode_image, image_to_msg
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from . import helpers


def _truth_of(path):
    return read_truth(path.replace(".mcap", ".truth.json"))


@pytest.mark.parametrize("fixture", ["small_recording", "tf_tree_recording", "raw_recording"])
def test_poses_match_truth(fixture, request):
    path = request.getfixturevalue(fixture)
    truth = _truth_of(path)
    with Recording(path) as rec:
        frames = list(rec.frames())
    assert len(frames) == len(truth.poses)
    for frame in frames:
        assert np.abs(frame.T_camera_object - truth.pose_at(frame.timestamp_ns)).max() < 1e-9


def edge_offsets(image: np.ndarray, uv: np.ndarray, normals: np.ndarray, reach: int = 3) -> np.ndarray:
    """Distance (px) from each point to the strongest gradient along its normal, for well-defined edges."""
    gx = cv2.Sobel(image.astype(np.float32), cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(image.astype(np.float32), cv2.CV_32F, 0, 1, ksize=3)
    steps = np.arange(-reach, reach + 1, dtype=np.float32)
    px = (uv[:, :1] + steps * normals[:, :1]).astype(np.float32)
    py = (uv[:, 1:] + steps * normals[:, 1:]).astype(np.float32)
    sx = cv2.remap(gx, px, py, cv2.INTER_LINEAR)
    sy = cv2.remap(gy, px, py, cv2.INTER_LINEAR)
    along = np.abs(sx * normals[:, :1] + sy * normals[:, 1:])
    best = np.argmax(along, axis=1)
    strong = (along.max(axis=1) > 40) & (best > 0) & (best < len(steps) - 1)
    i = np.arange(len(uv))[strong]
    b = best[strong]
    m0, m1, m2 = along[i, b - 1], along[i, b], along[i, b + 1]
    offset = steps[b] + 0.5 * (m0 - m2) / np.where(m0 - 2 * m1 + m2 == 0, -1, m0 - 2 * m1 + m2)
    return np.abs(offset)


def mean_truth_edge_offset(path: str) -> float:
    truth = _truth_of(path)
    offsets = []
    with Recording(path) as rec:
        for frame in rec.frames():
            T = frame.T_camera_object
            for a, b in zip(truth.a, truth.b):
                n = max(2, int(np.linalg.norm(b - a) / 0.003))
                s = (np.arange(n) + 0.5) / n
                points = transform_points(T, a + s[:, None] * (b - a))
                uv_l, uv_r, z = frame.intrinsics.project(points)
                for uv, img in ((uv_l, frame.left), (uv_r, frame.right)):
                    d = uv[-1] - uv[0]
                    normal = np.array([-d[1], d[0]]) / (np.hypot(*d) + 1e-12)
                    inside = (uv[:, 0] > 5) & (uv[:, 0] < img.shape[1] - 6) & (uv[:, 1] > 5) & \
                             (uv[:, 1] < img.shape[0] - 6)
                    if inside.sum():
                        offsets.append(edge_offsets(img, uv[inside], np.tile(normal, (inside.sum(), 1))))
    return float(np.mean(np.concatenate(offsets)))


@pytest.mark.parametrize("raw", ["raw_recording", "fisheye_recording"])
def test_raw_images_are_rectified_onto_the_truth(raw, small_recording, request):
    """plumb_bob, and the fisheye model (ROS's equidistant), rectified onto the truth's edges within half
    a pixel on average (the fisheye images rectified as if they were pinhole ones: 0.75 px)."""
    offset = mean_truth_edge_offset(request.getfixturevalue(raw))
    rectified = mean_truth_edge_offset(small_recording)
    print(f"mean truth-edge offset: {raw} {offset:.3f} px, rectified {rectified:.3f} px")
    assert offset < 0.5
    assert rectified < 1.0


def test_a_fisheye_calibration_is_never_taken_as_rectified():
    """theta is not tan(theta): with D zero a fisheye image is still distorted; and the model takes 4
    coefficients under any of its names."""
    K = np.array([[400.0, 0, 319.5], [0, 400.0, 239.5], [0, 0, 1]])
    P = np.hstack([K, np.zeros((3, 1))])
    for name in ("equidistant", "kannala_brandt", "fisheye"):
        cal = CameraCalibration(640, 480, K, np.zeros(4), np.eye(3), P, name, "camera_left")
        assert not cal.is_rectified
        check_calibration(cal, "left")
    assert CameraCalibration(640, 480, K, np.zeros(5), np.eye(3), P, "plumb_bob", "camera_left").is_rectified
    with pytest.raises(RecordingError, match="takes 4 coefficients k1..k4, D has 5"):
        check_calibration(CameraCalibration(640, 480, K, np.zeros(5), np.eye(3), P, "equidistant", "c"), "left")
    with pytest.raises(RecordingError, match="'fisheye62' is not supported .*rectify the images first"):
        check_calibration(CameraCalibration(640, 480, K, np.zeros(6), np.eye(3), P, "fisheye62", "c"), "left")


def test_rectification_maps_are_computed_once(raw_recording):
    with Recording(raw_recording) as rec:
        assert sum(1 for _ in rec.frames()) == 4
        assert len(rec._rectifiers) == 1
        assert not next(iter(rec._rectifiers.values())).rectified_input


def test_transform_tree_chain_and_interpolation():
    tree = TransformTree()
    T_world_camera = make_transform(np.eye(3), [1.0, 2.0, 3.0])
    tree.add("world", "camera", 0, [1.0, 2.0, 3.0], [0, 0, 0, 1], static=True)
    tree.add("world", "arm", 0, [0.0, 0.0, 0.0], [0, 0, 0, 1])
    q90 = [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    tree.add("world", "arm", 1000, [0.0, 0.0, 1.0], q90)
    tree.add("arm", "gripper", 5, [0.1, 0.0, 0.0], [0, 0, 0, 1])  # single sample: static
    T = tree.lookup("camera", "gripper", 500)
    q45 = [0, 0, np.sin(np.pi / 8), np.cos(np.pi / 8)]
    expected = np.linalg.inv(T_world_camera) @ transform_from_quat([0, 0, 0.5], q45) @ \
        make_transform(np.eye(3), [0.1, 0, 0])
    assert np.abs(T - expected).max() < 1e-12
    with pytest.raises(Exception, match="outside the transform samples"):
        tree.lookup("camera", "gripper", 5000, tolerance_ns=10)
    assert tree.path("camera", "nowhere") is None


def test_image_rect_topics_are_not_rectified_again(tmp_path, caplog):
    """ROS's image_rect beside the raw camera's camera_info (D and R not identity): the images are
    used as they are, with P; any other topic name is rectified with the calibration."""
    import dataclasses

    from accumcli.recording import Topics
    from accumcli.recording.calibration import StereoRectifier
    from accumcli.recording.reader import _is_rect_topic

    from . import helpers

    raw = [dataclasses.replace(helpers.calibration(side), D=np.array([0.1, 0, 0, 0, 0.0])) for side in ("left", "right")]
    left, right = helpers.image(1), helpers.image(2)
    as_given = StereoRectifier(*raw, images_rectified=True).rectify(left, right)
    assert as_given[0] is left and as_given[1] is right
    assert not np.array_equal(StereoRectifier(*raw).rectify(left, right)[0], left)
    assert _is_rect_topic("/cam/left/image_rect") and _is_rect_topic("/cam/left/image_rect_color/compressed")
    assert not _is_rect_topic("/cam/left/image_raw") and not _is_rect_topic("/stereo/left/image")
    path = helpers.one_pair(tmp_path / "rect.mcap", image_topic="/cam/{side}/image_rect",
                            calibration_topic="/cam/{side}/camera_info", calibrations=raw)
    topics = Topics(left_image="/cam/left/image_rect", right_image="/cam/right/image_rect",
                    left_calibration="/cam/left/camera_info", right_calibration="/cam/right/camera_info")
    with caplog.at_level("WARNING", logger="accumcli"), Recording(path, topics) as rec:
        frame = next(rec.frames())
    assert np.array_equal(frame.left, helpers.image(0))
    assert "is a rectified image topic (ROS's image_rect): its images are used as they are" in caplog.text


def test_images_without_a_stamp_are_read_at_their_log_time_with_a_warning(tmp_path, caplog):
    from accumcli.recording.messages import image_to_msg

    from . import helpers

    path = tmp_path / "unstamped.mcap"
    with RecordingWriter(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", helpers.calibration(side), helpers.T0)
        w.raw_transform("camera_left", "gripper", (0.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0), helpers.T0)
        for side in ("left", "right"):
            msg = image_to_msg(helpers.image(0), helpers.T0, f"camera_{side}", "png")
            msg.ClearField("timestamp")
            w._writer.write_message(f"/stereo/{side}/image", msg, log_time=helpers.T0, publish_time=helpers.T0)
    with caplog.at_level("WARNING", logger="accumcli"), Recording(path) as rec:
        assert next(rec.frames()).timestamp_ns == helpers.T0
    assert "1 image(s) on /stereo/left/image carry no time stamp (header.stamp zero): their log times" in caplog.text


def test_a_baseline_in_other_units_than_metres_is_warned_of(tmp_path, caplog):
    from . import helpers

    # the right P[0,3] from a baseline of 80 (mm) instead of 0.08 (m)
    path = helpers.one_pair(tmp_path / "mm.mcap", calibrations=[helpers.calibration(s, baseline=80.0)
                                                                for s in ("left", "right")])
    with caplog.at_level("WARNING", logger="accumcli"), Recording(path) as rec:
        next(rec.frames())
    assert "the stereo baseline is 80 m: the right P[0,3] must be -fx times the baseline in metres" in caplog.text


def test_the_writer_refuses_what_it_would_write_wrongly(tmp_path):
    from accumcli.errors import InputError
    from accumcli.recording import CameraCalibration

    from . import helpers

    with RecordingWriter(tmp_path / "w.mcap") as w:
        for call, message in (
                (lambda: w.image("/i", None, helpers.T0, "c"), "found None \\(did the image load\\?\\)"),
                (lambda: w.image("/i", helpers.image(0) / 255.0, helpers.T0, "c"), "uint8 image \\(8 bits"),
                (lambda: w.image("/i", helpers.image(0), helpers.T0, "c", "jpg"), "encoding 'jpg': expected png"),
                (lambda: w.transform("a", "b", np.eye(3), helpers.T0), "T a -> b"),
                (lambda: w.transform("a", "b", np.diag([2.0, 2, 2, 1]), helpers.T0), "T a -> b"),
                (lambda: w.image("/i", helpers.image(0), 1.75e18, "c"), "expected whole nanoseconds"),
                (lambda: w.image("/i", helpers.image(0), -1, "c"), "expected whole nanoseconds")):
            with pytest.raises(InputError, match=message):
                call()
        w.image("/i", helpers.image(0), np.int64(helpers.T0), "c")   # numpy integers are whole nanoseconds
    listed = CameraCalibration(160, 120, np.eye(3).tolist(), [0, 0, 0, 0, 0], np.eye(3).tolist(),
                               np.zeros((3, 4)).tolist(), "plumb_bob", "c")
    assert listed.K.shape == (3, 3) and listed.D.dtype == float
    with pytest.raises(InputError, match="P must be a 3x4 matrix"):
        CameraCalibration(160, 120, np.eye(3), np.zeros(5), np.eye(3), np.zeros((3, 3)), "plumb_bob", "c")


def test_a_gap_in_the_transform_stream_is_not_interpolated():
    tree = TransformTree()
    period = 33_000_000                      # 30 Hz, silent from 1.0 s to 2.2 s
    times = [k * period for k in range(31)] + [2_200_000_000 + k * period for k in range(30)]
    for t in times:
        tree.add("camera", "gripper", t, [0.0, 0.0, 0.5 + t * 1e-10], [0, 0, 0, 1])
    assert abs(tree.lookup("camera", "gripper", 500_000_000)[2, 3] - 0.55) < 1e-9      # between neighbours
    with pytest.raises(Exception, match=r"falls in a gap of the transform samples \(\[0.990, 2.200\] s, "
                                        r"their median spacing 0.033 s\)"):
        tree.lookup("camera", "gripper", 1_600_000_000)
    slow = TransformTree()                    # a slow stream is no gap: 5 Hz, one sample missing
    for t in [0, 200_000_000, 600_000_000, 800_000_000]:
        slow.add("camera", "gripper", t, [0.0, 0.0, 0.5], [0, 0, 0, 1])
    assert slow.lookup("camera", "gripper", 400_000_000)[2, 3] == 0.5


@pytest.mark.parametrize("encoding", ["mono8", "rgb8", "bgr8", "mono16", "png", "jpeg"])
def test_image_decoding(encoding):
    grey = helpers.image(3)
    if encoding in ("png", "jpeg"):
        msg = image_to_msg(grey, 0, "cam", encoding)
    else:
        data = {"mono8": grey, "rgb8": np.dstack([grey] * 3), "bgr8": np.dstack([grey] * 3),
                "mono16": grey.astype("<u2") * 257}[encoding]
        msg = RawImage(width=grey.shape[1], height=grey.shape[0], encoding=encoding,
                       step=data.strides[0], data=data.tobytes())
    decoded = decode_image(msg)
    assert decoded.shape == grey.shape and decoded.dtype == np.uint8
    tolerance = 30 if encoding == "jpeg" else 1
    assert np.abs(decoded.astype(int) - grey).mean() < tolerance


def _colour_image() -> np.ndarray:
    """(40, 60, 3) uint8 BGR, smooth and strongly coloured: red and blue swapped change its grey by 20 levels."""
    y, x = np.mgrid[0:40, 0:60]
    return np.dstack([10 + x // 4, 50 + y, 200 - x]).astype(np.uint8)


def _packed(bgr: np.ndarray, encoding: str) -> np.ndarray:
    """``bgr`` laid out as a raw image of ``encoding``: (H, W, channels) or (H, W)."""
    rgb = bgr[:, :, ::-1]
    if encoding.startswith("bayer_"):   # ROS's name: the first row's two filters, then the second row's
        mosaic = np.zeros(bgr.shape[:2], np.uint8)
        for k, colour in enumerate(encoding[6:10]):
            dy, dx = divmod(k, 2)
            mosaic[dy::2, dx::2] = rgb[dy::2, dx::2, "rgb".index(colour)]
        return mosaic if encoding.endswith("8") else mosaic.astype("<u2") * 257
    if encoding in ("uyvy", "yuv422", "yuyv", "yuv422_yuy2"):
        yuv = cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV).astype(int)
        u = (yuv[:, 0::2, 1] + yuv[:, 1::2, 1]) // 2
        v = (yuv[:, 0::2, 2] + yuv[:, 1::2, 2]) // 2
        y0, y1 = yuv[:, 0::2, 0], yuv[:, 1::2, 0]
        pairs = [u, y0, v, y1] if encoding in ("uyvy", "yuv422") else [y0, u, y1, v]
        return np.stack(pairs, axis=2).reshape(bgr.shape[0], bgr.shape[1], 2).astype(np.uint8)
    order = {"rgb": rgb, "bgr": bgr, "8UC": bgr}[encoding[:3]]
    if "a" in encoding[3:] or encoding == "8UC4":
        order = np.dstack([order, np.full(bgr.shape[:2], 255, np.uint8)])
    return order.astype("<u2") * 257 if encoding.endswith("16") else order


@pytest.mark.parametrize("encoding", [e for e in RAW_ENCODINGS if not e.startswith(("mono", "8UC1", "16UC1"))])
def test_colour_bayer_and_yuv_images_become_their_grey(encoding):
    """Every raw encoding read gives the grey OpenCV gives the colour image (within a grey level, 2 px
    inside for Bayer, demosaiced): a Bayer pattern read with its red and blue swapped is 20 levels off."""
    bgr = _colour_image()
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(int)
    data = _packed(bgr, encoding)
    msg = RawImage(width=bgr.shape[1], height=bgr.shape[0], encoding=encoding, step=data.strides[0],
                   data=data.tobytes())
    error = np.abs(decode_image(msg).astype(int) - grey)
    assert error[2:-2, 2:-2].max() <= 1
    if encoding.startswith("bayer_"):
        msg.encoding = "bayer_" + encoding[6:].translate(str.maketrans("rb", "br"))
        assert np.abs(decode_image(msg).astype(int) - grey)[2:-2, 2:-2].max() > 10


def test_a_compressed_bayer_mosaic_is_demosaiced():
    """ROS's compressed transport keeps a Bayer mosaic as a one-channel PNG, its format naming the pattern."""
    bgr = _colour_image()
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(int)
    png = cv2.imencode(".png", _packed(bgr, "bayer_gbrg8"))[1].tobytes()
    msg = CompressedImage(format="bayer_gbrg8; png compressed ", data=png)
    assert np.abs(decode_image(msg).astype(int) - grey)[2:-2, 2:-2].max() <= 1
    msg.format = "png"   # read as grey, the mosaic's filters are a grid of edges
    assert np.abs(decode_image(msg).astype(int) - grey)[2:-2, 2:-2].max() > 50


@pytest.mark.parametrize("encoding, said", [("32FC1", "floating-point values"), ("nv12", "is not supported")])
def test_unreadable_encodings_are_refused_when_the_recording_opens(tmp_path, encoding, said):
    path = tmp_path / "r.mcap"
    with RecordingWriter(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", helpers.calibration(side), helpers.T0)
            msg = image_to_msg(helpers.image(0), helpers.T0, f"camera_{side}", "mono8")
            msg.encoding = encoding
            w.message(f"/stereo/{side}/image", msg, helpers.T0)
        w.raw_transform("camera_left", "gripper", (0.0, 0.0, 0.5), (0, 0, 0, 1), helpers.T0)
    with pytest.raises(RecordingError, match=f"/stereo/left/image: image encoding '{encoding}' .*{said}"):
        Recording(path)


@pytest.mark.parametrize("bits, full_scale", [(10, 1023), (12, 4095), (16, 65535)])
def test_sixteen_bit_images_are_scaled_by_the_bits_they_use(bits, full_scale):
    from accumcli.recording.messages import sixteen_bit_full_scale

    grey = helpers.image(3)
    data = (grey.astype("<u2") << (bits - 8)) | ((1 << (bits - 8)) - 1)   # 10, 12 or 16 bits in mono16
    msg = RawImage(width=grey.shape[1], height=grey.shape[0], encoding="mono16", step=data.strides[0],
                   data=data.tobytes())
    assert sixteen_bit_full_scale(msg) == full_scale
    assert np.abs(decode_image(msg, full_scale=full_scale).astype(int) - grey).max() <= 1
    assert sixteen_bit_full_scale(image_to_msg(grey, 0, "cam", "png")) is None
    rgba = np.dstack([data.reshape(grey.shape)] * 3 + [np.full(grey.shape, 65535, "<u2")])   # opaque alpha
    assert sixteen_bit_full_scale(RawImage(width=grey.shape[1], height=grey.shape[0], encoding="rgba16",
                                           step=rgba.strides[0], data=rgba.tobytes())) == full_scale
    png = CompressedImage(format="png", data=cv2.imencode(".png", data.reshape(grey.shape))[1].tobytes())
    assert sixteen_bit_full_scale(png) == full_scale   # a 16-bit PNG of the same data (an empty model before)
    assert np.abs(decode_image(png, full_scale=full_scale).astype(int) - grey).max() <= 1


def test_corrupt_frame_is_skipped_with_a_warning(tmp_path, caplog):
    path = helpers.write(tmp_path / "corrupt.mcap", n=5, corrupt_left=(2,))
    with caplog.at_level(logging.WARNING), Recording(path) as rec:
        indices = [f.index for f in rec.frames()]
    assert indices == [0, 1, 3, 4]
    assert "frame 2" in caplog.text and "cannot decode" in caplog.text


def test_unpaired_image_is_skipped_never_paired_wrongly(tmp_path, caplog):
    path = helpers.write(tmp_path / "unpaired.mcap", n=5, unpaired_right=(1,))
    with caplog.at_level(logging.WARNING), Recording(path) as rec:
        frames = list(rec.frames())
    assert [f.timestamp_ns for f in frames] == [helpers.T0 + i * helpers.PERIOD for i in (0, 2, 3, 4)]
    for f in frames:
        i = (f.timestamp_ns - helpers.T0) // helpers.PERIOD
        assert np.array_equal(f.left, helpers.image(i)) and np.array_equal(f.right, helpers.image(i + 100))
    assert caplog.text.count("has no partner") == 2


def test_pose_out_of_range_and_invalid_quaternion(tmp_path):
    quats = [(0, 0, 0, 1), (0, 0, 0, 0), (0, 0, 0, 1), (np.nan, 0, 0, 1), (0, 0, 0, 1)]
    times = [helpers.T0 + i * helpers.PERIOD for i in range(5)]
    path = helpers.write(tmp_path / "badtf.mcap", n=7, tf_quats=quats, tf_times=times)
    with Recording(path) as rec:
        problems = {f.index: f.pose_problem for f in rec.frames()}
    assert problems[0] is None and problems[2] is None and problems[4] is None
    assert "invalid quaternion" in problems[1] and "invalid quaternion" in problems[3]
    assert "outside the transform samples" in problems[5] and "outside" in problems[6]


def test_frame_range_streams_only_the_asked_frames(small_recording):
    with Recording(small_recording) as rec:
        assert [f.index for f in rec.frames(2, 4)] == [2, 3]


def broken_files(tmp_path):
    good = helpers.write(tmp_path / "good.mcap")
    data = open(good, "rb").read()
    cases = {}
    (tmp_path / "empty.mcap").write_bytes(b"")
    cases["empty"] = (tmp_path / "empty.mcap", "empty file")
    (tmp_path / "trunc.mcap").write_bytes(data[: len(data) // 2])
    cases["truncated"] = (tmp_path / "trunc.mcap", "truncated")
    (tmp_path / "text.mcap").write_text("hello, not a recording\n")
    cases["not mcap"] = (tmp_path / "text.mcap", "not an MCAP file")
    cases["no right"] = (helpers.write(tmp_path / "noright.mcap", skip_topics=("/stereo/right/image",)),
                         "missing topic /stereo/right/image")
    cases["no calibration"] = (helpers.write(tmp_path / "nocal.mcap", skip_topics=("/stereo/left/calibration",)),
                               "missing topic /stereo/left/calibration")
    cases["no tf"] = (helpers.write(tmp_path / "notf.mcap", skip_topics=("/tf",)), "missing topic /tf")
    cases["missing file"] = (tmp_path / "absent.mcap", "no such file")
    return cases


@pytest.mark.parametrize("case", ["empty", "truncated", "not mcap", "no right", "no calibration", "no tf",
                                  "missing file"])
def test_whole_file_problems_raise_one_line(tmp_path, case):
    path, message = broken_files(tmp_path)[case]
    with pytest.raises(RecordingError, match=message) as info:
        Recording(str(path))
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_no_path_to_object_frame(tmp_path):
    path = helpers.write(tmp_path / "good.mcap")
    with pytest.raises(RecordingError, match="no transform path from 'camera_left' to 'board'"):
        Recording(path, object_frame="board")


def test_writer_is_atomic(tmp_path):
    target = tmp_path / "partial.mcap"
    with pytest.raises(RuntimeError):
        with RecordingWriter(target) as w:
            w.image("/stereo/left/image", helpers.image(0), 0, "camera_left")
            raise RuntimeError("interrupted")
    assert not target.exists() and not list(tmp_path.iterdir())


def test_rectification_wedges_give_no_segments(raw_recording):
    """Raw images rectified leave black wedges; their borders are edges of no object. With the
    frame's ``border_distance`` no 2D segment runs along a wedge (half of it or more within the
    4 px where the gradient is masked, ``Gradients.of``; real edges may end at one, or lie just
    beyond: the tip of a dark object cut by the top border here has an edge 4 to 6 px from it,
    whose piece of 15 px the pieces from 8 px keep); without it, over a hundred do (132 here)."""
    import dataclasses

    from accumcli.extract import extract_frame
    from accumcli.lines2d import LineParams

    masked_px = np.ceil(3 * LineParams().blur_sigma) + 1    # as Gradients.of masks them

    def near_wedge(extraction, border):
        count = 0
        for side, segments in enumerate((extraction.left, extraction.right)):
            ends = segments.endpoints().reshape(-1, 2, 2)
            samples = ends[:, :1] + np.linspace(0, 1, 9)[None, :, None] * (ends[:, 1:] - ends[:, :1])
            px = np.clip(np.rint(samples), 0, [border[side].shape[1] - 1, border[side].shape[0] - 1]).astype(int)
            count += int(((border[side][px[..., 1], px[..., 0]] <= masked_px).mean(axis=1) >= 0.5).sum())
        return count

    with Recording(raw_recording) as rec:
        frame = next(rec.frames())
    assert frame.border_distance is not None
    assert all(0.005 < (b == 0).mean() < 0.2 for b in frame.border_distance)   # wedges on both sides
    assert near_wedge(extract_frame(frame), frame.border_distance) == 0
    assert near_wedge(extract_frame(dataclasses.replace(frame, border_distance=None)), frame.border_distance) >= 100


def test_rectified_input_has_no_wedges(small_recording):
    with Recording(small_recording) as rec:
        assert next(rec.frames()).border_distance is None


def test_a_first_frame_darker_than_the_rest_does_not_saturate_them(small_recording, tmp_path, caplog):
    """16-bit PNGs of 12-bit data whose first frame is dim (its largest value needs 10 bits): the scale
    chosen from it saturated every later frame (dev_tprofile so made: completeness 0.345 against
    0.484); it now grows to the bits a later frame needs, with a warning."""
    from accumcli.recording.messages import image_to_msg

    path = tmp_path / "dim_first.mcap"
    with Recording(small_recording) as rec, RecordingWriter(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", rec.calibrations[side][0][1], rec.calibrations[side][0][0])
        originals = []
        for frame in rec.frames(0, 3):
            w.transform("camera_left", "gripper", frame.T_camera_object, frame.timestamp_ns)
            gain = 4 if frame.index == 0 else 16            # 10 bits in the first frame, 12 after
            for side, image in (("left", frame.left), ("right", frame.right)):
                msg = image_to_msg(image, frame.timestamp_ns, f"camera_{side}", "png")
                msg.data = cv2.imencode(".png", image.astype(np.uint16) * gain)[1].tobytes()
                w._put(f"/stereo/{side}/image", msg, frame.timestamp_ns)
            originals.append(frame.left)
    with caplog.at_level(logging.WARNING), Recording(path) as rec:
        decoded = [frame.left for frame in rec.frames()]
        again = [frame.left for frame in rec.frames()]   # a second pass (--motion tracked makes several)
    assert "from it on, the 16-bit images use 12 bits" in caplog.text
    for frame, original in enumerate(originals):
        assert np.abs(decoded[frame].astype(int) - original).mean() < 1.5, frame
        assert np.array_equal(again[frame], decoded[frame]), frame   # the scale of a later frame does not carry over


def test_a_time_offset_looks_the_poses_up_that_much_later(small_recording):
    """``time_offset_ns`` (--time-offset-ms): frame k's pose is the one of the stamp one frame period
    later, i.e. frame k + 1's without an offset."""
    import numpy as np

    from accumcli.recording import Recording

    with Recording(small_recording) as rec:
        frames = list(rec.frames(0, 3))
    period = frames[1].timestamp_ns - frames[0].timestamp_ns
    with Recording(small_recording, time_offset_ns=period) as rec:
        shifted = list(rec.frames(0, 2))
    assert [f.timestamp_ns for f in shifted] == [f.timestamp_ns for f in frames[:2]]   # the stamps stay
    for k in range(2):
        assert np.allclose(shifted[k].T_camera_object, frames[k + 1].T_camera_object, atol=1e-9)
    assert not np.allclose(shifted[0].T_camera_object, frames[0].T_camera_object, atol=1e-4)


def test_a_dither_adds_one_grey_level_to_a_tenth_of_the_pixels_the_same_each_time(small_recording):
    """``dither`` (``make suite --repeats``): 0 streams the images as recorded; a seed moves about a tenth
    of the pixels by one grey level, the same pixels every time it is read, other pixels for another
    seed, another frame or the other camera."""
    from accumcli.runs import RecordingOptions

    def images(**kw):
        with Recording(small_recording, **kw) as rec:
            return [(f.left.astype(int), f.right.astype(int)) for f in rec.frames(0, 2)]

    plain, again, one, two = images(), images(dither=0), images(dither=1), images(dither=2)
    assert all(np.array_equal(a, b) for pa, pb in zip(plain, again) for a, b in zip(pa, pb))
    moved = [[d != p for d, p in zip(dk, pk)] for dk, pk in zip(one, plain)]
    for (left_pair, right_pair), (dk, pk) in zip(moved, zip(one, plain)):
        for image, original in zip(dk, pk):
            assert np.abs(image - original).max() == 1
        for changed in (left_pair, right_pair):
            assert 0.07 < changed.mean() < 0.11      # a tenth, less where 0 or 255 clip
    assert np.mean(moved[0][0] & moved[0][1]) < 0.02        # left and right: other pixels
    assert np.mean(moved[0][0] & moved[1][0]) < 0.02        # frame 0 and frame 1: other pixels
    assert np.array_equal(one[0][0], images(dither=1)[0][0])
    assert not np.array_equal(one[0][0], two[0][0])
    with pytest.raises(Exception, match="dither"):
        RecordingOptions(dither=-1)


def _as_foxglove_json(source, target) -> None:
    """``source``'s messages written again on the same topics in Foxglove's JSON encoding (snake_case
    fields, times as {"sec", "nsec"}, bytes base64), as Foxglove's SDKs and bridges write them."""
    from google.protobuf import json_format
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    def foxglove_times(value):
        if isinstance(value, dict):
            return {k: foxglove_times(v) for k, v in value.items()}
        if isinstance(value, list):
            return [foxglove_times(v) for v in value]
        if isinstance(value, str) and value.endswith("Z") and value[:4].isdigit():
            from google.protobuf.timestamp_pb2 import Timestamp

            stamp = Timestamp()
            stamp.FromJsonString(value)
            return {"sec": stamp.seconds, "nsec": stamp.nanos}
        return value

    with open(source, "rb") as f, RecordingWriter(target) as w:
        for schema, channel, message, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            doc = foxglove_times(json_format.MessageToDict(msg, preserving_proto_field_name=True))
            w.json_message(channel.topic, schema.name, {"type": "object"}, doc, message.log_time)


def test_foxglove_json_recordings_read_as_protobuf_ones(tmp_path):
    """Foxglove's schemas in JSON encoding (Foxglove's SDKs and bridges write them so) give the same frames,
    images and poses as the protobuf recording they were converted from; a JSON message that is not an
    object of the schema is skipped with a warning."""
    protobuf = helpers.write(tmp_path / "pb.mcap", n=4)
    as_json = tmp_path / "json.mcap"
    _as_foxglove_json(protobuf, as_json)
    with Recording(protobuf) as a, Recording(as_json) as b:
        pairs = list(zip(a.frames(), b.frames(), strict=True))
    assert len(pairs) == 4
    for x, y in pairs:
        assert x.timestamp_ns == y.timestamp_ns and np.array_equal(x.left, y.left) and np.array_equal(x.right, y.right)
        assert np.array_equal(x.T_camera_object, y.T_camera_object) and x.intrinsics == y.intrinsics
    from accumcli.recording.messages import from_foxglove_json

    with pytest.raises(ValueError):
        from_foxglove_json(RawImage, b"[1, 2]")
    with pytest.raises(ValueError):
        from_foxglove_json(RawImage, b'{"width": "wide"}')
    stamp = from_foxglove_json(RawImage, b'{"timestamp": {"sec": 3, "nsec": 5}, "data": "AAE="}')
    assert (stamp.timestamp.seconds, stamp.timestamp.nanos, stamp.data) == (3, 5, b"\x00\x01")
    for time, expected in (('{"sec": 1750000000.25}', (1750000000, 250000000)),   # float seconds: not cut
                           ('{"sec": 3, "nsec": 1500000000}', (4, 500000000))):   # nsec carried
        stamp = from_foxglove_json(RawImage, f'{{"timestamp": {time}}}'.encode()).timestamp
        assert (stamp.seconds, stamp.nanos) == expected
    with pytest.raises(ValueError, match="must be numbers"):
        from_foxglove_json(RawImage, b'{"timestamp": {"sec": "3"}}')


def test_a_damaged_jpeg_is_refused_and_extraneous_bytes_are_not():
    """libjpeg returns a damaged JPEG filled grey and only says so on stderr: such a frame is a DecodeError (it was
    used, silently); its note of extraneous bytes before a marker (many cameras' JPEGs) loses no pixel."""
    from accumcli.recording.messages import DecodeError

    grey = cv2.GaussianBlur(helpers.image(1, 320, 240), (0, 0), 2)
    data = bytearray(cv2.imencode(".jpg", grey)[1].tobytes())
    extraneous = CompressedImage(format="jpeg", data=bytes(data[:-2]) + b"\0\0\0\xff\xd9")
    assert np.abs(decode_image(extraneous).astype(int) - grey).mean() < 3
    data[len(data) // 2:len(data) // 2 + 50] = b"\0" * 50
    with pytest.raises(DecodeError, match="damaged jpeg image data .*premature end of data segment"):
        decode_image(CompressedImage(format="jpeg", data=bytes(data)))


def test_a_jpeg_that_lost_its_way_in_corrupt_data_is_refused():
    """libjpeg reports "N extraneous bytes before marker 0xd9" also after corrupt data threw it off: more than 2
    such bytes that are not padding are damage (86 % of one such image was off by more than 20 levels)."""
    from accumcli.recording.messages import DecodeError, _CapturedStderr

    rng = np.random.default_rng(0)
    grey = cv2.GaussianBlur((rng.random((240, 320)) * 255).astype(np.uint8), (7, 7), 2)
    good = cv2.imencode(".jpg", grey)[1].tobytes()
    found = 0
    for _ in range(400):
        data = bytearray(good)
        at = int(rng.integers(700, len(data) - 10))
        data[at:at + 3] = rng.integers(0, 256, 3).astype(np.uint8).tobytes()
        with _CapturedStderr() as said:
            cv2.imdecode(np.frombuffer(bytes(data), np.uint8), cv2.IMREAD_UNCHANGED)
        if "extraneous bytes before marker 0xd9" in said.text and not said.text.startswith(("Corrupt JPEG data: 1 ",
                                                                                              "Corrupt JPEG data: 2 ")):
            found += 1
            with pytest.raises(DecodeError, match="damaged jpeg image data"):
                decode_image(CompressedImage(format="jpeg", data=bytes(data)))
    assert found >= 1


def test_a_compressed_depth_topic_is_refused_when_the_recording_opens(tmp_path):
    path = tmp_path / "depth.mcap"
    with RecordingWriter(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", helpers.calibration(side), helpers.T0)
            msg = image_to_msg(helpers.image(0), helpers.T0, f"camera_{side}", "png")
            msg.format = "16UC1; compressedDepth png"
            w.message(f"/stereo/{side}/image", msg, helpers.T0)
        w.raw_transform("camera_left", "gripper", (0.0, 0.0, 0.5), (0, 0, 0, 1), helpers.T0)
    with pytest.raises(RecordingError, match="/stereo/left/image: image format '16UC1; compressedDepth png' is a "
                                             "compressed depth image"):
        Recording(path)


def test_frame_names_with_a_leading_slash_are_tf2s(tmp_path):
    """ROS 1's tf wrote '/camera_left'; tf2 strips the slash: either spelling, in the tree or in the options,
    names one frame (the tree's '/gripper' needed --object-frame /gripper, and eval then refused its truth)."""
    from accumcli.runs import RecordingOptions

    path = tmp_path / "slash.mcap"
    with RecordingWriter(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", helpers.calibration(side), helpers.T0)
        for i in range(3):
            t = helpers.T0 + i * helpers.PERIOD
            w.raw_transform("/camera_left", "/gripper", (0.01 * i, 0.0, 0.5), (0, 0, 0, 1), t)
            for side in ("left", "right"):
                w.image(f"/stereo/{side}/image", helpers.image(i), t, f"/camera_{side}")
    for object_frame in ("gripper", "/gripper"):
        with RecordingOptions(object_frame=object_frame).open(path) as rec:
            assert [f.T_camera_object[0, 3] for f in rec.frames()] == pytest.approx([0.0, 0.01, 0.02])
    assert RecordingOptions(object_frame="/board").object_frame == "board"
