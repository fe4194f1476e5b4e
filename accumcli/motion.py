"""Repairing noisy recorded poses before accumulation (``--motion tracked``), in passes over the recording.

Refining each frame's recorded pose against the model accumulated so far fails at 1.5 deg / 4 mm of
gripper noise: the young model holds background, and the model accumulated with noisy poses is
smeared, so the refinement converges 2-40 deg off or is lost. What the images do give precisely is
the motion between two consecutive frames: frame k's own extracted segments (one triangulation, no
pose smear) refined on frame k+1's images. So:

1. pass 1 accumulates with the recorded poses: a smeared but background-free skeleton (the static
   background contradicts itself and is removed);
2. pass 2 keeps, of each frame's extracted segments placed by its recorded pose, those within
   ``near_m`` / ``near_deg`` of a pass-1 accepted segment (the object's), refines the recorded pose
   of each of the next ``span`` frames against them (``track.refine_pose``), and keeps each
   'tracked' result as a measurement of the correction between the two frames;
3. the corrections are fused with the recorded poses (``fuse``): a chain of small linear least
   squares, one per axis; the result is used by the ordinary accumulation (a third pass).

The recording is streamed once per pass; kept are the object segments of the last ``span`` frames
and, per frame, its recorded pose and ``span`` corrections of six numbers.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import solveh_banded
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from .geometry import invert, make_transform
from .segments import Segments
from .track import TrackParams, refine_pose

log = logging.getLogger("accumcli")


@dataclass(frozen=True)
class MotionParams:
    """``near_m`` / ``near_deg``: a frame's segment is the object's when its centre is this close to
    the line of a pass-1 accepted segment (and within its extent plus ``near_m``) and its direction
    this close (the pass-1 model is smeared by the noise, a few mm); ``sigma_relative_deg`` /
    ``sigma_relative_m``: the standard deviation of a verified frame-to-frame correction per axis
    (measured on random scenes: median 0.2-0.5 deg, 0.2-1 mm); ``gate_sigmas``: a correction further
    than this many standard deviations of the recorded poses' difference is not believed (a
    refinement can verify at a wrong local minimum, 6-22 deg or 12-14 mm off on the random scenes);
    ``span``: each frame is refined against the object segments of the ``span`` frames before it
    (a second link bridges a failed one, and a wrong one contradicts the others: on seeds 301-306 a
    span of 2 halved the median shortfall from the exact poses' model, 3 did not help further);
    ``residual_sigmas``: after the fusion, the correction furthest from the fused poses (in
    relative sigmas on any axis) is dropped while it is further than this, and the rest fused again
    (None: never); ``max_std_deg`` / ``max_std_mm``: the frame-to-frame refinement's limits on its
    standard deviations, twice ``TrackParams``' (one frame's 20-40 object segments determine a pose
    less than a model does; the gate and the residual test catch the wrong ones: on seeds 301-306
    the median shortfall 0.032 -> 0.029, the worst 0.099 -> 0.088)."""

    near_m: float = 0.01
    near_deg: float = 12.0
    sigma_relative_deg: float = 0.3
    sigma_relative_m: float = 0.001
    gate_sigmas: float = 3.0
    span: int = 2
    residual_sigmas: float | None = 2.0
    max_std_deg: float = 0.6
    max_std_mm: float = 2.0


def object_segments(segments_camera: Segments, T_recorded: np.ndarray, skeleton: Segments,
                    params: MotionParams) -> Segments:
    """The segments of one frame (camera frame) that lie on the skeleton (object frame, accepted
    segments), in the object frame by ``T_recorded`` (T_camera_object, (4, 4)), all accepted."""
    s = segments_camera.transformed(invert(T_recorded), skeleton.frame_id)
    if not len(s) or not len(skeleton):
        return s.select(np.zeros(len(s), bool))
    # candidate pairs by centre distance (a pair that passes lies within near_m + reach of each other)
    radius = 2 * params.near_m + (skeleton.lengths.max() + s.lengths.max()) / 2
    pairs = cKDTree(s.centers).sparse_distance_matrix(cKDTree(skeleton.centers), radius, output_type="ndarray")
    n, m = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    rel = s.centers[n] - skeleton.centers[m]                                   # (P, 3) metres
    along = np.sum(rel * skeleton.directions[m], axis=1)
    across = np.sqrt(np.maximum(np.sum(rel ** 2, axis=1) - along ** 2, 0.0))
    angle = np.degrees(np.arccos(np.clip(np.abs(np.sum(s.directions[n] * skeleton.directions[m], axis=1)), 0, 1)))
    reach = (skeleton.lengths[m] + s.lengths[n]) / 2 + params.near_m
    near = (across < params.near_m) & (angle < params.near_deg) & (np.abs(along) < reach)
    keep = np.zeros(len(s), bool)
    keep[n[near]] = True
    s = s.select(keep)
    s.confidence = np.ones(len(s))
    s.observations = np.ones(len(s), np.int64)
    return s


def correction(T_recorded: np.ndarray, T_refined: np.ndarray) -> np.ndarray:
    """(6,) the refined pose in the recorded one's object frame, ``T_recorded^-1 T_refined``, as
    (rotation vector rad, translation m)."""
    C = invert(T_recorded) @ T_refined
    return np.concatenate([Rotation.from_matrix(C[:3, :3]).as_rotvec(), C[:3, 3]])


def fuse(corrections: dict[tuple[int, int], np.ndarray], n: int, params: MotionParams) -> np.ndarray:
    """(n, 6) corrections x_k (object frame: rotation vector rad, translation m) of the n recorded
    poses, ``T_k = T_recorded_k exp(x_k)``.

    ``corrections[j, k]`` (j < k, k - j <= ``span``) measures ``x_k - x_j`` (frame j's segments refined
    on frame k: its pose is ``T_recorded_k exp(c)`` in frame j's gauge; to first order ``c = x_k - x_j``).
    The recorded poses are unbiased with a standard deviation ``s`` per axis, estimated from the
    corrections themselves (their median norm, for a 3D normal difference of two poses 1.538 sqrt(2) s;
    never below the relative sigma ``r``): every axis minimises ``sum x_k^2 / s^2 + sum (x_k - x_j -
    c_jk)^2 / r^2``, a banded system. A correction beyond ``gate_sigmas`` of ``sqrt(2 s^2 + r^2)``
    on any axis is dropped, and then, one at a time, the correction furthest from the fused poses
    while it is more than ``residual_sigmas`` r away on an axis (a wrong correction that other links
    contradict). Frames linked by corrections share one gauge (their mean error, reduced by the
    square root of their number); unlinked frames keep their recorded pose."""
    r = np.repeat([np.radians(params.sigma_relative_deg), params.sigma_relative_m], 3)
    x = np.zeros((n, 6))
    if not corrections or n < 2:
        return x
    c = np.stack(list(corrections.values()))
    s = np.maximum(np.repeat([np.median(np.linalg.norm(c[:, :3], axis=1)),
                              np.median(np.linalg.norm(c[:, 3:], axis=1))], 3) / (1.538 * np.sqrt(2)), r)
    gate = params.gate_sigmas * np.sqrt(2 * s ** 2 + r ** 2)
    used = {jk: v for jk, v in corrections.items() if 0 <= jk[0] < jk[1] < n and np.all(np.abs(v) <= gate)}
    log.info("motion: %d of %d frame-to-frame corrections used; recorded poses' sigma %.2f deg, %.1f mm",
             len(used), len(corrections), np.degrees(s[0]), s[3] * 1000)
    while True:
        x = _solve(used, n, s, r)
        if not used or params.residual_sigmas is None:
            return x
        worst, ratio = max(((jk, np.max(np.abs(x[jk[1]] - x[jk[0]] - v) / r)) for jk, v in used.items()),
                           key=lambda item: item[1])
        if ratio <= params.residual_sigmas:
            return x
        del used[worst]


def _solve(used: dict, n: int, s: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(n, 6) the least-squares corrections of ``fuse`` for the corrections ``used``, per axis."""
    x = np.zeros((n, 6))
    band = max([k - j for j, k in used] or [1])
    for axis in range(6):
        banded = np.zeros((band + 1, n))          # upper form: banded[band + i - j, j] = H[i, j]
        banded[band] = 1 / s[axis] ** 2
        rhs = np.zeros(n)
        w = 1 / r[axis] ** 2
        for (j, k), v in used.items():
            banded[band, k] += w
            banded[band, j] += w
            banded[band + j - k, k] -= w
            rhs[k] += w * v[axis]
            rhs[j] -= w * v[axis]
        x[:, axis] = solveh_banded(banded, rhs)
    return x


def corrected(T_recorded: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``T_recorded exp(x)`` (4, 4), x (6,) as ``fuse`` returns."""
    return T_recorded @ make_transform(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:])


def frame_to_frame(previous: Segments, frame, T_recorded: np.ndarray, track: TrackParams,
                   gradients=None, params: MotionParams = MotionParams()) -> np.ndarray | None:
    """The correction (``correction``) of frame's recorded pose measured against an earlier
    frame's object segments (``previous``: object frame, in that frame's recorded gauge), or None
    unless the refinement is 'tracked' (with ``params``' limits on its standard deviations)."""
    if len(previous) < 3:
        return None
    # every sample on the wide levels too: 20-40 segments with one point each were too few there
    # (seed 302: 0.944 / 0.448 with three, 0.879 / 0.436 with one)
    track = replace(track, max_std_deg=params.max_std_deg, max_std_mm=params.max_std_mm,
                    coarse_samples_per_segment=track.samples_per_segment)
    estimate = refine_pose(previous, frame, T_recorded, track, gradients=gradients)
    if estimate.status != "tracked":
        return None
    return correction(T_recorded, estimate.T_camera_object)
