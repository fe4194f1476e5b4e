"""The compiled per-group kernels give the numpy / scipy results bit for bit."""

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from accumcli.group_kernel import end_tapered, group_moments, group_range, line_extents, link_components
from accumcli.lines2d import dot2


def test_group_moments_equal_bincount_sums_bit_for_bit():
    rng = np.random.default_rng(3)
    n = 40
    index = rng.integers(0, n - 2, 5000)            # the last two groups empty
    x, y, w = rng.normal(300, 100, 5000), rng.normal(200, 80, 5000), rng.uniform(0, 50, 5000)
    sw, mx, my, sxx, syy, sxy = group_moments(index, n, x, y, w)
    ref_sw = np.bincount(index, w, n)
    safe = np.where(ref_sw > 0, ref_sw, 1.0)
    ref_mx, ref_my = np.bincount(index, w * x, n) / safe, np.bincount(index, w * y, n) / safe
    dx, dy = x - ref_mx[index], y - ref_my[index]
    for got, ref in ((sw, ref_sw), (mx, ref_mx), (my, ref_my), (sxx, np.bincount(index, w * dx * dx, n)),
                     (syy, np.bincount(index, w * dy * dy, n)), (sxy, np.bincount(index, w * dx * dy, n))):
        assert np.array_equal(got, ref)
    assert sw[-1] == 0 and mx[-1] == 0


def test_group_range_is_each_groups_min_and_max():
    rng = np.random.default_rng(4)
    groups, values = rng.integers(0, 30, 2000), rng.normal(0, 10, 2000)
    lo, hi = group_range(groups, 32, values)
    for k in range(30):
        assert lo[k] == values[groups == k].min() and hi[k] == values[groups == k].max()
    assert np.isinf(lo[30:]).all() and (lo[30:] > 0).all() and (hi[30:] < 0).all()


def test_end_tapered_equals_the_numpy_taper_bit_for_bit():
    """Points of 20 lines (and some of none, -1, which keep their magnitude): the weight falls to
    ``floor`` at a line's end and is the magnitude from ``taper`` - 0.5 inwards, as numpy computes it."""
    rng = np.random.default_rng(6)
    index = rng.integers(-1, 20, 3000)
    x, y, mag = rng.normal(300, 100, 3000), rng.normal(200, 80, 3000), rng.uniform(1, 50, 3000)
    center = rng.normal(250, 50, (20, 2))
    angle = rng.uniform(0, np.pi, 20)
    direction = np.column_stack([np.cos(angle), np.sin(angle)])
    got = end_tapered(index, *line_extents(index, x, y, center, direction), mag, 2.5, 0.1)
    on = index >= 0
    lab = index[on]
    t = dot2(np.column_stack([x, y])[on] - center[lab], direction[lab])
    lo, hi = group_range(lab, 20, t)
    ref = mag.copy()
    ref[on] *= np.clip((np.minimum(t - lo[lab], hi[lab] - t) + 0.5) / 2.5, 0.1, 1.0)
    assert np.array_equal(got, ref)
    assert np.array_equal(got[~on], mag[~on])
    at_end = (t == lo[lab]) | (t == hi[lab])
    assert at_end.sum() == 40 and np.allclose(got[on][at_end], 0.2 * mag[on][at_end])   # (0 + 0.5) / 2.5
    assert 0 < (got[on] == mag[on]).mean() < 1


def test_link_components_number_components_as_scipy_does():
    rng = np.random.default_rng(5)
    n = 500
    links = rng.integers(0, n, (300, 2))
    graph = csr_matrix((np.ones(len(links), np.int8), (links[:, 0], links[:, 1])), shape=(n, n))
    assert np.array_equal(link_components(n, links), connected_components(graph, directed=False)[1])
    assert np.array_equal(link_components(3, np.zeros((0, 2), np.int64)), [0, 1, 2])


def test_dot2_equals_the_sum_of_products():
    rng = np.random.default_rng(6)
    a, b = rng.normal(size=(100, 2)), rng.normal(size=(100, 2))
    assert np.array_equal(dot2(a, b), np.sum(a * b, axis=1))


