"""Logs written frame by frame into a run's output set: the Rerun log (None when no .rrd was asked
for) and the model MCAPs for Foxglove (empty when none was)."""

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


@contextlib.contextmanager
def scene_log(outputs, paths):
    """Yields a ``ModelMcap`` per ``.mcap`` among ``paths`` (written into the output set), closed at the end."""
    wanted = [p for p in paths if str(p).lower().endswith(".mcap")]
    if not wanted:
        yield []
        return
    from ..foxglove_scene import ModelMcap
    from ..recording import RecordingWriter

    with contextlib.ExitStack() as stack:
        yield [ModelMcap(stack.enter_context(RecordingWriter(outputs.open(p, "wb")))) for p in wanted]
