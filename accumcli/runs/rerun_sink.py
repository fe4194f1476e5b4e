"""A Rerun log for a run, written into the run's output set (or None when no .rrd was asked for)."""

from __future__ import annotations

import contextlib


@contextlib.contextmanager
def rerun_log(outputs, rrd, kind: str):
    """Yields a ``RerunLog`` saving to the output set's temporary for ``rrd``, closed at the end;
    rerun is imported only when an .rrd is asked for."""
    if not rrd:
        yield None
        return
    from ..visualize import RerunLog

    log_ = RerunLog(f"accum {kind}", rrd=outputs.path(rrd), kind=kind)
    try:
        yield log_
    finally:
        log_.close()
