"""Which files are wingopt's: the manifest of a result directory, and the checks made before a write.

The one rule for every file the package writes (issue 25):

* **A directory is wingopt's only if it holds nothing wingopt did not write.** Every directory
  wingopt writes carries a marker file (:data:`MARKER`) holding the manifest of the files it wrote
  there: their names, sizes and SHA-256 hashes. Before anything in it is replaced, every entry of
  the directory is compared with the manifest: a file that is not listed (a user's notebook, a
  sub-directory, a link) or one that changed since (an edited ``summary.json``) makes the run
  refuse, in one line naming the first such file. Nothing is ever deleted to make room.
* **An input is never inside what is replaced**: a command's input files (``--data``,
  ``--follow``, the problem file, the sweep spec, ...) below the output directory are refused.
* **A single output file** (``--write-problem``, ``--doc``) **onto an existing file is refused
  without --force**; with ``--force`` the earlier file is kept as ``NAME.bak`` (or ``NAME.bak.1``,
  ... when that name is taken: a backup never replaces another file).
* An **append-only log** (a study's ``records.jsonl``) is listed with the size and hash of what
  wingopt wrote; a later run only appends to it or cuts a torn line off the end that wingopt
  wrote, and only after checking that the part listed is unchanged and that the rest holds
  complete records of its own.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable
from pathlib import Path

from wingopt.errors import OutputError

__all__ = [
    "MARKER",
    "read_manifest",
    "manifest_entry",
    "scan",
    "first_foreign",
    "check_owned",
    "entry_unchanged",
    "check_inputs_outside",
    "check_new_file",
    "backup_name",
]

MARKER = ".wingopt-result"
"""The marker file of every directory wingopt writes: the manifest of the files it wrote there."""

_NOTE = "written by wingopt; a later run may replace the files listed here, and only if none changed"


def _digest(path: Path, size: int | None = None) -> str:
    """SHA-256 of ``path`` (of its first ``size`` bytes when given)."""
    h = hashlib.sha256()
    left = size
    with open(path, "rb") as fh:
        while left is None or left > 0:
            block = fh.read(1 << 20 if left is None else min(1 << 20, left))
            if not block:
                break
            h.update(block)
            if left is not None:
                left -= len(block)
    return h.hexdigest()


def manifest_entry(path: Path) -> dict:
    """``{"size": ..., "sha256": ...}`` of a file."""
    return {"size": path.stat().st_size, "sha256": _digest(path)}


def read_manifest(directory: Path) -> dict | None:
    """The manifest in ``directory`` (``{"files": {name: entry}}``), ``None`` without a marker, and
    ``{"files": None}`` for a marker that holds no manifest (an older wingopt's, or damaged)."""
    marker = Path(directory) / MARKER
    if not marker.is_file() or marker.is_symlink():
        return None
    try:
        data = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return {"files": None}
    if not isinstance(data, dict) or not isinstance(data.get("files"), dict):
        return {"files": None}
    return data


def write_manifest(directory: Path, files: dict) -> None:
    """Write the marker of ``directory`` listing ``files`` (atomically: a temporary sibling renamed)."""
    text = json.dumps({"written_by": "wingopt", "note": _NOTE, "files": files}, indent=1, sort_keys=True) + "\n"
    tmp = Path(directory) / f"{MARKER}.tmp-{os.getpid()}"
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, Path(directory) / MARKER)


def scan(directory: Path) -> dict:
    """The manifest entries of every file below ``directory`` (the marker excluded)."""
    directory = Path(directory)
    files = {}
    for dirpath, _dirs, names in os.walk(directory):
        for name in names:
            p = Path(dirpath) / name
            rel = p.relative_to(directory).as_posix()
            if rel == MARKER or p.is_symlink() or not p.is_file():
                continue
            files[rel] = manifest_entry(p)
    return files


def _log_tail_is_ours(path: Path, start: int) -> bool:
    """Bytes after ``start`` are complete study records (JSON objects with a ``key``), the last one
    possibly torn (no newline): what a run killed between an append and its manifest update leaves."""
    with open(path, "rb") as fh:
        fh.seek(start)
        tail = fh.read()
    lines = tail.split(b"\n")
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        last = i == len(lines) - 1  # no newline after it: a torn line
        try:
            rec = json.loads(line)
        except ValueError:
            if last:
                continue
            return False
        if not isinstance(rec, dict) or "key" not in rec:
            return False
    return True


def entry_unchanged(path: Path, entry) -> bool:
    """``path`` is the file its manifest ``entry`` lists (an append-only log: grown by records only)."""
    if not isinstance(entry, dict) or not path.is_file() or path.is_symlink():
        return False
    try:
        size = path.stat().st_size
        if entry.get("log"):  # append-only: the part wingopt listed is unchanged, the rest is its records
            listed = int(entry.get("size", -1))
            return (
                0 <= listed <= size and _digest(path, listed) == entry.get("sha256") and _log_tail_is_ours(path, listed)
            )
        return size == entry.get("size") and _digest(path) == entry.get("sha256")
    except (OSError, ValueError, TypeError):
        return False


