"""Provenance of a run, for ``summary.json`` and ``report.html``: what ran, on what, where and when.

``provenance(inputs)`` records the package version, the UTC time, the command line, the platform,
the BLAS threads in use and, for every input file, its absolute path, size and SHA-256 (a DIC
directory: every file in it, sorted, hashed as one). A problem given by a built-in name is hashed
from the file the package ships.
"""

from __future__ import annotations

import hashlib
import os
import platform
import sys
from datetime import UTC, datetime
from pathlib import Path

__all__ = ["provenance", "sha256_file", "file_record", "problem_record"]

_CHUNK = 1 << 20


def sha256_file(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file, or of a directory's files (sorted by relative path, each name then content)."""
    p = Path(path)
    h = hashlib.sha256()
    files = [p] if p.is_file() else sorted(f for f in p.rglob("*") if f.is_file())
    for f in files:
        if p.is_dir():
            h.update(str(f.relative_to(p)).encode() + b"\0")
        with open(f, "rb") as fh:
            while chunk := fh.read(_CHUNK):
                h.update(chunk)
    return h.hexdigest()


def file_record(option: str, path) -> dict | None:
    """``{"option", "path", "bytes", "sha256"}`` of an input file or directory (``None`` if it is not one)."""
    if path is None or not isinstance(path, (str, os.PathLike)) or str(path) in ("", "-", "<memory>"):
        return None
    p = Path(path).expanduser()
    if not p.exists():
        return None
    p = p.resolve()
    size = p.stat().st_size if p.is_file() else sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return {"option": option, "path": str(p), "bytes": int(size), "sha256": sha256_file(p)}


def _blas_threads() -> dict:
    """Threads of each BLAS/OpenMP library loaded (threadpoolctl), and the environment's settings."""
    out: dict = {
        k: os.environ[k] for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS") if k in os.environ
    }
    try:
        from threadpoolctl import threadpool_info  # a dependency; guarded: provenance never fails a run

        out["libraries"] = [
            {"api": i.get("internal_api"), "threads": i.get("num_threads"), "version": i.get("version")}
            for i in threadpool_info()
        ]
    except Exception:  # noqa: BLE001 - best effort
        pass
    return out


def provenance(inputs=(), argv: list[str] | None = None) -> dict:
    """The provenance record of a run (module docstring).

    Parameters
    ----------
    inputs : iterable of (option, path)
        The run's input files (``None`` paths and non-files are left out).
    argv : list of str, optional
        The command line (default ``sys.argv``).
    """
    import wingopt

    files = [r for r in (file_record(opt, path) for opt, path in inputs) if r is not None]
    seen, unique = set(), []
    for r in files:
        if r["path"] not in seen:
            seen.add(r["path"])
            unique.append(r)
    return {
        "package": "wingopt",
        "version": wingopt.__version__,
        "time_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "command_line": list(sys.argv if argv is None else argv),
        "working_directory": str(Path.cwd()),
        "inputs": unique,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "blas_threads": _blas_threads(),
    }


def problem_record(problem) -> dict:
    """The problem's name, its file (absolute path and SHA-256) and a SHA-256 of the problem as run:
    the in-memory dataclass (a calibrated or re-meshed problem differs from its file)."""
    import dataclasses
    import json

    src = getattr(problem, "source", None)
    rec = file_record("problem", src) or {}
    try:
        content = json.dumps(dataclasses.asdict(problem), sort_keys=True, default=repr)
    except TypeError:  # not a dataclass: its repr
        content = repr(problem)
    return {
        "name": getattr(problem, "name", None),
        "file": rec.get("path", None if src is None else str(src)),
        "file_sha256": rec.get("sha256"),
        "as_run_sha256": hashlib.sha256(content.encode()).hexdigest(),
    }
