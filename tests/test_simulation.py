"""The simulator: deterministic, consistent with its own truth."""

from __future__ import annotations

import base64
import dataclasses
import hashlib
import json

import cv2
import numpy as np
import pytest

from accumcli.edge_sampling import edge_samples, sample_count
from accumcli.errors import AccumError
from accumcli.evaluate import EdgeSamples
from accumcli.model_io import read_truth
from accumcli.recording import Recording
from accumcli.simulation import SimulationOptions, simulate
from accumcli.simulation.random_scene import RANDOM_SHAPES, extrude, make_clutter, profile
from accumcli.simulation.randomized import draw_parameters, visible_samples
from accumcli.simulation.raster import Buffers, Mesh, draw, triangulate
from accumcli.simulation.render import PinholeCamera


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
    # formats.md's part and kind on every edge: the object's creases and painted stripes, the gripper's creases
    assert {(e["part"], e["kind"]) for e in doc["edges"]} == {("object", "crease"), ("object", "paint"),
                                                               ("gripper", "crease")}
    n_frames = len(truth.poses)
    seen = np.concatenate(truth.seen)
    assert seen.min() >= 0 and seen.max() <= n_frames
    # the object faces the camera: a good share of its edges is seen, and never all (the back is hidden)
    creases = [e["part"] == "object" and e["kind"] == "crease" for e in doc["edges"]]
    object_seen = np.concatenate([s for s, crease in zip(truth.seen, creases) if crease])
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


# -- the random scene ---------------------------------------------------------------------------------------------



SMALL = dict(frames=2, width=160, height=120, scene="random")


def test_edge_samples_follow_formats_md():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([0.008, 0.0, 0.0])
    assert sample_count(a, b) == 4 and sample_count(a, a + 1e-4) == 2
    np.testing.assert_allclose(edge_samples(a, b, 4)[:, 0], [0.001, 0.003, 0.005, 0.007])


def test_evaluation_samples_where_the_simulator_counted(tmp_path):
    simulate(str(tmp_path / "r.mcap"), SimulationOptions(**SMALL, seed=2))
    truth = read_truth(str(tmp_path / "r.truth.json"))
    samples = EdgeSamples.of(truth)
    i = 5
    mine = samples.points[samples.edge == i]
    np.testing.assert_allclose(mine, edge_samples(truth.a[i], truth.b[i], len(truth.seen[i])))


def test_random_same_seed_same_bytes(tmp_path):
    options = SimulationOptions(**SMALL, seed=21)
    simulate(str(tmp_path / "a.mcap"), options)
    simulate(str(tmp_path / "b.mcap"), options)
    assert _digest(tmp_path / "a.mcap") == _digest(tmp_path / "b.mcap")
    assert (tmp_path / "a.truth.json").read_bytes() == (tmp_path / "b.truth.json").read_bytes()
    simulate(str(tmp_path / "c.mcap"), dataclasses.replace(options, seed=22))
    assert _digest(tmp_path / "c.mcap") != _digest(tmp_path / "a.mcap")


def test_draws_cover_the_documented_ranges():
    draws = [draw_parameters(SimulationOptions(scene="random", seed=s)) for s in range(60)]
    assert {d.shape for d in draws} == set(RANDOM_SHAPES) and len(RANDOM_SHAPES) >= 7
    for name, lo, hi in (("size_mm", 30, 120), ("distance_m", 0.45, 0.85), ("contrast", 0.05, 0.45),
                         ("blur_sigma", 0.5, 1.2), ("noise_sigma", 0.5, 2.5), ("illumination", 0.0, 0.2)):
        values = np.array([getattr(d, name) for d in draws])
        assert lo <= values.min() < lo + 0.2 * (hi - lo) and hi - 0.2 * (hi - lo) < values.max() <= hi, name
    assert {d.background for d in draws} == {"texture", "planes", "lines"}
    assert 5 < sum(d.clutter for d in draws) < 35
    np.testing.assert_allclose([abs(d.object_albedo - d.background_albedo) for d in draws],
                               [d.contrast for d in draws], atol=1e-9)


