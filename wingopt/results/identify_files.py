"""The files of one identification beyond its CSVs: ``field.nc``, the figures and ``report.html``.

:func:`write_identify_files` is called inside the run's result directory (``wingopt identify``,
:func:`wingopt.write_identify_outputs`) after ``summary.json``, ``load.csv`` and ``lift.csv``. The
field over time goes to ``field.nc`` (NetCDF through xarray, :mod:`wingopt.results.export`) when the
``data`` extra is installed; without it a warning names the extra and the rest is written.
"""

from __future__ import annotations

import logging
from pathlib import Path

from wingopt.errors import MissingExtraError
from wingopt.estimation.records import answered_by_steady_fit
from wingopt.estimation.registry import FRAME_METHODS
from wingopt.results.export import field_dataset, write_netcdf
from wingopt.results.run_report import identify_report

__all__ = ["write_identify_files", "route_name", "source_name", "FIELD_FILE"]

log = logging.getLogger(__name__)

FIELD_FILE = "field.nc"


def route_name(result) -> str:
    """The route's own name: ``full field (DIC)``, ``stream``, ``steady`` or ``transient``."""
    if result.method in FRAME_METHODS:
        return "full field (DIC)"
    steady = answered_by_steady_fit(result)
    if "phases" in result.info:  # the streaming protocol's result
        return "stream (steady refit)" if steady else "stream"
    return "steady" if steady else "transient"


def source_name(run) -> str:
    """What was identified: the data file's name, the DIC frames' source, or the simulated load case."""
    if run.protocol.get("load_case"):
        return f"simulated {run.protocol['load_case']}"
    report = run.data_report or {}
    src = report.get("file") or report.get("frames_source") or run.measurements.source
    return Path(str(src)).name if src else "data"


def write_identify_files(tmp: Path, run, summary: dict, X, Y, P, S, *, plots: bool = True) -> dict:
    """Write ``field.nc``, the figures (``plots``) and ``report.html`` into ``tmp``.

    Parameters
    ----------
    tmp : Path
        The run's (temporary) result directory.
    run : IdentifyRun
    summary : dict
        What ``summary.json`` holds (provenance included).
    X, Y, P, S : ndarray
        The grid of ``load.csv`` and the field behind the reported lift with its band (Pa).

    Returns
    -------
    dict
        ``{file name: caption}`` of the figures written.
    """
    try:
        ds = field_dataset(
            run, (X.shape[1], X.shape[0]), attrs={"source": source_name(run), "route": route_name(run.result)}
        )
        write_netcdf(ds, tmp / FIELD_FILE)
    except MissingExtraError as exc:  # the optional extra is missing: everything else is still written
        log.warning("%s not written: %s", FIELD_FILE, exc)
    figures: dict = {}
    title = f"{source_name(run)} · {route_name(run.result)} · {run.method}"
    if plots:
        from wingopt.plots.identify import plot_identification  # matplotlib: only when drawing

        figures = plot_identification(tmp, run, X, Y, P, S, title=title)
    identify_report(tmp / "report.html", summary, figures, route_name(run.result), source_name(run))
    return figures
