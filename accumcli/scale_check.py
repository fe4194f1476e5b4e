"""Does stereo depth agree with the recorded motion? A check of the calibration's scale.

A baseline or focal length a little off scales every triangulated point about the camera by the
same factor ``s``; the recorded poses do not change with it. A point seen at ``P`` in frame a
and again at ``Q`` in frame b then satisfies ``Q = R P + s t`` (``R``, ``t``: the recorded motion
from a to b in the camera frame, the extracted points scaled by ``s``) instead of ``Q = R P + t``,
so re-observations miss each other by ``(s - 1) |t|`` and the accumulation, which places them by
the motion, finds nothing to confirm. On the real chessboard a baseline 2 % too long took the
model's precision from 0.989 to 0.026 and its completeness from 1.000 to 0.059, with no word.

The estimate: for frame pairs ``GAPS`` apart, the share of a frame's segments (direction sigma
under ``MAX_SIGMA_DEG``) that land within ``MATCH_M`` and ``MATCH_DEG`` of a segment of the other
frame when moved by ``R P + s t``, counted for each ``s`` of ``SCALES``; the scale with the most
matches. It decides only where the motion tells scales apart: the count at its best must exceed
that at 1 by ``MIN_PEAK_RATIO``. Measured: the chessboard, dev_steps and the sample peak at 1.00
(the count at 1 is 3.0 to 8.8 times that at 0.97 or 1.03); the chessboard with a baseline 2 %
long peaks at 1.02 (4.6 times the count at 1); the real teabox, moved little by hand, cannot tell
(every scale within 1 % of the count at 1, with a baseline 3 % long too), and says nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .geometry import invert
from .segments import Segments

SCALES = np.round(np.arange(0.90, 1.1001, 0.01), 3)
GAPS = (1, 4)
MATCH_M = 0.002
MATCH_DEG = 5.0
MAX_SIGMA_DEG = 5.0
MAX_FRAMES = 60             # the check decides on the first frames; later ones add nothing to it
MAX_SEGMENTS = 600          # per frame, the surest (time and memory stay bounded)
MIN_PEAK_RATIO = 1.5
WARN_SCALE = 0.01


@dataclass
class ScaleCheck:
    """Match counts per scale over a run's first frames (``add``), and the run's warning (``report``)."""

    counts: np.ndarray = field(default_factory=lambda: np.zeros(len(SCALES)))
    frames: int = 0
    _recent: list = field(default_factory=list)   # (centres, directions, T_camera_object) of the last frames

    def add(self, segments: Segments, T_camera_object: np.ndarray | None) -> None:
        """One frame's extracted segments (camera frame) and its recorded pose (None: skipped)."""
        if T_camera_object is None or self.frames >= MAX_FRAMES or not len(segments):
            return
        self.frames += 1
        sigma = segments.extra.get("sigma_direction_rad")
        keep = np.ones(len(segments), bool) if sigma is None else sigma < np.radians(MAX_SIGMA_DEG)
        index = np.flatnonzero(keep)
        if sigma is not None and len(index) > MAX_SEGMENTS:
            index = index[np.argsort(sigma[index])[:MAX_SEGMENTS]]
        centers, directions = segments.centers[index], segments.directions[index]
        if len(centers):
            tree = cKDTree(centers)
            for gap in GAPS:
                if len(self._recent) >= gap:
                    self._count(tree, centers, directions, T_camera_object, *self._recent[-gap])
        self._recent = (self._recent + [(centers, directions, T_camera_object)])[-max(GAPS):]

    def _count(self, tree, centers, directions, T_b, centers_a, directions_a, T_a) -> None:
        """Matches of frame a's segments in frame b (``tree`` of b's centres) for every scale."""
        T_ba = T_b @ invert(T_a)          # the recorded motion from a's camera frame to b's
        R, t = T_ba[:3, :3], T_ba[:3, 3]
        moved = centers_a @ R.T
        turned = directions_a @ R.T
        cos_limit = np.cos(np.radians(MATCH_DEG))
        for i, s in enumerate(SCALES):
            dist, j = tree.query(moved + s * t, distance_upper_bound=MATCH_M)
            found = np.isfinite(dist)
            aligned = np.abs(np.sum(turned[found] * directions[j[found]], axis=1)) >= cos_limit
            self.counts[i] += int(aligned.sum())

    def estimate(self) -> tuple[float, float] | None:
        """(best scale, its count over the count at 1) when the motion tells scales apart, else None."""
        at_one = self.counts[np.argmin(np.abs(SCALES - 1.0))]
        best = int(np.argmax(self.counts))
        if self.counts[best] == 0:
            return None
        ratio = float(self.counts[best] / max(at_one, 1.0))
        return (float(SCALES[best]), ratio) if ratio >= MIN_PEAK_RATIO or SCALES[best] == 1.0 else None

    def warning(self) -> str | None:
        found = self.estimate()
        if found is None or abs(found[0] - 1.0) < WARN_SCALE - 1e-9:
            return None
        scale, ratio = found
        return (f"stereo depths are {scale:.2f} times what the recorded motion implies (segments seen again match "
                f"{ratio:.1f} times as often at that scale as at their own), so few are confirmed; check the baseline "
                f"and focal length of the calibration (or the poses' units)")
