"""The ``wingopt`` command.

Every module in this package that defines ``register(subparsers)`` is a sub-command; its
parser's ``func`` takes the parsed arguments and returns the exit code. Exit codes: 0 ok,
2 bad input (:class:`~wingopt.errors.InputError`), 3 solver failure
(:class:`~wingopt.errors.SolverError`), 130 / 143 / 129 interrupted by SIGINT / SIGTERM / SIGHUP,
70 internal error (a bug: an exception the package did not expect, reported in one line and not
as a traceback; ``WINGOPT_TRACEBACK=1`` shows the traceback). Every message is one line, control
characters escaped.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import re
import signal
import sys
import threading

from wingopt import __version__
from wingopt.cli.process import die_with_parent, exit_now, kill, remove_own_temporaries
from wingopt.errors import InputError, SolverError
from wingopt.optim.registry import available_backends

__all__ = [
    "main",
    "build_parser",
    "solver_flag_hint",
    "one_line",
    "EXIT_OK",
    "EXIT_INPUT",
    "EXIT_SOLVER",
    "EXIT_INTERNAL",
    "OUT_HELP",
    "add_force_option",
    "SOLVER_FLAGS",
    "warnings_printed",
]

EXIT_OK, EXIT_INPUT, EXIT_SOLVER, EXIT_INTERNAL = 0, 2, 3, 70

OUT_HELP = "output directory (replaced atomically; docs/cli.md)"
"""The ``--out`` help of every command that writes a result directory (wingopt.results.ownership)."""


def add_force_option(parser, option: str, name: str = "FILE") -> None:
    """``--force``: let ``option`` (a single output file) replace an existing file, kept as a backup
    (the rule of :mod:`wingopt.results.ownership`, the same for every such option)."""
    parser.add_argument("--force", action="store_true", help=f"let {option} replace a file (kept as {name}.bak)")


SOLVER_FLAGS = {("morph", "qp"): ("--solver", "qp"), ("identify", "mhe"): ("--solver", "window")}
"""(command, context of a :class:`SolverError`) -> the flag that picks another solver, and the
capability (:mod:`wingopt.optim.registry`) whose installed names it takes."""

log = logging.getLogger("wingopt")


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (exit code 2), with a pointer to --help."""

    def error(self, message: str):  # noqa: D102 - argparse API
        self.exit(EXIT_INPUT, one_line(f"{self.prog}: error: {message} (see '{self.prog} --help')") + "\n")


def _common_options() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-q", "--quiet", action="store_true", help="only errors (no stage lines)")
    common.add_argument("-v", "--verbose", action="count", default=0, help="more detail (-v INFO, -vv DEBUG)")
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


_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f\x80-\x9f]")


def one_line(text) -> str:
    """``text`` on one line with its control characters escaped (``\\r``, ``\\x1b``): what a
    message may hold (a sensor name with a carriage return, an ANSI escape) never garbles the terminal."""
    s = str(text).replace("\r\n", "\n").replace("\n", " ").replace("\t", " ")
    return _CONTROL.sub(lambda m: repr(m.group())[1:-1], s)


class _Lines(logging.Formatter):
    """``wingopt COMMAND: warning: ...`` (each warning once, on stderr); INFO and DEBUG name their source."""

    def __init__(self, command: str) -> None:
        super().__init__()
        self.command = command

    def format(self, record: logging.LogRecord) -> str:
        level = record.levelname.lower()
        if record.levelno >= logging.WARNING:
            msg = one_line(record.getMessage())
            own = record.name == "wingopt" or record.name.startswith("wingopt.cli")  # the command's own voice
            if record.levelno == logging.WARNING and not msg.startswith("[") and not own:
                # A warning an engine logged itself names its module, as the workflow's name their check.
                msg = f"[{record.name.removeprefix('wingopt.')}] {msg}"
            return f"wingopt {self.command}: {level}: {msg}"
        if record.name.startswith("wingopt.progress"):  # stage lines: the command's own voice
            return f"wingopt {self.command}: {one_line(record.getMessage())}"
        return f"wingopt {self.command}: {record.name.removeprefix('wingopt.')}: {one_line(record.getMessage())}"


class _WarningCount(logging.Filter):
    """Counts the warning lines the command's handler prints (the count its summary line gives)."""

    def __init__(self) -> None:
        super().__init__()
        self.count = 0

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno == logging.WARNING:
            self.count += 1
        return True


_WARNINGS = _WarningCount()


def warnings_printed() -> int:
    """How many ``warning:`` lines this command has printed on stderr so far."""
    return _WARNINGS.count


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
    _WARNINGS.count = 0
    handler.addFilter(_WARNINGS)
    root = logging.getLogger()
    for h in list(root.handlers):
        root.removeHandler(h)
    root.addHandler(handler)
    root.setLevel(max(level, logging.WARNING))  # other libraries: warnings and errors only
    logging.getLogger("wingopt").setLevel(level)
    # Stage lines and time estimates (wingopt.progress): shown unless --quiet, terminal or not.
    progress_level = logging.ERROR if level >= logging.ERROR else min(level, logging.INFO)
    logging.getLogger("wingopt.progress").setLevel(progress_level)


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


