"""Rigid transforms as (4, 4) float64 matrices, and the few operations on them.

``T_a_b`` maps points in frame b into frame a (see the package docstring).
Rotation conversions use scipy's ``Rotation`` (quaternions ``xyzw``), except the exponential and
angle of one rotation on the tracker's hot path (``rotation_about_point`` and ``extrapolate``: OpenCV's ``Rodrigues``;
``rotation_angle_deg``: atan2 of the skew part's norm and trace - 1, precise near 0 and 180 degrees;
``orthonormalized``: one compiled SVD): 6x faster than ``Rotation`` for a single matrix, whose per-call
overhead was a tenth of the tracking time.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .errors import InputError

RIGID_TOLERANCE = 1e-4   # max |R^T R - I|: chained products of estimated poses drift by ~1e-5


def check_transform(T, name: str = "T_camera_object") -> np.ndarray:
    """``T`` as a (4, 4) float64 rigid transform; raises ``InputError`` naming ``name`` and what is
    wrong: the shape, a non-finite entry, the last row, ``R^T R`` farther than ``RIGID_TOLERANCE``
    from I, or a reflection (det R < 0). Within the tolerance, R is returned projected onto the
    nearest rotation (SVD), so that products of checked poses do not drift further."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise InputError(f"{name}: expected a (4, 4) rigid transform, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise InputError(f"{name}: expected a (4, 4) rigid transform, got non-finite entries (NaN or inf)")
    if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(f"{name}: not a rigid transform: the last row must be [0, 0, 0, 1], got "
                         f"[{', '.join(f'{x:.3g}' for x in T[3])}] (a transposed matrix?)")
    R = T[:3, :3]
    deviation = float(np.abs(R.T @ R - np.eye(3)).max())
    if deviation > RIGID_TOLERANCE:
        raise InputError(f"{name}: not rigid: R^T R differs from I by {deviation:.3g}")
    if np.linalg.det(R) < 0:
        raise InputError(f"{name}: not rigid: det R = {np.linalg.det(R):.3g}, a reflection")
    return orthonormalized(T) if deviation > 1e-12 else T


def check_points(P, name: str = "points") -> np.ndarray:
    """``P`` as (N, 3) float64 finite points (rows); raises ``InputError`` naming ``name``."""
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"{name}: expected (N, 3) points, got shape {P.shape}")
    if not np.isfinite(P).all():
        bad = int((~np.isfinite(P)).any(axis=1).sum())
        raise InputError(f"{name}: expected finite (N, 3) points, got {bad} of {len(P)} with NaN or inf")
    return P


def make_transform(rotation: np.ndarray, translation) -> np.ndarray:
    """(4, 4) transform from a (3, 3) rotation and a (3,) translation in metres."""
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation
    return T


def transform_from_quat(translation, quat_xyzw) -> np.ndarray:
    """(4, 4) transform from a translation (metres) and a unit quaternion xyzw."""
    return make_transform(Rotation.from_quat(np.asarray(quat_xyzw, float)).as_matrix(), translation)


