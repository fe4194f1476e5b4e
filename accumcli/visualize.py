"""Rerun logging: the only module that imports rerun (rerun-sdk 0.41).

One ``RerunLog`` wraps one ``rr.RecordingStream`` (never the global one) with
exactly one sink: an .rrd file, a spawned viewer, or a viewer at a gRPC URL.

Entity tree (``world`` is the left camera frame for ``extract``, the object
frame for ``accumulate``; optical axes, ``ViewCoordinates.RDF``)::

    world/camera                     Transform3D (camera pose in world) + Pinhole
    world/camera/image               left image; .../segments its 2D segments
    world/frame_segments             this frame's 3D segments
    world/model/{accepted,tentative} the model by confidence
    world/trajectory                 camera or object positions
    images/right, images/right/segments
    stats/<name>                     one time series per count

Timelines: ``frame`` (sequence: the frame index) and ``time`` (timestamp).
Rerun puts pixel centres at half-integers, accum at integers (see the package
docstring), so 2D overlays and the principal point are shifted by +0.5 px.
Images are logged as JPEG (quality ``JPEG_QUALITY``), so an .rrd stays near the
size of the recording.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import socket
import sys
import urllib.parse
import uuid
from pathlib import Path

import cv2
import numpy as np

# rerun's own log lines (colours and all, naming our temporary file) would come beside accum's one-line
# error when an .rrd cannot be written; accum reports every failure of the sink itself. RUST_LOG of
# the user's shell still wins, and a spawned viewer gets the user's environment (``RerunLog``).
_QUIETED = "RUST_LOG" not in os.environ
os.environ.setdefault("RUST_LOG", "off")
import rerun as rr  # noqa: E402  (after the setting above)
import rerun.blueprint as rrb  # noqa: E402

from .errors import AccumError
from .geometry import invert, transform_points
from .outputs import output_error

PIXEL = 0.5  # accum pixel (u, v) + PIXEL = rerun pixel coordinate
MATCHED, UNMATCHED = (40, 200, 60), (255, 140, 0)  # RGB of 2D segments with / without a 3D partner
FRAME_SEGMENTS = (230, 90, 30)
TRUTH = (220, 40, 160)   # a truth's edges: a colour of their own, not the model's blue
ACCUMULATE_STATS = ("size", "accepted", "confirmed", "new", "pruned", "precision", "completeness", "background")
KINDS = ("extract", "accumulate", "track", "view")
JPEG_QUALITY = 85


def jpeg(image: np.ndarray) -> rr.EncodedImage:
    """An (H, W) grey or (H, W, 3) BGR uint8 image as a JPEG ``rr.EncodedImage``."""
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError(f"could not encode a {image.shape} {image.dtype} image as JPEG")
    return rr.EncodedImage(contents=data.tobytes(), media_type="image/jpeg")


def viewer_executable() -> str:
    """The Rerun viewer to spawn: ``rerun`` beside this Python (its venv) or on PATH.
    AccumError "cannot start the Rerun viewer ...; use --rrd" when there is none, or
    (on Linux) when neither DISPLAY nor WAYLAND_DISPLAY is set."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise AccumError("cannot start the Rerun viewer: no display (DISPLAY and WAYLAND_DISPLAY are unset); "
                         "use --rrd and open the file where there is one")
    beside = Path(sys.executable).with_name("rerun")
    found = str(beside) if beside.is_file() and os.access(beside, os.X_OK) else shutil.which("rerun")
    if found is None:
        raise AccumError("cannot start the Rerun viewer: no 'rerun' executable beside this Python or on PATH; "
                         "use --rrd (or install rerun-sdk where the viewer can run)")
    return found


def model_path(name: str) -> str:
    """The entity path of a model shown by name (a file's name: spaces and the like escaped, which
    Rerun otherwise warns of on stderr)."""
    return f"world/model/{rr.escape_entity_path_part(name)}"


