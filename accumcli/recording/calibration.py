"""Stereo calibration with ROS CameraInfo semantics, and rectification.

A ``CameraCalibration`` holds K, D, R, P as recorded. ``StereoRectifier`` turns a
left/right pair of them into the rectified stereo intrinsics that everything
downstream uses, and (for raw images) the remap tables, computed once per
calibration. Images are taken as already rectified when D is zero, R is the
identity and K equals P's left 3x3 (pinhole models): then they pass through
untouched. Distortion models: ``plumb_bob`` and ``rational_polynomial`` (OpenCV's
pinhole model), and the fisheye model under its three names (ROS's
``equidistant``, Foxglove's ``kannala_brandt``, OpenCV's ``fisheye``: r = f
theta_d(theta) with D = k1..k4), rectified by ``cv2.fisheye``; a fisheye
camera's images are never taken as rectified, since theta is not tan(theta)
even with D zero.
``check_calibration`` refuses, before any table is allocated, what OpenCV
cannot use: a size outside 1..16384 pixels or beyond 16.8 Mpx, a distortion
vector that is not 0, 4, 5, 8, 12 or 14 long, non-finite K, D, R or P, focal
lengths that are not positive, and a baseline that is not finite and positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError, RecordingError

FISHEYE = {"equidistant", "kannala_brandt", "fisheye"}   # one model, ROS's, Foxglove's and OpenCV's name
SUPPORTED_DISTORTION = {"plumb_bob", "rational_polynomial", ""} | FISHEYE
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
MAX_SIDE = 16384          # pixels, width or height of an image or calibration
MAX_PIXELS = 3840 * 2160  # width * height (8.3 Mpx, 4K UHD): extraction needs ~120 bytes a pixel of a pair,
                          # so a larger pair would take more than 1 GB (and the fuzz limit is 2 GB)


def size_problem(width: int, height: int) -> str | None:
    """Why an image or calibration size (pixels) is refused, or None."""
    if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
        return f"size {width}x{height} is outside 1..{MAX_SIDE} pixels"
    if width * height > MAX_PIXELS:
        return f"size {width}x{height} exceeds the limit of {MAX_PIXELS / 1e6:.1f} Mpx (4K UHD); downscale the images"
    return None


@dataclass(frozen=True)
class CameraCalibration:
    """One camera's calibration as recorded (CameraInfo semantics).

    K: (3, 3) raw intrinsics, pixels; D: (n,) distortion; R: (3, 3) rectifying
    rotation; P: (3, 4) projection of the rectified camera (pixels, metres).
    """

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    R: np.ndarray
    P: np.ndarray
    distortion_model: str
    frame_id: str

    def __post_init__(self):
        """K, D, R and P as float arrays of their shapes (given as lists too); ``InputError`` otherwise."""
        for name, shape in (("K", (3, 3)), ("D", None), ("R", (3, 3)), ("P", (3, 4))):
            try:
                value = np.asarray(getattr(self, name), float)
            except (TypeError, ValueError):
                value = None
            if value is None or (shape is not None and value.shape != shape) or (shape is None and value.ndim != 1):
                raise InputError(f"calibration {self.frame_id!r}: {name} must be "
                                 f"{'a ' + 'x'.join(map(str, shape)) + ' matrix' if shape else 'a list of coefficients'}")
            object.__setattr__(self, name, value)

    @property
    def fisheye(self) -> bool:
        return self.distortion_model in FISHEYE

    @property
    def is_rectified(self) -> bool:
        return (not self.fisheye and not np.any(self.D) and np.allclose(self.R, np.eye(3))
                and np.allclose(self.K, self.P[:, :3]))

    def key(self) -> tuple:
        """Hashable identity, to reuse remap tables while the calibration is unchanged."""
        return (self.width, self.height, self.K.tobytes(), self.D.tobytes(), self.R.tobytes(), self.P.tobytes())


@dataclass(frozen=True)
class StereoIntrinsics:
    """The rectified stereo pair: pixels and metres, left camera optical frame.

    A point (X, Y, Z) in the left camera frame projects to
    ``u = fx X / Z + cx``, ``v = fy Y / Z + cy`` in the left image and to
    ``u - fx * baseline / Z`` (same v) in the right image.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    baseline: float
    width: int
    height: int

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project ``points: (N, 3)`` metres, left camera frame.

        Returns (uv_left (N, 2), uv_right (N, 2), z (N,)) in pixels, (u, v) order.
        """
        z = points[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.fx * points[:, 0] / z + self.cx
            v = self.fy * points[:, 1] / z + self.cy
            d = self.fx * self.baseline / z
        return np.stack([u, v], axis=1), np.stack([u - d, v], axis=1), z

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("fx", "fy", "cx", "cy", "baseline", "width", "height")}


def check_calibration(cal: CameraCalibration, side: str) -> None:
    """Raise ``RecordingError`` naming ``side`` if ``cal`` cannot be used (see the module docstring)."""
    problem = size_problem(cal.width, cal.height)
    if problem:
        raise RecordingError(f"{side} calibration: {problem}")
    if cal.distortion_model not in SUPPORTED_DISTORTION:
        raise RecordingError(f"{side} calibration: distortion model {cal.distortion_model!r} is not supported "
                             "(expected plumb_bob, rational_polynomial or equidistant / kannala_brandt); rectify the "
                             "images first (e.g. image_proc) and give their rectified topics with a distortion-free "
                             "calibration")
    if cal.fisheye and len(cal.D) != 4:
        raise RecordingError(f"{side} calibration: the {cal.distortion_model} (fisheye) model takes 4 coefficients "
                             f"k1..k4, D has {len(cal.D)}")
    if len(cal.D) not in DISTORTION_LENGTHS:
        raise RecordingError(f"{side} calibration: D has {len(cal.D)} coefficients "
                             f"(expected {', '.join(map(str, DISTORTION_LENGTHS))})")
    for name in ("K", "D", "R", "P"):
        if not np.isfinite(getattr(cal, name)).all():
            raise RecordingError(f"{side} calibration: {name} holds NaN or infinite values")
    if cal.P[0, 0] <= 0 or cal.P[1, 1] <= 0:
        raise RecordingError(f"{side} calibration: P has no positive focal length (uncalibrated camera)")
    if not cal.is_rectified:
        if cal.K[0, 0] <= 0 or cal.K[1, 1] <= 0:
            raise RecordingError(f"{side} calibration: K has no positive focal length (uncalibrated camera)")
        # rectification inverts P[:, :3] R (OpenCV 5.1 raises on a singular one, a traceback)
        with np.errstate(all="ignore"):     # huge entries overflow: then they fail the tests
            rotation = np.allclose(cal.R @ cal.R.T, np.eye(3), atol=1e-3) and np.linalg.det(cal.R) > 0
            singular = [name for name, m in (("P", cal.P[:, :3]), ("K", cal.K)) if not np.linalg.cond(m) < 1e12]
        if not rotation:
            raise RecordingError(f"{side} calibration: R is not a rotation (R R^T = I, det +1), so the images "
                                 f"cannot be rectified; check the CameraInfo's R")
        if singular:
            raise RecordingError(f"{side} calibration: {singular[0]} (its 3x3 part) is singular, so the images "
                                 f"cannot be rectified")


class StereoRectifier:
    """Rectified intrinsics and (if needed) remap tables for one left/right calibration."""

    def __init__(self, left: CameraCalibration, right: CameraCalibration, images_rectified: bool = False):
        """``images_rectified``: the images are rectified already whatever the calibration says (ROS's
        ``image_rect`` beside the raw camera's ``camera_info``): P alone describes them."""
        for side, cal in (("left", left), ("right", right)):
            check_calibration(cal, side)
        if (left.width, left.height) != (right.width, right.height):
            raise RecordingError(f"left and right calibrations differ in size: {left.width}x{left.height} vs "
                                 f"{right.width}x{right.height}")
        P_left, P_right = left.P, right.P
        if not np.allclose(P_left[:, :3], P_right[:, :3], rtol=1e-6, atol=1e-6):
            raise RecordingError("left and right P differ in their 3x3 part: the pair is not rectified to one camera "
                                 "(calibrate the two cameras as a stereo pair, e.g. OpenCV's stereoRectify or ROS's "
                                 "camera_calibration with both cameras)")
        baseline = -P_right[0, 3] / P_right[0, 0] + P_left[0, 3] / P_left[0, 0]
        if not np.isfinite(baseline) or baseline == 0:
            raise RecordingError(f"stereo calibration: the baseline is {baseline:g} m (expected finite and "
                                 f"positive, from the right P[0,3] = -fx * baseline, found {P_right[0, 3]:g}): "
                                 "were the cameras calibrated one by one? Calibrate them as a stereo pair")
        if baseline < 0:
            raise RecordingError(
                f"right calibration: P[0,3] = {P_right[0, 3]:g} has the wrong sign (expected -fx * baseline < 0, "
                f"a baseline of {-baseline:g} m; are left and right swapped?)")
        self.intrinsics = StereoIntrinsics(
            fx=float(P_left[0, 0]), fy=float(P_left[1, 1]), cx=float(P_left[0, 2]), cy=float(P_left[1, 2]),
            baseline=float(baseline), width=int(left.width), height=int(left.height))
        self.rectified_input = images_rectified or (left.is_rectified and right.is_rectified)
        self._maps = None if self.rectified_input else [_rectify_maps(c) for c in (left, right)]
        self.border_distance = self._border_distances()

    def _border_distances(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(left, right) (H, W) uint8: each rectified pixel's distance, px (chessboard metric: the
        reach of a square filter), to the nearest pixel that rectification did not fill wholly
        from inside the raw image, capped at 255; None when it filled every pixel (rectified input,
        or no pixel maps outside). Rectifying raw images of a toed-in or distorted pair leaves black
        wedges whose borders are strong straight edges, the same in every frame: matched with each
        other or with real edges they become 3D segments that do not move with the object, and a
        model segment inside a wedge cannot be seen."""
        if self._maps is None:
            return None
        full = np.full((self.intrinsics.height, self.intrinsics.width), 255, np.uint8)
        filled = [cv2.remap(full, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0) == 255
                  for m1, m2 in self._maps]
        if all(f.all() for f in filled):
            return None
        return tuple(np.minimum(cv2.distanceTransform(f.view(np.uint8), cv2.DIST_C, 3), 255).astype(np.uint8)
                     for f in filled)

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rectified (H, W) images; the inputs themselves when already rectified."""
        if self._maps is None:
            return left, right
        return tuple(cv2.remap(img, m1, m2, cv2.INTER_LINEAR) for img, (m1, m2) in zip((left, right), self._maps))


def _rectify_maps(cal: CameraCalibration) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's remap tables from ``cal``'s raw image to its rectified one (P's 3x3, same size)."""
    size = (cal.width, cal.height)
    if cal.fisheye:
        return cv2.fisheye.initUndistortRectifyMap(cal.K, cal.D.reshape(1, 4), cal.R, cal.P[:, :3], size,
                                                   cv2.CV_16SC2)
    return cv2.initUndistortRectifyMap(cal.K, cal.D, cal.R, cal.P[:, :3], size, cv2.CV_16SC2)
