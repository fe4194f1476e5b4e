"""Interrupting ``accum accumulate`` at random moments: are the outputs always whole?

Runs the installed console script ``accum accumulate REC -o D/model.json -o D/model.ply``
(``--frames 0:7`` and ``0:8`` by turns, so that consecutive runs write different
models) KILLS times, each killed while it runs (after a random delay shorter than the
reference run) with SIGINT, SIGTERM or SIGKILL
(seeded). After each run it checks that

- each output is a complete file of one of the two runs (its bytes equal a reference
  run's), both from the same run (the set was not split), and either what was there
  before or the new run's;
- after SIGINT or SIGTERM no temporary file is left in D (after SIGKILL leftovers are
  counted and removed: nothing can clean up after SIGKILL);
- the exit status after SIGINT or SIGTERM is 130, with no traceback on stderr.

Not part of the tests. Usage: python benchmarks/interrupt.py [--kills 20] [--seed 0]
[--accum "python -m accumcli.cli"] (the command to run instead of the console script).
Exit status 1 when any check failed.
"""

from __future__ import annotations

import argparse
import random
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RECORDING = ROOT / "sample_data" / "sim_box.mcap"
OUTPUTS = ("model.json", "model.ply")
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)


ACCUM: list[str] = []  # the command that runs accum, set in main()


def console_script() -> str:
    beside = Path(sys.executable).with_name("accum")
    found = str(beside) if beside.exists() else shutil.which("accum")
    if found is None:
        sys.exit("no 'accum' console script beside this Python or on PATH; pip install -e . first")
    return found


def command(folder: Path, stop: int) -> list[str]:
    return [*ACCUM, "accumulate", str(RECORDING), "-o", str(folder / OUTPUTS[0]), "-o", str(folder / OUTPUTS[1]),
            "--frames", f"0:{stop}"]


def reference(stop: int) -> tuple[dict, float]:
    """(output name -> bytes, seconds) of one uninterrupted run over frames 0:stop."""
    folder = Path(tempfile.mkdtemp(prefix="accum-interrupt-ref-"))
    t0 = time.perf_counter()
    subprocess.run(command(folder, stop), check=True, capture_output=True)
    seconds = time.perf_counter() - t0
    files = {name: (folder / name).read_bytes() for name in OUTPUTS}
    shutil.rmtree(folder)
    return files, seconds


def version(folder: Path, name: str, references: dict) -> str:
    """Which reference run's complete file ``name`` is ('7', '8'), 'missing' or 'BROKEN'."""
    path = folder / name
    if not path.exists():
        return "missing"
    data = path.read_bytes()
    return next((str(stop) for stop, files in references.items() if files[name] == data), "BROKEN")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--accum", help="command running accum (default: the installed console script)")
    args = parser.parse_args()
    ACCUM[:] = shlex.split(args.accum) if args.accum else [console_script()]
    rng = random.Random(args.seed)
    references, durations = {}, {}
    for stop in (7, 8):
        references[stop], durations[stop] = reference(stop)
    shortest = min(durations.values())
    print(f"reference runs: {', '.join(f'frames 0:{s} {d:.2f} s' for s, d in durations.items())}; "
          f"kills at a uniform delay in [0, {0.95 * shortest:.2f}] s (while it runs)")
    folder = Path(tempfile.mkdtemp(prefix="accum-interrupt-"))
    for name in OUTPUTS:  # start from a complete previous set
        (folder / name).write_bytes(references[7][name])
    failures = 0
    print(f"{'#':>2} {'signal':<7} {'delay s':>7} {'exit':>5} {'before':>7} {'after json/ply':>15} {'temps':>5}  "
          "verdict")
    for i in range(args.kills):
        stop = 8 if i % 2 == 0 else 7
        sig = rng.choice(SIGNALS)
        delay = rng.uniform(0, 0.95 * shortest)
        before = version(folder, OUTPUTS[0], references)
        child = subprocess.Popen(command(folder, stop), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        time.sleep(delay)
        finished_first = child.poll() is not None
        if not finished_first:
            child.send_signal(sig)
        try:
            _, stderr = child.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            child.kill()
            _, stderr = child.communicate()
        after = [version(folder, name, references) for name in OUTPUTS]
        temps = [p.name for p in folder.iterdir() if p.name not in OUTPUTS]
        problems = []
        if after[0] != after[1]:
            problems.append("set split")
        if any(a not in (before, str(stop)) for a in after):
            problems.append("not the previous or the new file")
        if finished_first:
            if child.returncode != 0:
                problems.append(f"exit {child.returncode} after a full run")
        elif sig != signal.SIGKILL:
            if temps:
                problems.append(f"{len(temps)} temp left")
            if child.returncode != 130:
                problems.append(f"exit {child.returncode}, expected 130")
            if b"Traceback" in stderr:
                problems.append("traceback")
        for name in temps:
            (folder / name).unlink()
        failures += bool(problems)
        label = "(done)" if finished_first else sig.name
        print(f"{i:>2} {label:<7} {delay:>7.2f} {child.returncode:>5} {before:>7} {'/'.join(after):>15} "
              f"{len(temps):>5}  {'; '.join(problems) or 'ok'}", flush=True)
    shutil.rmtree(folder)
    print(f"{args.kills - failures} of {args.kills} runs passed every check")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