def blueprint(kind: str, images: bool = True) -> rrb.Blueprint:
    """Layout for ``kind``: the 3D world and, beside it, the left image with its overlays (and the
    model and truth projected into it) and the right image, and under them time series of
    ``stats/*`` (``accumulate``, ``track``); ``images`` False (a view without a recording): the
    world alone, no empty image panels."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r}, expected one of {KINDS}")
    world = rrb.Spatial3DView(origin="world", name="world")
    if not images:
        return rrb.Blueprint(world, collapse_panels=True)
    left = rrb.Spatial2DView(origin="world/camera", contents=["$origin/**", "/world/model/**", "/world/truth/**"],
                             name="left image")
    right = rrb.Spatial2DView(origin="images/right", name="right image")
    panels = [left, right]
    if kind in ("accumulate", "track"):
        panels.append(rrb.TimeSeriesView(origin="stats", name="counts"))
    return rrb.Blueprint(rrb.Horizontal(world, rrb.Vertical(*panels), column_shares=[3, 2]), collapse_panels=True)


def _strips(endpoints: np.ndarray) -> np.ndarray:
    """(N, 2, D) endpoints as float32 line strips of two points each."""
    return np.asarray(endpoints, np.float32).reshape(-1, 2, endpoints.shape[-1])


def _check_viewer_reachable(url: str) -> None:
    """AccumError unless something listens at the host and port of a Rerun gRPC ``url`` (rerun
    connects lazily and only fails at the end of the run, after its 6 s timeout)."""
    parsed = urllib.parse.urlparse(url)
    if parsed.scheme not in ("rerun", "rerun+http", "rerun+https") or not parsed.hostname:
        raise AccumError(f"--connect {url}: expected a Rerun viewer URL such as rerun+http://127.0.0.1:9876/proxy")
    port = parsed.port or 9876
    try:
        socket.create_connection((parsed.hostname, port), timeout=2.0).close()
    except OSError as e:
        raise AccumError(f"--connect {url}: no Rerun viewer answers at {parsed.hostname}:{port} ({e.strerror or e}); "
                         "start one with `rerun`, or write a file with --rrd") from None


def _rrd_problem(path: str, error: Exception) -> str:
    """Why Rerun's file writer stopped (it says only "File-writer thread shut down prematurely")."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        space = os.statvfs(folder)
        free = space.f_bavail * space.f_frsize
    except OSError:
        free = None
    if free is not None and free < 16 << 20:   # the message of a full disk under any other output
        return str(output_error(OSError(errno.ENOSPC, "no space"), f"the Rerun recording in {folder}"))
    return f"Rerun could not write the recording in {folder} ({error}); check the disk, or leave out --rrd"


@contextlib.contextmanager
def _viewer_environment():
    """The user's own environment while a viewer is started: its window, GPU or port errors must show."""
    if not _QUIETED:
        yield
        return
    os.environ.pop("RUST_LOG", None)
    try:
        yield
    finally:
        os.environ["RUST_LOG"] = "off"


