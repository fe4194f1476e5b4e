"""The decorator of the package's compiled kernels: numba's ``njit``, caching the compiled code next
to the module (or in the user's cache) when a place is writable, else compiling once per process
(numba refuses ``cache=True`` when it finds nowhere to write: a read-only install and home).

numba's error-message colours are off: formatting a message during type inference starts
colorama, whose exit hook then wrote a stray ESC[0m to every run's stdout on a terminal (also
with -q, also into a terminal's copy of the output)."""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")

from numba import njit  # noqa: E402  (after the setting above, which numba reads on import)


def kernel(function):
    try:
        return njit(cache=True)(function)
    except RuntimeError:        # "cannot cache function ...: no locator available"
        return njit(function)
