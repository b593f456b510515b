"""Study records: one JSON line per finished task, and the per-case summary table.

``records.jsonl`` is the one output file that is appended to rather than written whole: each
finished task adds one line with a single ``write`` of the complete line, then flush and fsync,
so a crash loses at most the line being written. A torn last line (no newline, or not JSON) is
ignored with a warning when read, and cut off before the next append. Every other output
(table, summary) is written to a temporary file and renamed into place
(:func:`wingopt.results.write_atomic`).
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from wingopt.errors import InputError
from wingopt.results import to_jsonable, write_atomic, write_csv
from wingopt.results.owned import append_synced, truncate_synced

__all__ = [
    "RecordLog",
    "read_records",
    "by_key",
    "TIMING_FIELDS",
    "summary_rows",
    "write_table",
]

log = logging.getLogger(__name__)

TIMING_FIELDS = ("duration_s", "cpu_s", "pid", "wall_s", "seconds")
"""Record fields that differ from run to run (timings, process ids); everything else is the result."""


def read_records(path: str | os.PathLike) -> list[dict]:
    """The records of ``path`` in file order (none if it does not exist); a torn last line is skipped."""
    path = Path(path)
    if not path.exists():
        return []
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text (UTF-8) file of JSON records") from None
    torn = bool(text) and not text.endswith("\n")  # the last write was cut short
    lines = text.splitlines()
    records = []
    for i, line in enumerate(lines):
        last = i == len(lines) - 1
        if last and torn:
            log.warning("%s: torn last line ignored (a task was being recorded when the run stopped)", path)
            continue
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except ValueError:
            rec = None
        if not isinstance(rec, dict):
            if last:
                log.warning("%s: unreadable last line ignored", path)
                continue
            raise InputError(f"{path}: line {i + 1}: expected a JSON record, got {line[:60]!r}")
        records.append(rec)
    return records


def by_key(records: Iterable[dict]) -> dict[str, dict]:
    """One record per task key: the first successful one, else the last failure.

    (Older ``compare`` runs could record a run twice: the first, the table's, carries the oracle fields.)
    """
    out: dict[str, dict] = {}
    for r in records:
        key = r.get("key")
        if key is None:
            continue
        if key not in out or (out[key].get("status", "ok") != "ok"):
            out[key] = r
    return out


class RecordLog:
    """Append-only records file. Opening it for appends cuts off a torn last line first.

    With ``owner`` (an :class:`~wingopt.results.writer.OwnedDirectory`: what the commands use) the
    file is the directory's append-only log: listed in its manifest, only ever appended to, and a
    torn line is cut only from the part this package appended (a user's file of the same name is
    refused, never cut). Without it (tests, the API on a file of one's own), as before.
    """

    def __init__(self, path: str | os.PathLike, fresh: bool = False, owner=None) -> None:
        self.path = Path(path)
        self._log = None
        if owner is not None:
            self._log = owner.open_log(self.path.name, fresh)
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if fresh or not self.path.exists():
            write_atomic(self.path, lambda p: p.write_text(""))
        else:
            self._cut_torn_tail()

    def _cut_torn_tail(self) -> None:
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):
            keep = data.rfind(b"\n") + 1
            log.warning("%s: cutting a torn last line (%d bytes) before appending", self.path, len(data) - keep)
            truncate_synced(self.path, keep)

    def append(self, record: dict) -> None:
        """Append one record: one write of the whole line, flushed and synced before returning."""
        line = (json.dumps(to_jsonable(record), allow_nan=False) + "\n").encode()
        if self._log is not None:
            self._log.append(line)
        else:
            append_synced(self.path, line)

    def read(self) -> list[dict]:
        return read_records(self.path)


def _stats(values: Sequence[float]) -> tuple[float, float, float, float]:
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if not v.size:
        return (math.nan,) * 4
    return float(v.mean()), float(v.std()), float(v.min()), float(v.max())


def summary_rows(records: Iterable[dict], case_fields: Sequence[str], metrics: Sequence[str]) -> list[dict]:
    """Per case (records equal on ``case_fields``): runs, failures and mean/std/min/max of each metric."""
    groups: dict[tuple, list[dict]] = {}
    for r in records:
        groups.setdefault(tuple(json.dumps(r.get(f)) for f in case_fields), []).append(r)
    rows = []
    for rs in groups.values():
        row = {f: rs[0].get(f) for f in case_fields}
        ok = [r for r in rs if r.get("status", "ok") == "ok"]
        row["runs"], row["failed"] = len(ok), len(rs) - len(ok)
        for m in metrics:
            mean, std, lo, hi = _stats([r.get(m) for r in ok if isinstance(r.get(m), (int, float))])
            row.update({f"{m}_mean": mean, f"{m}_std": std, f"{m}_min": lo, f"{m}_max": hi})
        rows.append(row)
    return rows


def write_table(path_stem: str | os.PathLike, rows: Sequence[dict], owner=None) -> list[Path]:
    """``STEM.csv`` (always) and ``STEM.parquet`` (when pyarrow is installed); returns the paths.

    ``owner``: the :class:`~wingopt.results.writer.OwnedDirectory` the table goes into (listed there).
    """
    stem = Path(path_stem)
    header = list(dict.fromkeys(k for r in rows for k in r))
    cells = [[_cell(r.get(k)) for k in header] for r in rows]

    def put(path: Path, fill) -> Path:
        return owner.write(path.name, fill) if owner is not None else write_atomic(path, fill)

    paths = [put(stem.with_suffix(".csv"), lambda p: write_csv(p, header, cells))]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return paths
    table = pa.Table.from_pylist([{k: _cell(r.get(k)) for k in header} for r in rows])
    paths.append(put(stem.with_suffix(".parquet"), lambda p: pq.write_table(table, p)))
    return paths


def _cell(v):
    if isinstance(v, (dict, list, tuple)):
        return json.dumps(to_jsonable(v))
    return v
