"""Compiled per-group sums and labels over edge points, and the gradient magnitude image (numba,
installed as a wheel).

Why compiled: each is one pass over the points, where numpy needed a whole-array call per sum
(``np.bincount`` six times for a line fit), a sort (the per-group range) or a sparse graph
(``scipy.sparse.csgraph.connected_components``), and 2D detection calls them on every image. The
results are those of the numpy versions bit for bit: sums in index order, as ``np.bincount``
adds, and components numbered by their lowest index, as scipy numbers them. The magnitude: one
pass instead of numpy's three.
"""

from __future__ import annotations

import numpy as np

from .jit import kernel


@kernel
def group_moments(index, n, x, y, w):  # pragma: no cover
    """Per group 0..``n``-1 of the points (``index`` (M,) int64, ``x``, ``y``, ``w`` (M,) float64):
    weight sum, weighted mean x and y (0 for a group of zero weight), and the weighted second
    moments about the mean, sum w dx dx, w dy dy, w dx dy ((n,) float64 each)."""
    sw, sx, sy = np.zeros(n), np.zeros(n), np.zeros(n)
    for i in range(len(index)):
        k = index[i]
        sw[k] += w[i]
        sx[k] += w[i] * x[i]
        sy[k] += w[i] * y[i]
    for k in range(n):
        safe = sw[k] if sw[k] > 0 else 1.0
        sx[k] /= safe
        sy[k] /= safe
    sxx, syy, sxy = np.zeros(n), np.zeros(n), np.zeros(n)
    for i in range(len(index)):
        k = index[i]
        dx, dy = x[i] - sx[k], y[i] - sy[k]
        sxx[k] += w[i] * dx * dx
        syy[k] += w[i] * dy * dy
        sxy[k] += w[i] * dx * dy
    return sw, sx, sy, sxx, syy, sxy


@kernel
def group_line_fit(index, n, xy, w):  # pragma: no cover
    """Per group 0..``n``-1 of the points (``index`` (M,) int64, ``xy`` (M, 2), ``w`` (M,) float64):
    the weight sum (n,), the weighted centroid (n, 2) and the unit direction (n, 2) of the weighted
    total-least-squares line, at half the angle of (2 sxy, sxx - syy) (``group_moments``): as
    ``lines2d._weighted_line_fit`` computed them with numpy after the sums, in the same pass."""
    x, y = np.empty(len(index)), np.empty(len(index))
    for i in range(len(index)):
        x[i], y[i] = xy[i, 0], xy[i, 1]
    sw, mx, my, sxx, syy, sxy = group_moments(index, n, x, y, w)
    centers, directions = np.empty((n, 2)), np.empty((n, 2))
    for k in range(n):
        angle = 0.5 * np.arctan2(2 * sxy[k], sxx[k] - syy[k])
        centers[k, 0], centers[k, 1] = mx[k], my[k]
        directions[k, 0], directions[k, 1] = np.cos(angle), np.sin(angle)
    return sw, centers, directions


@kernel
def line_extents(index, x, y, center, direction):  # pragma: no cover
    """Per point (``index`` (M,) int64 group or -1, ``x``, ``y`` (M,) float64) its position t along its
    group's line (``center``, unit ``direction`` (G, 2); undefined for -1), and per group the
    smallest and largest t (G,) (inf and -inf for an empty group)."""
    m, n = len(index), len(center)
    t = np.empty(m)
    lo, hi = np.full(n, np.inf), np.full(n, -np.inf)
    for i in range(m):
        k = index[i]
        if k < 0:
            continue
        t[i] = (x[i] - center[k, 0]) * direction[k, 0] + (y[i] - center[k, 1]) * direction[k, 1]
        lo[k] = min(lo[k], t[i])
        hi[k] = max(hi[k], t[i])
    return t, lo, hi


@kernel
def end_tapered(index, t, lo, hi, mag, taper_px, floor):  # pragma: no cover
    """(M,) ``mag`` of the points (``index`` (M,) int64 group or -1) scaled by clip((d + 0.5) /
    ``taper_px``, ``floor``, 1) at d along their group's line from its nearer end point (``t`` (M,),
    ``lo``, ``hi`` (G,): ``line_extents``): ``edge_chains.end_tapered_weights``, bit for bit as numpy
    computes it, in one pass instead of a dozen whole-array calls."""
    weights = mag.copy()
    for i in range(len(index)):
        k = index[i]
        if k < 0:
            continue
        scale = (min(t[i] - lo[k], hi[k] - t[i]) + 0.5) / taper_px
        weights[i] = mag[i] * min(max(scale, floor), 1.0)
    return weights


@kernel
def line_coordinates(xy, g, index, center, direction):  # pragma: no cover
    """Per point (``xy``, gradient ``g`` (M, 2) float64, line ``index`` (M,) int64) in the frame of
    its line (``center``, unit ``direction`` (L, 2), normal (-dy, dx)): (M,) position along the line,
    (M,) offset across it, and (M,) int64 polarity, 1 where the gradient points along the normal
    (or across it), else -1."""
    m = len(index)
    t, across = np.empty(m), np.empty(m)
    polarity = np.empty(m, np.int64)
    for i in range(m):
        k = index[i]
        dx, dy = direction[k, 0], direction[k, 1]
        rx, ry = xy[i, 0] - center[k, 0], xy[i, 1] - center[k, 1]
        t[i] = rx * dx + ry * dy
        across[i] = rx * -dy + ry * dx
        polarity[i] = 1 if g[i, 0] * -dy + g[i, 1] * dx >= 0 else -1
    return t, across, polarity


