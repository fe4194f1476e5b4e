"""Samples along straight edges, as formats.md section 4 defines them.

Sample i of k on the edge from a to b sits at ``a + (i + 0.5) / k * (b - a)``;
the truth's per-sample ``seen`` counts and every completeness figure use these
points. The simulator and the evaluation both sample here.
"""

from __future__ import annotations

import numpy as np

SAMPLE_SPACING_M = 0.002


def sample_count(a: np.ndarray, b: np.ndarray, spacing: float = SAMPLE_SPACING_M) -> int:
    """Samples on the edge a -> b ((3,) metres) at most ``spacing`` metres apart, at least 2."""
    return max(2, int(np.ceil(np.linalg.norm(np.asarray(b, float) - np.asarray(a, float)) / spacing)))


def edge_samples(a: np.ndarray, b: np.ndarray, k: int) -> np.ndarray:
    """(k, 3) points ``a + (i + 0.5) / k * (b - a)`` for i = 0..k-1, in the frame and unit of a and b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    s = (np.arange(k) + 0.5) / k
    return a + s[:, None] * (b - a)
