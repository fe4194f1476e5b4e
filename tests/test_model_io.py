"""Model, frames, poses and truth files: round trips, PLY readable by plyfile, Open3D and
trimesh, strict JSON, recognition by content, poses as MCAP, atomic writes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from plyfile import PlyData

from accumcli.errors import AccumError, FileFormatError
from accumcli.geometry import make_transform
from accumcli.model_io import (FramesWriter, PoseTrack, check_kind, confidence_rgb, describe_kind, dumps,
                               file_kind, read_frames, read_model, read_poses, read_truth, write_json,
                               write_json_lines, write_model, write_ply, write_poses, write_poses_mcap)
from accumcli.outputs import OutputSet
from accumcli.segments import Segments


def random_segments(n=50, seed=0) -> Segments:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return Segments("gripper", rng.uniform(-0.1, 0.1, (n, 3)), d / np.linalg.norm(d, axis=1, keepdims=True),
                    rng.uniform(0.005, 0.02, n), rng.uniform(0, 1, n), rng.integers(1, 20, n),
                    {"sigma_m": rng.uniform(0, 0.002, n)})


def test_model_json_round_trip(tmp_path):
    segments = random_segments()
    write_model(tmp_path / "m.json", segments)
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["format"] == "accum.model/1" and doc["frame_id"] == "gripper"
    assert set(doc["segments"][0]) >= {"center", "direction", "length", "confidence", "observations"}
    back = read_model(tmp_path / "m.json")
    assert np.allclose(back.centers, segments.centers, atol=1e-7)
    assert np.allclose(back.directions, segments.directions, atol=1e-6)
    assert np.allclose(back.confidence, segments.confidence, atol=1e-5)
    assert np.array_equal(back.observations, segments.observations)
    assert np.allclose(back.extra["sigma_m"], segments.extra["sigma_m"], atol=1e-7)


def test_written_confidences_keep_their_side_of_the_acceptance_line(tmp_path):
    """0.499996 rounded to 5 digits is 0.5: read back, a segment the run did not accept was accepted."""
    segments = random_segments(3)
    segments.confidence = np.array([0.499996, 0.5, 0.9])
    write_model(tmp_path / "m.json", segments)
    assert list(read_model(tmp_path / "m.json").accepted) == [False, True, True]


@pytest.mark.parametrize("length", [0.0, -0.01, None])
def test_a_segment_without_a_positive_length_is_refused(tmp_path, length):
    write_model(tmp_path / "m.json", random_segments(2))
    doc = json.loads((tmp_path / "m.json").read_text())
    if length is None:
        del doc["segments"][1]["length"]
    else:
        doc["segments"][1]["length"] = length
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(FileFormatError, match="length"):
        read_model(tmp_path / "m.json")


# -- strict JSON -------------------------------------------------------------------------------
def strict_loads(text: str):
    """json.loads that refuses NaN/Infinity, as strict parsers (JavaScript, Go, serde) do."""
    def refuse(name):
        raise ValueError(f"bare {name}")
    return json.loads(text, parse_constant=refuse)


def test_dumps_writes_null_for_non_finite():
    doc = {"a": float("nan"), "b": [1.0, float("inf"), np.float32(-np.inf)], "c": np.array([0.5, np.nan]),
           "d": np.int64(3), "e": np.bool_(True), "f": {"g": (float("-inf"),)}}
    assert strict_loads(dumps(doc)) == {"a": None, "b": [1.0, None, None], "c": [0.5, None], "d": 3, "e": True,
                                        "f": {"g": [None]}}
    assert dumps({"x": 1.5}) == '{"x":1.5}'
    assert dumps({"x": [1]}, indent=1) == '{\n "x": [\n  1\n ]\n}'


def test_every_json_writer_is_strict(tmp_path):
    segments = random_segments(4)
    segments.centers[0, 0] = np.nan
    segments.extra["sigma_m"][1] = np.inf
    write_model(tmp_path / "m.json", segments)
    row = strict_loads((tmp_path / "m.json").read_text())["segments"]
    assert row[0]["center"][0] is None and row[1]["sigma_m"] is None
    with FramesWriter(tmp_path / "f.jsonl") as w:
        w.write(segments, 5, residual=float("nan"))
    line = strict_loads((tmp_path / "f.jsonl").read_text())
    assert line["residual"] is None and line["timestamp_ns"] == 5
    track = PoseTrack("camera_left", "gripper", np.arange(2), np.stack([np.eye(4)] * 2), ["tracked"] * 2,
                      [{"residual_px": np.float64(np.nan)}, {"residual_px": 0.5}])
    write_poses(tmp_path / "p.json", track)
    poses = strict_loads((tmp_path / "p.json").read_text())["poses"]
    assert [p["residual_px"] for p in poses] == [None, 0.5]
    write_json_lines(tmp_path / "h.jsonl", [{"precision": float("nan")}, {"precision": 0.25}])
    assert [strict_loads(s) for s in (tmp_path / "h.jsonl").read_text().splitlines()] == [
        {"precision": None}, {"precision": 0.25}]


# -- PLY -------------------------------------------------------------------------------------
def test_ply_holds_accepted_segments_by_default(tmp_path):
    segments = random_segments(40)
    accepted = segments.select(segments.accepted)
    write_ply(tmp_path / "m.ply", segments)
    write_ply(tmp_path / "all.ply", segments, all_segments=True)
    ply = PlyData.read(str(tmp_path / "m.ply"))
    assert 0 < len(accepted) < 40
    assert ply["vertex"].count == 2 * len(accepted) and ply["edge"].count == len(accepted)
    assert (ply["edge"]["confidence"] >= 0.5).all()
    assert PlyData.read(str(tmp_path / "all.ply"))["edge"].count == 40
    assert "accepted segments" in (tmp_path / "m.ply").read_text().splitlines()[2]


def test_ply_keeps_the_contract(tmp_path):
    segments = random_segments(7)
    write_ply(tmp_path / "m.ply", segments, all_segments=True)
    ply = PlyData.read(str(tmp_path / "m.ply"))
    assert [(p.name, p.val_dtype) for p in ply["vertex"].properties][:3] == [("x", "f4"), ("y", "f4"), ("z", "f4")]
    assert [(p.name, p.val_dtype) for p in ply["edge"].properties][:3] == [("vertex1", "i4"), ("vertex2", "i4"),
                                                                          ("confidence", "f4")]
    vertices = np.column_stack([ply["vertex"][k] for k in "xyz"])
    v1, v2 = ply["edge"]["vertex1"], ply["edge"]["vertex2"]
    assert np.allclose((vertices[v1] + vertices[v2]) / 2, segments.centers, atol=1e-6)
    assert np.allclose(np.linalg.norm(vertices[v2] - vertices[v1], axis=1), segments.lengths, atol=1e-6)
    assert np.allclose(ply["edge"]["confidence"], segments.confidence, atol=1e-5)
    rgb = np.column_stack([ply["vertex"][k] for k in ("red", "green", "blue")])
    assert ply["vertex"]["red"].dtype == np.uint8
    assert np.array_equal(rgb[v1], confidence_rgb(segments.confidence))
    assert np.array_equal(rgb[v2], rgb[v1])


def test_confidence_colours():
    assert confidence_rgb(np.array([0.0, 0.25, 0.5, 1.0, np.nan])).tolist() == [
        [255, 0, 0], [255, 128, 0], [255, 255, 0], [0, 255, 0], [255, 0, 0]]


def test_ply_opens_in_open3d(tmp_path):
    o3d = pytest.importorskip("open3d")
    segments = random_segments(9)
    write_ply(tmp_path / "m.ply", segments, all_segments=True)
    lines = o3d.io.read_line_set(str(tmp_path / "m.ply"))
    assert np.asarray(lines.lines).tolist() == [[2 * i, 2 * i + 1] for i in range(9)]
    assert np.allclose(np.asarray(lines.points), segments.endpoints().reshape(-1, 3), atol=1e-6)
    assert np.allclose(np.asarray(lines.colors) * 255, confidence_rgb(segments.confidence), atol=0.5)


def test_ply_opens_in_trimesh(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    segments = random_segments(9)
    write_ply(tmp_path / "m.ply", segments, all_segments=True)
    path = trimesh.load(str(tmp_path / "m.ply"))
    assert isinstance(path, trimesh.path.Path3D)
    assert len(path.entities) == 9
    ends = np.array([path.vertices[e.points] for e in path.entities])
    assert np.allclose(ends, segments.endpoints(), atol=1e-6)


def test_empty_ply(tmp_path):
    write_ply(tmp_path / "m.ply", Segments.empty("gripper"))
    ply = PlyData.read(str(tmp_path / "m.ply"))
    assert ply["vertex"].count == 0 and ply["edge"].count == 0


# -- frames, poses ---------------------------------------------------------------------------
def test_frames_jsonl_round_trip(tmp_path):
    with FramesWriter(tmp_path / "f.jsonl") as w:
        for i in range(3):
            w.write(random_segments(5, seed=i), timestamp_ns=1000 * i)
    rows = list(read_frames(tmp_path / "f.jsonl"))
    assert [t for t, _, _ in rows] == [0, 1000, 2000]
    assert all(len(s) == 5 for _, s, _ in rows)


def test_writers_take_files_of_an_output_set(tmp_path):
    paths = [str(tmp_path / n) for n in ("m.json", "m.ply", "f.jsonl")]
    with OutputSet(paths) as out:
        write_model(out.open(paths[0]), random_segments(3))
        write_ply(out.open(paths[1]), random_segments(3), all_segments=True)
        with FramesWriter(out.open(paths[2])) as w:
            w.write(random_segments(2), 7)
        assert not any((tmp_path / n).exists() for n in ("m.json", "m.ply", "f.jsonl"))
    assert len(read_model(paths[0])) == 3
    assert PlyData.read(paths[1])["edge"].count == 3
    assert [t for t, _, _ in read_frames(paths[2])] == [7]


def test_poses_round_trip(tmp_path):
    poses = np.stack([make_transform(np.eye(3), [0, 0, 0.5 + i]) for i in range(3)])
    poses[1] = np.nan
    track = PoseTrack("camera_left", "gripper", np.arange(3) * 10, poses, ["tracked", "lost", "tracked"])
    write_poses(tmp_path / "p.json", track)
    back = read_poses(tmp_path / "p.json")
    assert back.status == ["tracked", "lost", "tracked"]
    assert np.allclose(back.poses[2], poses[2]) and np.isnan(back.poses[1]).all()
    assert back.tracked().tolist() == [True, False, True]


def read_mcap_transforms(path) -> list:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(channel.topic, msg.parent_frame_id, msg.child_frame_id, message.log_time,
                 msg.translation.z) for _, channel, message, msg in reader.iter_decoded_messages()]


def test_poses_mcap_on_its_own_topic_and_frame(tmp_path):
    poses = np.stack([make_transform(np.eye(3), [0, 0, 0.5 + i]) for i in range(3)])
    track = PoseTrack("camera_left", "gripper", np.array([10, 20, 30]), poses, ["tracked", "lost", "tracked"])
    assert write_poses_mcap(tmp_path / "p.mcap", track) == 2
    assert read_mcap_transforms(tmp_path / "p.mcap") == [("/accum/poses", "camera_left", "gripper_tracked", 10, 0.5),
                                                         ("/accum/poses", "camera_left", "gripper_tracked", 30, 2.5)]
    write_poses_mcap(tmp_path / "q.mcap", track, topic="/tf", child_frame_id="est")
    assert {(t, c) for t, _, c, _, _ in read_mcap_transforms(tmp_path / "q.mcap")} == {("/tf", "est")}
    assert file_kind(tmp_path / "p.mcap") == "recording"


# -- recognition by content ------------------------------------------------------------------
@pytest.fixture
def files(tmp_path):
    """One file of every kind, each under a misleading name where that is possible."""
    made = {}
    write_model(made.setdefault("model", tmp_path / "model.ply"), random_segments(3))
    write_ply(made.setdefault("ply", tmp_path / "ply.json"), random_segments(3))
    with FramesWriter(made.setdefault("frames", tmp_path / "frames.json")) as w:
        w.write(random_segments(2), 1)
        w.write(random_segments(2), 2)
    with FramesWriter(made.setdefault("one frame", tmp_path / "one.json")) as w:
        w.write(random_segments(2), 1)
    write_poses(made.setdefault("poses", tmp_path / "poses.mcap"),
                PoseTrack("c", "o", np.arange(1), np.eye(4)[None], ["tracked"]))
    made["truth"] = tmp_path / "truth.json"
    made["truth"].write_text(json.dumps({"format": "accum.truth/1", "edges": [{"a": [0, 0, 0], "b": [1, 0, 0]}]},
                                        indent=1))
    write_poses_mcap(made.setdefault("recording", tmp_path / "rec.json"),
                     PoseTrack("c", "o", np.arange(1), np.eye(4)[None], ["tracked"]))
    (made.setdefault("empty", tmp_path / "empty.json")).write_bytes(b"")
    (made.setdefault("binary", tmp_path / "bin.json")).write_bytes(b"\x8e\xff{\x00\x01" * 50)
    (made.setdefault("latin-1", tmp_path / "latin.json")).write_bytes('{"format": "caf\xe9"}'.encode("latin-1"))
    (made.setdefault("text", tmp_path / "text.json")).write_text("hello\n")
    (made.setdefault("json", tmp_path / "other.json")).write_text('{"format": "other/2", "x": 1}')
    return made


def test_file_kind_by_content(files):
    assert {name: file_kind(path) for name, path in files.items()} == {
        "model": "model", "ply": "ply", "frames": "frames", "one frame": "frames", "poses": "poses",
        "truth": "truth", "recording": "recording", "empty": "empty", "binary": "binary", "latin-1": "binary",
        "text": "text", "json": "json"}


def test_file_kind_of_long_and_pretty_files(tmp_path, files):
    big = random_segments(600)
    write_model(tmp_path / "big.json", big)
    with FramesWriter(tmp_path / "big.jsonl") as w:
        w.write(big, 1)
    assert (tmp_path / "big.json").stat().st_size > 65536
    assert file_kind(tmp_path / "big.json") == "model" and file_kind(tmp_path / "big.jsonl") == "frames"
    write_json(tmp_path / "pretty.json", json.loads((tmp_path / "big.json").read_text()), indent=2)
    assert file_kind(tmp_path / "pretty.json") == "model" and len(read_model(tmp_path / "pretty.json")) == 600
    assert describe_kind(files["json"]) == "a JSON file of format 'other/2'"
    assert describe_kind(files["ply"]) == "a PLY file"


@pytest.mark.parametrize("reader, given, message", [
    (read_model, "ply", r"ply\.json: expected a model JSON \(accum\.model/1\), got a PLY file$"),
    (read_model, "recording", r"expected a model JSON \(accum\.model/1\), got a recording \(MCAP, rosbag2 or ROS 1 bag\)$"),
    (read_model, "frames", r"expected a model JSON \(accum\.model/1\), got a frames JSONL file"),
    (read_model, "binary", r"got a binary file$"),
    (read_model, "latin-1", r"got a binary file$"),
    (read_model, "empty", r"got an empty file$"),
    (read_model, "json", r"got a JSON file of format 'other/2'$"),
    (read_poses, "model", r"expected a poses JSON \(accum\.poses/1\), got a model JSON"),
    (read_truth, "poses", r"expected a truth JSON \(accum\.truth/1\), got a poses JSON"),
    (lambda p: list(read_frames(p)), "model", r"expected a frames JSONL file .*, got a model JSON"),
    (lambda p: list(read_frames(p)), "binary", r"got a binary file$"),
])
def test_readers_refuse_other_kinds(files, reader, given, message):
    with pytest.raises(FileFormatError, match=message):
        reader(files[given])


def test_a_broken_json_is_named_as_such(tmp_path):
    """A truncated JSON was "a JSON file of another kind"."""
    (tmp_path / "cut.json").write_text('{"segments": [')
    (tmp_path / "other.json").write_text('{"a": 1}')
    (tmp_path / "lines.jsonl").write_text('{"a": 1}\n{"a": 2}\n')
    with pytest.raises(FileFormatError, match=r"got text that is not valid JSON \(Expecting value"):
        check_kind(tmp_path / "cut.json", "poses")
    for name in ("other.json", "lines.jsonl"):
        with pytest.raises(FileFormatError, match="got a JSON file of another kind"):
            check_kind(tmp_path / name, "poses")


def test_check_kind_accepts_several(files):
    assert check_kind(files["poses"], "model", "poses") == "poses"
    with pytest.raises(FileFormatError, match="expected a model JSON .* or a PLY file, got a text file"):
        check_kind(files["text"], "model", "ply")
    with pytest.raises(FileFormatError, match="nope.json: no such file"):
        check_kind(files["text"].with_name("nope.json"), "model")


@pytest.mark.parametrize("content, message", [
    (b'{"format": "accum.model/1", "segments": [{"center": [0, 0]}]}', "malformed segment"),
    (b'{"format": "accum.model/1", "segments": 3}', "expected a list under 'segments'"),
    (b'{"format": "accum.model/1", "segments": [1]', "not valid JSON"),
    (b'{"format": "accum.model/1", "x": "' + b" " * 70000 + b'\xe9"}', "bad.json: byte 70034 is not UTF-8 text"),
])
def test_bad_model_files(tmp_path, content, message):
    (tmp_path / "bad.json").write_bytes(content)
    with pytest.raises(FileFormatError, match=message):
        read_model(tmp_path / "bad.json")


@pytest.mark.parametrize("edge, message", [
    ('{"a": [0.05, 0.05, 0.05], "b": [0.05, 0.05, 0.05]}', r"edge 1 has no length \(a == b\)"),
    ('{"a": [0, 0, NaN], "b": [0, 0, 1]}', "edge 1 has NaN or infinite coordinates"),
])
def test_bad_truth_edges(tmp_path, edge, message):
    """An edge without a direction would make every distance to it NaN, which hid all background."""
    path = tmp_path / "t.json"
    path.write_text('{"format": "accum.truth/1", "object_frame": "gripper", "edges": '
                    '[{"a": [0, 0, 0], "b": [0.1, 0, 0]}, ' + edge + ']}')
    with pytest.raises(FileFormatError, match=message):
        read_truth(path)


def test_truth_edges_of_two_coordinates(tmp_path):
    path = tmp_path / "t.json"
    path.write_text('{"format": "accum.truth/1", "object_frame": "gripper", "edges": ' +
                    ", ".join(['[{"a": [0, 0], "b": [1, 0]}'] + ['{"a": [0, 0], "b": [1, 0]}'] * 2) + ']}')
    with pytest.raises(FileFormatError, match="every edge needs 'a' and 'b' of 3 numbers"):
        read_truth(path)


def test_empty_frames_file_has_no_frames(files):
    assert list(read_frames(files["empty"])) == []


def test_bad_frames_line(tmp_path):
    good = dumps({"format": "accum.model/1", "timestamp_ns": 1, "frame_id": "c", "segments": []})
    (tmp_path / "f.jsonl").write_bytes((good + "\n" + good.replace('"timestamp_ns":1', '"timestamp_ns":"x"')
                                        + "\n").encode())
    with pytest.raises(FileFormatError, match=r"f\.jsonl, line 2: expected an integer 'timestamp_ns'"):
        list(read_frames(tmp_path / "f.jsonl"))


# -- atomic writes ---------------------------------------------------------------------------
def test_interrupted_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "m.json"
    write_model(target, random_segments(3))
    before = target.read_bytes()

    def explode(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("accumcli.model_io.dumps", explode)
    with pytest.raises(KeyboardInterrupt):
        write_model(target, random_segments(9))
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_writer_into_a_missing_folder(tmp_path):
    with pytest.raises(AccumError, match=r"the folder .*nope does not exist; create it or write elsewhere"):
        write_ply(tmp_path / "nope" / "m.ply", random_segments(3))
