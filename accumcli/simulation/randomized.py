"""Rendering a random scene (``SimulationOptions(scene="random")``) with exact truth.

Visibility of an edge sample in one camera, from that camera's triangle z-buffer
at the supersampled pixel the sample projects to (nearest pixel centre):
- in front (z > 5 cm) and inside the image (3 px from its border);
- unoccluded: the winning surface there lies on a plane through the sample
  (within 0.2 mm: the sample's own face or the other face of its crease, or a
  decal on one), or is no nearer than the sample minus 1 mm (the sample is on a
  silhouette over what lies behind);
- not seen end-on: the edge makes at least ``MIN_VIEW_ANGLE_DEG`` with the
  sample's viewing ray (an edge pointing at the camera draws no line);
- on a grey-level step: in the camera's noise-free image (after shading,
  exposure and blur, before noise) the grey levels 2 px to either side of the
  projected edge differ by at least ``MIN_STEP_GREY``.
A sample is seen in a frame when it is visible in both cameras.
"""

from __future__ import annotations

import base64
import json
from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np

from ..atomic import atomic_open
from ..edge_sampling import SAMPLE_SPACING_M, edge_samples, sample_count
from ..geometry import make_transform, quat_from_transform, transform_points
from ..recording import RecordingWriter, Topics
from .random_scene import (
    BACKGROUNDS,
    RANDOM_SHAPES,
    draw_lighting,
    draw_motion,
    make_clutter,
    make_random_background,
    make_random_gripper,
    make_random_object,
    random_trajectory,
)
from .raster import Buffers, Mesh, draw
from .simulate import (
    FRAME_PERIOD_NS,
    RAW_MARGIN_PX,
    START_NS,
    SimulationOptionError,
    SimulationOptions,
    SimulationResult,
    _calibrations,
    _interpolate_at,
    _rectified_camera,
    _write_poses,
    project_inside,
)

MIN_STEP_GREY = 6.0
STEP_OFFSET_PX = 2.0
COPLANAR_M = 2e-4
MIN_VIEW_ANGLE_DEG = 5.0
OCCLUSION_TOLERANCE_M = 0.001
STREAMS = {"draws": 1, "object": 2, "gripper": 3, "background": 4, "clutter": 5, "motion": 6, "light": 7,
           "noise": 8, "calibration": 9}


def _stream(seed: int, name: str) -> np.random.Generator:
    return np.random.default_rng([seed, 7103, STREAMS[name]])


@dataclass(frozen=True)
class RandomDraws:
    """The resolved scene parameters (pinned or drawn); see ``SimulationOptions``."""

    shape: str
    size_mm: float
    distance_m: float
    contrast: float
    background_albedo: float
    object_albedo: float
    blur_sigma: float
    noise_sigma: float
    illumination: float
    background: str
    clutter: bool
    per_frame_deg: float


def draw_parameters(o: SimulationOptions) -> RandomDraws:
    """Draw every parameter from the seed, in a fixed order, then apply the options' pins."""
    rng = _stream(o.seed, "draws")
    drawn = dict(shape=RANDOM_SHAPES[int(rng.integers(len(RANDOM_SHAPES)))], size_mm=rng.uniform(30, 120),
                 distance_m=rng.uniform(0.45, 0.85), contrast=rng.uniform(0.05, 0.45),
                 blur_sigma=rng.uniform(0.5, 1.2), noise_sigma=rng.uniform(0.5, 2.5),
                 illumination=rng.uniform(0.0, 0.2), background=BACKGROUNDS[int(rng.integers(len(BACKGROUNDS)))],
                 clutter=bool(rng.uniform() < 0.3), per_frame_deg=rng.uniform(6, 12))
    background_albedo, sign = rng.uniform(0.25, 0.75), rng.choice([-1.0, 1.0])
    for name in drawn:
        if getattr(o, name) is not None:
            drawn[name] = getattr(o, name)
    _check(drawn)
    contrast = float(drawn["contrast"])
    albedo = background_albedo + sign * contrast
    if not 0.05 <= albedo <= 0.95:
        albedo = background_albedo - sign * contrast
    return RandomDraws(background_albedo=float(background_albedo), object_albedo=float(np.clip(albedo, 0.03, 0.97)),
                       **{k: (v if isinstance(v, (str, bool)) else float(v)) for k, v in drawn.items()})