def quat_from_transform(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(translation (3,), quat_xyzw (4,)) of a transform; the quaternion has w >= 0."""
    q = Rotation.from_matrix(T[:3, :3]).as_quat()
    if q[3] < 0:
        q = -q
    return T[:3, 3].copy(), q


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform: ``invert(T_a_b) == T_b_a``."""
    R = T[:3, :3]
    return make_transform(R.T, -R.T @ T[:3, 3])


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply ``T_a_b`` to ``points: (N, 3)`` in b; returns (N, 3) in a."""
    return points @ T[:3, :3].T + T[:3, 3]


def inside_box(points: np.ndarray, box: np.ndarray) -> np.ndarray:
    """(N,) bool: ``points: (N, 3)`` within ``box: (3, 2)`` (per axis min, max; same frame and unit)."""
    return np.all((points >= box[:, 0]) & (points <= box[:, 1]), axis=1)


def rotate_vectors(T: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Rotate ``vectors: (N, 3)`` (directions, no translation) by ``T``."""
    return vectors @ T[:3, :3].T


def interpolate(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Pose at fraction ``s`` in [0, 1] between T0 and T1: linear translation, slerp rotation."""
    rotations = Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]]))
    R = Slerp([0.0, 1.0], rotations)([s]).as_matrix()[0]
    return make_transform(R, (1.0 - s) * T0[:3, 3] + s * T1[:3, 3])


def extrapolate(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Pose at fraction ``s`` of the way from T0 to T1 at constant velocity, ``s`` any real (beyond 1:
    a prediction): the rotation ``exp(s log(R1 R0^T)) R0`` and the origin moving on the line through
    both translations (an object turning about itself, not about the camera)."""
    step = cv2.Rodrigues(T1[:3, :3] @ T0[:3, :3].T)[0]
    R = cv2.Rodrigues(s * step)[0] @ T0[:3, :3]
    return make_transform(R, T0[:3, 3] + s * (T1[:3, 3] - T0[:3, 3]))


def rotation_about_point(rotvec: np.ndarray, pivot: np.ndarray, translation) -> np.ndarray:
    """(4, 4) transform ``p -> R (p - pivot) + pivot + translation`` with ``R = exp(rotvec)``
    (rotation vector (3,), radians; pivot and translation (3,), metres): a rotation about
    ``pivot`` followed by a translation, each taken as it is. This is not the SE(3)
    exponential of a twist (whose translation would be ``V(rotvec) @ translation``); for
    Gauss-Newton increments it keeps rotation and translation decoupled."""
    R = cv2.Rodrigues(np.asarray(rotvec, np.float64).reshape(3, 1))[0]
    return make_transform(R, pivot + translation - R @ pivot)


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle in degrees of a (3, 3) rotation: atan2 of the skew part's norm (2 sin) and trace - 1
    (2 cos), precise near 0 and 180 degrees (arccos of the trace alone loses precision near zero)."""
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])     # 2 sin(angle) axis
    return float(np.degrees(np.arctan2(np.linalg.norm(skew), np.trace(R) - 1.0)))


def orthonormalized(T: np.ndarray) -> np.ndarray:
    """``T`` (4, 4) with its rotation projected onto the nearest rotation (SVD, compiled:
    ``pose_kernel.nearest_rotation``): products of many small increments drift from orthonormal."""
    from .pose_kernel import nearest_rotation   # here: importing this module must not load numba

    return make_transform(nearest_rotation(np.ascontiguousarray(T[:3, :3], np.float64)), T[:3, 3])


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(rotation error in degrees, translation error in metres) between two poses."""
    dR = T_est[:3, :3].T @ T_true[:3, :3]
    return rotation_angle_deg(dR), float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))


def mean_transform(Ts: np.ndarray) -> np.ndarray:
    """Mean of ``Ts: (N, 4, 4)`` rigid transforms (chordal mean rotation, mean translation)."""
    R = Rotation.from_matrix(Ts[:, :3, :3]).mean().as_matrix()
    return make_transform(R, Ts[:, :3, 3].mean(axis=0))


def unit(vectors: np.ndarray) -> np.ndarray:
    """Rows of ``vectors: (N, 3)`` scaled to unit length."""
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def skew(vectors: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the cross-product matrices [v]_x of ``vectors`` (..., 3): [v]_x w = v x w."""
    v = np.asarray(vectors, float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def unit_or_zero(vectors: np.ndarray) -> np.ndarray:
    """Rows of ``vectors: (..., 3)`` scaled to unit length; zero rows stay zero (``unit`` gives NaN)."""
    return vectors / np.maximum(np.linalg.norm(vectors, axis=-1, keepdims=True), 1e-12)


def outer(vectors: np.ndarray) -> np.ndarray:
    """(N, 3, 3) outer products v v^T of the rows of ``vectors: (N, 3)``."""
    return vectors[:, :, None] * vectors[:, None, :]
