"""Many recordings at once: per recording the model (JSON, PLY), optionally the poses and the
figures against its truth, in ``OUTDIR/NAME/``, plus ``OUTDIR/summary.csv``.

Each recording is one task that reads its inputs and writes its outputs by path, so the same
tasks run in a local process pool (``workers``) or on a Ray cluster (``ray_address``: an
existing cluster's address, or ``"local"`` for Ray's local cluster on this machine) with a
shared file system. A task's failure is its row's status; it never stops the batch. A task whose
outputs are complete for the same inputs and options (``OUTDIR/NAME/done.json``: the inputs'
sizes and modification times and the options) is skipped, so a re-run does only what is missing.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import logging
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from .atomic import atomic_open
from .errors import AccumError, InputError, is_whole_number
from .model_io import dumps
from .pipeline import AccumulateParams
from .runs import FrameRange, RecordingOptions, accumulate_recording, evaluate_file, track_recording
from .runs.parallel import resolve_workers

log = logging.getLogger("accumcli")

COLUMNS = ("recording", "frames", "segments", "accepted", "precision", "completeness", "background", "status")
TABLE_COLUMNS = COLUMNS[:-1] + ("pairs_per_s", "status")


@dataclass(frozen=True)
class BatchOptions:
    """What every task of a batch does: accumulate with ``params``; with ``track``, track the model
    through the same recording; with ``truth_from_sidecar``, evaluate against ``NAME.truth.json``."""

    params: AccumulateParams = field(default_factory=AccumulateParams)
    recording: RecordingOptions = field(default_factory=RecordingOptions)
    frames: FrameRange = field(default_factory=FrameRange)
    track: bool = False
    truth_from_sidecar: bool = False

    def fingerprint(self) -> str:
        return hashlib.sha256(repr(self).encode()).hexdigest()[:16]


def _inputs_stamp(recording: Path, options: BatchOptions) -> dict:
    """Size and modification time of every input file (a rosbag2 folder's files one by one: rewriting a
    bag file in place leaves the folder's own stamp as it was)."""
    paths = [recording] + ([_sidecar(recording)] if options.truth_from_sidecar else [])
    paths = [f for p in paths for f in (sorted(p.iterdir()) if p.is_dir() else [p])]
    files = {str(p): [p.stat().st_size, p.stat().st_mtime_ns] if p.exists() else None for p in paths}
    return {"inputs": files, "options": options.fingerprint()}


def _sidecar(recording: Path) -> Path:
    """NAME.truth.json beside the recording NAME.mcap (or the rosbag2 folder NAME)."""
    return recording.with_name((recording.name if recording.is_dir() else recording.stem) + ".truth.json")


OUTPUTS = ("done.json", "eval.json", "poses.json", "model.json", "model.ply")   # what a task may write


def output_folder(outdir, recording) -> Path:
    """``OUTDIR/NAME``, NAME the recording's file name without its suffix."""
    return Path(outdir) / Path(recording).stem


class _Warnings(logging.Handler):
    """The warnings a task logs, kept for its row (a Ray worker's own log does not reach the user)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def run_task(recording: str, outdir: str, options: BatchOptions) -> dict:
    """One recording: its outputs in ``OUTDIR/NAME/`` and its summary row, whose ``warnings`` are
    those the task logged (``_on_ray`` logs them again where the user sees them). Never raises for a
    problem of the recording (the row's status says it); a bug keeps its exception."""
    warnings = _Warnings()
    log.addHandler(warnings)
    try:
        row = _task(recording, outdir, options)
    finally:
        log.removeHandler(warnings)
    return {**row, "warnings": warnings.messages} if warnings.messages else row


def _task(recording: str, outdir: str, options: BatchOptions) -> dict:
    rec = Path(recording)
    row = {"recording": str(rec), "status": "ok"}
    folder = output_folder(outdir, rec)
    done = folder / "done.json"
    stamp = _inputs_stamp(rec, options) if rec.exists() else None
    try:
        if done.exists() and stamp is not None and json.loads(done.read_text()).get("stamp") == stamp:
            return {**json.loads(done.read_text())["row"], "skipped": True}
    except (OSError, ValueError):
        pass
    for name in OUTPUTS:   # an earlier run's (other options) must not stand beside this one's
        with contextlib.suppress(FileNotFoundError):
            (folder / name).unlink()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        model_json = folder / "model.json"
        result = accumulate_recording(rec, [str(model_json), str(folder / "model.ply")], params=options.params,
                                      options=options.recording, frames=options.frames)
        row.update(frames=result.frames, segments=len(result.model), accepted=result.accepted,
                   pairs_per_s=round(result.pairs_per_second, 2))
        if options.track:
            track_recording(result.model, rec, [str(folder / "poses.json")], options=options.recording,
                            extract_params=options.params.extract, frames=options.frames)
        if options.truth_from_sidecar:
            truth = _sidecar(rec)
            if not truth.exists():
                raise InputError(f"{rec}: no truth sidecar {truth.name}")
            figures = evaluate_file(str(model_json), str(truth))
            if options.track:
                figures["poses"] = evaluate_file(str(folder / "poses.json"), str(truth))
            with atomic_open(folder / "eval.json") as f:
                f.write(dumps(figures, indent=1) + "\n")
            row.update({k: round(figures[k], 4) for k in ("precision", "completeness", "background")
                        if isinstance(figures.get(k), float) and math.isfinite(figures[k])})
        with atomic_open(done) as f:
            json.dump({"stamp": stamp, "row": row}, f, allow_nan=False)
    except AccumError as e:
        row["status"] = f"error: {e}"
        with contextlib.suppress(OSError):   # a recording that failed before any output leaves no folder
            folder.rmdir()
    return row


@dataclass
class BatchResult:
    rows: list
    seconds: float
    summary: str

    @property
    def failed(self) -> int:
        return sum(r["status"].startswith("error") for r in self.rows)


def run_batch(recordings, outdir, options: BatchOptions = BatchOptions(), *, workers: int | None = None,
              ray_address: str | None = None, progress=lambda done, total: None) -> BatchResult:
    """Every recording as one task (local process pool of ``workers``, None: 1; or Ray at ``ray_address``,
    which schedules them by the cluster's CPUs: ``workers`` is then refused, not silently ignored);
    rows in the order of ``recordings``; ``OUTDIR/summary.csv`` written at the end."""
    recordings = [str(r) for r in recordings]
    if not recordings:
        raise InputError("no recording given")
    names = [Path(r).stem for r in recordings]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"two recordings have the same name ({', '.join(twice)}): their outputs would collide")
    if ray_address is not None and workers is not None:
        raise InputError("--workers sets the local pool's processes; with --ray the cluster schedules the "
                         "recordings on its CPUs: drop --workers")
    workers = 1 if workers is None else workers
    if not is_whole_number(workers) or workers < 1:
        raise InputError(f"expected at least 1 worker, found {workers}")
    workers = int(workers)
    if ray_address is None:
        workers = resolve_workers(workers, len(recordings))   # a local pool: at most the recordings and CPUs
    try:
        Path(outdir).mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise AccumError(f"{outdir}: cannot create the output folder ({e.strerror or e}); "
                         "choose a folder you can write to") from None
    if not os.access(outdir, os.W_OK):
        raise AccumError(f"{outdir}: the output folder is not writable")
    t0 = time.perf_counter()
    if ray_address is not None:
        rows = _on_ray(recordings, str(outdir), options, ray_address, progress)
    elif workers == 1:
        rows = []
        for r in recordings:
            rows.append(run_task(r, str(outdir), options))
            progress(len(rows), len(recordings))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(run_task, r, str(outdir), options) for r in recordings]
            rows = []
            for future in futures:
                rows.append(future.result())
                progress(len(rows), len(recordings))
    summary = Path(outdir) / "summary.csv"
    with atomic_open(summary) as f:
        f.write(summary_csv(rows))
    return BatchResult(rows, time.perf_counter() - t0, str(summary))


