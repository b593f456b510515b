"""Result directories and files: every write of the package goes through here.

A run writes into a hidden sibling of its output directory and swaps it in on success, so a failed
or interrupted run never leaves a half-written directory and never destroys the results of an
earlier run. What may be replaced is decided by one rule, :mod:`wingopt.results.ownership`: a
directory carries the manifest of the files wingopt wrote there (:data:`MARKER`), and it is
replaced only if it holds nothing else and nothing changed; an input of the run is never inside
it; a single output file onto an existing one is refused without ``force`` (and kept as
``NAME.bak`` with it). Studies and caches, which grow file by file, use :class:`~wingopt.results.owned.OwnedDirectory`.
Hidden work directories left by a killed run (``.NAME.tmp-PID-*``, ``.NAME.old-PID``) are removed
by the next run at the same place once their process is gone.
"""

from __future__ import annotations

import csv
import errno
import json
import logging
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wingopt.errors import OutputError
from wingopt.results.ownership import (
    MARKER,
    backup_name,
    check_inputs_outside,
    check_new_file,
    check_owned,
    first_foreign,
    read_manifest,
    scan,
    write_manifest,
)

__all__ = [
    "ResultDirectory",
    "write_json",
    "write_csv",
    "to_jsonable",
    "check_writable",
    "check_file_writable",
    "write_text_atomic",
    "write_atomic",
    "write_json_atomic",
    "write_arrays_atomic",
    "check_new_file",
    "MARKER",
]

log = logging.getLogger(__name__)


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays (and nested containers) to plain JSON types."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def write_json(path: Path, data: Any) -> None:
    Path(path).write_text(json.dumps(to_jsonable(data), indent=2) + "\n")


def write_csv(path: Path, header: Sequence[str], rows: Iterable[Sequence[float]]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for r in rows:
            w.writerow([f"{v:.10g}" if isinstance(v, (float, np.floating)) else v for v in r])


def _is_ours(path: Path) -> bool:
    return (path / MARKER).is_file()


def check_writable(target: str | os.PathLike, *, inputs: Iterable = (), what: str = "out") -> Path:
    """Raise :class:`OutputError` unless ``target`` can become a new (or replaced) directory.

    Allowed: a path that does not exist (its nearest existing parent must be a writable directory),
    an empty directory, or a directory wingopt wrote that holds nothing else, unchanged
    (:func:`~wingopt.results.ownership.check_owned`). Refused: a file, a directory with anything
    wingopt did not write (named), the working directory or one of its parents, a mount point, and
    a directory that holds one of the run's ``inputs`` (``(option, path)`` pairs or paths).
    """
    if not isinstance(target, (str, os.PathLike)) or not str(target).strip() or "\0" in str(target):
        raise OutputError(f"{what} = {target!r}: expected the path of a directory")
    given = str(target)
    target = Path(target).expanduser().resolve()
    check_inputs_outside(target, given, inputs, what)
    if target.exists() and not target.is_dir():
        raise OutputError(f"{what} = {given!r}: exists and is not a directory")
    if target.is_dir():
        cwd = Path.cwd().resolve()
        if target == cwd or target in cwd.parents:
            raise OutputError(f"{what} = {given!r}: is the working directory or contains it; give a new directory")
        if os.path.ismount(target):
            raise OutputError(f"{what} = {given!r}: is a mount point; give a new directory inside it")
        check_owned(target, given, what)
    parent = target.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(f"{what} = {given!r}: {str(parent)!r} is a file, not a directory")
    # Probe by creating a directory: permission bits alone say nothing for root or read-only mounts.
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".wingopt-probe-", dir=parent))
    except OSError as exc:
        raise OutputError(f"{what} = {given!r}: directory {str(parent)!r} is not writable ({exc.strerror})") from None
    return target


def check_file_writable(path: str | os.PathLike, what: str = "file") -> Path:
    """The resolved ``path`` of a single output file; :class:`OutputError` (naming ``what``) if it is
    a directory or its directory does not exist."""
    target = Path(path).expanduser().resolve()
    if target.is_dir():
        raise OutputError(f"{what} = {str(path)!r}: is a directory")
    if not target.parent.is_dir():
        raise OutputError(f"{what} = {str(path)!r}: directory {str(target.parent)!r} does not exist")
    return target


