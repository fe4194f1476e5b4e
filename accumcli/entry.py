"""The console script's entry point: SIGTERM is handled like Ctrl-C (one line, exit 130, outputs
left as they were) from the first moment, before the heavy imports of the command line."""

from __future__ import annotations

import signal
import sys


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main() -> None:
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        from .cli import main as cli_main
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        sys.exit(130)
    cli_main()
