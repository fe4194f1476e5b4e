"""Extraction of the next frames in other processes while the current one is accumulated.

Frames are independent given the recorded poses, so with ``workers`` > 1 this process and a pool
of ``workers - 1`` helper processes extract them, at most ``2 * workers`` frames ahead of the one
handed on, and hand them back in recording order: memory stays bounded and the result is the same,
byte for byte, whatever the number of workers (extraction of one frame is deterministic). A helper
takes a frame only when it is ready (its start-up, importing the library and loading the compiled
kernels, takes about a second, 30 frames' work); until then, and whenever the helpers have enough
frames queued, this process extracts the frame itself. So a short recording costs no more than
with one worker, and a long one uses both cores from the first second. With ``workers`` = 1
extraction runs inline, without a pool.

The pool starts its processes from a fork server (``forkserver``), not by forking this process:
a fork of a process whose OpenCV and BLAS thread pools are running can deadlock in the child. As
with any multiprocessing, a script that calls a run with ``workers`` > 1 must guard its entry
point (``if __name__ == "__main__":``), since the workers import the main module.

Interrupts are this process's: a SIGINT or SIGTERM sent to the whole process group (``timeout``,
Ctrl-C in a terminal, a service manager stopping the job) reaches the helpers too, and killed
them (a BrokenProcessPool traceback; a helper killed with a frame half sent to it could hang
CPython 3.11 for good). So a helper ignores both once started (``_helper_start``), frames go to
the helpers only once all of them have warmed up (a helper that died starting, in its first
second, is seen there: this process then extracts every frame), the helpers are started with
interrupts held back, and an interrupted run waits for helpers still starting before it ends.
This process stops handing out frames, waits for the few queued, and cleans its outputs up.
Measured: 72 group signals at 0.4 to 4.5 s into extract and accumulate of the teabox, and 40 at
0.6 to 1.7 s into extract of the sample: no traceback, no hang, no process left. A SIGINT in a
helper's first second can still print its KeyboardInterrupt (the helper's own start-up).
"""

from __future__ import annotations

import collections
import logging
import multiprocessing
import os
from concurrent.futures import Future, ProcessPoolExecutor, wait
from typing import Iterable, Iterator

from ..errors import InputError, is_whole_number
from ..extract import ExtractParams, FrameSegments, extract_frame
from ..lines2d import StageTimes
from ..outputs import signals_blocked
from ..recording import StereoFrame

log = logging.getLogger("accumcli")


def _helper_start() -> None:
    """A helper runs OpenCV on one thread (the processes share the cores) and ignores interrupts
    (the run's own process handles them; see the module docstring)."""
    import signal

    import cv2

    cv2.setNumThreads(1)
    for interrupt in (signal.SIGINT, signal.SIGTERM):
        signal.signal(interrupt, signal.SIG_IGN)


def _new_pool(helpers: int) -> ProcessPoolExecutor:
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    return ProcessPoolExecutor(helpers, mp_context=context, initializer=_helper_start)


def _ready() -> bool:
    """A helper's warm-up: the compiled kernels loaded, by extracting a small made-up pair (a
    slanted bright quadrilateral, 8 px of disparity), so that its first real frame is not a slow one."""
    import cv2
    import numpy as np

    from ..recording import StereoIntrinsics

    left = np.full((120, 160), 40, np.uint8)
    cv2.fillConvexPoly(left, np.array([[50, 30], [120, 40], [110, 95], [40, 85]], np.int32), 200)
    right = np.roll(left, -8, axis=1)
    intrinsics = StereoIntrinsics(fx=100.0, fy=100.0, cx=80.0, cy=60.0, baseline=0.04, width=160, height=120)
    extract_frame(StereoFrame(0, 0, left, right, intrinsics, None), ExtractParams(), "camera")
    return True


def _extract(frame: StereoFrame, params: ExtractParams, camera_frame: str) -> tuple[FrameSegments, dict]:
    times = StageTimes()
    extraction = extract_frame(frame, params, camera_frame, times)
    extraction.gradients = None   # megabytes per frame to send back; tracking computes its own
    return extraction, times.seconds