def first_foreign(directory: Path, manifest: dict | None = None) -> tuple[str, str] | None:
    """The first entry of ``directory`` wingopt did not write, or that changed since: ``(name, why)``.

    ``None`` when every entry is a file of the manifest, unchanged (or the directory is empty).
    """
    directory = Path(directory)
    manifest = read_manifest(directory) if manifest is None else manifest
    entries = []
    for dirpath, dirs, names in os.walk(directory):
        for name in sorted(dirs):
            p = Path(dirpath) / name
            if p.is_symlink():
                entries.append(p)
        for name in sorted(names):
            entries.append(Path(dirpath) / name)
        dirs.sort()
    listed = (manifest or {}).get("files") or {}
    for p in sorted(entries, key=lambda q: q.relative_to(directory).as_posix()):
        rel = p.relative_to(directory).as_posix()
        if rel == MARKER and manifest is not None:
            continue
        if rel not in listed:
            return rel, "which wingopt did not write"
        if not entry_unchanged(p, listed[rel]):
            return rel, "which changed since wingopt wrote it"
    # Sub-directories that hold no file of the manifest (a user's empty folder) are foreign too.
    for dirpath, dirs, _names in os.walk(directory):
        for name in sorted(dirs):
            rel = (Path(dirpath) / name).relative_to(directory).as_posix()
            if not any(f.startswith(rel + "/") for f in listed):
                return rel + "/", "which wingopt did not write"
    return None


def check_owned(target: Path, given: str, what: str = "out") -> None:
    """Raise :class:`OutputError` unless the directory ``target`` is empty or holds only files
    wingopt wrote there, unchanged (see the module docstring). Reads, never writes."""
    target = Path(target)
    try:
        empty = not any(target.iterdir())
    except OSError as exc:
        raise OutputError(f"{what} = {given!r}: cannot read it ({exc.strerror})") from None
    if empty:
        return
    manifest = read_manifest(target)
    if manifest is None:
        try:
            first = min(p.name for p in target.iterdir())
        except (OSError, ValueError):
            first = "?"
        raise OutputError(
            f"{what} = {given!r}: exists and was not written by wingopt (no {MARKER} file; it holds {first!r}); "
            "give a new directory (wingopt never deletes files it did not write)"
        )
    if manifest.get("files") is None:
        raise OutputError(
            f"{what} = {given!r}: its {MARKER} holds no list of the files wingopt wrote (an older wingopt's); "
            "wingopt cannot tell them from yours: give a new directory"
        )
    try:
        found = first_foreign(target, manifest)
    except OSError as exc:
        raise OutputError(f"{what} = {given!r}: cannot read it ({exc.strerror})") from None
    if found is not None:
        name, why = found
        raise OutputError(
            f"{what} = {given!r}: holds {name!r}, {why}; wingopt replaces only its own unchanged files: "
            "move it away or give a new directory"
        )


OUTPUT_FILE_OPTIONS = ("write-problem", "doc")
"""Single output files written beside a result directory (never inside it: it is replaced whole)."""


def _inside(path: Path, directory: Path) -> bool:
    return path == directory or directory in path.parents


def check_inputs_outside(target: Path, given: str, inputs: Iterable, what: str = "out") -> None:
    """Raise :class:`OutputError` if an input file (``(option, path)`` pairs or paths) is ``target``
    or lies below it: a directory that is replaced must not hold what the run reads."""
    target = Path(target)
    for item in inputs:
        option, path = item if isinstance(item, tuple) else ("input", item)
        if path is None or str(path) in ("", "-"):
            continue
        if option == "problem" and not Path(path).is_file():  # a built-in name, not a file here
            continue
        try:
            p = Path(path).expanduser()
            resolved = p.resolve()
            candidates = {resolved, Path(os.path.abspath(p))}
        except (OSError, RuntimeError, ValueError):
            continue
        if any(_inside(c, target) for c in candidates):
            noun = "the file" if option.lstrip("-") in OUTPUT_FILE_OPTIONS else "the input"
            raise OutputError(
                f"{what} = {given!r}: holds {noun} {str(path)!r} ({option}); the output directory is "
                "replaced as a whole, so it must not hold what the run reads or writes beside it: give "
                "another directory"
            )


def backup_name(path: Path) -> Path:
    """``NAME.bak``, or ``NAME.bak.1``, ``NAME.bak.2``, ... : the first name that is free."""
    candidate = path.with_name(path.name + ".bak")
    k = 0
    while candidate.exists() or candidate.is_symlink():
        k += 1
        candidate = path.with_name(f"{path.name}.bak.{k}")
    return candidate


def check_new_file(path, what: str, *, force: bool = False, inputs: Iterable = ()) -> Path:
    """The resolved ``path`` of a single output file, checked before any work.

    Refused (:class:`OutputError` naming ``what``): a directory, a missing directory, a path that
    is not a regular file (a device, a link to a directory); an existing file without ``force``
    (with it the file is kept as ``NAME.bak`` when written); an input file of the run (``inputs``)
    without ``force``.
    """
    given = str(path)
    p = Path(path).expanduser()
    target = p.resolve()
    if target.is_dir():
        raise OutputError(f"{what} = {given!r}: is a directory")
    if not target.parent.is_dir():
        raise OutputError(f"{what} = {given!r}: directory {str(target.parent)!r} does not exist")
    if target.exists() and not target.is_file():
        raise OutputError(f"{what} = {given!r}: exists and is not a regular file")
    if force:
        return target
    for item in inputs:
        option, inp = item if isinstance(item, tuple) else ("input", item)
        if inp is None or str(inp) in ("", "-"):
            continue
        try:
            same = Path(inp).expanduser().resolve() == target
        except (OSError, RuntimeError, ValueError):
            same = False
        if same:
            raise OutputError(
                f"{what} = {given!r}: is the input {option}; write a new file (or give --force to replace it, "
                "the earlier one kept as a .bak)"
            )
    if target.exists() or p.is_symlink():
        raise OutputError(
            f"{what} = {given!r}: exists; give a new file name, or --force to replace it (the earlier file is "
            "then kept as NAME.bak)"
        )
    return target