SUPERVISED = frozenset({"morph", "identify", "demo", "modes", "gains"})
"""Commands whose work may sit in one long C call (a sparse factorisation, a dense Riccati or
eigen-decomposition that holds the interpreter's lock for minutes). Run from the console script
(``main()`` without arguments) they run in a child process that the main process watches: a
signal ends the child at once, its temporary output directories are removed and the main process
reports it, within a second whatever the child is doing. Called in-process (``main([...])``:
tests, embedding), for streams (``identify --follow``, ``--data -``: their own handlers keep every
estimate on a signal) and for the other commands (``compare``, ``sweep``: a dask client;
``calibrate``, ``design-sensors``: their ``--write-problem`` files) the work runs in this process,
where a signal is honoured between calls."""


def _supervise(args) -> int:
    """Run the command in a forked child and wait; on SIGINT/SIGTERM/SIGHUP kill the child, remove
    its temporary output directories and report the signal (:data:`SUPERVISED`)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    pid = os.fork()
    if pid == 0:  # the child: the work; the parent alone answers signals
        code = EXIT_INTERNAL
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the parent acts
            signal.signal(signal.SIGHUP, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            die_with_parent()
            code = _run(args)
        finally:
            exit_now(code)
    name = f"wingopt {args.command}"
    try:
        _, status = os.waitpid(pid, 0)
    except (KeyboardInterrupt, Terminated) as exc:
        kill(pid)
        remove_own_temporaries(getattr(args, "out", None), pid)
        signum = exc.signum if isinstance(exc, Terminated) else signal.SIGINT
        what = "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"terminated by {signal.Signals(signum).name}"
        _say(f"{name}: {what}; nothing written")
        return 128 + signum
    code = os.waitstatus_to_exitcode(status)
    if code < 0:  # the child was killed (the out-of-memory killer, a signal sent to it alone)
        remove_own_temporaries(getattr(args, "out", None), pid)
        _say(f"{name}: error: the run was killed by {signal.Signals(-code).name}; nothing written")
        return 128 - code
    return code


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``wingopt`` console script; returns the exit code.

    Exit codes: 0 ok, 2 bad input or unwritable output, 3 solver failure, 130 interrupted (SIGINT),
    128 + N terminated by signal N (143 for SIGTERM). Each failure is one line on stderr.
    """
    parser = build_parser()
    args, deprecated = _parse(parser, argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_INPUT
    _configure_logging(args)
    for message in deprecated:  # old option spellings (wingopt.cli.options.DEPRECATED): one line each
        log.warning("%s", message)
    _RECEIVED.clear()
    old = _install_handlers()
    main_thread = threading.current_thread() is threading.main_thread() and bool(old)
    streaming = getattr(args, "follow", None) or getattr(args, "data", None) == "-"  # its own handlers
    supervised = args.command in SUPERVISED and main_thread and argv is None and not streaming
    try:
        if supervised and hasattr(os, "fork") and not os.environ.get("WINGOPT_NO_FORK"):
            return _supervise(args)
        return _run(args)
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _run(args) -> int:
    name = f"wingopt {args.command}"
    try:
        return int(args.func(args) or EXIT_OK)
    except InputError as exc:
        _say(f"{name}: error: {exc}")
        return EXIT_INPUT
    except SolverError as exc:
        _say(f"{name}: solver failure: {exc}{solver_flag_hint(args.command, exc)}")
        return EXIT_SOLVER
    except KeyboardInterrupt:
        _say(f"{name}: interrupted (Ctrl-C); nothing written")
        return 128 + signal.SIGINT
    except Terminated as exc:
        _say(f"{name}: terminated by {signal.Signals(exc.signum).name}; nothing written")
        return 128 + exc.signum
    except Exception as exc:
        # A signal that arrives inside a C extension (e.g. while a module initialises) comes back
        # wrapped ("ImportError: initialization failed"); report it as the signal it was.
        inner = exc.__cause__ or exc.__context__
        if isinstance(inner, (Terminated, KeyboardInterrupt)) or _RECEIVED:
            signum = inner.signum if isinstance(inner, Terminated) else (_RECEIVED or [signal.SIGINT])[0]
            what = "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"terminated by {signal.Signals(signum).name}"
            _say(f"{name}: {what}; nothing written")
            return 128 + signum
        if isinstance(exc, BrokenPipeError):
            _quiet_stdout()
            _say(f"{name}: error: standard output was closed before the run ended")
            return EXIT_INPUT
        if isinstance(exc, MemoryError):
            _say(f"{name}: error: out of memory: the size estimate did not foresee it; reduce the sizes of this run")
            return EXIT_INPUT
        if isinstance(exc, OSError):
            where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
            _say(f"{name}: error: {exc.strerror or exc}{where}")
            return EXIT_INPUT
        # Last resort: a bug. One line, never a traceback (unless asked for), a documented exit code.
        if os.environ.get("WINGOPT_TRACEBACK"):
            raise
        _say(f"{name}: internal error: {type(exc).__name__}: {exc}; please report it")
        return EXIT_INTERNAL


def _parse(parser, argv):
    """Parsed arguments and the deprecation messages of old option spellings (each once)."""
    import warnings

    from wingopt.cli.options import DeprecatedOptionWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DeprecatedOptionWarning)
        args = parser.parse_args(argv)
    messages = []
    for w in caught:
        if issubclass(w.category, DeprecatedOptionWarning):
            messages.append(str(w.message))
        else:  # not ours: as it would have been without the catch
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return args, list(dict.fromkeys(messages))


def _say(line: str) -> None:
    """One line on stderr (control characters escaped); silent if stderr itself is closed."""
    try:
        print(one_line(line), file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _quiet_stdout() -> None:
    """Point a closed stdout at /dev/null, so that Python's flush at exit does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