AUTO_MIN_FRAMES = 40


def resolve_workers(workers: int | str | None, frames: int) -> int:
    """``workers``, or for None (``--workers auto``) what measured fastest on two cores: 2 processes,
    but 1 for fewer than ``AUTO_MIN_FRAMES`` frames or on one CPU. Measured with ``accum accumulate``
    as a whole command (start-up included; farm-bench, 2-core machine, A B A B): 2 workers took
    1.00x the wall time of one on 36 frames (the helper is still starting for most of them), 0.88x on
    60 frames and 0.67x on 120 of 640x480. Under 40 frames a run would wait for a helper that is
    still starting. More than 2 was not measured: give ``--workers N`` on a bigger machine. A number
    given is capped at the frames and the CPUs (with a warning for the CPUs): each process costs
    about 200 MB and a second to start, and 99999 of them ran for a quarter of an hour on 2 frames."""
    if workers == "auto":
        workers = None
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if workers is not None:
        if not is_whole_number(workers) or workers < 1:
            raise InputError(f"workers: expected a whole number of at least 1, or 'auto' / None, found {workers!r}")
        if workers > cpus:
            log.warning("--workers %d: this machine gives the run %d CPUs; using at most %d", workers, cpus, cpus)
        return max(1, min(int(workers), cpus, frames))
    return 1 if frames < AUTO_MIN_FRAMES or cpus < 2 else 2


def extracted_frames(frames: Iterable[StereoFrame], params: ExtractParams, camera_frame: str, workers: int,
                     times: StageTimes) -> Iterator[tuple[StereoFrame, FrameSegments]]:
    """(frame, its extraction) in recording order; per-stage times are added to ``times``. Close it
    (``contextlib.closing``) where the caller may stop early or be interrupted: its helpers end
    then, not whenever the generator is collected (after the run's error was reported, or never)."""
    if workers <= 1:
        for frame in frames:
            yield frame, extract_frame(frame, params, camera_frame, times)
        return
    helpers = workers - 1
    with _new_pool(helpers) as pool:
        ready: list[Future] = []
        try:
            with signals_blocked():   # the submits start the helpers: not interrupted between a fork and its record
                ready = [pool.submit(_ready) for _ in range(helpers)]
            yield from _hand_out(frames, pool, ready, params, camera_frame, workers, times)
        except BaseException:   # an interrupt: the pool's shutdown does not wait for a helper still starting,
            wait(ready, timeout=READY_WAIT_S)   # which then failed to find its queue's semaphore (a traceback)
            raise


READY_WAIT_S = 30.0   # how long an interrupted run waits for its helpers to finish starting


def _hand_out(frames, pool, ready, params, camera_frame, workers, times):
    """``extracted_frames``' loop: each frame to a helper when all are ready and fewer than two per
    helper are queued, else extracted here; (frame, extraction) in recording order."""
    helpers = workers - 1
    pending: collections.deque = collections.deque()    # (frame, future of its extraction)
    for frame in frames:
        queued = sum(not work.done() for _, work in pending)
        if all(r.done() and r.exception() is None for r in ready) and queued < 2 * helpers:
            pending.append((frame, pool.submit(_extract, frame, params, camera_frame)))
        else:                      # the helpers are starting or busy: this process takes it
            done: Future = Future()
            done.set_result((extract_frame(frame, params, camera_frame, times), {}))   # its times added
            pending.append((frame, done))
        while pending and (len(pending) > 2 * workers or pending[0][1].done()):
            yield _collect(pending.popleft(), times)
    while pending:
        yield _collect(pending.popleft(), times)


def _collect(item, times: StageTimes) -> tuple[StereoFrame, FrameSegments]:
    """(frame, extraction) of a pending item, the stage times of a helper's added to ``times``."""
    frame, future = item
    extraction, seconds = future.result()
    for stage, value in seconds.items():
        times.seconds[stage] = times.seconds.get(stage, 0.0) + value
    return frame, extraction