@kernel
def group_range(groups, n, values):  # pragma: no cover
    """(n,) smallest and (n,) largest of ``values`` (M,) float64 per group 0..``n``-1 of ``groups``
    (M,) int64 (inf and -inf for an empty group)."""
    lo, hi = np.full(n, np.inf), np.full(n, -np.inf)
    for i in range(len(groups)):
        k = groups[i]
        if values[i] < lo[k]:
            lo[k] = values[i]
        if values[i] > hi[k]:
            hi[k] = values[i]
    return lo, hi


@kernel
def link_components(n, links):  # pragma: no cover
    """(n,) int64 component 0..C-1 of every node of the undirected graph ``links`` (E, 2) int64,
    numbered by their lowest node (union by the smaller root, then one pass in node order)."""
    parent = np.arange(n)
    for k in range(len(links)):
        a, b = links[k, 0], links[k, 1]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a < b:
            parent[b] = a
        elif b < a:
            parent[a] = b
    label = np.empty(n, np.int64)
    count = 0
    for i in range(n):
        root = i
        while parent[root] != root:
            root = parent[root]
        if root == i:
            label[i] = count
            count += 1
        else:
            label[i] = label[root]
    return label


@kernel
def magnitude(gx, gy):  # pragma: no cover
    """(H, W) float32 sqrt(gx^2 + gy^2) of (H, W) float32 gradients, in float32 (as numpy's
    ``np.sqrt(gx * gx + gy * gy)``)."""
    out = np.empty(gx.shape, np.float32)
    for r in range(gx.shape[0]):
        for c in range(gx.shape[1]):
            out[r, c] = np.sqrt(gx[r, c] * gx[r, c] + gy[r, c] * gy[r, c])
    return out


@kernel
def supporting_runs(order, labels, polarity, t, max_gap):  # pragma: no cover
    """Runs of the points taken in ``order`` (K,) int64 (sorted by line ``labels``, ``polarity``, ``t``
    (M,)): a new run where the line or the polarity changes or ``t`` steps more than ``max_gap``.
    Returns per ordered point its run (K,) int64, and per run its first and last ``t``, its line and
    its point count (int64): ``lines2d.local_segments``' runs bit for bit, in one pass instead of a
    reordering of five arrays and a dozen whole-array calls."""
    k = len(order)
    run = np.empty(k, np.int64)
    n = 0
    for i in range(k):
        a = order[i]
        if i == 0:
            n += 1
        else:
            b = order[i - 1]
            if labels[a] != labels[b] or polarity[a] != polarity[b] or t[a] - t[b] > max_gap:
                n += 1
        run[i] = n - 1
    t_lo, t_hi = np.empty(n), np.empty(n)
    line, count = np.empty(n, np.int64), np.zeros(n, np.int64)
    for i in range(k):
        r, a = run[i], order[i]
        if count[r] == 0:
            t_lo[r] = t[a]
            line[r] = labels[a]
        t_hi[r] = t[a]
        count[r] += 1
    return run, t_lo, t_hi, line, count


@kernel
def piece_groups(order, run, t, mag, first_center, spacing, pieces):  # pragma: no cover
    """The piece (group) of each ordered point (``order`` (K,), its ``run`` (K,), ``t``, ``mag`` (M,)):
    round((t - ``first_center``) / ``spacing``) of its run clipped to the run's ``pieces`` (R,), -1
    where the run has none; groups are numbered run by run. Returns the group (K,) int64 and per
    group (G,): the weight sum of ``mag``, the sum of ``mag`` t, the point count, the run and the
    first point's index (into the unordered arrays): ``lines2d.local_segments``' bincounts bit for
    bit (sums in order)."""
    n_runs = len(pieces)
    first_piece = np.empty(n_runs, np.int64)
    total = 0
    for r in range(n_runs):
        first_piece[r] = total
        total += pieces[r]
    group = np.full(len(order), -1, np.int64)
    sw, swt = np.zeros(total), np.zeros(total)
    count, group_run, first = np.zeros(total, np.int64), np.zeros(total, np.int64), np.zeros(total, np.int64)
    for i in range(len(order)):
        r, a = run[i], order[i]
        if pieces[r] <= 0:
            continue
        step = spacing[r] if spacing[r] > 0 else 1.0
        piece = min(max(np.rint((t[a] - first_center[r]) / step), 0.0), max(pieces[r] - 1, 0))
        g = first_piece[r] + np.int64(piece)
        group[i] = g
        sw[g] += mag[a]
        swt[g] += mag[a] * t[a]
        if count[g] == 0:
            first[g] = a
            group_run[g] = r
        count[g] += 1
    return group, sw, swt, count, group_run, first