def _check(d: dict) -> None:
    if d["shape"] not in RANDOM_SHAPES:
        raise SimulationOptionError(f"unknown shape {d['shape']!r} (expected one of {', '.join(RANDOM_SHAPES)})")
    if d["background"] not in BACKGROUNDS:
        raise SimulationOptionError(f"unknown background {d['background']!r} "
                                    f"(expected one of {', '.join(BACKGROUNDS)})")
    limits = dict(size_mm=(5, 400), distance_m=(0.25, 3.0), contrast=(0.0, 0.9), blur_sigma=(0.0, 5.0),
                  noise_sigma=(0.0, 20.0), illumination=(0.0, 0.5), per_frame_deg=(0.0, 45.0))
    for name, (lo, hi) in limits.items():
        if not lo <= float(d[name]) <= hi:
            raise SimulationOptionError(f"{name} = {d[name]} is out of range; use {lo} to {hi}")


@dataclass
class World:
    """Everything the frames need: moving meshes (object frame), static buffers per camera, truth edges."""

    draws: RandomDraws
    moving: Mesh
    edges: list  # (a, b, part, kind)
    static: list  # Buffers per camera (left, right)
    key_poses: np.ndarray
    tf_times: np.ndarray
    truth_poses: np.ndarray
    image_times: np.ndarray
    lighting: object


