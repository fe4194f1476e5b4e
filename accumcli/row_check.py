"""Do the rectified images' rows agree? A check on the extracted segments themselves.

A stereo pair whose right image lies ``dy`` px lower than the left (a calibration a little off)
shifts the disparity measured along the rows of an edge by ``dy`` times its cotangent against
the rows, so edges of different angle disagree in depth where they meet. On dev_steps, a right
image 0.3 px too low took the accumulated precision from 0.989 to 0.866 (0.6 px: 0.538);
``StereoParams.row_offset_px`` of the same 0.3 took it back to 0.981.

The estimate: where two triangulated segments of the left image meet at an L-junction (both
their lines end there: within ``JUNCTION_PX`` of where the lines cross, of a piece's end and of
the whole line's extent) at angles at least ``MIN_ANGLE_DEG`` apart, both at least
``MIN_ROW_ANGLE_DEG`` off the rows and with a fitted direction (sigma under ``MAX_SIGMA_DEG``),
their disparities extrapolated to the junction give ``d_a - d_b = dy (cot_a - cot_b)``, one
sample of ``dy``; the median of the samples is the estimate. An edge that runs on through the
point (a T-junction, where an occluding edge crosses another at another depth) is no sample:
without that test, exact-rectified simulated recordings gave confident wrong estimates (+0.67
px from 171 samples on one, +1.08 px from 30 on another). Samples whose disparities differ by
more than ``MAX_JUMP_PX`` at the junction are dropped; the rest decide only when there are
``MIN_SAMPLES`` of them and their spread (1.4826 MAD) is at most ``MAX_SPREAD_PX``, and a warning
needs ``WARN_PX``.

A large offset thins the samples out (fewer matches, larger jumps): dev_steps with its right image
2 px low gave 18 samples at 1.99 (precision 0.459 against 0.957, and no word), dev_tprofile 2 px
high 26 at -1.98, the chessboard 1 px low 12 at 0.95. So fewer than ``MIN_SAMPLES``, at least
``MIN_FEW_SAMPLES``, decide too where they lie at ``MIN_PLACES`` places ``PLACE_M`` apart both in the
left camera's frame and (with poses) in the object's: those three have 8, 5 and 11 such places. One
junction seen again and again is not that: an exact simulated scene (sim_100) gives 10 samples at
-1.51 px, spread 0.05, all at one place in the camera's frame (background that the object passes).
Few samples also decide only for offsets of ``MIN_FEW_PX`` or more, the ones that thin them out: an
exact scene (``accum simulate --seed 12``) gave 28 at 0.18 px from 5 places, a false warning.

Measured over whole recordings: on 12 exact suite scenes, 5 exact tracking
scenes, the devset and the real chessboard every estimate that decides lies within 0.07 px of 0
(the real teabox: 9 samples, its edges run near the rows, no estimate); right images moved down
by 0.3 px give 0.282 (dev_steps), 0.287 (dev_tprofile), by 0.4 px 0.380 (the sample), 0.486
(sim_103), up by 0.3 px -0.284.

Why by hand: OpenCV's feature matchers (SIFT) put the vertical offset of exact-rectified
simulated pairs at 0.19 to 0.45 px on 3 of 12, from corners where two depths meet; the edges'
own geometry needs no extra detection.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .extract import FrameSegments
from .geometry import invert, transform_points
from .recording import StereoIntrinsics
from .stereo import backproject

log = logging.getLogger("accumcli")

JUNCTION_PX = 4.0
MIN_ANGLE_DEG = 30.0
MIN_ROW_ANGLE_DEG = 15.0
MAX_SIGMA_DEG = 3.0
MAX_JUMP_PX = 3.0
MIN_COT_GAP = 0.5
MIN_SAMPLES = 30
MIN_FEW_SAMPLES = 10        # fewer than MIN_SAMPLES decide only from this many ...
MIN_PLACES = 5              # ... at this many places PLACE_M apart, in the camera's frame and the object's
PLACE_M = 0.002
MIN_FEW_PX = 0.5            # ... and an offset at least this large (what thins the samples out)
MAX_SPREAD_PX = 0.2
WARN_PX = 0.15
MAX_SAMPLES = 5000          # memory stays bounded on long recordings (the first ones are kept)


def junction_samples(extraction: FrameSegments, intrinsics: StereoIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """(K,) samples of the right image's row offset, px (module docstring), from one frame's
    triangulated segments (``extraction.segments``, left camera frame), and (K, 3) their junctions,
    metres, left camera frame."""
    none = np.zeros(0), np.zeros((0, 3))
    s = extraction.segments
    if not len(s) or not {"sigma_direction_rad", "u", "v"} <= s.extra.keys():
        return none
    fitted = (extraction.right_index >= 0) & (s.extra["sigma_direction_rad"] < np.radians(MAX_SIGMA_DEG))
    index = np.flatnonzero(fitted)
    line = extraction.left.line_direction[extraction.left_index[index]]              # (n, 2) unit, image
    keep = np.abs(line[:, 1]) > np.sin(np.radians(MIN_ROW_ANGLE_DEG))
    index, line = index[keep], line[keep]
    if len(index) < 2:
        return none
    center = np.column_stack([s.extra["u"][index], s.extra["v"][index]])
    uv, uv_right, _ = intrinsics.project(s.endpoints()[index].reshape(-1, 3))          # the 3D ends, px
    disparity = (uv[:, 0] - uv_right[:, 0]).reshape(-1, 2)                             # (n, 2) px
    uv = uv.reshape(-1, 2, 2)
    t = np.sum((uv - center[:, None, :]) * line[:, None, :], axis=-1)                  # along the line, px
    span = t[:, 1] - t[:, 0]
    slope = (disparity[:, 1] - disparity[:, 0]) / np.where(np.abs(span) > 1e-6, span, 1e-6)
    d_center = disparity[:, 0] - slope * t[:, 0]
    ends_2d = extraction.left.endpoints()[extraction.left_index[index]]              # (n, 2, 2) px
    pairs = cKDTree(ends_2d.reshape(-1, 2)).query_pairs(JUNCTION_PX, output_type="ndarray")
    a, b = pairs[:, 0] // 2, pairs[:, 1] // 2
    a, b = a[a != b], b[a != b]
    a, b = (x[np.abs(np.sum(line[a] * line[b], axis=1)) < np.cos(np.radians(MIN_ANGLE_DEG))] for x in (a, b))
    # the junction: where the two lines cross (c_a + t_a u_a = c_b + t_b u_b)
    det = line[b, 0] * line[a, 1] - line[a, 0] * line[b, 1]
    rel = center[b] - center[a]
    t_a = (line[b, 0] * rel[:, 1] - line[b, 1] * rel[:, 0]) / det
    t_b = (line[a, 0] * rel[:, 1] - line[a, 1] * rel[:, 0]) / det
    junction = center[a] + t_a[:, None] * line[a]
    # both lines end there (an L-junction): an edge that runs on through it (T-junction, crossing) does not
    left = extraction.left
    line_id = left.line_id[extraction.left_index[index]]
    lo, hi = left.line_extents()          # each line's extent, px
    t_piece = left.t[extraction.left_index[index]]
    near = np.ones(len(a), bool)
    for k, t_k in ((a, t_a), (b, t_b)):
        near &= np.min(np.linalg.norm(ends_2d[k] - junction[:, None, :], axis=2), axis=1) <= JUNCTION_PX
        t_junction = t_piece[k] + t_k                    # along the piece's line (``line`` is its direction)
        near &= np.minimum(np.abs(t_junction - lo[line_id[k]]), np.abs(t_junction - hi[line_id[k]])) <= JUNCTION_PX
    d_a, d_b = d_center[a] + slope[a] * t_a, d_center[b] + slope[b] * t_b
    cot_gap = line[a, 0] / line[a, 1] - line[b, 0] / line[b, 1]
    ok = near & (np.abs(cot_gap) >= MIN_COT_GAP) & (np.abs(d_a - d_b) <= MAX_JUMP_PX)
    points = backproject(junction[ok, 0], junction[ok, 1], np.maximum((d_a[ok] + d_b[ok]) / 2, 1e-6), intrinsics)
    return ((d_a - d_b) / cot_gap)[ok], points


@dataclass
class RowCheck:
    """The row offset's samples over a run's frames (``add``), what they say (``estimate``) and the
    warning of the run (``report``)."""

    samples: list = field(default_factory=list)
    camera_points: list = field(default_factory=list)   # their junctions, metres, left camera frame ...
    object_points: list = field(default_factory=list)   # ... and object frame (frames with a pose)

    @property
    def count(self) -> int:
        return sum(len(v) for v in self.samples)

    def add(self, extraction: FrameSegments, intrinsics: StereoIntrinsics,
            T_camera_object: np.ndarray | None = None) -> None:
        """One frame's samples, kept while fewer than ``MAX_SAMPLES`` are (a frame without any adds
        nothing: the lists do not grow with the recording's length), with its pose (4, 4) if known."""
        room = MAX_SAMPLES - self.count
        if room > 0:
            found, points = (x[:room] for x in junction_samples(extraction, intrinsics))
            if len(found):
                self.samples.append(found)
                self.camera_points.append(points)
                if T_camera_object is not None:
                    self.object_points.append(transform_points(invert(T_camera_object), points))

    def places(self) -> int:
        """The fewest places ``PLACE_M`` apart that the samples' junctions take, in the camera's frame
        and (where the frames had poses) in the object's."""
        frames = [self.camera_points] + ([self.object_points] if self.object_points else [])
        return min(_places(np.concatenate(points)) for points in frames)

    def estimate(self) -> tuple[float, float, int] | None:
        """(median offset px, spread px, samples) when the samples are enough and agree, else None."""
        if self.count < MIN_FEW_SAMPLES or (self.count < MIN_SAMPLES and self.places() < MIN_PLACES):
            return None
        v = np.concatenate(self.samples)
        median = float(np.median(v))
        if self.count < MIN_SAMPLES and abs(median) < MIN_FEW_PX:   # few samples speak for large offsets only
            return None
        spread = float(1.4826 * np.median(np.abs(v - median)))
        return (median, spread, len(v)) if spread <= MAX_SPREAD_PX else None

    def warning(self, row_offset_px: float = 0.0) -> str | None:
        """A one-line warning when the rows disagree by ``WARN_PX`` or more beyond ``row_offset_px``
        (the offset the run already corrected), else None."""
        found = self.estimate()
        if found is None or abs(found[0]) < WARN_PX:
            return None
        median, spread, n = found
        side = "below" if median > 0 else "above"
        given = f" with --row-offset {row_offset_px:.2f}" if row_offset_px else ""
        return (f"the rectified images' rows disagree{given}: the right image's rows lie {abs(median):.2f} px {side} "
                f"the left's (median of {n} edge junctions, spread {spread:.2f} px), which skews the depth of edges "
                f"near the rows; check the stereo calibration, or try --row-offset {row_offset_px + median:.2f}")

    def report(self, recording, row_offset_px: float = 0.0) -> str | None:
        """``warning``, also logged as the run's warning about ``recording``; where the samples cannot
        decide, what they say (-v)."""
        text = self.warning(row_offset_px)
        if text:
            log.warning("%s: %s", recording, text)
        elif self.count and self.estimate() is None:
            v = np.concatenate(self.samples)
            median = float(np.median(v))
            log.info("%s: the rows' check cannot decide: %d edge junctions at %d places (needs %d, or %d at %d places) "
                     "at a median %.2f px, spread %.2f px (at most %.2f); if the depths look wrong, check the stereo "
                     "calibration", recording, len(v), self.places(), MIN_SAMPLES, MIN_FEW_SAMPLES, MIN_PLACES, median,
                     1.4826 * float(np.median(np.abs(v - median))), MAX_SPREAD_PX)
        return text


def _places(points: np.ndarray) -> int:
    """How many of ``points`` (N, 3) lie ``PLACE_M`` or more from every one counted before them (a
    greedy count; N is small where it matters: under ``MIN_SAMPLES``)."""
    tree, counted = cKDTree(points), np.zeros(len(points), bool)
    for i in range(len(points)):
        near = tree.query_ball_point(points[i], PLACE_M)
        counted[i] = not counted[near].any()
    return int(counted.sum())
