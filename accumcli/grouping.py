"""Vectorised choice of one element per group, shared by matching and accumulation."""

from __future__ import annotations

import numpy as np


def best_per_key(keys: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """Indices of the lowest-``cost`` element of every distinct key (ties: the first)."""
    order = np.lexsort((cost, keys))
    first = np.ones(len(order), bool)
    first[1:] = keys[order][1:] != keys[order][:-1]
    return order[first]
