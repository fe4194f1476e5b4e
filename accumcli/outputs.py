"""Interim stand-in for the output set (being replaced): checks folders up front, writes each
output to a temporary name, renames all at the end, removes temporaries on failure."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from .errors import AccumError


class OutputSet:
    def __init__(self, paths):
        self.targets = [Path(p) for p in paths if p]
        for t in self.targets:
            if not t.parent.is_dir():
                raise AccumError(f"{t}: the folder {t.parent} does not exist")
        self._temps = {t: t.parent / f".accum-{os.getpid()}-{i}.tmp" for i, t in enumerate(self.targets)}

    def path(self, target) -> str:
        return str(self._temps[Path(target)])

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            for t, tmp in self._temps.items():
                if tmp.exists():
                    os.replace(tmp, t)
        for tmp in self._temps.values():
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
