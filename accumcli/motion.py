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
3. the corrections are fused with the recorded poses (``fuse``): one block-banded linear least squares
   over all frames, each link weighted by its images' information;
4. pass 3 accumulates with the fused poses, and each frame's fused pose is refined against that
   model's accepted segments (``on_model``); each refinement is one more measurement of its frame,
   and ``fuse`` solves again with the links, the recorded poses and these; the ordinary accumulation
   (the fifth pass over the frames: pass 3 reads them twice, to accumulate and to refine) uses the result,
   each frame's observations taking on its pose's uncertainty (``fuse``'s covariance, times
   ``covariance_scale``; ``line_model.pose_sigmas``): a frame that no refinement placed well gates
   wide and weighs little, instead of starting twins beside the segments its neighbours placed. The links rest on one frame's own segments, whose triangulation
   errors bias the out-of-plane rotation by 2-7 deg on some links; the model of all frames averages
   them out. On ``make motion``'s seeds 301-306 refining on the model took the worst shortfall from
   the exact poses' model from 0.044 to 0.027, on seeds 307-312, which nothing here was chosen on,
   from 0.119 to 0.055. Fusing the refinement with the rest instead of taking it as it is: seeds
   301-312 within 0.02 on 9 of 12 (7 before), median 0.009 (0.007), worst 0.109 (0.115), median pose
   error 0.53 deg (0.58). More rounds of 3-4 drift (2: 0.56 deg, 4: 0.68 deg): the model built with
   the fused poses agrees with them. The refinement itself is not the limit: against the model of the
   exact poses it reaches 0.18 deg / 0.38 mm on the same frames.

Measured and not kept (seeds 302-307 and 312, 4 runs each, 2026-12-07): the final accumulation trusting
the repaired poses' planes to 1 degree instead of 0.5 (every seed the same within 0.01); leaving out of it
the frames that no refinement verified ('linked' and 'recorded'): precision up (307 0.824 -> 0.953) but
completeness down as much (307 0.556 -> 0.474, 302 0.603 -> 0.455); leaving out only the 'recorded'
ones: 307's shortfall 0.079 -> 0.045, 301's 0.015 -> 0.024, the others the same.

The recording is streamed once per pass; kept are the object segments of the last ``span`` frames
and, per frame, its recorded pose and ``span`` corrections of six numbers.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from .geometry import invert, make_transform, skew
from .segments import Segments
from .track import TrackParams, refine_pose

log = logging.getLogger("accumcli")


