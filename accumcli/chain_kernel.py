"""The compiled kernel of ``edge_chains.straight_chains``: connected components of the chain links
and their Douglas-Peucker cuts, round by round, in one pass over the points per round.

Why compiled (numba, installed as a wheel): the numpy version needed about fifteen whole-array calls
and a sparse-graph labelling per round, half of the 2D detection time (10 ms per 640x480 image);
the loops here are over points and links, each touched a few times per round. The rules are those
of ``straight_chains`` (its docstring), in the same order, so the labels are the same: components
are numbered by their lowest point index (as scipy's ``connected_components`` numbers them), the
line fits sum their points in index order (as ``np.bincount`` does), ties along a chain go to the
lower index (as the stable ``np.lexsort`` orders them).
"""

from __future__ import annotations

import numpy as np

from .group_kernel import group_moments
from .jit import kernel


@kernel
def straight_chain_labels(xy, mag, pixel, links, max_residual_px, rounds, min_length_px):  # pragma: no cover
    """(M,) label 0..K-1 of the straight chain of every point (-1: none). ``xy`` (M, 2) float64
    px, ``mag`` (M,) float64 weights, ``pixel`` (M, 2) int64 (row, column), ``links`` (E, 2)
    int64 point index pairs (``edge_chains.chain_links``)."""
    m = len(mag)
    labels = np.full(m, -1, np.int64)
    if m == 0:
        return labels
    e = len(links)
    start = np.zeros(m + 1, np.int64)                 # adjacency (CSR) with each entry's link
    for k in range(e):
        start[links[k, 0] + 1] += 1
        start[links[k, 1] + 1] += 1
    for i in range(m):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    neighbour = np.empty(2 * e, np.int64)
    via = np.empty(2 * e, np.int64)
    for k in range(e):
        a, b = links[k, 0], links[k, 1]
        neighbour[fill[a]], via[fill[a]] = b, k
        fill[a] += 1
        neighbour[fill[b]], via[fill[b]] = a, k
        fill[b] += 1
    link_alive = np.ones(e, np.bool_)
    active = np.ones(m, np.bool_)
    key = np.zeros(m, np.int64)
    comp = np.full(m, -1, np.int64)
    stack = np.empty(m, np.int64)
    points = np.arange(m)               # the active points, ascending: each round walks only these
    n_points = m
    live = np.arange(e)                 # the links still alive, ascending
    n_live = e
    n_final = 0
    for round_ in range(rounds + 1):
        # a link lives on while its two ends are active and on the same side of every cut
        kept = 0
        for q in range(n_live):
            k = live[q]
            a, b = links[k, 0], links[k, 1]
            if active[a] and active[b] and key[a] == key[b]:
                live[kept] = k
                kept += 1
            else:
                link_alive[k] = False
        n_live = kept
        for p in range(n_points):
            comp[points[p]] = -1
        n = 0
        for p in range(n_points):
            s = points[p]
            if comp[s] >= 0:
                continue
            comp[s] = n
            top = 1
            stack[0] = s
            while top:
                top -= 1
                v = stack[top]
                for q in range(start[v], start[v + 1]):
                    w = neighbour[q]
                    if link_alive[via[q]] and comp[w] < 0:
                        comp[w] = n
                        stack[top] = w
                        top += 1
            n += 1
        # weighted TLS line per component, summed in index order
        active_points = points[:n_points]
        _, mx, my, sxx, syy, sxy = group_moments(comp[active_points], n, xy[active_points, 0], xy[active_points, 1],
                                                 mag[active_points])
        ux, uy = np.empty(n), np.empty(n)
        for c in range(n):
            angle = 0.5 * np.arctan2(2 * sxy[c], sxx[c] - syy[c])
            ux[c], uy[c] = np.cos(angle), np.sin(angle)
        # the first and the last point along each line (ties: the lower index first)
        t = np.empty(m)
        first = np.full(n, -1, np.int64)
        last = np.full(n, -1, np.int64)
        for p in range(n_points):
            i = points[p]
            c = comp[i]
            t[i] = (xy[i, 0] - mx[c]) * ux[c] + (xy[i, 1] - my[c]) * uy[c]
            if first[c] < 0 or t[i] < t[first[c]]:
                first[c] = i
            if last[c] < 0 or t[i] >= t[last[c]]:
                last[c] = i
        cx, cy, length = np.empty(n), np.empty(n), np.empty(n)
        for c in range(n):
            dx, dy = xy[last[c], 0] - xy[first[c], 0], xy[last[c], 1] - xy[first[c], 1]
            length[c] = np.sqrt(dx * dx + dy * dy)
            norm = max(length[c], 1e-9)
            cx[c], cy[c] = dx / norm, dy / norm
        # the farthest point from the chord (ties: the first along the line, then the lower index)
        worst = np.full(n, -1, np.int64)
        worst_across = np.full(n, -1.0)
        for p in range(n_points):
            i = points[p]
            c = comp[i]
            rx, ry = xy[i, 0] - xy[first[c], 0], xy[i, 1] - xy[first[c], 1]
            across = abs(rx * cy[c] - ry * cx[c])
            j = worst[c]
            if j < 0 or across > worst_across[c] or (across == worst_across[c] and t[i] < t[j]):
                worst[c], worst_across[c] = i, across
        bent = np.zeros(n, np.bool_)
        rank = np.empty(n, np.int64)
        any_bent = False
        for c in range(n):
            bent[c] = worst_across[c] > max_residual_px and round_ < rounds and length[c] >= min_length_px
            if bent[c]:
                any_bent = True
            else:
                rank[c] = n_final
                n_final += 1
        left = 0
        for p in range(n_points):
            i = points[p]
            c = comp[i]
            if not bent[c]:
                labels[i] = rank[c]
                active[i] = False
                continue
            j = worst[c]
            if max(abs(pixel[i, 0] - pixel[j, 0]), abs(pixel[i, 1] - pixel[j, 1])) <= 1:
                active[i] = False          # the cut point and its 8-neighbours: a corner's own pixels
                continue
            key[i] = c * 2 + (1 if t[i] > t[j] else 0)
            points[left] = i           # still active: the next round's points, ascending
            left += 1
        n_points = left
        if not any_bent or left == 0:
            break
    return labels


