"""Compiled tests over the near pairs of line ends in 2D detection: ``lines2d._complete_junctions``
(runs meeting at a corner) and ``edge_chains.collinear_lines`` (chains on one line).

Why compiled (numba, installed as a wheel): on a textured image (teabox: print on the box, grain,
floor tiles; the simulator's random backgrounds) 100,000 to 600,000 pairs of ends lie within 14 px
of each other. Listing them with a KD-tree (``cKDTree.query_pairs``) and testing them in numpy
gathered a dozen (pairs, 2) arrays per call: 14 ms per call on teabox, 30 on sim_108. Here the ends
are binned by their line's direction and by position (``_binned``), only the bins a test can pass
are searched (collinear: the neighbouring directions; a corner: every other direction, since two
lines in one bin are too parallel to meet), and each pair within reach (squared distance at most
its square, as the KD-tree's) is tested where it is found, with the same arithmetic in the same
order as the numpy expressions it replaced (no fused multiply-add: numba does not contract without
fastmath). Growth is a maximum and the collinear pairs only join components, so the order in which
pairs are found does not matter: the results are the same bits.
"""

from __future__ import annotations

import numpy as np

from .chain_kernel import grouped_order
from .jit import kernel


@kernel
def _binned(ends, direction, bins, reach):  # pragma: no cover
    """Ends (2K, 2) px (the K lines' low ends, then their high ends; ``direction`` (K, 2) of each
    line, unit vectors) binned by the line's direction (``bins`` over the half turn) and by
    position (cells at least ``reach`` wide, wider where that would make far more cells than
    ends). Returns (usable (2K,) bool: finite end and direction, key (2K, 3) int64 (bin, row,
    column), start (R C B + 1,) of each cell-and-bin's run in ``order`` (the usable ends), the bins
    of a cell one after the other, rows, columns)."""
    k_lines = len(direction)
    m = len(ends)
    usable = np.zeros(m, np.bool_)
    x0, y0, x1, y1 = np.inf, np.inf, -np.inf, -np.inf
    for e in range(m):
        c = e - k_lines if e >= k_lines else e
        usable[e] = (np.isfinite(ends[e, 0]) and np.isfinite(ends[e, 1]) and np.isfinite(direction[c, 0])
                     and np.isfinite(direction[c, 1]))
        if usable[e]:
            x0, y0, x1, y1 = min(x0, ends[e, 0]), min(y0, ends[e, 1]), max(x1, ends[e, 0]), max(y1, ends[e, 1])
    # a hair over reach: rounding in (x - x0) // size cannot put two ends within reach two cells apart
    size = max(reach, 1e-6) * (1 + 1e-9)
    if usable.any():
        while (bins * ((x1 - x0) // size + 1) * ((y1 - y0) // size + 1) > 4 * m + 100_000
               and (x1 - x0 >= size or y1 - y0 >= size)):
            size *= 2
    key = np.zeros((m, 3), np.int64)
    for e in range(m):
        if usable[e]:
            c = e - k_lines if e >= k_lines else e
            angle = np.arctan2(direction[c, 1], direction[c, 0]) % np.pi
            key[e, 0] = min(int(angle / np.pi * bins), bins - 1)
            key[e, 1] = int((ends[e, 1] - y0) // size)
            key[e, 2] = int((ends[e, 0] - x0) // size)
    rows, columns = key[:, 1].max() + 1, key[:, 2].max() + 1
    cell = np.where(usable, (key[:, 1] * columns + key[:, 2]) * bins + key[:, 0], -1)
    start, order = grouped_order(cell, bins * rows * columns)
    return usable, key, start, order, rows, columns


@kernel
def _neighbour_cells(key, p, rows, columns, cells):  # pragma: no cover
    """The cells (row * columns + column) of end ``p``'s 3 x 3 neighbourhood inside the grid of
    ``_binned``, written to ``cells`` (9,); returns how many."""
    count = 0
    for dy in range(-1, 2):
        row = key[p, 1] + dy
        if 0 <= row < rows:
            for dx in range(-1, 2):
                column = key[p, 2] + dx
                if 0 <= column < columns:
                    cells[count] = row * columns + column
                    count += 1
    return count


@kernel
def junction_growth(ends, outward, centers, directions, line, needed, reach, radius, min_sin,
                    parallel_deg):  # pragma: no cover
    """(2N,) how far each run end (``ends`` (2N, 2) px: the N runs' low ends, then their high ends;
    ``outward`` (2N, 2) their outward unit directions) grows to meet another line's run: for every
    pair of ends within ``reach`` px of runs on different lines (``line`` (N,)) whose directions
    (``directions`` (N, 2), through ``centers`` (N, 2)) cross at more than ``min_sin`` (the sine of
    ``parallel_deg``), both grow to the lines' intersection when it lies at most ``radius`` px
    beyond each end and at most 1 px behind it; an end keeps the largest growth. Directions are unit
    vectors; ``min_sin`` is passed as numpy computes it (the comparison is then numpy's own). Only
    the growth of the ``needed`` (N,) runs is asked for: pairs of two others are not looked at (on a
    textured image most runs are too short to give a piece, whatever they grow; sim_108: 20 ms a
    call when every pair was), so the other runs' growth may fall short."""
    n = len(line)
    grow = np.zeros(2 * n)
    if n == 0:
        return grow
    bins = int(np.ceil(180.0 / (0.95 * parallel_deg)))     # one bin is too narrow for two lines to meet
    usable, key, start, order, rows, columns = _binned(ends, directions, bins, reach)
    r2 = reach * reach
    cells = np.empty(9, np.int64)
    for p in range(2 * n):
        rp = p - n if p >= n else p
        if not usable[p] or not needed[rp]:
            continue
        for c in range(_neighbour_cells(key, p, rows, columns, cells)):
            base = cells[c] * bins
            own = base + key[p, 0]
            for part in range(2):        # the cell's other bins: before and after p's own
                first, last = (start[base], start[own]) if part == 0 else (start[own + 1], start[base + bins])
                for k in range(first, last):
                    q = order[k]
                    rq = q - n if q >= n else q
                    if q == p or (q < p and needed[rq]):    # each pair once: from its lower needed end
                        continue
                    ex, ey = ends[q, 0] - ends[p, 0], ends[q, 1] - ends[p, 1]
                    if ex * ex + ey * ey > r2:
                        continue
                    if line[rp] == line[rq]:
                        continue
                    # the pair's arithmetic from its lower end, whichever found it (the same bits)
                    lo, hi, rlo, rhi = (p, q, rp, rq) if p < q else (q, p, rq, rp)
                    d1x, d1y, d2x, d2y = directions[rlo, 0], directions[rlo, 1], directions[rhi, 0], directions[rhi, 1]
                    cross = d1x * d2y - d1y * d2x
                    if not abs(cross) > min_sin:
                        continue
                    diffx, diffy = centers[rhi, 0] - centers[rlo, 0], centers[rhi, 1] - centers[rlo, 1]
                    a = (diffx * d2y - diffy * d2x) / cross
                    meetx, meety = centers[rlo, 0] + a * d1x, centers[rlo, 1] + a * d1y
                    grow_lo = (meetx - ends[lo, 0]) * outward[lo, 0] + (meety - ends[lo, 1]) * outward[lo, 1]
                    grow_hi = (meetx - ends[hi, 0]) * outward[hi, 0] + (meety - ends[hi, 1]) * outward[hi, 1]
                    if grow_lo >= -1.0 and grow_lo <= radius and grow_hi >= -1.0 and grow_hi <= radius:
                        grow[lo] = max(grow[lo], grow_lo)
                        grow[hi] = max(grow[hi], grow_hi)
    return grow


@kernel
def collinear_links(ends, center, direction, normal, reach_px, max_deg, min_cos, max_offset_px):  # pragma: no cover
    """(L, 2) int64 pairs of chains (``ends`` (2K, 2) px: the K chains' low ends, then their high
    ends; lines through ``center`` (K, 2) along ``direction`` (K, 2), unit vectors, ``normal`` (K,
    2)) with ends within ``reach_px`` of each other, directions within ``max_deg`` (|cos| at least
    ``min_cos``, its cosine as numpy computes it) and each end within ``max_offset_px`` of the other
    chain's line. Only ends in neighbouring direction bins (at least 1.01 ``max_deg`` wide, around
    the half turn) are compared."""
    k_chains = len(center)
    m = len(ends)
    if m < 2:
        return np.empty((0, 2), np.int64)
    bins = max(1, min(100_000, int(np.pi / (max(np.radians(max_deg), 1e-9) * 1.01))))
    usable, key, start, order, rows, columns = _binned(ends, direction, bins, reach_px)
    r2 = reach_px * reach_px
    lowest = -1 if bins >= 3 else 0          # neighbouring bins, each once (-1 and +1 are one bin of two)
    highest = 2 if bins >= 3 else bins
    cells = np.empty(9, np.int64)
    links = np.empty((max(16, m), 2), np.int64)
    found = 0
    for p in range(m):
        if not usable[p]:
            continue
        i = p - k_chains if p >= k_chains else p
        for c in range(_neighbour_cells(key, p, rows, columns, cells)):
            for db in range(lowest, highest):
                b = cells[c] * bins + (key[p, 0] + db) % bins
                for k in range(start[b], start[b + 1]):
                    q = order[k]
                    ex, ey = ends[q, 0] - ends[p, 0], ends[q, 1] - ends[p, 1]
                    if q <= p or ex * ex + ey * ey > r2:
                        continue
                    j = q - k_chains if q >= k_chains else q
                    if i == j or not abs(direction[i, 0] * direction[j, 0]
                                         + direction[i, 1] * direction[j, 1]) >= min_cos:
                        continue
                    if not abs((ends[q, 0] - center[i, 0]) * normal[i, 0]
                               + (ends[q, 1] - center[i, 1]) * normal[i, 1]) <= max_offset_px:
                        continue
                    if not abs((ends[p, 0] - center[j, 0]) * normal[j, 0]
                               + (ends[p, 1] - center[j, 1]) * normal[j, 1]) <= max_offset_px:
                        continue
                    if found == len(links):              # full: twice the room
                        links = np.concatenate((links, np.empty_like(links)))
                    links[found, 0], links[found, 1] = i, j
                    found += 1
    return links[:found].copy()
