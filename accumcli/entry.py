"""The console script's entry point: SIGTERM is handled like Ctrl-C (one line, exit 130, outputs
left as they were) from the first moment, before the heavy imports of the command line."""

from __future__ import annotations

import sys


def main() -> None:
    from .outputs import interrupt_on_sigterm  # the standard library and errors.py only

    interrupt_on_sigterm()
    try:
        from .cli import main as cli_main
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        sys.exit(130)
    try:
        cli_main()
    except KeyboardInterrupt:   # one that came after the command's own handling (while exiting)
        sys.stderr.write("error: interrupted\n")
        sys.exit(130)
