"""Directories that grow file by file under the ownership rule: a study's records, table and summary,
a cache of gains (:class:`OwnedDirectory`), and the append-only log of a study (:class:`AppendLog`).

Unlike a result directory (:class:`~wingopt.results.writer.ResultDirectory`), which is replaced
whole, these are written in place, one file at a time; each file is listed in the directory's
manifest (:mod:`wingopt.results.ownership`) as it is written, so that a later run (``--resume``)
can tell them from a user's. Nothing in them is ever removed.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from wingopt.errors import OutputError
from wingopt.results.ownership import entry_unchanged, manifest_entry, read_manifest, write_manifest
from wingopt.results.writer import _os_error, _umask, check_writable, to_jsonable, write_atomic

__all__ = ["OwnedDirectory", "AppendLog", "append_synced", "truncate_synced"]

log = logging.getLogger(__name__)


class OwnedDirectory:
    """A directory that grows file by file (a study's records, table and summary; a cache of gains).

    Checked like a result directory (:func:`check_writable`: empty, new, or holding only files
    wingopt wrote there, unchanged; no input inside), then created with its manifest; every file
    is written through :meth:`write` (atomically, then listed) and the append-only log through
    :meth:`open_log` (listed with the size and hash of what was appended). Nothing in it is ever
    removed.
    """

    def __init__(self, target: str | os.PathLike, *, inputs: Iterable = (), what: str = "out") -> None:
        self.given, self.what = str(target), what
        self.path = check_writable(target, inputs=inputs, what=what)
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            os.chmod(self.path, 0o777 & ~_umask()) if not any(self.path.iterdir()) else None
        except OSError as exc:
            raise OutputError(f"{what} = {self.given!r}: cannot create it ({exc.strerror})") from None
        manifest = read_manifest(self.path)
        self.files: dict = dict((manifest or {}).get("files") or {})
        self._logs: dict[str, Any] = {}
        self._save()

    def _save(self) -> None:
        try:
            write_manifest(self.path, self.files)
        except OSError as exc:
            raise _os_error(self.path, exc) from None

    def owns(self, name: str) -> bool:
        """``name`` is a file wingopt wrote here (listed in the manifest) and it is unchanged."""
        return name in self.files and entry_unchanged(self.path / name, self.files[name])

    def write(self, name: str, fill: Callable[[Path], None], log: bool = False) -> Path:
        """``fill(tmp)`` then rename onto ``NAME`` (a file listed here, or a new name); listed after
        (``log``: as an append-only log, whose later appends are listed by :class:`AppendLog`)."""
        p = self.path / name
        if (p.exists() or p.is_symlink()) and name not in self.files:
            raise OutputError(f"{self.what} = {self.given!r}: holds {name!r}, which wingopt did not write; kept")
        try:
            write_atomic(p, fill)
            self.files[name] = {"log": True, **manifest_entry(p)} if log else manifest_entry(p)
        except OSError as exc:
            if isinstance(exc, OutputError):
                raise
            raise _os_error(self.path, exc) from None
        self._save()
        return p

    def write_text(self, name: str, text: str) -> Path:
        return self.write(name, lambda tmp: tmp.write_text(text))

    def write_json(self, name: str, data: Any) -> Path:
        text = json.dumps(to_jsonable(data), indent=2) + "\n"
        return self.write(name, lambda tmp: tmp.write_text(text))

    def open_log(self, name: str, fresh: bool) -> AppendLog:
        """The append-only log ``NAME``: started empty (``fresh``) or continued."""
        log_ = AppendLog(self, name, fresh)
        self._logs[name] = log_
        return log_


class AppendLog:
    """An append-only file of an :class:`OwnedDirectory` (a study's ``records.jsonl``).

    Listed in the manifest with ``log: true``, the size and the SHA-256 of what was appended so far
    (updated after every append). A continued log is first checked (the listed part unchanged, the
    rest complete records: :mod:`wingopt.results.ownership`); a torn last line after the listed part
    (a run killed mid-write) is cut off, nothing before it ever is.
    """

    def __init__(self, owner: OwnedDirectory, name: str, fresh: bool) -> None:
        self.owner, self.name = owner, name
        self.path = owner.path / name
        entry = owner.files.get(name)
        exists = self.path.exists() or self.path.is_symlink()
        if exists and (entry is None or not entry.get("log")):
            raise OutputError(f"{owner.what} = {owner.given!r}: holds {name!r}, which wingopt did not write; kept")
        self._hash = hashlib.sha256()
        if fresh or not exists:
            owner.write(name, lambda tmp: tmp.write_text(""), log=True)
            self.size = 0
        else:
            listed = int(entry.get("size", 0))
            data = self.path.read_bytes()
            if data and not data.endswith(b"\n"):
                keep = max(data.rfind(b"\n") + 1, listed)
                if keep < len(data):
                    log.warning("%s: cutting a torn last line (%d bytes) before appending", self.path, len(data) - keep)
                    truncate_synced(self.path, keep)
                    data = data[:keep]
            self._hash.update(data)
            self.size = len(data)
        self._note()

    def _note(self) -> None:
        self.owner.files[self.name] = {"log": True, "size": self.size, "sha256": self._hash.hexdigest()}
        self.owner._save()

    def append(self, data: bytes) -> None:
        """One write of ``data`` (a whole line), flushed and synced, then listed."""
        append_synced(self.path, data)
        self._hash.update(data)
        self.size += len(data)
        self._note()


def append_synced(path: Path, data: bytes) -> None:
    """Append ``data`` with one ``write`` (a whole line: a crash loses at most this line), then fsync."""
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        os.write(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)


def truncate_synced(path: Path, size: int) -> None:
    """Cut ``path`` to ``size`` bytes (a torn last line), then fsync."""
    with open(path, "r+b") as fh:
        fh.truncate(size)
        fh.flush()
        os.fsync(fh.fileno())