def test_a_pin_changes_only_its_own_draw():
    free = draw_parameters(SimulationOptions(scene="random", seed=4))
    pinned = draw_parameters(SimulationOptions(scene="random", seed=4, shape="cross", noise_sigma=0.7))
    assert (pinned.shape, pinned.noise_sigma) == ("cross", 0.7)
    assert dataclasses.replace(pinned, shape=free.shape, noise_sigma=free.noise_sigma) == free


def test_pinned_options_are_honoured(tmp_path):
    options = SimulationOptions(frames=3, width=320, height=240, scene="random", seed=9, shape="T", size_mm=50.0,
                                distance_m=0.6, contrast=0.3, blur_sigma=0.8, noise_sigma=1.5, illumination=0.1,
                                background="lines", clutter=True, per_frame_deg=8.0)
    simulate(str(tmp_path / "p.mcap"), options)
    doc = json.load(open(tmp_path / "p.truth.json"))
    meta = doc["simulation"]
    for name in ("shape", "size_mm", "distance_m", "contrast", "blur_sigma", "noise_sigma", "illumination",
                 "background", "clutter", "per_frame_deg"):
        assert meta[name] == getattr(options, name), name
    assert abs(abs(meta["object_albedo"] - meta["background_albedo"]) - 0.3) < 1e-9
    truth = read_truth(str(tmp_path / "p.truth.json"))
    is_object = np.array([e["part"] == "object" for e in doc["edges"]])
    corners = np.concatenate([truth.a[is_object], truth.b[is_object]])
    assert np.ptp(corners, axis=0).max() == pytest.approx(0.050)
    kinds = [e["kind"] for e in doc["edges"] if e["part"] == "object"]
    assert kinds.count("crease") == 3 * len(profile("T", 1, 1)) == 24
    assert {e["kind"] for e in doc["edges"] if e["part"] == "gripper"} == {"crease"}
    assert 0.55 < np.mean(truth.poses[:, 2, 3]) < 0.65
    # noise: the same scene without noise differs from it by the pinned standard deviation
    simulate(str(tmp_path / "q.mcap"), dataclasses.replace(options, noise_sigma=0.0))
    with Recording(str(tmp_path / "p.mcap")) as p, Recording(str(tmp_path / "q.mcap")) as q:
        diff = np.concatenate([(a.left.astype(float) - b.left).ravel() for a, b in zip(p.frames(), q.frames())])
    assert diff.std() == pytest.approx(np.sqrt(1.5 ** 2 + 1 / 12), rel=0.06)


def test_clutter_stays_off_the_moving_parts():
    rng = np.random.default_rng(3)
    moving = np.array([[[-0.1, -0.2, 0.5], [0.1, 0.08, 0.7]], [[0.0, -0.15, 0.55], [0.15, 0.1, 0.72]]])
    solids = make_clutter(rng, 0.6, moving, (0.53, 0.4), 0.5)
    assert 4 <= len(solids) <= 8
    for solid in solids:
        vertices = np.concatenate([p.vertices for p in solid])
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        assert abs((lo[2] + hi[2]) / 2 - 0.6) <= 0.12 + 1e-9  # at the object's depth
        assert not np.any(np.all((lo <= moving[:, 1]) & (hi >= moving[:, 0]), axis=1))  # off the moving parts