@dataclass(frozen=True)
class MotionParams:
    """``near_m`` / ``near_deg``: a frame's segment is the object's when its centre is this close to
    the line of a pass-1 accepted segment (and within its extent plus ``near_m``) and its direction
    this close (the pass-1 model is smeared by the noise, a few mm); ``sigma_relative_deg`` /
    ``sigma_relative_m``: the least standard deviation per axis of the recorded poses (a floor of
    ``fuse``'s estimate) and a term of the gate; ``gate_sigmas``: a correction further than this many
    standard deviations of the recorded poses' difference is not believed (a refinement can verify at
    a wrong local minimum, 6-22 deg or 12-14 mm off on the random scenes), nor one whose chi-square
    against that difference over the six axes exceeds ``gate_chi2`` (6 degrees of freedom, 1 %: on
    seed 302 two links from one frame, 4 deg and 9-12 mm wrong and each within 3 sigma on every axis,
    agreed with each other and were the only ones to two frames, which they took 12.6 mm off; this
    halved the worst shortfall, 0.072 to 0.044, and 22.5 (0.1 %) let them through); ``span``: each frame is
    refined against the object segments of the ``span`` frames before it (a second link bridges a
    failed one, and a wrong one contradicts the others: on seeds 301-306 a span of 2 halved the median
    shortfall from the exact poses' model, 3 did not help further; on seeds 301-312, 2 runs each,
    2026-12-07, 4 against 2: the same median shortfall (0.012), repaired poses 0.54 degrees / 0.88 mm
    against 0.56 / 0.96, worst seed 0.065 against 0.087, but 301 and 310 0.019 -> 0.026 and 0.005 ->
    0.019: within the draws' scatter); ``residual_chi2``: after the
    fusion, the link furthest from the fused poses (chi-square of its information) is dropped while
    above this (6 degrees of freedom, 1 %), and the rest fused again (None: never);
    ``information_scale``: a link's image information is divided by this (its residuals are
    correlated along each edge, so the Gauss-Newton figure is too confident: measured on seeds 301-306);
    ``search_px`` / ``tukey_px``: the refinement's coarse-to-fine levels (the recorded poses are a few
    pixels off: the tracker's 40 and 24 px levels took it to clutter); ``prior_deg`` / ``prior_mm``: its
    prior about the recorded pose per axis, about the recorded poses' frame-to-frame error, and about
    the fused pose in ``on_model``; ``model_pass``: refine the fused poses on the model of
    pass 3 (step 4); ``model_gate_deg`` / ``model_gate_mm``: a refinement that moves a fused pose
    further is not believed (on seeds 301-312 no gate measured the same within noise);
    ``model_min_coverage``: the coverage that refinement needs (``on_model``); ``iterations_per_level``:
    the refinements' Gauss-Newton steps a level (the tracker's 10 took ``make motion`` from 10 to 8 of
    12 seeds within 0.02, worst 0.049 -> 0.078: ``information_scale`` and the gates were measured
    with 5); ``covariance_scale``: the fused poses' covariance (``fuse``) that the accumulation takes
    on (``FrameContext.pose_covariance``) is multiplied by this: against the truth of ``make motion``'s
    12 seeds (each frame's error less its seed's mean error, the gauge, which moves the whole model and
    no observation against another) the median of the squared errors over sigma of the six axes was
    1.36, where a calibrated covariance gives 0.455 (chi-square, one degree of freedom): the links'
    residuals stay correlated beyond ``information_scale``, and refinements verify at local minima a
    few tenths of a degree off. Since crowded pieces claim wider sigmas (``stereo.crowding``) the exact
    poses' models gained more precision than the tracked ones; without the pose covariance then
    (``make motion``'s tracked runs, 4 a seed, 2026-12-07): 7 of 12 within 0.02 of the exact poses'
    model against 8, median 0.015 against 0.014, worst 0.054 against 0.056 (301 0.056 -> 0.011, but
    302 0.036 -> 0.054, 304 0.003 -> 0.031): not kept."""

    near_m: float = 0.01
    near_deg: float = 12.0
    sigma_relative_deg: float = 0.1
    sigma_relative_m: float = 0.0003
    gate_sigmas: float = 3.0
    gate_chi2: float = 16.8
    span: int = 2
    residual_chi2: float | None = 16.8
    information_scale: float = 10.0
    search_px: tuple = (12.0, 6.0, 3.0)
    tukey_px: tuple = (6.0, 4.0, 2.5)
    prior_deg: float = 2.0
    prior_mm: float = 5.0
    model_pass: bool = True
    model_gate_deg: float = 3.0
    model_gate_mm: float = 8.0
    model_min_coverage: float = 0.3
    iterations_per_level: int = 5
    covariance_scale: float = 3.0


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


