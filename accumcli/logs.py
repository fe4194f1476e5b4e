"""Summarised warnings: the first few of each kind, then one "... and N more" line.

A per-frame problem on a long recording would otherwise print one line per
frame. ``LimitedWarnings`` lets the first ``limit`` warnings of one kind
through to its logger and counts the rest; ``summarise()`` (or leaving the
``with`` block) logs "<prefix>... and N more such warnings (<kind>)" once per
kind and resets the counts.
"""

from __future__ import annotations

import logging


class LimitedWarnings:
    """Warnings through ``logger``, at most ``limit`` per kind until ``summarise()``.

    ``kind`` is any short string naming the problem ("unpaired image"); the
    message is formatted as by ``logging`` (``msg % args``).
    """

    def __init__(self, logger: logging.Logger, limit: int = 5, prefix: str = ""):
        self.logger = logger
        self.limit = int(limit)
        self.prefix = prefix
        self.counts: dict[str, int] = {}

    def warning(self, kind: str, msg: str, *args) -> None:
        n = self.counts.get(kind, 0) + 1
        self.counts[kind] = n
        if n <= self.limit:
            self.logger.warning(msg, *args)

    __call__ = warning

    def suppressed(self) -> int:
        """Warnings counted but not yet logged, over all kinds."""
        return sum(max(n - self.limit, 0) for n in self.counts.values())

    def summarise(self) -> None:
        """Log one "... and N more such warnings" line per kind that exceeded the limit; reset."""
        for kind, n in self.counts.items():
            if n > self.limit:
                self.logger.warning("%s... and %d more such warnings (%s)", self.prefix, n - self.limit, kind)
        self.counts = {}

    def __enter__(self) -> "LimitedWarnings":
        return self

    def __exit__(self, *exc) -> None:
        self.summarise()