def test_non_convex_faces_are_covered_exactly():
    section = profile("L", 0.1, 0.1)
    triangles = triangulate(np.column_stack([section, np.zeros(len(section))]), np.array([0.0, 0.0, 1.0]))
    assert len(triangles) == len(section) - 2
    area = sum(0.5 * abs(np.linalg.det(np.array([section[b] - section[a], section[c] - section[a]])))
               for a, b, c in triangles)
    assert area == pytest.approx(0.1 * 0.1 - 0.06 * 0.065)  # the L is the square less its inner corner
    # the cap of an L seen head on: covered pixel centres match its area (pixels of 1/600 m at 1 m), no seams
    solid = extrude(section, 1.0, 1.05, np.full(len(section) + 2, 0.5))
    camera = PinholeCamera(600.0, 600.0, 79.5, 59.5, 160, 120)
    buffers = Buffers.empty(camera, 1)
    draw(buffers, Mesh.of(solid.polygons[:1]), np.eye(4), camera, 1, np.array([0.0, 0.0, -1.0]), 1.0)
    assert (buffers.ids == 0).sum() == pytest.approx(area * 600 ** 2, rel=0.03)
    cap = buffers.ids == 0
    assert not np.any(cap[1:-1, 1:-1] < (cap[:-2, 1:-1] & cap[2:, 1:-1] & cap[1:-1, :-2] & cap[1:-1, 2:]))


def _visibility(solid, T, camera, supersample=4):
    mesh = Mesh.of(solid.polygons)
    buffers = Buffers.empty(camera, supersample)
    draw(buffers, mesh, T, camera, supersample, np.array([0.0, 0.0, -1.0]), 1.0)
    image = cv2.resize(buffers.color, (camera.width, camera.height), interpolation=cv2.INTER_AREA) * 255
    a = np.array([e[0] for e in solid.edges])
    b = np.array([e[1] for e in solid.edges])
    counts = [sample_count(p, q) for p, q in zip(a, b)]
    points = np.concatenate([edge_samples(p, q, k) for p, q, k in zip(a, b, counts)])
    tangents = np.repeat((b - a) / np.linalg.norm(b - a, axis=1, keepdims=True), counts, axis=0)
    owner = np.repeat(np.arange(len(a)), counts)
    return points, owner, visible_samples(points, tangents, T, buffers, mesh, image, camera, supersample, 0)


def test_edges_seen_end_on_are_not_seen():
    """Edges on an image step, unoccluded, 3 and 8 degrees off their viewing rays: only the second is seen."""
    camera = PinholeCamera(300.0, 300.0, 79.5, 59.5, 160, 120)
    image = np.zeros((120, 160), np.float32)
    image[:, 80:] = 200.0  # a vertical step between columns 79 and 80, at u = 79.5
    ray = np.array([0.0, 0.0, 1.0])
    for angle, seen in ((3.0, False), (8.0, True)):
        d = np.array([0.0, np.sin(np.radians(angle)), np.cos(np.radians(angle))])
        points = 0.5 * ray + np.linspace(0.0, 0.02, 5)[:, None] * d  # on the optical axis: u = 79.5
        visible = visible_samples(points, np.repeat(d[None], 5, axis=0), np.eye(4), Buffers.empty(camera, 4),
                                  Mesh.of([]), image, camera, 4, 0)
        assert visible.all() == seen and visible.any() == seen, angle


def test_an_l_hides_what_lies_behind_its_leg():
    """Seen along its x axis from the leg's side, an L shows only the four edges of the leg's outer face."""
    w, d = 0.1, 0.06
    solid = extrude(profile("L", w, w), -d / 2, d / 2, np.full(8, 0.8))
    R = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # object x -> camera z
    assert np.isclose(np.linalg.det(R), 1.0)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [0.0, 0.0, 0.5 + w / 2]
    points, _, visible = _visibility(solid, T, PinholeCamera(300.0, 300.0, 79.5, 59.5, 160, 120))
    on_near_face = np.abs(points[:, 0] + w / 2) < 1e-9
    behind = points[:, 0] > -w / 2 + 0.004
    assert visible[on_near_face].mean() > 0.95
    assert not visible[behind].any()
    assert behind.sum() > 0.7 * len(points)


