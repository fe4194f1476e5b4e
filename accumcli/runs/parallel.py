"""Extraction of the next frames in other processes while the current one is accumulated.

Frames are independent given the recorded poses, so with ``workers`` > 1 the frames read (in
this process, in order) are extracted by a pool of ``workers`` processes, at most
``2 * workers`` frames ahead, and handed back in recording order: memory stays bounded and the
result is the same, byte for byte, whatever the number of workers (extraction of one frame is
deterministic). With ``workers`` = 1 extraction runs inline, without a pool.

The pool starts its processes from a fork server (``forkserver``), not by forking this process:
a fork of a process whose OpenCV and BLAS thread pools are running can deadlock in the child. As
with any multiprocessing, a script that calls a run with ``workers`` > 1 must guard its entry
point (``if __name__ == "__main__":``), since the workers import the main module.
"""

from __future__ import annotations

import collections
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from typing import Iterable, Iterator

from ..extract import ExtractParams, FrameSegments, extract_frame
from ..lines2d import StageTimes
from ..recording import StereoFrame


def _one_thread() -> None:
    import cv2

    cv2.setNumThreads(1)


def _extract(frame: StereoFrame, params: ExtractParams, camera_frame: str) -> tuple[FrameSegments, dict]:
    times = StageTimes()
    extraction = extract_frame(frame, params, camera_frame, times)
    extraction.gradients = None   # megabytes per frame to send back; tracking computes its own
    return extraction, times.seconds


AUTO_MIN_FRAMES = 40


def resolve_workers(workers: int | None, frames: int) -> int:
    """``workers``, or for None (``--workers auto``) what measured fastest on two cores: 2 processes,
    but 1 for fewer than ``AUTO_MIN_FRAMES`` frames or on one CPU. Measured with ``accum accumulate``
    as a whole command (start-up included; farm-bench, 2-core machine): 2 workers took 1.02x the
    wall time of one on 24 and 36 frames (the pool's start-up, each worker importing the library and
    loading the compiled kernels, outweighs) and 0.81x on 60 frames of 640x480. More than 2 was not
    measured: give ``--workers N`` on a bigger machine."""
    if workers is not None:
        return workers
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return 1 if frames < AUTO_MIN_FRAMES or cpus < 2 else 2


def extracted_frames(frames: Iterable[StereoFrame], params: ExtractParams, camera_frame: str, workers: int,
                     times: StageTimes) -> Iterator[tuple[StereoFrame, FrameSegments]]:
    """(frame, its extraction) in recording order; per-stage times are added to ``times``."""
    if workers <= 1:
        for frame in frames:
            yield frame, extract_frame(frame, params, camera_frame, times)
        return
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_one_thread) as pool:
        pending: collections.deque = collections.deque()
        for frame in frames:
            pending.append((frame, pool.submit(_extract, frame, params, camera_frame)))
            if len(pending) >= 2 * workers:
                yield _collect(pending.popleft(), times)
        while pending:
            yield _collect(pending.popleft(), times)


def _collect(item, times: StageTimes) -> tuple[StereoFrame, FrameSegments]:
    frame, future = item
    extraction, seconds = future.result()
    for stage, value in seconds.items():
        times.seconds[stage] = times.seconds.get(stage, 0.0) + value
    return frame, extraction