def test_magnitude_equals_hypot_on_sobel_gradients():
    import cv2
    from accumcli.lines2d import Gradients

    image = np.random.default_rng(8).integers(0, 256, (60, 80)).astype(np.uint8)
    grad = Gradients.of(image)
    assert np.array_equal(grad.magnitude, np.hypot(grad.gx, grad.gy))
    assert np.array_equal(grad.gx * 8, cv2.Sobel(cv2.GaussianBlur(image, (0, 0), grad.blur_sigma), cv2.CV_32F, 1, 0))


def test_line_coordinates_place_points_along_and_across_their_line():
    from accumcli.group_kernel import line_coordinates

    center, direction = np.array([[10.0, 20.0], [0.0, 0.0]]), np.array([[0.6, 0.8], [1.0, 0.0]])
    xy = np.array([[10.0 + 3 * 0.6 - 2 * 0.8, 20.0 + 3 * 0.8 + 2 * 0.6], [5.0, -1.0]])
    g = np.array([[-0.8, 0.6], [0.0, 2.0]])            # along both lines' normals
    t, across, polarity = line_coordinates(xy, g, np.array([0, 1]), center, direction)
    assert np.allclose(t, [3, 5]) and np.allclose(across, [2, -1]) and list(polarity) == [1, 1]
    t, across, polarity = line_coordinates(xy, -g, np.array([0, 1]), center, direction)
    assert list(polarity) == [-1, -1]


def test_supporting_runs_and_piece_groups_equal_the_numpy_runs_and_bincounts_bit_for_bit():
    """Points of 12 lines, both polarities, with gaps: the runs (a new one where the line or the
    polarity changes or t steps more than the gap) and the pieces' sums, as ``local_segments``
    computed them with numpy before (a reordering, np.diff, np.cumsum, np.bincount)."""
    from accumcli.group_kernel import piece_groups, supporting_runs

    rng = np.random.default_rng(8)
    m = 4000
    labels, polarity = rng.integers(0, 12, m), rng.choice([-1, 1], m)
    t = np.round(rng.uniform(0, 80, m), 1)
    mag = rng.uniform(1, 40, m)
    order = np.lexsort((t, polarity, labels))[100:]            # some points dropped, as the across-check does
    run, t_lo, t_hi, line, count = supporting_runs(order, labels, polarity, t, 3.0)
    ts, ls, ps = t[order], labels[order], polarity[order]
    brk = np.ones(len(ts), bool)
    brk[1:] = (ls[1:] != ls[:-1]) | (ps[1:] != ps[:-1]) | (np.diff(ts) > 3.0)
    ref_run = np.cumsum(brk) - 1
    assert np.array_equal(run, ref_run) and np.array_equal(t_lo, ts[brk]) and np.array_equal(line, ls[brk])
    assert np.array_equal(t_hi, ts[np.r_[np.flatnonzero(brk)[1:], len(ts)] - 1])
    assert np.array_equal(count, np.bincount(ref_run)) and brk.sum() > 12 * 2    # gaps split lines

    pieces = np.where(rng.uniform(size=len(t_lo)) < 0.8, np.ceil((t_hi - t_lo + 1) / 15.0), 0).astype(np.int64)
    length = (t_hi - t_lo + 1) / np.maximum(pieces, 1)
    first_center, spacing = t_lo + length / 2 - 0.5, length
    group, sw, swt, n, group_run, first = piece_groups(order, run, t, mag, first_center, spacing, pieces)
    piece = np.clip(np.round((ts - first_center[run]) / np.where(spacing[run] > 0, spacing[run], 1.0)), 0,
                    np.maximum(pieces[run] - 1, 0)).astype(np.int64)
    has = pieces[run] > 0
    ref_group = (np.cumsum(pieces) - pieces)[run] + piece
    assert np.array_equal(group[has], ref_group[has]) and (group[~has] == -1).all() and (~has).any()
    g, w = ref_group[has], mag[order][has]
    assert np.array_equal(sw, np.bincount(g, w, pieces.sum())) and np.array_equal(n, np.bincount(g, minlength=len(sw)))
    assert np.array_equal(swt, np.bincount(g, w * ts[has], pieces.sum()))
    seen = n > 0
    assert np.array_equal(group_run[seen], run[has][np.unique(g, return_index=True)[1]])
    assert np.array_equal(labels[first[seen]], line[group_run[seen]])