def test_truth_poses_match_the_recorded_tf_and_seen_bits(tmp_path):
    simulate(str(tmp_path / "t.mcap"), SimulationOptions(frames=3, width=160, height=120, scene="random", seed=5,
                                                         tf_tree=True))
    doc = json.load(open(tmp_path / "t.truth.json"))
    truth = read_truth(str(tmp_path / "t.truth.json"))
    with Recording(str(tmp_path / "t.mcap")) as rec:
        frames = list(rec.frames())
    assert len(frames) == 3
    for frame in frames:
        np.testing.assert_allclose(frame.T_camera_object, truth.pose_at(frame.timestamp_ns), atol=1e-6)
    n = sum(len(e["seen"]) for e in doc["edges"])
    bits = np.array([np.unpackbits(np.frombuffer(base64.b64decode(p["seen"]), np.uint8))[:n] for p in doc["poses"]])
    assert np.array_equal(bits.sum(axis=0), np.concatenate([e["seen"] for e in doc["edges"]]))
    assert 0 < bits.mean() < 1


def test_bad_random_options_say_what_to_do(tmp_path):
    with pytest.raises(AccumError, match="unknown shape 'star'.*expected one of box, prism"):
        simulate(str(tmp_path / "x.mcap"), SimulationOptions(**SMALL, shape="star"))
    with pytest.raises(AccumError, match=r"size_mm only apply to scene='random'; add scene='random'"):
        simulate(str(tmp_path / "x.mcap"), SimulationOptions(frames=1, size_mm=40.0))
    with pytest.raises(AccumError, match="distance_m = 9.0 is out of range; use 0.25 to 3.0"):
        simulate(str(tmp_path / "x.mcap"), SimulationOptions(**SMALL, distance_m=9.0))


def _lefts(path) -> np.ndarray:
    with Recording(str(path)) as rec:
        return np.array([frame.left.astype(float) for frame in rec.frames()])


def test_pinned_blur_and_illumination_act_on_the_images(tmp_path):
    base = SimulationOptions(frames=3, width=160, height=120, scene="random", seed=8, noise_sigma=0.0,
                             illumination=0.0, shape="box")
    for name, options in (("sharp", dataclasses.replace(base, blur_sigma=0.0)),
                          ("blurred", dataclasses.replace(base, blur_sigma=1.1)),
                          ("drifting", dataclasses.replace(base, blur_sigma=0.0, illumination=0.2))):
        simulate(str(tmp_path / f"{name}.mcap"), options)
    sharp, blurred, drifting = (_lefts(tmp_path / f"{n}.mcap") for n in ("sharp", "blurred", "drifting"))
    # the blurred recording is the sharp one blurred with sigma 1.1 px (up to 8-bit rounding)
    reblurred = np.array([cv2.GaussianBlur(image, (0, 0), 1.1) for image in sharp])
    assert np.abs(reblurred - blurred)[:, 5:-5, 5:-5].max() <= 1.0
    assert np.abs(np.diff(sharp, axis=2)).mean() > 1.3 * np.abs(np.diff(blurred, axis=2)).mean()
    # without drift the background corner holds still; with drift its exposure changes
    corner = (slice(None), slice(0, 12), slice(0, 12))
    assert np.ptp(sharp[corner], axis=0).max() == 0
    assert np.abs(np.diff(drifting[corner], axis=0)).mean() > 2.0


def test_options_that_would_fail_deep_inside_are_refused_up_front():
    from accumcli.simulation import SimulationOptions
    from accumcli.simulation.simulate import SimulationOptionError

    for options, message in ((dict(frames=0), "frames 0: expected at least 1"), (dict(width=0), "width 0"),
                             (dict(supersample=0), "supersample 0"), (dict(baseline=0.0), "baseline 0.0"),
                             (dict(encoding="bmp"), "encoding 'bmp': expected png, jpeg or mono8")):
        with pytest.raises(SimulationOptionError, match=message):
            SimulationOptions(**options)