@kernel
def neighbour_links(pixel, g, mag, height, width, cos_max):  # pragma: no cover
    """(E, 2) int64 index pairs (i, j) of 8-neighbouring points (``pixel`` (M, 2) int64 (row,
    column) in an image of ``height`` x ``width``) whose unit gradients (``g`` (M, 2) / ``mag`` (M,))
    agree (dot at least ``cos_max``), each pair once: for the neighbour offsets right, down-left,
    down, down-right in turn, the points in index order (the order of ``edge_chains.chain_links``'
    numpy version, which the chain labels depend on through the links' order)."""
    m = len(mag)
    index = np.full((height + 2, width + 2), -1, np.int32)     # padded: border neighbours are -1
    for i in range(m):
        index[pixel[i, 0] + 1, pixel[i, 1] + 1] = i
    ux, uy = np.empty(m), np.empty(m)          # the unit gradients, each division once
    for i in range(m):
        ux[i], uy[i] = g[i, 0] / mag[i], g[i, 1] / mag[i]
    links = np.empty((4 * m, 2), np.int64)
    found = 0
    for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):
        for i in range(m):
            j = index[pixel[i, 0] + 1 + dr, pixel[i, 1] + 1 + dc]
            if j < 0:
                continue
            if ux[i] * ux[j] + uy[i] * uy[j] >= cos_max:
                links[found, 0], links[found, 1] = i, j
                found += 1
    return links[:found].copy()


@kernel
def grouped_order(keys, groups):  # pragma: no cover
    """Indices (M,) grouped by ``keys`` (M,) int64 in 0..``groups``-1, a stable counting sort (a
    negative key leaves its index out): (start (groups + 1,) of each group's run in order, order)."""
    start = np.zeros(groups + 1, np.int64)
    for i in range(len(keys)):
        if keys[i] >= 0:
            start[keys[i] + 1] += 1
    for k in range(groups):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(start[groups], np.int64)
    for i in range(len(keys)):
        k = keys[i]
        if k >= 0:
            order[fill[k]] = i
            fill[k] += 1
    return start, order


@kernel
def line_order(labels, polarity, t):  # pragma: no cover
    """(M,) the order of ``np.lexsort((t, polarity, labels))`` (``labels`` (M,) int64 >= 0, ``polarity``
    (M,) -1 or 1, ``t`` (M,) float64): a stable counting sort by (label, polarity), then a stable
    sort by ``t`` within each group (insertion for up to 32, else merge sort). Why: the lexsort's three
    stable passes over every edge point of an image took 1.7 ms of ``lines2d.local_segments``' 3.8;
    the groups are small."""
    if len(t) == 0:
        return np.empty(0, np.int64)
    keys = 2 * labels + (polarity > 0)
    groups = 2 * (labels.max() + 1)
    start, order = grouped_order(keys, groups)
    for k in range(groups):
        a, b = start[k], start[k + 1]
        if b - a > 32:
            members = order[a:b].copy()
            order[a:b] = members[np.argsort(t[members], kind="mergesort")]
        else:                          # a short group: a stable insertion sort, no allocation
            for i in range(a + 1, b):
                item = order[i]
                j = i - 1
                while j >= a and t[order[j]] > t[item]:
                    order[j + 1] = order[j]
                    j -= 1
                order[j + 1] = item
    return order
