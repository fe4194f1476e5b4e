"""``accum simulate``: deterministic stereo recordings with ground truth.

A seeded scene (``scene.py``) is rendered (``render.py``) into a rectified
stereo pair per frame, written as an MCAP recording per formats.md, with the
truth sidecar of formats.md section 4: the object's and gripper's true edges in
the object frame, the true poses, and per edge sample the number of frames in
which it was seen (in front of the camera, inside both images, not hidden in
either depth buffer, and on a grey-level step of at least ``MIN_STEP`` in both
noise-free images).

Options beyond the default: ``raw`` writes distorted images with a small
rectifying rotation in the calibration (``distortion``: by the ``plumb_bob``
model, or ``fisheye``, written under Foxglove's name ``kannala_brandt``, ROS's
``equidistant``); ``tf_tree`` writes a static
world -> camera_left transform on /tf_static and world -> gripper at three times
the image rate, offset in time from the images (the truth is the
interpolation the reader must do, so it stays exact); ``pose_noise`` perturbs
the written gripper poses (RMS degrees, RMS metres) while the truth stays exact.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from ..atomic import atomic_open
from ..edge_sampling import SAMPLE_SPACING_M, edge_samples, sample_count
from ..errors import AccumError
from ..geometry import (
    interpolate,
    make_transform,
    quat_from_transform,
    transform_points,
    unit,
)
from ..recording import CameraCalibration, RecordingWriter, Topics
from .render import PinholeCamera, empty_layer, finish_image, rasterize, reduce
from .scene import SHAPES, make_background, make_gripper, make_object, trajectory

START_NS = 1_750_000_000 * 1_000_000_000
FRAME_PERIOD_NS = 100_000_000
MIN_STEP = 10.0 / 255.0
OCCLUSION_TOLERANCE_M = 0.004
RAW_MARGIN_PX = 40
DISTORTIONS = ("plumb_bob", "fisheye")


class SimulationOptionError(AccumError, ValueError):
    """An option of the simulator that cannot be used (unknown shape, a value out of range)."""


@dataclass(frozen=True)
class SimulationOptions:
    """What to render. ``scene="classic"`` (the default) is the original fixed scene: a box, prism or
    house (``shape``, default box) of about 100 mm at about 0.5 m before a wall with rectangles at 1.1 m,
    noise 2.0 and blur 0.6 px unless given, 9.8 deg per frame; its recordings are byte for byte those of
    the simulator before the random scene existed (the committed sample regenerates unchanged).

    ``scene="random"`` draws every field left None from the seed (each from its own stream, so pinning
    one leaves the others' draws unchanged):

    - ``shape``: uniform among ``RANDOM_SHAPES`` (box, prism (hexagonal), wedge, trapezoid, house,
      and the non-convex L, T, U, steps, cross), extruded; width : height : depth drawn as
      1 : U(0.55, 1) : U(0.35, 1);
    - ``size_mm``: the object's largest dimension, U(30, 120) mm;
    - ``distance_m``: the depth of the object's path centre, U(0.45, 0.85) m;
    - ``contrast``: |object albedo - background mean albedo|, U(0.05, 0.45); background mean U(0.25,
      0.75), the sign drawn (flipped if the object would leave [0.05, 0.95]); each face x U(0.8, 1.2);
      0 to 4 painted bands or windows at +-U(0.15, 0.4) from their face;
    - ``blur_sigma``: Gaussian optics blur, U(0.5, 1.2) px; ``noise_sigma``: U(0.5, 2.5) grey levels;
    - ``illumination``: drift amplitude U(0, 0.2): exposure gain 1 +- it, offset +- 30 x it grey levels,
      the light turning by up to 200 x it deg over the sequence; faces are shaded by their normal
      (Lambert, ambient U(0.3, 0.6), light from the camera's side, azimuth +-45, elevation 10 to 60 deg);
    - ``background``: uniform among "texture", "planes", "lines" (see ``random_scene``);
    - ``clutter``: True with probability 0.3: 4 to 8 static solids at the object's depth (+-0.12 m)
      beside, above and below its path, never within 5 mm of the object or gripper;
    - ``per_frame_deg``: the peak yaw rate, U(6, 12) deg per frame (motion in ``random_scene.draw_motion``:
      yaw, pitch and roll swings, the gripper coming from above or, half of the time, from behind).
    A two-finger gripper with palm and wrist sized to the object (grey levels U(0.15, 0.8)) holds it; its
    edges are in the truth (``part`` "gripper", ``kind`` "crease"; the object's are "crease" or "paint").
    Random scenes are rendered by the triangle z-buffer (``raster.py``); their truth's ``seen`` follows
    the rule in ``randomized.py`` (unoccluded in the z-buffer, inside both images, a grey-level step of
    at least 6 in both noise-free images).
    """

    frames: int = 36
    width: int = 640
    height: int = 480
    shape: str | None = None
    seed: int = 0
    raw: bool = False
    distortion: str = "plumb_bob"   # of raw images: plumb_bob or fisheye
    tf_tree: bool = False
    pose_noise_deg: float = 0.0
    pose_noise_m: float = 0.0
    encoding: str = "png"
    baseline: float = 0.08
    noise_sigma: float | None = None
    blur_sigma: float | None = None
    supersample: int = 4
    per_frame_deg: float | None = None
    scene: str = "classic"
    size_mm: float | None = None
    distance_m: float | None = None
    contrast: float | None = None
    illumination: float | None = None
    background: str | None = None
    clutter: bool | None = None

    def __post_init__(self):
        """The options whose wrong values would fail deep inside, or write a recording accum refuses."""
        problems = [f"{name} {getattr(self, name)!r}: expected {want}" for name, ok, want in (
            ("frames", isinstance(self.frames, int) and self.frames >= 1, "at least 1"),
            ("width", isinstance(self.width, int) and self.width >= 16, "at least 16 px"),
            ("height", isinstance(self.height, int) and self.height >= 16, "at least 16 px"),
            ("supersample", isinstance(self.supersample, int) and self.supersample >= 1, "at least 1"),
            ("baseline", isinstance(self.baseline, (int, float)) and self.baseline > 0, "more than 0 m"),
            ("encoding", self.encoding in ("png", "jpeg", "mono8"), "png, jpeg or mono8"),
            ("distortion", self.distortion in DISTORTIONS, " or ".join(DISTORTIONS))) if not ok]
        if problems:
            raise SimulationOptionError("; ".join(problems))


CLASSIC_FIELDS = ("frames", "width", "height", "shape", "seed", "raw", "distortion", "tf_tree", "pose_noise_deg",
                  "pose_noise_m", "encoding", "baseline", "noise_sigma", "blur_sigma", "supersample", "per_frame_deg")
RANDOM_ONLY = ("size_mm", "distance_m", "contrast", "illumination", "background", "clutter")
SCENES = ("classic", "random")


def _classic(o: SimulationOptions) -> SimulationOptions:
    """The classic scene's options with its defaults filled in; random-only options refused."""
    pinned = [name for name in RANDOM_ONLY if getattr(o, name) is not None]
    if pinned:
        raise SimulationOptionError(f"{', '.join(pinned)} only apply to scene='random'; "
                                    f"add scene='random' (accum simulate --scene random)")
    if o.shape is not None and o.shape not in SHAPES:
        raise SimulationOptionError(f"unknown shape {o.shape!r} for the classic scene (expected one of "
                                    f"{', '.join(SHAPES)}); the random scene has more")
    return replace(o, shape=o.shape or "box", noise_sigma=2.0 if o.noise_sigma is None else o.noise_sigma,
                   blur_sigma=0.6 if o.blur_sigma is None else o.blur_sigma,
                   per_frame_deg=9.8 if o.per_frame_deg is None else o.per_frame_deg)


@dataclass
class SimulationResult:
    recording: str
    truth: str
    frames: int
    edges: int
    seen_fraction: float  # of edge samples seen in at least 3 frames


def _rectified_camera(o: SimulationOptions) -> PinholeCamera:
    f = 600.0 * o.width / 640.0
    return PinholeCamera(f, f, (o.width - 1) / 2.0, (o.height - 1) / 2.0, o.width, o.height)


def _calibrations(o: SimulationOptions, camera: PinholeCamera, rng: np.random.Generator):
    """Left and right CameraCalibration, and for raw images the raw -> rectified pixel maps."""
    P = np.array([[camera.fx, 0.0, camera.cx, 0.0], [0.0, camera.fy, camera.cy, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P_right = P.copy()
    P_right[0, 3] = -camera.fx * o.baseline
    calibrations, raw_maps = [], []
    for side, P_side in (("left", P), ("right", P_right)):
        frame_id = f"camera_{side}"
        if not o.raw:
            calibrations.append(CameraCalibration(o.width, o.height, P[:, :3].copy(), np.zeros(5), np.eye(3),
                                                  P_side, "plumb_bob", frame_id))
            continue
        K = np.array([[camera.fx * rng.uniform(1.01, 1.04), 0.0, camera.cx + rng.uniform(-6, 6)],
                      [0.0, camera.fy * rng.uniform(1.01, 1.04), camera.cy + rng.uniform(-6, 6)], [0.0, 0.0, 1.0]])
        D = np.array([rng.uniform(-0.15, -0.08), rng.uniform(0.01, 0.04), rng.uniform(-1e-3, 1e-3),
                      rng.uniform(-1e-3, 1e-3), 0.0])
        R = Rotation.from_rotvec(rng.normal(0.0, np.radians(0.5), 3)).as_matrix()
        grid = np.stack(np.meshgrid(np.arange(o.width, dtype=np.float64), np.arange(o.height, dtype=np.float64)),
                        axis=-1).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9)
        fisheye = o.distortion == "fisheye"
        if fisheye:   # r = f theta (1 + k1 theta^2 + ...): a mild fisheye's k1..k4
            D = np.array([D[1], rng.uniform(-0.01, 0.01), 0.0, 0.0])
            rect = cv2.fisheye.undistortPoints(grid, K, D.reshape(1, 4), R=R, P=P[:, :3], criteria=criteria)
        else:
            rect = cv2.undistortPoints(grid, K, D, R=R, P=P[:, :3], criteria=criteria)
        rect = rect.reshape(o.height, o.width, 2)
        model = "kannala_brandt" if fisheye else "plumb_bob"   # Foxglove's names
        calibrations.append(CameraCalibration(o.width, o.height, K, D, R, P_side, model, frame_id))
        raw_maps.append(((rect[..., 0] + RAW_MARGIN_PX).astype(np.float32),
                         (rect[..., 1] + RAW_MARGIN_PX).astype(np.float32)))
    return calibrations, raw_maps


def _sample_edges(edges: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge samples at ``a + (i + 0.5) / k (b - a)``: points (M, 3), tangents (M, 3), edge index (M,)."""
    points, tangents, owner = [], [], []
    for index, (a, b, _) in enumerate(edges):
        k = sample_count(a, b, SAMPLE_SPACING_M)
        points.append(edge_samples(a, b, k))
        tangents.append(np.repeat(unit((b - a)[None]), k, axis=0))
        owner.append(np.full(k, index))
    return np.concatenate(points), np.concatenate(tangents), np.concatenate(owner)


def project_inside(points_cam: np.ndarray, camera: PinholeCamera):
    """Depth z (M,) metres, pixel (u, v) (M,) each, and (M,) bool: in front (z > 5 cm) and at least 3 px
    inside the image, of points (M, 3) in the camera frame."""
    z = points_cam[:, 2]
    ok = z > 0.05
    zs = np.where(ok, z, 1.0)
    u = camera.fx * points_cam[:, 0] / zs + camera.cx
    v = camera.fy * points_cam[:, 1] / zs + camera.cy
    ok &= (u >= 3) & (u <= camera.width - 4) & (v >= 3) & (v <= camera.height - 4)
    return z, u, v, ok


def _visible(points_cam: np.ndarray, tangents_cam: np.ndarray, camera: PinholeCamera, depth_min: np.ndarray,
             clean: np.ndarray, supersample: int, margin: int) -> np.ndarray:
    """(M,) bool: samples in front, inside the image, unoccluded and on a grey-level step."""
    z, u, v, ok = project_inside(points_cam, camera)
    S = supersample
    us = np.clip(np.round((u + margin + 0.5) * S - 0.5).astype(int), 0, depth_min.shape[1] - 1)
    vs = np.clip(np.round((v + margin + 0.5) * S - 0.5).astype(int), 0, depth_min.shape[0] - 1)
    ok &= z <= depth_min[vs, us] + OCCLUSION_TOLERANCE_M
    ahead = points_cam + 0.001 * tangents_cam
    za = np.where(ahead[:, 2] > 0.05, ahead[:, 2], 1.0)
    du = camera.fx * ahead[:, 0] / za + camera.cx - u
    dv = camera.fy * ahead[:, 1] / za + camera.cy - v
    norm = np.hypot(du, dv) + 1e-12
    nu, nv = -dv / norm, du / norm
    sample = [cv2.remap(clean, (u + margin + s * 2.0 * nu).astype(np.float32).reshape(1, -1),
                        (v + margin + s * 2.0 * nv).astype(np.float32).reshape(1, -1), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE).ravel() for s in (-1, 1)]
    return ok & (np.abs(sample[1] - sample[0]) >= MIN_STEP)


def simulate(output: str, options: SimulationOptions = SimulationOptions(), topics: Topics = Topics(),
             truth_output: str | None = None, progress=None, visibility: list | None = None) -> SimulationResult:
    """Render and write ``output`` (.mcap) and its truth sidecar (``NAME.truth.json``).

    ``progress(frames_done)`` is called after each frame; if ``visibility`` is a
    list, each frame's (S,) bool array of visible edge samples (in the truth's
    sample order) is appended to it, for measuring single stages per frame.
    """
    if options.scene not in SCENES:
        raise SimulationOptionError(f"unknown scene {options.scene!r} (expected one of {', '.join(SCENES)})")
    if options.scene == "random":
        from .randomized import simulate_random
        return simulate_random(output, options, topics, truth_output or _truth_path(output), progress, visibility)
    o = _classic(options)
    meta = {name: getattr(o, name) for name in CLASSIC_FIELDS}
    rng = np.random.default_rng(o.seed)
    camera = _rectified_camera(o)
    margin = RAW_MARGIN_PX if o.raw else 0
    render_camera = camera.with_margin(margin)
    S = o.supersample
    obj, half_width = make_object(o.shape, rng)
    object_top = min(p.vertices[:, 1].min() for p in obj.polygons)
    gripper = make_gripper(half_width, object_top)
    background = make_background(rng, camera.width / 2 / camera.fx)
    # the raw calibration draws from its own generator: with and without --raw, scene and motion are the same
    calibrations, raw_maps = _calibrations(o, camera, np.random.default_rng([o.seed, 3]))
    phase = rng.uniform(0, 2 * np.pi)
    moving = obj.polygons + gripper.polygons
    edges = obj.edges + gripper.edges

    image_times = START_NS + FRAME_PERIOD_NS * np.arange(o.frames, dtype=np.int64)
    if o.tf_tree:  # gripper clock: three samples per frame, 13 ms before the images, covering them all
        tf_times = image_times[0] - 13_000_000 + (FRAME_PERIOD_NS // 3) * np.arange(3 * o.frames + 2,
                                                                                  dtype=np.int64)
    else:
        tf_times = image_times
    key_poses = trajectory((tf_times - START_NS) / FRAME_PERIOD_NS, phase, o.per_frame_deg)
    truth_poses = np.stack([_interpolate_at(tf_times, key_poses, t) for t in image_times])

    T_right_left = make_transform(np.eye(3), [-o.baseline, 0.0, 0.0])
    light0 = unit(np.array([[-0.4, -0.7, -0.6]]))[0]
    backgrounds = []
    for T_cam_left in (np.eye(4), T_right_left):
        layer = empty_layer(render_camera, S)
        rasterize(layer, background.polygons, T_cam_left, render_camera, S, light0)
        backgrounds.append(layer)

    samples, tangents, owner = _sample_edges(edges)
    seen = np.zeros(len(samples), np.int64)
    kernel = np.ones((3, 3), np.uint8)
    truth_path = truth_output or _truth_path(output)
    with RecordingWriter(output) as writer:
        writer.metadata("simulation", {**meta, "generator": "accum simulate"})
        for side, cal in zip(("left", "right"), calibrations):
            writer.calibration(getattr(topics, f"{side}_calibration"), cal, int(image_times[0]))
        _write_poses(writer, topics, o, tf_times, key_poses, rng)
        for i, (t_ns, T_cam_obj) in enumerate(zip(image_times, truth_poses)):
            gain = rng.uniform(0.9, 1.1)
            light = unit((light0 + rng.normal(0.0, 0.08, 3))[None])[0]
            visible = np.ones(len(samples), bool)
            for side, T_cam_left, base in zip(("left", "right"), (np.eye(4), T_right_left), backgrounds):
                layer = type(base)(base.color.copy(), base.depth.copy())
                T = T_cam_left @ T_cam_obj
                rasterize(layer, moving, T, render_camera, S, light)
                clean = reduce(layer, S)
                visible &= _visible(transform_points(T, samples), transform_points(T, tangents) -
                                    transform_points(T, np.zeros((1, 3))), camera, cv2.erode(layer.depth, kernel),
                                    clean, S, margin)
                if o.raw:  # sample the supersampled render, box-filtered, at the raw pixels: one interpolation
                    map_x, map_y = ((m + 0.5) * S - 0.5 for m in raw_maps[side == "right"])
                    clean = cv2.remap(cv2.blur(layer.color, (S, S)), map_x.astype(np.float32),
                                      map_y.astype(np.float32), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                image = finish_image(clean, gain, o.blur_sigma, o.noise_sigma, rng)
                writer.image(getattr(topics, f"{side}_image"), image, int(t_ns), f"camera_{side}", o.encoding)
            seen += visible
            if visibility is not None:
                visibility.append(visible)
            if progress:
                progress(i + 1)
    truth = _truth_document(meta, edges, samples, owner, seen, image_times, truth_poses, camera)
    with atomic_open(truth_path) as f:
        json.dump(truth, f, indent=1)
    counts = seen
    return SimulationResult(output, truth_path, o.frames, len(edges), float(np.mean(counts >= 3)))


def _truth_path(output: str) -> str:
    return (output[:-5] if output.endswith(".mcap") else output) + ".truth.json"


def _interpolate_at(times: np.ndarray, poses: np.ndarray, t: int) -> np.ndarray:
    i = int(np.searchsorted(times, t, side="right")) - 1
    if times[i] == t or i == len(times) - 1:
        return poses[i]
    return interpolate(poses[i], poses[i + 1], float((t - times[i]) / (times[i + 1] - times[i])))


def _write_poses(writer: RecordingWriter, topics: Topics, o: SimulationOptions, times: np.ndarray,
                 poses: np.ndarray, rng: np.random.Generator) -> None:
    """The gripper poses on /tf (optionally noisy; optionally through a world frame)."""
    noise_rng = np.random.default_rng([o.seed, 7])
    T_world_camera = make_transform(Rotation.from_euler("xyz", [-100, 5, 3], degrees=True).as_matrix(),
                                    [0.4, -0.2, 0.9])
    if o.tf_tree:
        writer.transform("world", "camera_left", T_world_camera, int(times[0]), topic=topics.tf_static)
    for t_ns, T_cam_obj in zip(times, poses):
        if o.pose_noise_deg or o.pose_noise_m:
            rotvec = noise_rng.normal(0.0, np.radians(o.pose_noise_deg) / np.sqrt(3), 3)
            shift = noise_rng.normal(0.0, o.pose_noise_m / np.sqrt(3), 3)
            T_cam_obj = T_cam_obj @ make_transform(Rotation.from_rotvec(rotvec).as_matrix(), shift)
        if o.tf_tree:
            writer.transform("world", "gripper", T_world_camera @ T_cam_obj, int(t_ns), topic=topics.tf)
        else:
            writer.transform("camera_left", "gripper", T_cam_obj, int(t_ns), topic=topics.tf)


# the scene's edge kinds as formats.md's part and kind (the random scene's terms)
PART_KIND = {"object": ("object", "crease"), "stripe": ("object", "paint"), "gripper": ("gripper", "crease")}


def _truth_document(meta: dict, edges, samples, owner, seen, image_times, poses, camera) -> dict:
    doc_edges = []
    for index, (a, b, kind) in enumerate(edges):
        part, kind = PART_KIND[kind]
        doc_edges.append({"a": [round(float(x), 9) for x in a], "b": [round(float(x), 9) for x in b],
                          "part": part, "kind": kind, "seen": seen[owner == index].tolist()})
    doc_poses = []
    for t_ns, T in zip(image_times, poses):
        translation, quat = quat_from_transform(T)
        doc_poses.append({"timestamp_ns": int(t_ns), "translation": translation.tolist(),
                          "rotation_xyzw": quat.tolist()})
    return {"format": "accum.truth/1", "object_frame": "gripper", "camera_frame": "camera_left",
            "edges": doc_edges, "poses": doc_poses,
            "simulation": {**meta, "fx": camera.fx, "cx": camera.cx, "cy": camera.cy,
                           "sample_spacing_m": SAMPLE_SPACING_M, "min_step_grey": MIN_STEP * 255,
                           "edge_kinds": {"crease": "edge of the object's polyhedron or of the gripper's "
                                                    "fingers, palm or wrist",
                                          "paint": "boundary of a painted stripe on the object"}}}
