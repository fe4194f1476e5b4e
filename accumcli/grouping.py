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


def group_range(groups: np.ndarray, n: int, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) smallest and (n,) largest of ``values`` per group 0..n-1 (inf and -inf for an empty one).
    Compiled (``group_kernel.group_range``): ``np.minimum.at`` ran 25 times slower on some arrays
    than on others of the same size (numpy 2.4), and sorting for ``reduceat`` took a third of
    ``edge_chains.collinear_lines``."""
    return kernel_range(np.ascontiguousarray(groups, np.int64), int(n), np.ascontiguousarray(values, np.float64))
