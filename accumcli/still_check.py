"""Does a model move with the object? A check on the images alone, for recordings without a truth.

Accumulation keeps what re-appears where the recorded motion predicts it; background that stays
still in the camera's view should fade. Whether it did can be read off the images without a truth.
A model segment (object frame) is placed in a frame by that frame's pose; for two frames a and b it
has two places in each image: its own (placed by that frame's pose) and the other's (placed by the
other frame's pose: where it is if it stays still in the camera's view). Where the two lie at least
``min_shift_px`` apart across its line, the edge evidence of each place (``edge_evidence``: the
median over ``samples`` points of the largest gradient across the line within 1 px) votes: it
moves with the object when both images show it at their own places ``ratio`` times more than at
the other places; it stays still when one image shows it at its own place and the other at that
same place (held still), ``ratio`` times more than elsewhere. Why both images of a pair: a model
segment lies where the frames that saw it put it; in a frame far from those, its own place and the
other's are both wrong, and a test of one image alone let background "move" by chance (0.39 to
0.45 of its length on the devset). A segment moves with ``min_moving_votes`` (2) such pairs, stays
still when fewer and more pairs said still, and is undecided otherwise (the object never moved at
it, it left the image, or the pairs split).

Frames: ``frames`` of the recording (with a pose), evenly spaced, and every pair of them. Why not the
accumulation's own confirmations: they are what is being checked; the gradients here are the plain
Sobel of the left image (``lines2d.Gradients``), with no detector, no stereo and no model of the
accumulation in between.

Measured: one frame's own extracted segments (object and background) placed by its pose, on the
sample and four devset recordings: the segments on truth edges move (all of their length), the
background (more than 20 mm from every edge) stays still for 0.92 to 0.995 of its length and moves
for 0.002 to 0.022. The real teabox's model (80 frames) moves with the board for 0.92 of its length
and stays still for 0.08, along the handle's silhouette against the floor and by the image's border,
where its truth, which knows the box and the board's plane only, calls 0.46 background."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .edge_evidence import edge_evidence
from .geometry import transform_points
from .lines2d import Gradients
from .recording import StereoIntrinsics
from .segments import Segments


@dataclass(frozen=True)
class StillCheckParams:
    frames: int = 12            # frames sampled evenly over the recording
    min_shift_px: float = 3.0   # the two places of a segment this far apart across its line tell them apart
    ratio: float = 1.5          # one place's edge evidence this many times the other's decides a pair
    samples: int = 15           # points along a segment
    margin_px: float = 3.0      # points this near the image's border are not judged
    min_moving_votes: int = 2   # a segment moves with the object when this many pairs say so


@dataclass
class StillCheck:
    """Per segment (N,) votes of the frame pairs that told its two places apart, and its verdict;
    ``lengths`` (N,) metres. The shares are of the summed length."""

    moving_votes: np.ndarray
    still_votes: np.ndarray
    lengths: np.ndarray
    frames: int

    min_moving_votes: int = 2

    @property
    def moving(self) -> np.ndarray:
        return self.moving_votes >= self.min_moving_votes

    @property
    def still(self) -> np.ndarray:
        return ~self.moving & (self.still_votes > self.moving_votes)

    def shares(self) -> dict:
        """Shares of the segments' length that move with the object, stay still, are undecided."""
        total = max(float(self.lengths.sum()), 1e-12)
        moving, still = self.moving, self.still
        return {"moving_share": float(self.lengths[moving].sum() / total),
                "still_share": float(self.lengths[still].sum() / total),
                "undecided_share": float(self.lengths[~moving & ~still].sum() / total),
                "segments_checked": int(len(self.lengths)), "frames_checked": int(self.frames)}


def sampled_frames(count: int, wanted: int) -> np.ndarray:
    """Indices (positions among ``count`` frames) of ``wanted`` frames evenly spread, first and last included."""
    return np.unique(np.round(np.linspace(0, count - 1, min(wanted, count))).astype(int)) if count else np.zeros(0, int)


def still_check(model: Segments, views: list[tuple[Gradients, np.ndarray]], intrinsics: StereoIntrinsics,
                params: StillCheckParams = StillCheckParams()) -> StillCheck:
    """The check of ``model``'s segments (object frame) on ``views``: per frame its left image's
    ``Gradients`` and its pose ``T_camera_object`` (4, 4). Every pair of views votes (module
    docstring)."""
    n, k = len(model), len(views)
    moving_votes, still_votes = np.zeros(n, np.int64), np.zeros(n, np.int64)
    if n == 0 or k < 2:
        return StillCheck(moving_votes, still_votes, model.lengths.copy(), k, params.min_moving_votes)
    t = np.linspace(-0.5, 0.5, params.samples)
    points = model.centers[:, None, :] + model.directions[:, None, :] * (model.lengths[:, None] * t)[:, :, None]
    placed = [_project(points, T, intrinsics) for _, T in views]          # (N, S, 2) by each view's pose
    normals = [_normals(uv) for uv in placed]
    # evidence[b][a]: in view b's image, of the segments placed by view a's pose
    size = (intrinsics.width, intrinsics.height)
    evidence = [[edge_evidence(grads, placed[a], normals[a], size, params.margin_px) for a in range(k)]
                for grads, _ in views]
    r = params.ratio
    for a in range(k):
        for b in range(a + 1, k):
            shift = np.abs(np.sum((placed[b] - placed[a]).mean(axis=1) * normals[a], axis=1))
            e = np.stack([evidence[a][a], evidence[a][b], evidence[b][b], evidence[b][a]])
            told = (shift >= params.min_shift_px) & np.isfinite(e).all(axis=0)
            a_own, a_other, b_own, b_other = e
            moving = np.minimum(a_own, b_own) > r * np.maximum(a_other, b_other)
            still = (np.minimum(a_own, b_other) > r * np.maximum(a_other, b_own)) | (
                np.minimum(b_own, a_other) > r * np.maximum(a_own, b_other))
            moving_votes += told & moving
            still_votes += told & still
    return StillCheck(moving_votes, still_votes, model.lengths.copy(), k, params.min_moving_votes)


def _project(points: np.ndarray, T_camera_object: np.ndarray, intrinsics: StereoIntrinsics) -> np.ndarray:
    """(N, S, 2) left-image pixels of points (N, S, 3) in the object frame (NaN behind the camera)."""
    camera = transform_points(T_camera_object, points.reshape(-1, 3))
    camera[camera[:, 2] <= 1e-6] = np.nan
    return intrinsics.project(camera)[0].reshape(points.shape[0], points.shape[1], 2)


def _normals(uv: np.ndarray) -> np.ndarray:
    """(N, 2) unit normals of projected segments (N, S, 2), from their end points."""
    d = uv[:, -1] - uv[:, 0]
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    return np.stack([-d[:, 1], d[:, 0]], axis=1)
