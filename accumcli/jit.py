"""The decorator of the package's compiled kernels: numba's ``njit``, caching the compiled code next
to the module (or in the user's cache) when a place is writable, else compiling once per process
(numba refuses ``cache=True`` when it finds nowhere to write: a read-only install and home)."""

from __future__ import annotations

from numba import njit


def kernel(function):
    try:
        return njit(cache=True)(function)
    except RuntimeError:        # "cannot cache function ...: no locator available"
        return njit(function)
