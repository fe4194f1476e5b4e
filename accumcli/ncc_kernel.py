"""The compiled loops of ``critical`` (numba, installed as a wheel): the normalized
cross-correlation of ``_block_match`` and the run ends on each critical segment's line
(``ends_on_lines``, one pass over the pairs where numpy built five (K, E) arrays: 4.5 ms a frame on
the teabox).

Why compiled: numpy needed (M, h, h) and (M, h, D + 2w) float copies of the windows and strips and
a batched product per window column, a quarter of the extraction time spent on a few hundred run
ends per frame. Here the window sums are exact integers, as they were exact in float32
before, and the normalization is the same float64 arithmetic in the same order: the NCC is the
numpy version's bit for bit.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel


@kernel
def row_ncc(left_img, right_img, row, column, d_lo, d_hi, w):  # pragma: no cover
    """(M, d_hi - d_lo + 1) float64 NCC of the (2w + 1)^2 window of ``left_img`` centred on
    (``row``, ``column``) (M,) int64 with the windows of ``right_img`` centred on the same row,
    columns ``column - d_hi + k`` for k = 0..d_hi - d_lo; pixels beyond the images repeat the border
    ones; 0 where either window is flat."""
    height, width = left_img.shape
    h = 2 * w + 1
    n = h * h
    shifts = d_hi - d_lo + 1
    span = shifts + h - 1
    ncc = np.zeros((len(row), shifts))
    a = np.empty((h, h), np.int32)          # int32: sums of h * h * 255^2 fit (w up to 20), and
    b = np.empty((h, span), np.int32)       # int32 products vectorize where int64 ones do not
    cross = np.empty(shifts, np.int32)
    column_sum = np.empty(span, np.int32)
    column_square = np.empty(span, np.int32)
    for m in range(len(row)):
        sum_a = np.int64(0)
        square_a = np.int64(0)
        for y in range(h):
            r = min(max(row[m] - w + y, 0), height - 1)
            for x in range(h):
                value = np.int32(left_img[r, min(max(column[m] - w + x, 0), width - 1)])
                a[y, x] = value
                sum_a += value
                square_a += value * value
            for x in range(span):
                b[y, x] = np.int32(right_img[r, min(max(column[m] - d_hi - w + x, 0), width - 1)])
        cross[:] = 0
        for y in range(h):
            for x in range(h):
                for s in range(shifts):
                    cross[s] += a[y, x] * b[y, x + s]
        column_sum[:] = 0
        column_square[:] = 0
        for y in range(h):
            for x in range(span):
                column_sum[x] += b[y, x]
                column_square[x] += b[y, x] * b[y, x]
        energy_a = float(square_a) * n - float(sum_a) ** 2
        sum_b = np.int64(0)
        square_b = np.int64(0)
        for x in range(h - 1):
            sum_b += column_sum[x]
            square_b += column_square[x]
        for s in range(shifts):          # the window's sums slide along the strip (exact integers)
            sum_b += column_sum[s + h - 1]
            square_b += column_square[s + h - 1]
            if s > 0:
                sum_b -= column_sum[s - 1]
                square_b -= column_square[s - 1]
            c = float(cross[s]) * n - float(sum_a) * float(sum_b)
            energy_b = float(square_b) * n - float(sum_b) ** 2
            denominator = np.sqrt(max(energy_b, 0.0) * energy_a)
            ncc[m, s] = c / max(denominator, 1.0) if denominator > 0 else 0.0
    return ncc


@kernel
def ends_on_lines(ends, centers, direction, end_direction, half_length, across_px, gap_px, cos_parallel):  # pragma: no cover
    """For K segments (``centers``, unit ``direction`` (K, 2), ``half_length`` (K,) px) the nearest of
    the E run ends (``ends``, their lines' ``end_direction`` (E, 2)) on the segment's line (within
    ``across_px`` of it, parallel: |cos| at least ``cos_parallel``) before it and after it (beyond
    -half_length + ``gap_px`` and half_length - ``gap_px`` along it): (K,) index of each (0 where
    there is none, as numpy's argmax of all -inf gives) and (K,) its place along the line (-inf, inf
    where there is none). One pass over the K x E pairs instead of (K, E) arrays."""
    k_count = len(centers)
    e0, e1 = np.zeros(k_count, np.int64), np.zeros(k_count, np.int64)
    t0, t1 = np.full(k_count, -np.inf), np.full(k_count, np.inf)
    for k in range(k_count):
        dx, dy = direction[k, 0], direction[k, 1]
        for e in range(len(ends)):
            rx, ry = ends[e, 0] - centers[k, 0], ends[e, 1] - centers[k, 1]
            if not abs(rx * dy - ry * dx) <= across_px:
                continue
            if not abs(dx * end_direction[e, 0] + dy * end_direction[e, 1]) >= cos_parallel:
                continue
            along = rx * dx + ry * dy
            if along <= -half_length[k] + gap_px and along > t0[k]:
                t0[k], e0[k] = along, e
            if along >= half_length[k] - gap_px and along < t1[k]:
                t1[k], e1[k] = along, e
    return e0, e1, t0, t1
