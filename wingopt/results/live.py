"""A CSV file written row by row while a run is going (the streaming estimator's lift rows).

Unlike the final outputs, which :class:`~wingopt.results.writer.ResultDirectory` swaps in
atomically, a live file is appended to and flushed after every row, so that another process can
follow it (``tail -f``) and a stopped run keeps every row it wrote. It lives inside the run's
working directory (the hidden sibling of ``--out``) and is moved into place with the rest.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wingopt.errors import OutputError

__all__ = ["LiveCsv"]


class LiveCsv:
    """Append rows to ``path`` (header first), flushing each row to the operating system.

    Parameters
    ----------
    path : path
    header : sequence of str
    """

    def __init__(self, path: str | Path, header: Sequence[str]) -> None:
        self.path = Path(path)
        try:
            self._fh = open(self.path, "w", newline="", encoding="utf-8")
        except OSError as exc:
            raise OutputError(f"cannot write {str(self.path)!r} ({exc.strerror})") from None
        self._w = csv.writer(self._fh)
        self.rows = 0
        self._w.writerow(header)
        self._fh.flush()

    def append(self, row: Sequence) -> None:
        """Write one row (floats with 10 significant digits) and flush it."""
        self._w.writerow([f"{v:.10g}" if isinstance(v, (float, np.floating)) else v for v in row])
        self._fh.flush()
        self.rows += 1

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()

    def __enter__(self) -> LiveCsv:
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False
