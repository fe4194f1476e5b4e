"""Does a model move with the object? A check on the images alone, for recordings without a truth.

Accumulation keeps what re-appears where the recorded motion predicts it; background that stays
still in the camera's view should fade. Whether it did can be read off the images without a truth:
a model segment (object frame) seen at frame a lies, at frame b, either where the object's motion
takes it (``moving``: placed by frame b's pose) or where it was at frame a (``still``: placed by frame
a's pose, held still in the camera's frame). Where those two places lie at least ``min_shift_px``
apart across the segment's line in frame b's left image, the image tells them apart: the edge
evidence of each (the median, over ``samples`` points along the projected segment, of the largest
gradient across the line within 1 px of it) decides the pair when one is ``ratio`` times the other.
A segment moves with the object when more frame pairs say so than say it stays still, stays still
when more say that, and is undecided otherwise (no pair could tell: the object did not move at it,
or it left the image; or the pairs split).

Frames: ``frames`` of the recording (every frame with a pose), evenly spaced, and every ordered
pair of them. Why not the accumulation's own confirmations: they are what is being checked; the
gradients here are the plain Sobel of the left image (``lines2d.Gradients``), with no detector, no
stereo and no model of the accumulation in between.

Measured: on the real teabox (model of all 80 frames) the box's accepted segments, judged by its
truth's faces, move with it (1.64 m of 1.64 m); of the 2.1 m that its truth does not place on the
box or the board's plane, 1.8 m moves too (the handle by which the board is moved, the board's disc
rim, box edges more than 4 mm from the truth's faces), 0.16 m stays still and 0.14 m is undecided,
all along the handle's silhouette against the floor."""

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