def summary_csv(rows) -> str:
    """The rows as CSV, one line per recording (``COLUMNS``). Speed is left out (it is in the printed
    table and in each ``done.json``) so that the same inputs give the same file however they ran."""
    text = io.StringIO()
    writer = csv.DictWriter(text, COLUMNS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue()


def _on_ray(recordings, outdir, options, address, progress) -> list:
    try:
        import ray
    except ImportError:
        raise AccumError("--ray needs Ray: pip install 'accumcli[ray]'") from None
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=None if address == "local" else address, include_dashboard=False,
                     log_to_driver=False, logging_level=logging.ERROR)
        except (ConnectionError, RuntimeError, ValueError) as e:
            raise AccumError(f"cannot reach the Ray cluster at {address!r} ({e}); start one with "
                             "'ray start --head' or use --ray local") from None
    try:
        task = ray.remote(run_task)
        refs = [task.remote(r, outdir, options) for r in recordings]
        rows = []
        for ref in refs:
            rows.append(ray.get(ref))
            for message in rows[-1].get("warnings", []):   # said in a worker whose log the driver does not show
                log.warning("%s", message)
            progress(len(rows), len(recordings))
        return rows
    finally:
        if started:
            ray.shutdown()


def table_lines(rows) -> list[str]:
    """The printed table of ``accum batch`` (a skipped task's status says so)."""
    shown = [{**r, "status": r["status"] + (" (skipped: up to date)" if r.get("skipped") else "")} for r in rows]
    widths = {c: max(len(c), *(len(_fmt(r.get(c))) for r in shown)) for c in TABLE_COLUMNS}
    line = "  ".join(c.ljust(widths[c]) for c in TABLE_COLUMNS)
    return [line.rstrip()] + ["  ".join(_fmt(r.get(c)).ljust(widths[c]) for c in TABLE_COLUMNS).rstrip()
                              for r in shown]


def _fmt(value) -> str:
    if value is None:
        return "-"
    return f"{value:.3f}" if isinstance(value, float) else str(value)

