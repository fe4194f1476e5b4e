"""Atomic file output: write to a temporary file beside the target, then rename.

An interrupted run never leaves half a file; the target is either the old one
or the complete new one.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from .errors import AccumError


@contextlib.contextmanager
def atomic_open(path, mode: str = "w"):
    """Open a temporary file for writing; on success it replaces ``path``."""
    target = Path(path)
    if not target.parent.is_dir():
        raise AccumError(f"{target}: the folder {target.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, mode) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
