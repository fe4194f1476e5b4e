"""``make bench``: every benchmark, one thread, figures printed."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_accumulate  # noqa: E402
import bench_batch  # noqa: E402
import bench_extract  # noqa: E402
import bench_peer  # noqa: E402
import bench_reader  # noqa: E402
import bench_track  # noqa: E402

SUITES = {"reader": bench_reader.main, "extract": bench_extract.main, "accumulate": bench_accumulate.main,
          "track": bench_track.main, "peer": bench_peer.main, "batch": bench_batch.main}

if __name__ == "__main__":
    chosen = sys.argv[1:] or list(SUITES)
    for name in chosen:
        SUITES[name]()