def _replace_with(target: Path, fill) -> None:
    """``fill(tmp)`` on a temporary sibling of ``target``, then rename it onto ``target``."""
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.tmp-", dir=target.parent)
    os.close(fd)
    try:
        fill(Path(tmp))
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_text_atomic(
    path: str | os.PathLike, text: str, *, what: str = "file", force: bool = False, inputs: Iterable = ()
):
    """Write one text file (``--write-problem``, ``--doc``) atomically: a temporary sibling renamed into place.

    The rule of :func:`~wingopt.results.ownership.check_new_file`: an existing file (or an input of
    the run) is refused without ``force``; with it, the earlier file is first copied to ``NAME.bak``
    (``NAME.bak.1``, ... when taken), itself written atomically, so at every moment the file is
    whole, old or new. Returns ``(path, backup path or None)``; an ``OSError`` becomes an
    :class:`OutputError` naming ``what``.
    """
    target = check_new_file(path, what, force=force, inputs=inputs)
    kept = None
    try:
        if target.is_file():
            kept = backup_name(target)
            _replace_with(kept, lambda tmp: shutil.copyfile(target, tmp))
        _replace_with(target, lambda tmp: tmp.write_text(text))
    except OSError as exc:
        raise OutputError(f"{what} = {str(path)!r}: cannot write it ({exc.strerror or exc})") from None
    return target, kept


def write_atomic(path: str | os.PathLike, fill: Callable[[Path], None]) -> Path:
    """``fill(tmp)`` on a temporary sibling of ``path`` (its directory created), renamed into place.

    For a file rewritten while a study runs (its table, summary, records) or a cache: a reader
    never sees it half-written, and a failed ``fill`` leaves the earlier file.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    _replace_with(target, fill)
    return target


def write_json_atomic(path: str | os.PathLike, data: Any) -> Path:
    """:func:`write_atomic` of ``data`` as JSON (:func:`to_jsonable` applied)."""
    text = json.dumps(to_jsonable(data), indent=2) + "\n"
    return write_atomic(path, lambda tmp: tmp.write_text(text))


def write_arrays_atomic(path: str | os.PathLike, **arrays: Any) -> Path:
    """:func:`write_atomic` of named arrays as ``.npz`` (``numpy.savez``; the name is kept as given)."""

    def fill(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    return write_atomic(path, fill)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def clean_stale(target: Path) -> list[Path]:
    """Remove the hidden work directories of dead wingopt runs next to ``target``.

    Only ``.NAME.tmp-PID-*`` / ``.NAME.old-PID`` siblings whose process is gone and that are empty or
    hold :data:`MARKER` are removed: a foreign directory of a similar name is left alone. A killed
    stream's work directory that holds estimate rows (its live CSVs) is not removed: it is moved
    aside to ``NAME.killed-PID`` (:func:`keep_killed_rows`), with a warning, before the new run starts.
    """
    removed = []
    for pattern in (f".{target.name}.tmp-*", f".{target.name}.old-*"):
        for p in target.parent.glob(pattern):
            rest = p.name[len(target.name) + 6 :]
            pid_text = rest.split("-", 1)[0]
            if not p.is_dir() or p.is_symlink() or not pid_text.isdigit():
                continue
            if int(pid_text) == os.getpid() or _pid_alive(int(pid_text)):
                continue
            try:
                if _is_ours(p) and p.name.startswith(f".{target.name}.tmp-") and keep_killed_rows(p, target, pid_text):
                    continue
                if _is_ours(p) or not any(p.iterdir()):
                    shutil.rmtree(p)
                    removed.append(p)
            except OSError:
                pass
    if removed:
        log.info("removed %d stale work director%s of killed runs", len(removed), "y" if len(removed) == 1 else "ies")
    return removed


def _rows(path: Path) -> int:
    """Complete data rows of a CSV written row by row (the header and a torn last line not counted)."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return 0
    return max(text.count("\n") - 1, 0)


def keep_killed_rows(work: Path, target: Path, pid: str) -> Path | None:
    """Move a killed run's work directory ``work`` aside to ``NAME.killed-PID`` when its CSVs hold
    rows (a stream's estimates, flushed as they came), and warn; ``None`` (nothing kept) otherwise."""
    rows = sum(_rows(f) for f in work.glob("*.csv"))
    if rows == 0:
        return None
    kept = target.with_name(f"{target.name}.killed-{pid}")
    n = 0
    while kept.exists():
        n += 1
        kept = target.with_name(f"{target.name}.killed-{pid}.{n}")
    os.replace(work, kept)
    log.warning(
        "a killed run at %s left %d estimate row(s) in its work directory: kept in %s (wingopt does not delete "
        "it; remove it when done)",
        target,
        rows,
        kept,
    )
    return kept


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _os_error(target: Path, exc: OSError) -> OutputError:
    what = "the disk is full" if exc.errno in (errno.ENOSPC, errno.EDQUOT) else exc.strerror or str(exc)
    return OutputError(f"out = {str(target)!r}: cannot write ({what})")


