"""Atomic output of one file: the single-file case of ``outputs.OutputSet`` (same checks,
short temporary name in the same folder, symlink and mode kept, temp removed on any
exception, rename with SIGINT/SIGTERM held back). An interrupted run never leaves half
a file: the target is either the old one or the complete new one.
"""

from __future__ import annotations

import contextlib

from .outputs import OutputSet


@contextlib.contextmanager
def atomic_open(path, mode: str = "w"):
    """A file (``"w"`` UTF-8 text or ``"wb"``) whose content replaces ``path`` when the block
    ends without error; raises AccumError when ``path`` cannot be written."""
    with OutputSet([path]) as out:
        yield out.open(path, mode)


@contextlib.contextmanager
def atomic_path(path):
    """A temporary path (in ``path``'s folder) for writers that open the file themselves;
    whatever is there when the block ends without error replaces ``path``."""
    with OutputSet([path]) as out:
        yield out.path(path)


@contextlib.contextmanager
def opened(target, mode: str = "w"):
    """``target`` itself if it is an open file (e.g. from ``OutputSet.open``; left open),
    else ``atomic_open(target, mode)``."""
    if hasattr(target, "write"):
        yield target
    else:
        with atomic_open(target, mode) as f:
            yield f
