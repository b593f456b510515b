"""Atomic result directories: a run writes into a hidden sibling and swaps it in on success.

A failed or interrupted run therefore never leaves a half-written output directory and never
destroys the results of an earlier run at the same place.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wingopt.errors import OutputError

__all__ = ["ResultDirectory", "write_json", "write_csv", "to_jsonable", "check_writable"]

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


def check_writable(target: Path) -> Path:
    """Raise :class:`OutputError` unless ``target`` can become a new (or replaced) directory."""
    target = Path(target).expanduser().resolve()
    if target.exists() and not target.is_dir():
        raise OutputError(f"out = {str(target)!r}: exists and is not a directory")
    parent = target.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(f"out = {str(target)!r}: {str(parent)!r} is a file, not a directory")
    # Probe by creating a directory: permission bits alone say nothing for root or read-only mounts.
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".wingopt-probe-", dir=parent))
    except OSError as exc:
        raise OutputError(
            f"out = {str(target)!r}: directory {str(parent)!r} is not writable ({exc.strerror})"
        ) from None
    return target


class ResultDirectory:
    """Context manager yielding a temporary directory that becomes ``target`` on success.

    Examples
    --------
    >>> with ResultDirectory("out/run1") as tmp:        # doctest: +SKIP
    ...     write_json(tmp / "summary.json", {"ok": True})
    """

    def __init__(self, target: str | os.PathLike) -> None:
        self.target = check_writable(Path(target))
        self._tmp: Path | None = None

    def __enter__(self) -> Path:
        try:
            self.target.parent.mkdir(parents=True, exist_ok=True)
            self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.tmp-", dir=self.target.parent))
        except OSError as exc:
            raise OutputError(f"out = {str(self.target)!r}: cannot create it ({exc.strerror})") from None
        return self._tmp

    def __exit__(self, exc_type, exc, tb) -> bool:
        assert self._tmp is not None
        if exc_type is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            return False
        old = None
        if self.target.exists():
            old = self.target.parent / f".{self.target.name}.old-{os.getpid()}"
            os.replace(self.target, old)
        os.replace(self._tmp, self.target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        log.info("results written to %s", self.target)
        return False