class ResultDirectory:
    """Context manager yielding a temporary directory that becomes ``target`` on success.

    ``target`` is checked first (:func:`check_writable`, with the run's ``inputs``) and again just
    before it is replaced: a file that appeared there meanwhile is never deleted (the new results
    are then left next to it, in ``NAME.new-PID``, and the error says so). The directory gets the
    manifest of its files (:data:`MARKER`) and the usual permissions (``0777 & ~umask``). An
    ``OSError`` while writing (disk full, quota, permissions) becomes an :class:`OutputError`; any
    exception, ``KeyboardInterrupt`` and ``SystemExit`` included, removes the temporary directory
    (:meth:`commit` first keeps what was written, for a stream that must keep its estimates).

    Examples
    --------
    >>> with ResultDirectory("out/run1") as tmp:        # doctest: +SKIP
    ...     write_json(tmp / "summary.json", {"ok": True})
    """

    def __init__(self, target: str | os.PathLike, inputs: Iterable = ()) -> None:
        self.given = str(target)
        self.inputs = list(inputs)
        self.target = check_writable(target, inputs=self.inputs)
        self._tmp: Path | None = None
        self.kept_at: Path | None = None

    def __enter__(self) -> Path:
        try:
            self.target.parent.mkdir(parents=True, exist_ok=True)
            clean_stale(self.target)
            self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.tmp-{os.getpid()}-", dir=self.target.parent))
            write_manifest(self._tmp, {})
        except OSError as exc:
            if self._tmp is not None:
                shutil.rmtree(self._tmp, ignore_errors=True)
            raise OutputError(f"out = {str(self.target)!r}: cannot create it ({exc.strerror})") from None
        return self._tmp

    def commit(self) -> Path:
        """Move what was written so far to ``target`` now (the ``with`` block then only cleans up)."""
        assert self._tmp is not None
        if not self._tmp.exists():
            return self.target
        old = None
        try:
            write_manifest(self._tmp, scan(self._tmp))
            os.chmod(self._tmp, 0o777 & ~_umask())
            if self.target.exists() or self.target.is_symlink():
                found = None
                if not self.target.is_dir() or self.target.is_symlink():
                    found = (self.target.name, "which is not a directory wingopt wrote")
                else:
                    manifest = read_manifest(self.target)
                    if manifest is None and any(self.target.iterdir()):
                        found = (next(iter(sorted(p.name for p in self.target.iterdir()))), "created meanwhile")
                    elif manifest is not None:
                        found = (
                            first_foreign(self.target, manifest)
                            if manifest.get("files") is not None
                            else (MARKER, "an older wingopt's marker")
                        )
                if found is not None:  # appeared since the check: keep it, and keep the new results too
                    self.kept_at = self.target.with_name(f"{self.target.name}.new-{os.getpid()}")
                    os.replace(self._tmp, self.kept_at)
                    raise OutputError(
                        f"out = {self.given!r}: now holds {found[0]!r} ({found[1]}), which wingopt never deletes; "
                        f"the results are in {str(self.kept_at)!r}"
                    )
                old = self.target.parent / f".{self.target.name}.old-{os.getpid()}"
                os.replace(self.target, old)
            os.replace(self._tmp, self.target)
        except BaseException as exc:
            if old is not None and not self.target.exists():
                os.replace(old, self.target)  # put the earlier results back
                old = None
            if self.kept_at is None:
                shutil.rmtree(self._tmp, ignore_errors=True)
            if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                raise _os_error(self.target, exc) from None
            raise
        finally:
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
        log.info("results written to %s", self.target)
        return self.target

    def __exit__(self, exc_type, exc, tb) -> bool:
        assert self._tmp is not None
        if exc_type is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            if issubclass(exc_type, OSError) and not issubclass(exc_type, OutputError):
                raise _os_error(self.target, exc) from None
            return False
        self.commit()
        return False