def build_world(o: SimulationOptions, render_camera, camera) -> World:
    d = draw_parameters(o)
    size = d.size_mm / 1000
    obj, half_width = make_random_object(d.shape, size, d.object_albedo, _stream(o.seed, "object"))
    gripper = make_random_gripper(obj, half_width, _stream(o.seed, "gripper"))
    moving = Mesh.of(obj.polygons + gripper.polygons)
    edges = [(a, b, "object", k) for a, b, k in obj.edges] + [(a, b, "gripper", k) for a, b, k in gripper.edges]

    tan_half = (camera.width / 2 / camera.fx, camera.height / 2 / camera.fy)
    motion = draw_motion(_stream(o.seed, "motion"), d.distance_m, size, d.per_frame_deg, tan_half)
    image_times = START_NS + FRAME_PERIOD_NS * np.arange(o.frames, dtype=np.int64)
    if o.tf_tree:
        tf_times = image_times[0] - 13_000_000 + (FRAME_PERIOD_NS // 3) * np.arange(3 * o.frames + 2, dtype=np.int64)
    else:
        tf_times = image_times
    key_poses = random_trajectory((tf_times - START_NS) / FRAME_PERIOD_NS, motion)
    truth_poses = np.stack([_interpolate_at(tf_times, key_poses, t) for t in image_times])

    vertices = np.concatenate([p.vertices for p in obj.polygons + gripper.polygons])
    placed = np.stack([transform_points(T, vertices) for T in truth_poses])
    boxes = np.stack([placed.min(axis=1), placed.max(axis=1)], axis=1)
    reach = float(np.max(placed[..., 2]))
    static_polygons = make_random_background(d.background, _stream(o.seed, "background"), d.background_albedo,
                                             reach + 0.05, float(np.max(placed[..., 1])) + 0.02, tan_half)
    if d.clutter:
        for solid in make_clutter(_stream(o.seed, "clutter"), d.distance_m, boxes, tan_half, d.background_albedo):
            static_polygons += solid
    static_mesh = Mesh.of(static_polygons, first_id=len(moving.albedo))
    lighting = draw_lighting(_stream(o.seed, "light"), o.frames, d.illumination)
    static = []
    for T_cam_left in (np.eye(4), make_transform(np.eye(3), [-o.baseline, 0.0, 0.0])):
        buffers = Buffers.empty(render_camera, o.supersample)
        draw(buffers, static_mesh, T_cam_left, render_camera, o.supersample, lighting.light[0], lighting.ambient)
        static.append(buffers)
    return World(d, moving, edges, static, key_poses, tf_times, truth_poses, image_times, lighting)


def visible_samples(points_obj: np.ndarray, tangents_obj: np.ndarray, T_cam_obj: np.ndarray, buffers: Buffers,
                    moving: Mesh, image: np.ndarray, camera, supersample: int, margin: int) -> np.ndarray:
    """(M,) bool: samples (object frame, metres) visible in one camera (module docstring); ``image``
    the noise-free (H, W) float32 grey levels of that camera with ``margin`` px on each side."""
    p = transform_points(T_cam_obj, points_obj)
    z, u, v, ok = project_inside(p, camera)
    along = np.abs(np.sum((tangents_obj @ T_cam_obj[:3, :3].T) * p, axis=1)) / np.linalg.norm(p, axis=1)
    ok &= along < np.cos(np.radians(MIN_VIEW_ANGLE_DEG))
    S = supersample
    H, W = buffers.depth.shape
    cols = np.clip(np.round((u + margin + 0.5) * S - 0.5).astype(int), 0, W - 1)
    rows = np.clip(np.round((v + margin + 0.5) * S - 0.5).astype(int), 0, H - 1)
    winner, depth = buffers.ids[rows, cols], buffers.depth[rows, cols]
    behind = depth >= z - OCCLUSION_TOLERANCE_M
    own = (winner >= 0) & (winner < len(moving.albedo))
    coplanar = np.zeros(len(z), bool)
    mine = np.flatnonzero(own)
    face = winner[mine]
    distance = np.sum(moving.normals[face] * points_obj[mine], axis=1) - moving.offsets[face]
    coplanar[mine] = np.abs(distance) < COPLANAR_M
    ok &= behind | coplanar
    # the image normal of the projected edge, from a point 1 mm along it
    q = transform_points(T_cam_obj, points_obj + 0.001 * tangents_obj)
    qz = np.where(q[:, 2] > 0.05, q[:, 2], 1.0)
    du, dv = camera.fx * q[:, 0] / qz + camera.cx - u, camera.fy * q[:, 1] / qz + camera.cy - v
    norm = np.hypot(du, dv) + 1e-12
    nu, nv = -dv / norm, du / norm
    grey = [cv2.remap(image, (u + margin + s * STEP_OFFSET_PX * nu).astype(np.float32).reshape(1, -1),
                      (v + margin + s * STEP_OFFSET_PX * nv).astype(np.float32).reshape(1, -1), cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REPLICATE).ravel() for s in (-1, 1)]
    return ok & (np.abs(grey[1] - grey[0]) >= MIN_STEP_GREY)


def simulate_random(output: str, o: SimulationOptions, topics: Topics, truth_path: str, progress,
                    visibility: list | None) -> SimulationResult:
    """``simulate`` for ``scene="random"``: same files, same recording layout as the classic scene."""
    camera = _rectified_camera(o)
    margin = RAW_MARGIN_PX if o.raw else 0
    render_camera = camera.with_margin(margin)
    S = o.supersample
    world = build_world(o, render_camera, camera)
    d = world.draws
    calibrations, raw_maps = _calibrations(o, camera, _stream(o.seed, "calibration"))
    edge_list = [(a, b) for a, b, _, _ in world.edges]
    counts = [sample_count(a, b, SAMPLE_SPACING_M) for a, b in edge_list]
    samples = np.concatenate([edge_samples(a, b, k) for (a, b), k in zip(edge_list, counts)])
    tangents = np.concatenate([np.repeat(((b - a) / np.linalg.norm(b - a))[None], k, axis=0)
                               for (a, b), k in zip(edge_list, counts)])
    seen = np.zeros(len(samples), np.int64)
    bits = []
    noise_rng = _stream(o.seed, "noise")
    T_right_left = make_transform(np.eye(3), [-o.baseline, 0.0, 0.0])
    meta = {**asdict(replace(o, **{k: getattr(d, k) for k in ("shape", "size_mm", "distance_m", "contrast",
                                                                "blur_sigma", "noise_sigma", "illumination",
                                                                "background", "clutter", "per_frame_deg")})),
            "object_albedo": d.object_albedo, "background_albedo": d.background_albedo}
    with RecordingWriter(output) as writer:
        writer.metadata("simulation", {**meta, "generator": "accum simulate"})
        for side, cal in zip(("left", "right"), calibrations):
            writer.calibration(getattr(topics, f"{side}_calibration"), cal, int(world.image_times[0]))
        _write_poses(writer, topics, o, world.tf_times, world.key_poses, None)
        for i, (t_ns, T_cam_obj) in enumerate(zip(world.image_times, world.truth_poses)):
            light, gain, offset = world.lighting.light[i], world.lighting.gain[i], world.lighting.offset[i]
            visible = np.ones(len(samples), bool)
            for side, T_cam_left, static in zip(("left", "right"), (np.eye(4), T_right_left), world.static):
                buffers = static.copy()
                T = T_cam_left @ T_cam_obj
                draw(buffers, world.moving, T, render_camera, S, light, world.lighting.ambient)
                if o.raw:  # the raw pixels sample the box-filtered supersampled render: one interpolation
                    map_x, map_y = ((m + 0.5) * S - 0.5 for m in raw_maps[side == "right"])
                    area = cv2.remap(cv2.blur(buffers.color, (S, S)), map_x.astype(np.float32),
                                     map_y.astype(np.float32), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                    rectified = _expose(cv2.resize(buffers.color, None, fx=1 / S, fy=1 / S,
                                                   interpolation=cv2.INTER_AREA), gain, offset, d.blur_sigma)
                else:
                    area = cv2.resize(buffers.color, None, fx=1 / S, fy=1 / S, interpolation=cv2.INTER_AREA)
                clean = _expose(area, gain, offset, d.blur_sigma)
                visible &= visible_samples(samples, tangents, T, buffers, world.moving,
                                           rectified if o.raw else clean, camera, S, margin)
                noisy = clean + noise_rng.normal(0.0, d.noise_sigma, clean.shape).astype(np.float32)
                image = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
                writer.image(getattr(topics, f"{side}_image"), image, int(t_ns), f"camera_{side}", o.encoding)
            seen += visible
            bits.append(base64.b64encode(np.packbits(visible).tobytes()).decode("ascii"))
            if visibility is not None:
                visibility.append(visible)
            if progress:
                progress(i + 1)
    truth = _truth(meta, world, counts, seen, bits, camera)
    with atomic_open(truth_path) as f:
        json.dump(truth, f, indent=1)
    return SimulationResult(output, truth_path, o.frames, len(world.edges), float(np.mean(seen >= 3)))


def _expose(area: np.ndarray, gain: float, offset: float, blur_sigma: float) -> np.ndarray:
    """Grey levels (float32) of shaded albedo ``area``: gain and offset of the exposure, then optics blur."""
    out = area * np.float32(255.0 * gain) + np.float32(offset)
    return cv2.GaussianBlur(out, (0, 0), blur_sigma) if blur_sigma > 0 else out


def _truth(meta: dict, world: World, counts: list, seen: np.ndarray, bits: list, camera) -> dict:
    starts = np.concatenate([[0], np.cumsum(counts)])
    edges = [{"a": [round(float(x), 9) for x in a], "b": [round(float(x), 9) for x in b], "part": part,
              "kind": kind, "seen": seen[starts[i]:starts[i + 1]].tolist()}
             for i, (a, b, part, kind) in enumerate(world.edges)]
    poses = []
    for t_ns, T, frame_bits in zip(world.image_times, world.truth_poses, bits):
        translation, quat = quat_from_transform(T)
        poses.append({"timestamp_ns": int(t_ns), "translation": translation.tolist(),
                      "rotation_xyzw": quat.tolist(), "seen": frame_bits})
    return {"format": "accum.truth/1", "object_frame": "gripper", "camera_frame": "camera_left",
            "edges": edges, "poses": poses,
            "visibility": {"step_m": SAMPLE_SPACING_M, "min_contrast_grey": MIN_STEP_GREY,
                           "about": "edge 'seen'[i]: frames in which sample i (at t = (i + 0.5) / n from a to b) "
                                    "was unoccluded, inside both images and on a grey-level step >= "
                                    "min_contrast_grey in both noise-free images; pose 'seen': base64 of "
                                    "numpy.packbits of that frame's flags, samples of all edges in order"},
            "simulation": {**meta, "fx": camera.fx, "cx": camera.cx, "cy": camera.cy,
                           "edge_parts": {"object": "the held object", "gripper": "fingers, palm and wrist"},
                           "edge_kinds": {"crease": "edge between two faces of a solid",
                                          "paint": "boundary of a painted mark on a face"}}}
