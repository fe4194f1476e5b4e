"""Compiled tests over the near pairs of line ends that 2D detection finds with a KD-tree:
``lines2d._complete_junctions`` (runs meeting at a corner) and ``edge_chains.collinear_lines``
(chains on one line).

Why compiled (numba, installed as a wheel): on a textured real image (teabox: print on the box, grain,
floor tiles) about 110,000 pairs of ends lie within 14 px of each other, and the numpy version
gathered and combined a dozen (pairs, 2) arrays per call: 11 ms of a call's 14, a quarter of the
detection time there. The loop here touches each pair once, with the same arithmetic in the same
order as the numpy expressions it replaced (no fused multiply-add: numba does not contract without
fastmath), so the results are the same bits.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel


@kernel
def junction_growth(pairs, ends, outward, centers, directions, line, radius, min_sin):  # pragma: no cover
    """(2N,) how far each run end (``ends`` (2N, 2) px: the N runs' low ends, then their high ends;
    ``outward`` (2N, 2) their outward unit directions) grows to meet another line's run: for every
    pair of ends (``pairs`` (P, 2) int64) of runs on different lines (``line`` (N,)) whose
    directions (``directions`` (N, 2), through ``centers`` (N, 2)) cross at more than ``min_sin``,
    both grow to the lines' intersection when it lies at most ``radius`` px beyond each end and
    less than 1 px behind it; an end keeps the largest growth."""
    n = len(line)
    grow = np.zeros(2 * n)
    for k in range(len(pairs)):
        p, q = pairs[k, 0], pairs[k, 1]
        rp = p - n if p >= n else p
        rq = q - n if q >= n else q
        if line[rp] == line[rq]:
            continue
        d1x, d1y, d2x, d2y = directions[rp, 0], directions[rp, 1], directions[rq, 0], directions[rq, 1]
        cross = d1x * d2y - d1y * d2x
        if not abs(cross) > min_sin:
            continue
        diffx, diffy = centers[rq, 0] - centers[rp, 0], centers[rq, 1] - centers[rp, 1]
        a = (diffx * d2y - diffy * d2x) / cross
        meetx, meety = centers[rp, 0] + a * d1x, centers[rp, 1] + a * d1y
        grow_p = (meetx - ends[p, 0]) * outward[p, 0] + (meety - ends[p, 1]) * outward[p, 1]
        grow_q = (meetx - ends[q, 0]) * outward[q, 0] + (meety - ends[q, 1]) * outward[q, 1]
        if grow_p >= -1.0 and grow_p <= radius and grow_q >= -1.0 and grow_q <= radius:
            grow[p] = max(grow[p], grow_p)
            grow[q] = max(grow[q], grow_q)
    return grow


@kernel
def collinear_pairs(pairs, ends, center, direction, normal, min_cos, max_offset_px):  # pragma: no cover
    """(P,) bool: the pairs of chain ends (``pairs`` (P, 2) int64 into ``ends`` (2K, 2) px: the K
    chains' low ends, then their high ends) of two different chains whose directions (``direction``
    (K, 2), lines through ``center`` (K, 2), ``normal`` (K, 2)) agree within ``min_cos`` and whose
    ends lie within ``max_offset_px`` of the other chain's line."""
    k_chains = len(center)
    ok = np.zeros(len(pairs), np.bool_)
    for k in range(len(pairs)):
        p, q = pairs[k, 0], pairs[k, 1]
        i = p - k_chains if p >= k_chains else p
        j = q - k_chains if q >= k_chains else q
        if i == j:
            continue
        if not abs(direction[i, 0] * direction[j, 0] + direction[i, 1] * direction[j, 1]) >= min_cos:
            continue
        if not abs((ends[q, 0] - center[i, 0]) * normal[i, 0] + (ends[q, 1] - center[i, 1]) * normal[i, 1]) <= max_offset_px:
            continue
        ok[k] = abs((ends[p, 0] - center[j, 0]) * normal[j, 0] + (ends[p, 1] - center[j, 1]) * normal[j, 1]) <= max_offset_px
    return ok
