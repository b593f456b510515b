"""The ``wingopt`` command.

Every module in this package that defines ``register(subparsers)`` is a sub-command; its
parser's ``func`` takes the parsed arguments and returns the exit code. Exit codes: 0 ok,
2 bad input (:class:`~wingopt.errors.InputError`), 3 solver failure
(:class:`~wingopt.errors.SolverError`).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import signal
import sys

from wingopt import __version__
from wingopt.errors import InputError, SolverError
from wingopt.optim.registry import available_backends

__all__ = ["main", "build_parser", "solver_flag_hint", "EXIT_OK", "EXIT_INPUT", "EXIT_SOLVER", "SOLVER_FLAGS"]

EXIT_OK, EXIT_INPUT, EXIT_SOLVER = 0, 2, 3

SOLVER_FLAGS = {("morph", "qp"): ("--solver", "qp"), ("identify", "mhe"): ("--backend", "window")}
"""(command, context of a :class:`SolverError`) -> the flag that picks another solver, and the
capability (:mod:`wingopt.optim.registry`) whose installed names it takes."""

log = logging.getLogger("wingopt")


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (exit code 2), with a pointer to --help."""

    def error(self, message: str):  # noqa: D102 - argparse API
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _common_options() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    g = common.add_argument_group("output verbosity")
    g.add_argument("-q", "--quiet", action="store_true", help="only errors (logging level ERROR)")
    g.add_argument("-v", "--verbose", action="count", default=0, help="more detail (-v INFO, -vv DEBUG)")
    return common


def _command_modules():
    import wingopt.cli as pkg

    mods = []
    for info in pkgutil.iter_modules(pkg.__path__):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"wingopt.cli.{info.name}")
        if hasattr(mod, "register"):
            mods.append(mod)
    return sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.__name__))


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="wingopt",
        description="Control and estimation of flexible wings: plate morphing and membrane load identification.",
        epilog="Run 'wingopt COMMAND --help' for a command's options and an example.",
    )
    parser.add_argument("--version", action="version", version=f"wingopt {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    common = _common_options()
    for mod in _command_modules():
        mod.register(sub, common)
    return parser


class _Lines(logging.Formatter):
    """``wingopt COMMAND: warning: ...`` (each warning once, on stderr); INFO and DEBUG name their source."""

    def __init__(self, command: str) -> None:
        super().__init__()
        self.command = command

    def format(self, record: logging.LogRecord) -> str:
        level = record.levelname.lower()
        if record.levelno >= logging.WARNING:
            return f"wingopt {self.command}: {level}: {record.getMessage()}"
        return f"wingopt {self.command}: {record.name.removeprefix('wingopt.')}: {record.getMessage()}"


def solver_flag_hint(command: str, exc: SolverError) -> str:
    """`` (--flag name|name|...)``: how to pick another solver after ``exc`` in ``command`` (or "")."""
    flag = SOLVER_FLAGS.get((command, exc.context))
    if flag is None:
        return ""
    return f" ({flag[0]} {'|'.join(available_backends(flag[1]))})"


def _configure_logging(args) -> None:
    level = logging.WARNING
    if getattr(args, "quiet", False):
        level = logging.ERROR
    elif getattr(args, "verbose", 0) >= 2:
        level = logging.DEBUG
    elif getattr(args, "verbose", 0) == 1:
        level = logging.INFO
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_Lines(getattr(args, "command", "") or ""))
    root = logging.getLogger()
    for h in list(root.handlers):
        root.removeHandler(h)
    root.addHandler(handler)
    root.setLevel(max(level, logging.WARNING))  # other libraries: warnings and errors only
    logging.getLogger("wingopt").setLevel(level)


class Terminated(BaseException):
    """Raised by the SIGTERM/SIGHUP handler so that ``with`` blocks (the result writer) clean up."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


_RECEIVED: list[int] = []  # signals the handler turned into exceptions during this run


def _on_signal(signum, frame):
    _RECEIVED.append(signum)
    # Later signals during the clean-up are ignored: a second Ctrl-C must not leave a half-removed
    # work directory behind.
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, signal.SIG_IGN)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


def _install_handlers() -> dict:
    """Route SIGINT/SIGTERM/SIGHUP to exceptions; returns the previous handlers (main thread only)."""
    old = {}
    try:
        for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            old[s] = signal.signal(s, _on_signal)
    except ValueError:  # not the main thread (e.g. called from a worker thread): leave them
        pass
    return old


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``wingopt`` console script; returns the exit code.

    Exit codes: 0 ok, 2 bad input or unwritable output, 3 solver failure, 130 interrupted (SIGINT),
    128 + N terminated by signal N (143 for SIGTERM). Each failure is one line on stderr.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_INPUT
    _configure_logging(args)
    name = f"wingopt {args.command}"
    _RECEIVED.clear()
    old = _install_handlers()
    try:
        return int(args.func(args) or EXIT_OK)
    except InputError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except SolverError as exc:
        print(f"{name}: solver failure: {exc}{solver_flag_hint(args.command, exc)}", file=sys.stderr)
        return EXIT_SOLVER
    except KeyboardInterrupt:
        print(f"{name}: interrupted (Ctrl-C); nothing written", file=sys.stderr)
        return 128 + signal.SIGINT
    except Terminated as exc:
        print(f"{name}: terminated by {signal.Signals(exc.signum).name}; nothing written", file=sys.stderr)
        return 128 + exc.signum
    except Exception as exc:
        # A signal that arrives inside a C extension (e.g. while a module initialises) comes back
        # wrapped ("ImportError: initialization failed"); report it as the signal it was.
        inner = exc.__cause__ or exc.__context__
        if isinstance(inner, (Terminated, KeyboardInterrupt)) or _RECEIVED:
            signum = inner.signum if isinstance(inner, Terminated) else (_RECEIVED or [signal.SIGINT])[0]
            what = "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"terminated by {signal.Signals(signum).name}"
            print(f"{name}: {what}; nothing written", file=sys.stderr)
            return 128 + signum
        if isinstance(exc, MemoryError):
            print(f"{name}: error: out of memory; try a coarser --mesh or a shorter --t-end", file=sys.stderr)
            return EXIT_INPUT
        if isinstance(exc, OSError):
            where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
            print(f"{name}: error: {exc.strerror or exc}{where}", file=sys.stderr)
            return EXIT_INPUT
        raise
    finally:
        for s, h in old.items():
            signal.signal(s, h)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
