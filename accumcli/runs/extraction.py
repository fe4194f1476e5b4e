"""``extract_recording``: local 3D segments of every stereo frame of a recording, as a frames file."""

from __future__ import annotations

from contextlib import closing
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..extract import ExtractParams
from ..lines2d import StageTimes
from ..model_io import FramesWriter, pose_fields
from ..outputs import OutputSet
from ..row_check import RowCheck
from .base import FrameRange, Progress, RecordingOptions, frame_range, in_frames, no_progress, nothing_done, path_list
from .frame_logs import rerun_log
from .parallel import extracted_frames, resolve_workers


@dataclass
class ExtractionResult:
    """Counts summed over the frames (``segments``, ``left_2d``, ``critical``, ``unmatched``), the
    per-stage times (seconds, summed), the wall time, the files written and the warning of the rows'
    check (``row_check``; None when the rows agree or the frames cannot tell)."""

    frames: int = 0
    totals: dict = field(default_factory=lambda: {"segments": 0, "left_2d": 0, "critical": 0, "critical_3d": 0, "unmatched": 0})
    times: StageTimes = field(default_factory=StageTimes)
    seconds: float = 0.0
    outputs: list = field(default_factory=list)
    row_warning: str | None = None

    def per_frame(self, key: str) -> float:
        return self.totals[key] / max(self.frames, 1)

    @property
    def pairs_per_second(self) -> float:
        return self.frames / max(self.seconds, 1e-9)


def extract_recording(recording, output, *, params: ExtractParams = ExtractParams(),
                      options: RecordingOptions = RecordingOptions(), frames: FrameRange = FrameRange(),
                      rrd=None, with_2d: bool = False, workers: int | None = 1,
                      progress: Progress = no_progress) -> ExtractionResult:
    """Extract every stereo frame in ``frames`` of ``recording`` into ``output`` (JSON lines, one
    model-format object per frame in the left camera frame, with the recorded pose where there is
    one; formats.md), and the rectified intrinsics. ``with_2d``: each line also carries the left
    2D segments (``segments_2d``: endpoints u0, v0, u1, v1 px, the indices of those that became 3D
    segments, and the critical angle) for the funnel of ``accum eval``. ``rrd``: also a Rerun
    recording. ``workers``: extracting processes (the same bytes whatever the number; None:
    ``parallel.resolve_workers``; more than 1: guard a script's entry point, ``accumulate_recording``).
    ``params``: ``ExtractParams``; ``options``: ``RecordingOptions``; ``progress``: ``Progress``. Needs no
    object pose. Raises ``AccumError`` (``InputError``, ``RecordingError``)."""
    given = path_list(output, "output")
    if len(given) != 1:
        raise InputError(f"output: expected one frames file, found {len(given)}")
    output, frames = given[0], frame_range(frames)
    outputs = OutputSet([output, rrd], inputs=[recording])
    result = ExtractionResult(outputs=[p for p in (output, rrd) if p])
    t0 = time.perf_counter()
    rows = RowCheck()
    with options.open(recording, require_pose=False) as rec, outputs:
        total = frames.check(rec)
        with FramesWriter(outputs.open(output)) as out, rerun_log(outputs, rrd, "extract") as viz, \
                closing(extracted_frames(rec.frames(frames.start, frames.stop), params, rec.camera_frame,
                                         resolve_workers(workers, total), result.times)) as extractions:
            for frame, extraction in extractions:
                header = {"frame_index": frame.index, "counts": extraction.counts,
                          "intrinsics": frame.intrinsics.as_dict()}
                if with_2d:
                    header["segments_2d"] = {
                        "left": np.round(extraction.left.endpoints().reshape(-1, 4), 2).tolist(),
                        "matched": np.unique(extraction.left_index).astype(int).tolist(),
                        "critical_angle_deg": params.stereo.critical_angle_deg}
                if frame.T_camera_object is not None:
                    header["T_camera_object"] = pose_fields(frame.T_camera_object)
                out.write(extraction.segments, frame.timestamp_ns, **header)
                rows.add(extraction, frame.intrinsics, frame.T_camera_object)
                if viz:
                    viz.extraction(frame, extraction)
                result.frames += 1
                for key in result.totals:
                    result.totals[key] += extraction.counts[key]
                progress(result.frames, total)
            if result.frames == 0:
                raise nothing_done(recording, f"no stereo frame could be read{in_frames(frames)}", rec=rec)
    result.row_warning = rows.report(recording, params.stereo.row_offset_px)
    result.seconds = time.perf_counter() - t0
    return result