def fuse(links: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]], n: int, params: MotionParams,
         on_model: dict[int, tuple[np.ndarray, np.ndarray]] | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(n, 6) corrections x_k (object frame: rotation vector rad, translation m) of the n recorded
    poses, ``T_k = T_recorded_k exp(x_k)``.

    ``links[j, k] = (c, information)`` (j < k, k - j <= ``span``): frame j's segments refined on frame k
    measure ``x_k - x_j`` (to first order ``c``), with the (6, 6) information of the images in x's
    coordinates (``link_information``), divided here by ``information_scale``. ``on_model[k] = (m,
    information)``: frame k refined on the model of all frames measures ``x_k`` itself (``m``, the
    fused correction plus the refinement's, to first order), weighed the same way. The recorded poses
    are unbiased with a standard deviation ``s`` per axis, estimated from the links along their best
    seen rotation and translation directions (for the difference of two poses a median |N(0, 2 s^2)|;
    never below the relative sigma ``r``). All frames together minimise
    ``sum |x_k|^2 / s^2 + sum (x_k - x_j - c)^T L (x_k - x_j - c) + sum (x_k - m_k)^T M (x_k - m_k)``,
    one block-banded system: the images decide the directions they see (lateral, in-plane), the
    recorded poses the rest (depth and out-of-plane rotation of a small object: a link's 1 sigma there
    is 1-3 mm and about 0.5 deg).
    A link beyond ``gate_sigmas`` of ``sqrt(2 s^2 + r^2)`` on any axis, or whose chi-square against
    it over all six, ``sum c^2 / (2 s^2 + r^2)``, exceeds ``gate_chi2``, is dropped, and then, one at a
    time, the link furthest from the fused poses while its chi-square ``e^T L e`` exceeds
    ``residual_chi2`` (a wrong link that the others and the recorded poses contradict). Frames linked
    share one gauge (their mean error, reduced by the square root of their number); unlinked frames
    keep their recorded pose. Without links the recorded poses' sigma is unknown and nothing is fused.

    Also returns each frame's (6, 6) covariance of x_k (rad^2, m^2; the diagonal blocks of the
    normal equations' inverse; ``pose_covariance`` for the accumulation), or None where nothing is fused."""
    r = np.repeat([np.radians(params.sigma_relative_deg), params.sigma_relative_m], 3)
    x = np.zeros((n, 6))
    if not links or n < 2:
        return x, None
    s = np.maximum(np.repeat(_recorded_sigma(links.values()), 3), r)
    spread = 2 * s ** 2 + r ** 2     # the variance of two recorded poses' difference, per axis
    used = {jk: (c, L / params.information_scale) for jk, (c, L) in links.items()
            if 0 <= jk[0] < jk[1] < n and np.all(np.abs(c) <= params.gate_sigmas * np.sqrt(spread))
            and float(np.sum(c ** 2 / spread)) <= params.gate_chi2}
    measured = {k: (m, M / params.information_scale) for k, (m, M) in (on_model or {}).items() if 0 <= k < n}
    log.info("motion: %d of %d frame-to-frame corrections used%s; recorded poses' sigma %.2f deg, %.1f mm",
             len(used), len(links), f", {len(measured)} frames measured on the model" if on_model is not None else "",
             np.degrees(s[0]), s[3] * 1000)
    while True:
        factor, x = _solve(used, n, s, measured)
        if not used or params.residual_chi2 is None:
            return x, _block_covariance(factor, n)
        chi2 = {jk: float((x[jk[1]] - x[jk[0]] - c) @ L @ (x[jk[1]] - x[jk[0]] - c)) for jk, (c, L) in used.items()}
        worst = max(chi2, key=chi2.get)
        if chi2[worst] <= params.residual_chi2:
            return x, _block_covariance(factor, n)
        del used[worst]


def _recorded_sigma(links) -> np.ndarray:
    """(2,) the recorded poses' standard deviation per axis (rad, m) from the links (c, information):
    each link's correction along its best seen rotation and translation direction (the information's
    top eigenvectors; the others are held by the prior) is the difference of two recorded errors,
    |N(0, 2 s^2)|, median 0.6745 sqrt(2) s. (Pooling every direction with a tenth of the top
    eigenvalue or more: seeds 301-306 median shortfall 0.020, worst 0.077, against 0.013, 0.072.)"""
    along = []
    for c, L in links:
        u_rotation, u_translation = (np.linalg.eigh(L[part, part])[1][:, -1] for part in (slice(0, 3), slice(3, 6)))
        along.append((abs(c[:3] @ u_rotation), abs(c[3:] @ u_translation)))
    return np.median(np.array(along), axis=0) / (0.6745 * np.sqrt(2))


def _solve(used: dict, n: int, s: np.ndarray, measured: dict) -> tuple[np.ndarray, np.ndarray]:
    """The Cholesky factor (``cholesky_banded``, upper form) of the normal equations of ``fuse`` for
    the links ``used`` ((c, L) by (j, k)) and the frames ``measured`` ((m, M) by k), block-banded (6 x 6
    blocks within the links' span), and the (n, 6) least-squares corrections."""
    band = 6 * max([k - j for j, k in used] or [1]) + 5
    banded = np.zeros((band + 1, 6 * n))        # upper form: banded[band + i - j, j] = H[i, j], i <= j
    banded[band] = np.tile(1 / s ** 2, n)
    rhs = np.zeros(6 * n)
    rows, cols = np.triu_indices(6)                                     # a diagonal block's upper triangle
    i, m = np.meshgrid(np.arange(6), np.arange(6), indexing="ij")     # an off-diagonal block, all of it
    for (j, k), (c, L) in used.items():
        Lc = L @ c
        rhs[6 * k:6 * k + 6] += Lc
        rhs[6 * j:6 * j + 6] -= Lc
        for a in (j, k):
            banded[band + rows - cols, 6 * a + cols] += L[rows, cols]
        banded[band + (6 * j + i) - (6 * k + m), 6 * k + m] -= L          # the (j, k) block, above the diagonal
    for k, (measurement, M) in measured.items():
        rhs[6 * k:6 * k + 6] += M @ measurement
        banded[band + rows - cols, 6 * k + cols] += M[rows, cols]
    factor = cholesky_banded(banded)
    return factor, cho_solve_banded((factor, False), rhs).reshape(n, 6)


def _block_covariance(factor: np.ndarray, n: int, chunk: int = 64) -> np.ndarray:
    """(n, 6, 6) the diagonal blocks of the inverse of the banded matrix whose Cholesky factor is
    ``factor``: solved against the identity's columns ``chunk`` frames at a time (memory 36 n chunk)."""
    blocks = np.empty((n, 6, 6))
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        rhs = np.zeros((6 * n, 6 * (stop - start)))
        rhs[6 * start:6 * stop] = np.eye(6 * (stop - start))
        own = cho_solve_banded((factor, False), rhs)[6 * start:6 * stop].reshape(stop - start, 6, stop - start, 6)
        blocks[start:stop] = own[np.arange(stop - start), :, np.arange(stop - start), :]
    return blocks


def link_information(estimate) -> np.ndarray:
    """(6, 6) the information of a refinement (``PoseEstimate.information``: increments (rotation,
    translation) about its pivot, camera frame) in the coordinates of its correction x (rotation vector,
    translation; object frame, ``T_recorded exp(x)``): for a pose T = (R, t), y = A^-1 x with
    A^-1 = [[R, 0], [[t - pivot]_x R, R]], so L_x = A^-T L_y A^-1."""
    T = estimate.T_camera_object
    R, a = T[:3, :3], T[:3, 3] - estimate.pivot
    A_inv = np.block([[R, np.zeros((3, 3))], [skew(a) @ R, R]])
    return A_inv.T @ estimate.information @ A_inv


def corrected(T_recorded: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``T_recorded exp(x)`` (4, 4), x (6,) as ``fuse`` returns."""
    return T_recorded @ make_transform(Rotation.from_rotvec(x[:3]).as_matrix(), x[3:])


def on_model(model: Segments, frame, T_fused: np.ndarray, track: TrackParams, gradients=None,
             params: MotionParams = MotionParams()) -> tuple[np.ndarray, np.ndarray] | None:
    """Frame's fused pose T_camera_object (4, 4) refined on ``model`` (the accepted segments of the
    accumulation with the fused poses, object frame) as ``frame_to_frame`` refines, with its prior
    about the fused pose: the refinement's correction of the fused pose (``correction``) and its
    information (``link_information``) for ``fuse``; None unless the refinement is 'tracked' and
    moves the fused pose by at most ``model_gate_deg`` and ``model_gate_mm``. 'Tracked' here needs a
    coverage of ``model_min_coverage`` (0.3), not the tracker's 0.45: the model of all frames shows a
    frame the aspects it was built from, and ``fuse`` weighs and gates each refinement anyway. On
    ``make motion`` the tracker's limit left seed 307's frames 0-8 and 19-21 unrefined (coverage 0.29
    to 0.41); with 0.3 its shortfall is 0.066 (0.093), 311's 0.011 (0.016), every other seed's and
    the real teabox's ``--motion tracked`` model the same (0.2: 307 0.069). Measured and not kept
    (2026-12-07, 12 seeds, 2 runs each): each frame refined on the model of the other frames only (two
    or three folds of alternate frames, so that a frame's own pose error is not in the model it is
    refined on): the repaired poses as far off as before (seed 307 0.84 degrees both, 301 0.68 ->
    0.72), 8 of 12 scenes within 0.02 with three folds against 10 of 12 (304 0.017 -> 0.048): what
    limits these poses is not the model agreeing with its own frame."""
    track = replace(track, min_coverage=params.model_min_coverage)
    found = frame_to_frame(model, frame, T_fused, track, gradients, params)
    if found is None:
        return None
    c = found[0]
    if np.degrees(np.linalg.norm(c[:3])) > params.model_gate_deg or np.linalg.norm(c[3:]) * 1000 > params.model_gate_mm:
        return None
    return found


def frame_to_frame(previous: Segments, frame, T_recorded: np.ndarray, track: TrackParams,
                   gradients=None, params: MotionParams = MotionParams()) -> tuple[np.ndarray, np.ndarray] | None:
    """The correction (``correction``) of frame's recorded pose measured against an earlier
    frame's object segments (``previous``: object frame, in that frame's recorded gauge) and its
    information (``link_information``), or None unless the refinement is 'tracked'. The refinement
    searches ``search_px`` about the recorded pose with ``prior_deg`` / ``prior_mm`` about it
    (``track._gauss_newton``), and no limit on its standard deviations nor on how many segments it
    expects in view (``min_shown_segments``): ``fuse`` weighs each direction by the link's information
    and gates the links instead (with the tracker's 10 segments, seed 307 of ``make motion`` went from
    0.000 to 0.055 short of the exact poses' model)."""
    if len(previous) < 3:
        return None
    # every sample on the wide levels too: 20-40 segments with one point each were too few there
    # (seed 302: 0.944 / 0.448 with three, 0.879 / 0.436 with one)
    track = replace(track, max_std_deg=np.inf, max_std_mm=np.inf, min_shown_segments=0.0,
                    coarse_samples_per_segment=track.samples_per_segment,
                    search_px=params.search_px, tukey_px=params.tukey_px, prior_deg=params.prior_deg,
                    prior_mm=params.prior_mm, iterations_per_level=params.iterations_per_level)
    estimate = refine_pose(previous, frame, T_recorded, track, gradients=gradients)
    if estimate.status != "tracked" or estimate.information is None:
        return None
    return correction(T_recorded, estimate.T_camera_object), link_information(estimate)
