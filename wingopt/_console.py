"""The ``wingopt`` console script: a signal is answered from the first instruction on.

Importing the command line (scipy, CVXPY, the command modules) takes about half a second; a
Ctrl-C or SIGTERM in that time used to end in Python's traceback. Until
:func:`wingopt.cli.main` installs its own handlers, a signal ends the start-up in one line, with
the usual exit code (128 + the signal's number) and nothing written.
"""

from __future__ import annotations

import signal
import sys

__all__ = ["main"]


def _starting(signum, frame):
    sys.stderr.write(f"wingopt: {signal.Signals(signum).name} while starting; nothing written\n")
    raise SystemExit(128 + signum)


def main() -> int:
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, _starting)
    from wingopt.cli import main as cli_main

    return cli_main()
