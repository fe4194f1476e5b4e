"""Shared helpers of the benchmarks: cached simulated recordings, peak memory of a child process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CACHE = ROOT / "out" / "bench"


def recording(name: str, **options) -> str:
    """A simulated recording made once and kept in out/bench/ (same options, same file)."""
    from accumcli.simulation import SimulationOptions, simulate

    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"{name}.mcap"
    stamp = CACHE / f"{name}.options.json"
    wanted = json.dumps(options, sort_keys=True)
    if not path.exists() or not stamp.exists() or stamp.read_text() != wanted:
        print(f"  (simulating {name}: {options})", flush=True)
        simulate(str(path), SimulationOptions(**options))
        stamp.write_text(wanted)
    return str(path)


def accumulate_params(view_planes: bool = True, motion: str = "gripper", image_confirm: bool = False,
                      across_frames: bool = False):
    """The accumulation parameters of the scoreboards: the defaults, or ``accum accumulate
    --average-directions``, ``--motion tracked``, ``--image-confirm`` and / or ``--across-frames``."""
    from accumcli.accumulate import image_confirming
    from accumcli.line_model import LineModelParams
    from accumcli.pipeline import AccumulateParams
    from accumcli.temporal_lines import TemporalParams

    return AccumulateParams(line_model=LineModelParams(view_planes=view_planes), motion=motion,
                            rule=image_confirming(image_confirm), temporal=TemporalParams() if across_frames else None)


def run_child(code: str) -> dict:
    """Run Python ``code`` in a fresh single-threaded interpreter; it prints one JSON line, returned
    with the child's peak resident memory (MB) added.

    The peak is the child's own ``VmHWM`` (/proc/self/status): ``ru_maxrss`` of a child on Linux
    starts from the parent's peak at fork, so it reports the benchmark driver, not the run."""
    wrapper = (code + "\nimport json as _j\n"
               "_hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM:')][0].split()[1]\n"
               "print(_j.dumps({**RESULT, 'peak_rss_mb': int(_hwm) / 1024}))")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", wrapper], env=env, capture_output=True, text=True, cwd=ROOT)
    if out.returncode != 0:
        raise RuntimeError(f"benchmark child failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def score_rows(rows, score) -> dict:
    """``score(row)`` for every row (by ``row.name``); a row's failure is reported in its row
    (``{"error": ...}``) and the others go on. Times each row on stderr."""
    import time

    results = {}
    for row in rows:
        start = time.perf_counter()
        try:
            results[row.name] = score(row)
        except Exception as e:  # noqa: BLE001 - the scoreboard reports every row
            results[row.name] = {"error": f"{type(e).__name__}: {e}"}
        print(f"  {row.name}: {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)
    return results
