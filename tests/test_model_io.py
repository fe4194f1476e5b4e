"""Model, frames, poses and truth files: round trips, PLY readable by plyfile, atomic writes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from plyfile import PlyData

from accumcli.errors import FileFormatError
from accumcli.geometry import make_transform
from accumcli.model_io import (FramesWriter, PoseTrack, read_frames, read_model, read_poses, write_model,
                               write_ply, write_poses)
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


def test_ply_is_a_line_set(tmp_path):
    segments = random_segments(7)
    write_ply(tmp_path / "m.ply", segments)
    ply = PlyData.read(str(tmp_path / "m.ply"))
    assert ply["vertex"].count == 14 and ply["edge"].count == 7
    vertices = np.column_stack([ply["vertex"][k] for k in "xyz"])
    v1, v2 = ply["edge"]["vertex1"], ply["edge"]["vertex2"]
    assert np.allclose((vertices[v1] + vertices[v2]) / 2, segments.centers, atol=1e-6)
    assert np.allclose(np.linalg.norm(vertices[v2] - vertices[v1], axis=1), segments.lengths, atol=1e-6)
    assert np.allclose(ply["edge"]["confidence"], segments.confidence, atol=1e-6)


def test_frames_jsonl_round_trip(tmp_path):
    with FramesWriter(tmp_path / "f.jsonl") as w:
        for i in range(3):
            w.write(random_segments(5, seed=i), timestamp_ns=1000 * i)
    rows = list(read_frames(tmp_path / "f.jsonl"))
    assert [t for t, _, _ in rows] == [0, 1000, 2000]
    assert all(len(s) == 5 for _, s, _ in rows)


def test_poses_round_trip(tmp_path):
    poses = np.stack([make_transform(np.eye(3), [0, 0, 0.5 + i]) for i in range(3)])
    poses[1] = np.nan
    track = PoseTrack("camera_left", "gripper", np.arange(3) * 10, poses, ["tracked", "lost", "tracked"])
    write_poses(tmp_path / "p.json", track)
    back = read_poses(tmp_path / "p.json")
    assert back.status == ["tracked", "lost", "tracked"]
    assert np.allclose(back.poses[2], poses[2]) and np.isnan(back.poses[1]).all()


@pytest.mark.parametrize("content, message", [
    ("not json", "not a JSON model"),
    ('{"format": "other"}', "expected format 'accum.model/1'"),
    ('{"format": "accum.model/1", "segments": [{"center": [0, 0]}]}', "malformed segment"),
])
def test_bad_model_files(tmp_path, content, message):
    (tmp_path / "bad.json").write_text(content)
    with pytest.raises(FileFormatError, match=message):
        read_model(tmp_path / "bad.json")


def test_interrupted_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "m.json"
    write_model(target, random_segments(3))
    before = target.read_bytes()

    def explode(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(json, "dump", explode)
    with pytest.raises(KeyboardInterrupt):
        write_model(target, random_segments(9))
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]
