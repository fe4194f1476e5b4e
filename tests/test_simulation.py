"""The simulator: deterministic, consistent with its own truth."""

from __future__ import annotations

import hashlib
import json

import numpy as np

from accumcli.model_io import read_truth
from accumcli.recording import Recording
from accumcli.simulation import SimulationOptions, simulate


def _digest(path) -> str:
    with Recording(str(path)) as rec:
        h = hashlib.sha256()
        for frame in rec.frames():
            h.update(frame.left.tobytes())
            h.update(frame.right.tobytes())
    return h.hexdigest()


def test_same_seed_same_recording(tmp_path):
    options = SimulationOptions(frames=2, width=160, height=120, seed=5)
    simulate(str(tmp_path / "a.mcap"), options)
    simulate(str(tmp_path / "b.mcap"), options)
    assert _digest(tmp_path / "a.mcap") == _digest(tmp_path / "b.mcap")
    assert (tmp_path / "a.truth.json").read_text() == (tmp_path / "b.truth.json").read_text()
    simulate(str(tmp_path / "c.mcap"), SimulationOptions(frames=2, width=160, height=120, seed=6))
    assert _digest(tmp_path / "c.mcap") != _digest(tmp_path / "a.mcap")


def test_truth_sidecar_contents(small_recording):
    truth = read_truth(small_recording.replace(".mcap", ".truth.json"))
    doc = json.load(open(small_recording.replace(".mcap", ".truth.json")))
    assert doc["format"] == "accum.truth/1" and doc["object_frame"] == "gripper"
    assert set(truth.kinds) == {"object", "stripe", "gripper"}
    n_frames = len(truth.poses)
    seen = np.concatenate(truth.seen)
    assert seen.min() >= 0 and seen.max() <= n_frames
    # the object faces the camera: a good share of its edges is seen, and never all (the back is hidden)
    object_seen = np.concatenate([s for s, k in zip(truth.seen, truth.kinds) if k == "object"])
    assert 0.2 < np.mean(object_seen >= 1) < 0.95
    # edge samples follow formats.md: sample i of k at a + (i + 0.5) / k (b - a), about 2 mm apart
    lengths = np.linalg.norm(truth.b - truth.a, axis=1)
    counts = np.array([len(s) for s in truth.seen])
    assert np.all(lengths / counts <= 0.002 + 1e-9)


def test_shapes_differ(tmp_path):
    sizes = {}
    for shape in ("box", "prism", "house"):
        simulate(str(tmp_path / f"{shape}.mcap"), SimulationOptions(frames=1, width=160, height=120, shape=shape))
        sizes[shape] = len(read_truth(str(tmp_path / f"{shape}.truth.json")).kinds)
    assert len(set(sizes.values())) == 3
