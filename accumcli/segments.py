"""Local 3D line segments: the paper's entity l = (p, u), with a length.

A ``Segments`` is a struct of arrays in one frame (``frame_id``): the camera
frame for single-frame extraction, the object frame for a model.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .geometry import check_transform, rotate_vectors, transform_points


@dataclass
class Segments:
    """N local 3D line segments.

    centers: (N, 3) float64, metres, in ``frame_id``; directions: (N, 3) unit
    vectors (the sign carries no meaning: lines are undirected); lengths: (N,)
    metres; confidence: (N,) in [0, 1], >= 0.5 means "part of the object";
    observations: (N,) int, frames that confirmed the segment. ``extra`` holds
    further per-segment columns (first axis N) that are kept through
    selection and written to JSON under their own names.
    """

    frame_id: str
    centers: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray
    confidence: np.ndarray
    observations: np.ndarray
    extra: dict = field(default_factory=dict)

    @classmethod
    def empty(cls, frame_id: str) -> "Segments":
        return cls(frame_id, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0, np.int64))

    def __len__(self) -> int:
        return len(self.centers)

    def select(self, index) -> "Segments":
        """The segments at a boolean mask or integer index array."""
        return Segments(self.frame_id, self.centers[index], self.directions[index], self.lengths[index],
                        self.confidence[index], self.observations[index],
                        {k: v[index] for k, v in self.extra.items()})

    def transformed(self, T_new_old: np.ndarray, frame_id: str) -> "Segments":
        """The same segments expressed in another frame (``T_new_old``, (4, 4), maps this frame into
        it; ``InputError`` if it is not a rigid transform). Centres and directions are moved; the
        ``extra`` columns are kept as they are (a vector column such as ``view_direction`` is not
        rotated: the caller does that)."""
        T_new_old = check_transform(T_new_old, "T_new_old")
        return replace(self, frame_id=frame_id, centers=transform_points(T_new_old, self.centers),
                       directions=rotate_vectors(T_new_old, self.directions))

    def endpoints(self) -> np.ndarray:
        """(N, 2, 3) segment endpoints, metres."""
        half = (self.lengths / 2)[:, None] * self.directions
        return np.stack([self.centers - half, self.centers + half], axis=1)

    @property
    def accepted(self) -> np.ndarray:
        """(N,) bool: confidence >= 0.5, the decision line of formats.md."""
        return self.confidence >= 0.5


def concatenate(parts: list[Segments], frame_id: str) -> Segments:
    """One ``Segments`` of several in the same frame (extra columns kept where all parts have them)."""
    parts = [p for p in parts if len(p)] or [Segments.empty(frame_id)]
    keys = [k for k in parts[0].extra if all(k in p.extra for p in parts)]   # in order: same bytes out
    return Segments(frame_id, *(np.concatenate([getattr(p, name) for p in parts]) for name in
                                ("centers", "directions", "lengths", "confidence", "observations")),
                    {k: np.concatenate([p.extra[k] for p in parts]) for k in keys})
