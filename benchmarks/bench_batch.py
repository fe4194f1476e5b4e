"""``accum batch`` over 12 recordings with 1 and 2 local workers and on Ray's local cluster: the
wall time of each, the speed-up over one worker, and whether the three summary.csv are the same.

Target (issue 12): close to 2x with 2 workers on a 2-core machine; the same summary from all three.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

from common import recording

COUNT = 12


def main() -> dict:
    from accumcli.batch import BatchOptions, run_batch
    from accumcli.runs import FrameRange

    paths = [recording(f"batch_{seed}", frames=12, seed=seed, scene="random") for seed in range(200, 200 + COUNT)]
    options = BatchOptions(frames=FrameRange(0, 12), truth_from_sidecar=True)
    out = Path(tempfile.mkdtemp(prefix="accum-batch-"))
    results, summaries = {}, {}
    for name, kwargs in (("1 worker", dict(workers=1)), ("2 workers", dict(workers=2)),
                         ("ray local", dict(ray_address="local"))):
        folder = out / name.replace(" ", "_")
        t0 = time.perf_counter()
        result = run_batch(paths, folder, options, **kwargs)
        results[name] = time.perf_counter() - t0
        summaries[name] = (folder / "summary.csv").read_text()
        failed = result.failed
        print(f"batch       {name:<9}: {COUNT} recordings of 12 frames in {results[name]:6.1f} s "
              f"({results['1 worker'] / results[name]:.2f}x one worker), {failed} failed", flush=True)
    same = len(set(summaries.values())) == 1
    print(f"batch       the three summary.csv are {'identical' if same else 'DIFFERENT'}")
    shutil.rmtree(out, ignore_errors=True)
    return {"seconds": results, "same_summary": same}


if __name__ == "__main__":
    main()
