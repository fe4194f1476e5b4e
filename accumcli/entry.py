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
    except SystemExit as done:
        if not done.code:
            _finished()
        raise
    _finished()


def _finished() -> None:
    """The command succeeded and its outputs are in place: SIGINT and SIGTERM are ignored while the
    interpreter shuts down (joining worker threads takes a few tenths of a second), where SIGTERM
    ended the process with exit 143 and no word although its new outputs were already written."""
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
