"""The console's child process (:data:`wingopt.cli.SUPERVISED`): what the watching process does to it
and after it, kept apart from the command line's parsing."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

__all__ = ["remove_own_temporaries", "die_with_parent", "kill", "exit_now"]


def remove_own_temporaries(out, pid: int | None = None) -> None:
    """Remove the temporary directories process ``pid`` (default this one) made for ``out``
    (``.NAME.tmp-PID-*``, :class:`~wingopt.results.ResultDirectory`); an earlier result it had moved
    aside (``.NAME.old-PID``) goes back in place."""
    import shutil

    if not out or str(out) == "-":
        return
    target = Path(out).expanduser().absolute()
    pid = os.getpid() if pid is None else pid
    for tmp in target.parent.glob(f".{target.name}.tmp-{pid}-*"):
        shutil.rmtree(tmp, ignore_errors=True)
    old = target.parent / f".{target.name}.old-{pid}"  # killed between the two renames of a commit
    if old.is_dir() and not old.is_symlink():
        if target.exists():
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(old, target)  # the earlier results back in place


def die_with_parent() -> None:
    """Linux: the child gets SIGKILL if the watching process dies (killed with -9 itself)."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError, TypeError):
        pass


def kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    except (ProcessLookupError, ChildProcessError):
        pass


def exit_now(code: int) -> None:
    """End the (child) process with ``code`` at once, its output flushed."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)
