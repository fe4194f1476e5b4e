"""Is there an edge along a projected segment? The gradient across it, read from the image.

Used where a segment's place in an image must be judged without a detector: whether it moves with
the object (``still_check``) and whether a frame that extracted nothing there still shows its edge
(``line_model``'s misses)."""

from __future__ import annotations

import cv2
import numpy as np

from .lines2d import Gradients

ROW = 1024   # points per row of the maps given to OpenCV's remap (it takes at most 32767 rows or columns)


def edge_evidence(grads: Gradients, uv: np.ndarray, normal: np.ndarray, size: tuple[int, int],
                  margin_px: float = 1.0) -> np.ndarray:
    """(N,) grey levels per pixel: the median over each segment's points ``uv`` (N, S, 2) px of the
    largest gradient across its line (``normal`` (N, 2) unit) within 1 px of it; NaN where a point
    lies outside the image of ``size`` (width, height) less ``margin_px``."""
    n, s = uv.shape[:2]
    best = np.zeros((n, s), np.float32)
    inside = np.ones((n, s), bool)
    width, height = size
    for offset in (-1.0, 0.0, 1.0):
        p = uv + normal[:, None, :] * offset
        u, v = p[..., 0], p[..., 1]
        inside &= (u >= margin_px) & (u <= width - 1 - margin_px) & (v >= margin_px) & (v <= height - 1 - margin_px)
        gx, gy = _read(grads.gx, u, v), _read(grads.gy, u, v)
        best = np.maximum(best, np.abs(gx * normal[:, None, 0] + gy * normal[:, None, 1]))
    return np.where(inside.all(axis=1), np.median(best, axis=1), np.nan)


def _read(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``image`` (H, W) float32 at (u, v) (any shape, px), bilinear; 0 outside (and where NaN)."""
    if u.size == 0:
        return np.zeros(u.shape, np.float32)
    flat_u, flat_v = u.astype(np.float32).ravel(), v.astype(np.float32).ravel()
    pad = -len(flat_u) % ROW
    if pad:
        flat_u, flat_v = np.concatenate([flat_u, np.full(pad, -10.0, np.float32)]), \
            np.concatenate([flat_v, np.full(pad, -10.0, np.float32)])
    out = cv2.remap(image, flat_u.reshape(-1, ROW), flat_v.reshape(-1, ROW), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT)
    return out.ravel()[:u.size].reshape(u.shape)
