"""The ``wingopt`` console script: a signal is answered from the first instruction on.

Importing the command line (scipy, CVXPY, the command modules) takes about half a second; a
Ctrl-C or SIGTERM in that time used to end in Python's traceback. Until
:func:`wingopt.cli.main` installs its own handlers, a signal ends the start-up in one line, with
the usual exit code (128 + the signal's number) and nothing written.
"""

from __future__ import annotations

import _signal  # the C module: no import of signal.py (and its enum) before the handlers are in
import os
import sys

__all__ = ["main"]

_NAMES = {_signal.SIGINT: "SIGINT", _signal.SIGTERM: "SIGTERM", _signal.SIGHUP: "SIGHUP"}


def _starting(signum, frame):
    # Exit at once rather than raise: a handler runs wherever the interpreter is, and inside
    # importlib's module-lock weakref callback an exception is only printed ("Exception ignored
    # in ...", with a traceback) and the start-up goes on. Nothing is open for writing yet, so there
    # is nothing for a clean shutdown to flush but stderr.
    sys.stderr.write(f"wingopt: {_NAMES.get(signum, signum)} while starting; nothing written\n")
    sys.stderr.flush()
    os._exit(128 + signum)


def main() -> int:
    for s in _NAMES:
        _signal.signal(s, _starting)
    from wingopt.cli import main as cli_main

    return cli_main()