class RerunLog:
    """Logs accum's frames, segments and models to one Rerun recording."""

    def __init__(self, app: str, rrd: str | None = None, kind: str = "view", spawn: bool = False,
                 connect: str | None = None, images: bool = True):
        """``app``: application id; exactly one of ``rrd`` (file path, works headless; give
        ``OutputSet.path(...)`` to make the .rrd part of a run's atomic set), ``spawn``
        (start a viewer; AccumError from ``viewer_executable`` where none can run) or
        ``connect`` (gRPC URL, e.g. ``rerun+http://127.0.0.1:9876/proxy``); ``images``: whether
        the layout has image panels (``blueprint``)."""
        if (rrd is not None) + bool(spawn) + (connect is not None) != 1:
            raise ValueError("RerunLog needs exactly one sink: rrd, spawn or connect")
        layout = blueprint(kind, images)
        executable = viewer_executable() if spawn else None
        self.rec = rr.RecordingStream(app, recording_id=uuid.uuid4())
        if rrd is not None:
            self.rec.save(str(rrd))
        elif spawn:
            try:
                with _viewer_environment():
                    rr.spawn(executable_path=executable, recording=self.rec)
            except Exception as e:  # the viewer failed to start (rerun raises RuntimeError and others)
                raise AccumError(f"cannot start the Rerun viewer ({type(e).__name__}: {e}); use --rrd") from None
        else:
            _check_viewer_reachable(connect)
            try:
                self.rec.connect_grpc(connect)
            except (RuntimeError, ValueError) as e:   # rerun: an invalid endpoint
                raise AccumError(f"--connect {connect}: {e}") from None
        self.connect, self.rrd = connect, rrd
        self.rec.send_blueprint(layout)
        self.rec.log("world", rr.ViewCoordinates.RDF, static=True)

    def set_frame(self, index: int, timestamp_ns: int) -> None:
        """Timelines ``frame`` (sequence) and ``time`` (timestamp, nanoseconds since the epoch)."""
        self.rec.set_time("frame", sequence=int(index))
        self.rec.set_time("time", timestamp=np.datetime64(int(timestamp_ns), "ns"))

    def camera(self, intrinsics, T_world_camera: np.ndarray | None = None) -> None:
        """``world/camera``: its pose (if given) and a pinhole from ``StereoIntrinsics`` (left camera)."""
        if T_world_camera is not None:
            self.rec.log("world/camera", rr.Transform3D(translation=T_world_camera[:3, 3],
                                                        mat3x3=T_world_camera[:3, :3]))
        K = intrinsics.K.copy()
        K[:2, 2] += PIXEL
        self.rec.log("world/camera", rr.Pinhole(image_from_camera=K, resolution=[intrinsics.width, intrinsics.height],
                                                camera_xyz=rr.ViewCoordinates.RDF))

    def images(self, frame) -> None:
        """The rectified left image on ``world/camera/image``, the right one on ``images/right``, as JPEG."""
        self.rec.log("world/camera/image", jpeg(frame.left))
        self.rec.log("images/right", jpeg(frame.right))

    def segments_2d(self, result) -> None:
        """2D segments of a ``FrameSegments`` in both images; those that became 3D segments in MATCHED colour."""
        for path, segs, used in (("world/camera/image/segments", result.left, result.left_index),
                                 ("images/right/segments", result.right, result.right_index)):
            matched = np.zeros(len(segs), bool)
            matched[np.asarray(used, int)] = True
            colors = np.where(matched[:, None], MATCHED, UNMATCHED).astype(np.uint8)
            self.rec.log(path, rr.LineStrips2D(_strips(segs.endpoints() + PIXEL), colors=colors,
                                               radii=rr.Radius.ui_points(1.0), draw_order=10.0))

    def segments_3d(self, path: str, segments, T_world_frame: np.ndarray) -> None:
        """``segments`` (in their frame) as line strips in world; ``T_world_frame`` maps their frame into world."""
        ends = transform_points(T_world_frame, segments.endpoints().reshape(-1, 3)).reshape(-1, 2, 3)
        self.rec.log(path, rr.LineStrips3D(_strips(ends), colors=FRAME_SEGMENTS, radii=rr.Radius.ui_points(1.0)))

    def model(self, model, T_world_object: np.ndarray = np.eye(4), path: str = "world/model") -> None:
        """The model (object frame) in world: accepted segments blue, tentative ones light grey,
        each darker the more confident; under ``path``/accepted and ``path``/tentative."""
        c = model.confidence[:, None]
        blue = np.column_stack([60 * (1 - c), 60 + 100 * (1 - c), 140 + 115 * (1 - c)])
        grey = np.repeat(230 - 120 * c, 3, axis=1)
        colors = np.where(model.accepted[:, None], blue, grey).astype(np.uint8)
        ends = transform_points(T_world_object, model.endpoints().reshape(-1, 3)).reshape(-1, 2, 3)
        for name, keep, width in (("accepted", model.accepted, 2.0), ("tentative", ~model.accepted, 1.0)):
            self.rec.log(f"{path}/{name}", rr.LineStrips3D(_strips(ends[keep]), colors=colors[keep],
                                                                radii=rr.Radius.ui_points(width)))

    def truth(self, truth, T_world_object: np.ndarray = np.eye(4), path: str = "world/truth") -> None:
        """A truth's edges (``Segments``, object frame) in world, in ``TRUTH`` colour on ``path``."""
        ends = transform_points(T_world_object, truth.endpoints().reshape(-1, 3)).reshape(-1, 2, 3)
        self.rec.log(path, rr.LineStrips3D(_strips(ends), colors=TRUTH, radii=rr.Radius.ui_points(1.0)))

    def scalars(self, values: dict) -> None:
        """One ``stats/<name>`` time series per finite numeric value."""
        for name, value in values.items():
            if isinstance(value, (int, float, np.number)) and not isinstance(value, bool) and np.isfinite(value):
                self.rec.log(f"stats/{name}", rr.Scalars(float(value)))

    def trajectory(self, positions: np.ndarray) -> None:
        """``positions``: (N, 3) metres in world, as one line strip."""
        self.rec.log("world/trajectory", rr.LineStrips3D([np.asarray(positions, np.float32)],
                                                         colors=(120, 120, 255), radii=rr.Radius.ui_points(1.0)))

    def extraction(self, frame, result) -> None:
        """One frame of ``accum extract``: world = left camera frame."""
        self.set_frame(frame.index, frame.timestamp_ns)
        self.camera(frame.intrinsics, np.eye(4))
        self.images(frame)
        self.segments_2d(result)
        self.segments_3d("world/frame_segments", result.segments, np.eye(4))

    def accumulation(self, step, model, row: dict) -> None:
        """One frame of ``accum accumulate``: world = object frame; ``model`` in it; counts from ``row``."""
        frame = step.frame
        T_object_camera = invert(step.T_camera_object)
        self.set_frame(frame.index, frame.timestamp_ns)
        self.camera(frame.intrinsics, T_object_camera)
        self.images(frame)
        self.segments_2d(step.extraction)
        self.segments_3d("world/frame_segments", step.extraction.segments, T_object_camera)
        self.model(model)
        self.scalars({k: row[k] for k in ACCUMULATE_STATS if k in row})

    def recording_frame(self, frame, models: dict, T_camera_object: np.ndarray | None, source: str = "recorded",
                        truth=None, T_camera_truth: np.ndarray | None = None) -> None:
        """One frame of ``accum view`` on a recording: world = left camera frame (``posed``), and the
        frame's camera and images."""
        self.set_frame(frame.index, frame.timestamp_ns)
        self.camera(frame.intrinsics, np.eye(4))
        self.images(frame)
        self.posed(models, T_camera_object, source, truth, T_camera_truth)

    def posed(self, models: dict, T_camera_object: np.ndarray | None, source: str, truth=None,
              T_camera_truth: np.ndarray | None = None) -> None:
        """At the current time, in world = the left camera frame: each model (name -> Segments) placed
        at the object pose ``T_camera_object`` on ``world/model/<name>`` (so the left image shows it
        too), or cleared where there is no pose; ``source``, where the pose comes from (a poses file's
        status and reason), on ``pose_source``; ``truth`` (Segments or None) on ``world/truth`` at the
        truth's own pose ``T_camera_truth`` (cleared where it has none), so that a wrong pose shows
        against it."""
        self.rec.log("pose_source", rr.TextLog(source, level="INFO" if T_camera_object is not None else "WARN"))
        if truth is not None:
            if T_camera_truth is None:
                self.rec.log("world/truth", rr.Clear(recursive=True))
            else:
                self.truth(truth, T_camera_truth)
        if T_camera_object is None:
            self.rec.log("world/model", rr.Clear(recursive=True))
            self.rec.log("world/object", rr.Clear(recursive=False))
            return
        for name, model in models.items():
            self.model(model, T_camera_object, model_path(name))
        self.rec.log("world/object", rr.Transform3D(translation=T_camera_object[:3, 3],
                                                    mat3x3=T_camera_object[:3, :3]),
                     rr.TransformAxes3D(0.05))

    def frame_segments(self, index: int, timestamp_ns: int, segments, T_world_camera: np.ndarray = np.eye(4)) -> None:
        """One line of a frames file: its 3D segments (left camera frame) in world."""
        self.set_frame(index, timestamp_ns)
        self.segments_3d("world/frame_segments", segments, T_world_camera)

    def tracking(self, frame, model, estimate, trajectory: list) -> None:
        """One frame of ``accum track``: world = left camera frame; the model placed at the
        estimated pose (so it overlays the left image), the trajectory so far, residual and inliers."""
        self.set_frame(frame.index, frame.timestamp_ns)
        self.camera(frame.intrinsics, np.eye(4))
        self.images(frame)
        if np.isfinite(estimate.T_camera_object).all():
            self.model(model.select(model.accepted), estimate.T_camera_object, "world/model")
        if len(trajectory) > 1:
            self.trajectory(np.array(trajectory))
        self.scalars({"residual_px": estimate.residual_px, "inliers": estimate.inliers,
                      "tracked": float(estimate.status == "tracked")})

    def close(self) -> None:
        """Flush everything to the sink and detach from it (an .rrd is complete afterwards)."""
        try:
            self.rec.flush()
        except RuntimeError as e:   # rerun: the viewer went away, or never answered; or the file's disk is full
            if self.connect is not None:
                raise AccumError(f"the Rerun viewer at {self.connect} did not take the data ({e}); "
                                 "start it with `rerun`, or write a file with --rrd") from None
            if self.rrd is not None:
                raise AccumError(_rrd_problem(str(self.rrd), e)) from None
            raise
        self.rec.disconnect()

    def __enter__(self) -> "RerunLog":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
