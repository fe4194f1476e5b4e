"""Vectorised choice of one element per group, shared by matching and accumulation."""

from __future__ import annotations

import numpy as np

from .group_kernel import group_range as kernel_range


def best_per_key(keys: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """Indices of the lowest-``cost`` element of every distinct key (ties: the first)."""
    order = np.lexsort((cost, keys))
    first = np.ones(len(order), bool)
    first[1:] = keys[order][1:] != keys[order][:-1]
    return order[first]


def ranges(first: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(count.sum(),) the indices first[k] .. first[k] + count[k] - 1 of every k in turn: the hits of a
    sorted search (``np.searchsorted`` gives ``first`` and ``count``) without a loop."""
    return np.repeat(first, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)


def group_range(groups: np.ndarray, n: int, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) smallest and (n,) largest of ``values`` per group 0..n-1 (inf and -inf for an empty one).
    Compiled (``group_kernel.group_range``): ``np.minimum.at`` ran 25 times slower on some arrays
    than on others of the same size (numpy 2.4), and sorting for ``reduceat`` took a third of
    ``edge_chains.collinear_lines``."""
    return kernel_range(np.ascontiguousarray(groups, np.int64), int(n), np.ascontiguousarray(values, np.float64))
