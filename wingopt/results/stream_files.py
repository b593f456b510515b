"""What a stream leaves beside its ``lift.csv`` and ``summary.json``: the lift figure and ``report.html``.

A stream (``identify --data -``, ``--follow``) writes its estimates as they come; once it has
ended, its lift history is read back from ``lift.csv`` and drawn with the reported lift and band,
and the run's report is written as an identification's (:func:`~.run_report.identify_report`).
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import numpy as np

from wingopt.results.provenance import problem_record, provenance
from wingopt.results.run_report import identify_report
from wingopt.results.writer import to_jsonable, write_json

__all__ = ["write_stream_outputs", "write_stream_files"]

log = logging.getLogger(__name__)

MAX_POINTS = 20000
"""The most points a stream's lift figure draws (an hour at 1 kHz is thinned to it, evenly)."""


def write_stream_outputs(tmp: Path, summary: dict, source: str, inputs, problem) -> None:
    """Complete ``summary`` with the provenance of ``inputs`` (``(option, path)`` pairs) and the
    problem file's record, and write ``summary.json``, ``lift.png`` and ``report.html`` into ``tmp``."""
    summary["provenance"] = provenance(inputs)
    summary["problem_file"] = problem_record(problem)
    on_disk = to_jsonable(summary)
    write_json(tmp / "summary.json", on_disk)
    write_stream_files(tmp, on_disk, source)


def write_stream_files(tmp: Path, summary: dict, source: str, *, plots: bool = True) -> dict:
    """Write ``lift.png`` (``plots``) and ``report.html`` of a finished stream into ``tmp``.

    Parameters
    ----------
    tmp : Path
        The stream's (temporary) result directory, holding its ``lift.csv``.
    summary : dict
        What ``summary.json`` holds (provenance included).
    source : str
        The stream's input, as its report names it.

    Returns
    -------
    dict
        ``{file name: caption}`` of the figures written.
    """
    figures: dict = {}
    t, lift, std = _lift_history(tmp / "lift.csv")
    if plots and t.size:
        from wingopt.plots.identify import plot_lift  # matplotlib: only when drawing

        reported = (summary.get("lift_N"), summary.get("lift_std_N"))
        title = f"{Path(source).name} · stream · {summary.get('status')}"
        plot_lift(tmp / "lift.png", t, lift, std, title=title, reported=reported)
        figures["lift.png"] = "lift history of the stream with its 1-sigma band and the reported lift"
    identify_report(tmp / "report.html", summary, figures, "stream", Path(source).name)
    return figures


def _lift_history(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, lift, std)`` of a stream's ``lift.csv``, thinned to :data:`MAX_POINTS` rows at most
    (read twice, row by row: an hour at 1 kHz is never held whole)."""
    with open(path, newline="", encoding="utf-8") as fh:
        count = sum(1 for _ in fh) - 1
    step = max(1, -(-count // MAX_POINTS))
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [r for i, r in enumerate(csv.DictReader(fh)) if i % step == 0]

    def column(name: str) -> np.ndarray:
        return np.array([float(r[name]) if r.get(name) not in (None, "") else np.nan for r in rows])

    return column("t"), column("lift_N"), column("lift_std_N")
