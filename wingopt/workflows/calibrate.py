"""Calibrate a membrane before a run, the ``wingopt calibrate`` use case: a record without load in,
the prestrains and damping with their posterior out, and a problem file that carries them.

:func:`calibrate_membrane` reads the problem and the calibration record (a release, a pluck or a
tap with no flow), runs :func:`wingopt.estimation.calibration.fit.calibrate`;
:func:`write_calibration_outputs` hands the result to :mod:`wingopt.results`: ``summary.json`` (with
its provenance), the figures, ``report.html`` and,
with ``write_problem``, the problem file with ``[identification] prestrain, prestrain_std,
prestrain_correlation, damping, damping_std, calibration`` set. ``wingopt identify`` with that
problem then takes the calibration's posterior as its prior on the tension and the damping.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wingopt import resources
from wingopt.errors import InputError
from wingopt.estimation.calibration.fit import Calibration, calibrate
from wingopt.estimation.core.sanity import as_measurements
from wingopt.measurements import Measurements, read_measurements
from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem, read_problem_table
from wingopt.problem.toml_text import table_text
from wingopt.results import ResultDirectory, check_new_file, to_jsonable, write_json, write_text_atomic
from wingopt.results.provenance import problem_record, provenance
from wingopt.results.run_report import calibration_report
from wingopt.status import RunStatus
from wingopt.validate import check_number

log = logging.getLogger(__name__)

__all__ = [
    "CalibrationRun",
    "calibrate_membrane",
    "calibrated_problem",
    "calibrated_problem_text",
    "write_calibration_outputs",
]


@dataclass(eq=False)
class CalibrationRun:
    """One calibration: the problem, the record, the identified parameters."""

    problem: Any
    source: str
    measurements: Measurements
    calibration: Calibration
    data_report: dict | None
    wall_s: float
    outputs: dict = field(default_factory=dict, init=False, repr=False)  # provenance, once written

    @property
    def status(self) -> RunStatus:
        """The calibration's :class:`~wingopt.status.RunStatus` (``summary()["status"]``)."""
        return self.calibration.status

    def __repr__(self) -> str:
        # The dataclass repr prints the problem and the whole record.
        p = self.calibration.parameters
        pars = ", ".join(f"{k}={v:.4g}" for k, v in p.items())
        return (
            f"CalibrationRun(problem={self.problem.name!r}, data={self.source!r}, samples={self.measurements.count}, "
            f"{pars}, status='{self.status}', warnings={len(self.calibration.warnings)}, wall={self.wall_s:.3g} s)"
        )

    def summary(self) -> dict:
        c = self.calibration
        names = list(c.parameters)
        return {
            "problem": self.problem.name,
            "status": str(self.status),
            "data": self.source,
            "data_report": self.data_report,
            "samples": int(self.measurements.count),
            "parameters": c.parameters,
            "parameters_std": c.parameters_std,
            "correlation": {"names": names, "matrix": c.correlation.tolist()},
            "chi2_per_datum": c.chi2_per_datum,
            "model_adequate": c.adequate,
            "estimator": c.info,
            "wall_s": self.wall_s,
            "warnings": list(c.warnings),
            **self.outputs,
        }


def calibrate_membrane(
    problem,
    data: str | Path | Measurements,
    *,
    nodes: tuple[int, int] | None = None,
    release_peak: float | None = None,
    noise_std: float | None = None,
    max_memory: float | None = None,
) -> CalibrationRun:
    """Identify the prestrains and damping of ``problem``'s membrane from the record ``data``.

    Parameters
    ----------
    problem : MembraneProblem or str
        The problem (a built-in name or a path loads it).
    data : path or Measurements
        The calibration record (CSV: ``t`` and one column per sensor), with no load on the wing.
    nodes : (int, int), optional
        Estimator mesh (default: the problem's).
    release_peak : float, optional
        The record starts at rest in the protocol's bubble shape with this peak (m): a release from
        a known push. Default: the initial shape is unknown (a pluck or a tap) and identified.
    noise_std : float, optional
        Sensor noise std (default: estimated from the data).
    max_memory : float, optional
        Refuse a run estimated to need more bytes (before any work).

    Returns
    -------
    CalibrationRun
    """
    if isinstance(problem, (str, Path)):
        problem = load_problem(problem)
    if getattr(problem, "kind", None) != "membrane":
        raise InputError(f"problem: calibrate needs a membrane problem, got kind {getattr(problem, 'kind', None)!r}")
    check_number("noise_std", noise_std, lo=1e-12, hi=0.5, allow_none=True)
    check_number("release_peak", release_peak, allow_none=True)
    check_number("max_memory", max_memory, positive=True, allow_none=True)
    if data is None or isinstance(data, (bytes, bool)):
        raise InputError(f"data = {data!r}: expected a CSV path, a Measurements or an array of rows t, s_1 .. s_p")
    if nodes is not None:
        problem = problem.with_mesh(nodes)
    if release_peak is not None and not (math.isfinite(release_peak) and 0 < abs(release_peak) < 0.5):
        raise InputError(f"release_peak = {release_peak!r}: expected the release bubble's peak in m (e.g. 0.004)")
    peak = 0.0 if release_peak is None else float(release_peak)
    fit_problem = dataclasses.replace(
        problem, identification=dataclasses.replace(problem.identification, initial_deflection=peak)
    )
    report = None
    if isinstance(data, (str, Path)):
        if Path(data).is_dir():
            raise InputError(f"data = {str(data)!r}: is a directory, expected a CSV file")
        meas, csv_report = read_measurements(data, problem.sensor_names, problem.measurements)
        report, source = csv_report.as_dict(), str(data)
    else:
        meas, source = as_measurements(data, problem.sensor_names), getattr(data, "source", "") or "<memory>"
    resources.check(resources.estimate_identify(problem.nodes, meas.count, method="batch"), max_memory)
    t0 = time.perf_counter()
    cal = calibrate(MembraneModel.from_problem(fit_problem), meas, noise_std=noise_std)
    cal = dataclasses.replace(cal, warnings=[w if w.startswith("[") else f"[calibration] {w}" for w in cal.warnings])
    for w in cal.warnings:  # each once, naming the fit that said it
        log.warning("%s", w)
    return CalibrationRun(problem, source, meas, cal, report, time.perf_counter() - t0)


def calibrated_problem(run: CalibrationRun):
    """The problem with the calibration's posterior as its ``[identification]`` prior.

    Parameters
    ----------
    run : CalibrationRun
        From :func:`calibrate_membrane`.

    Returns
    -------
    MembraneProblem
        In memory, with the values :func:`calibrated_problem_text` writes (``identify`` on either
        gives the same answer).
    """
    if not isinstance(run, CalibrationRun):
        raise InputError(f"run = {type(run).__name__}: expected the CalibrationRun of calibrate_membrane")
    ident = _calibrated_fields(run)
    ident["prestrain"], ident["prestrain_std"] = tuple(ident["prestrain"]), tuple(ident["prestrain_std"])
    return run.problem.with_identification(**ident)


def calibrated_problem_text(run: CalibrationRun) -> str:
    """The problem file's text with the calibration's posterior as ``[identification]`` prior."""
    header = f"calibrated by wingopt calibrate from {run.source} (problem {run.problem.source})"
    updates = {"identification": _calibrated_fields(run)}
    channels = run.problem.measurements
    if channels is not None and not channels.is_identity:  # the DAQ's map the record was read with
        updates["measurements"] = channels.table(run.problem.sensor_names)
    return table_text(read_problem_table(run.problem.source), updates, header)


def _calibrated_fields(run: CalibrationRun) -> dict:
    c = run.calibration
    r = float(c.correlation[0, 1])
    ident = {
        "prestrain": [round(c.parameters["prestrain_x"], 7), round(c.parameters["prestrain_y"], 7)],
        "prestrain_std": [round(c.parameters_std["prestrain_x"], 7), round(c.parameters_std["prestrain_y"], 7)],
        "prestrain_correlation": round(max(min(r, 0.999), -0.999), 4),
        "damping": round(c.parameters["damping"], 5),
        "damping_std": round(c.parameters_std["damping"], 5),
        "calibration": f"{Path(run.source).name}: {run.measurements.count} samples, chi-square per datum "
        f"{c.chi2_per_datum:.2f}{'' if c.adequate else ' (inadequate)'}",
    }
    if not c.adequate:  # every run on this prior says so (identify's data check)
        ident["calibration_misfit"] = round(float(c.chi2_per_datum), 3)
    return ident


def calibration_inputs(problem, data) -> list[tuple[str, str]]:
    """The files a calibration reads, as ``(option, path)``: never overwritten, never inside ``--out``."""
    src = problem if isinstance(problem, (str, Path)) else getattr(problem, "source", None)
    out = [("problem", str(src))] if src else []
    if isinstance(data, (str, Path)):
        out.append(("--data", str(data)))
    return out


def write_calibration_outputs(
    run: CalibrationRun,
    out_dir: str | Path,
    write_problem: str | Path | None = None,
    *,
    force: bool = False,
    plots: bool = True,
):
    """Write ``summary.json`` (with the provenance: version, time, command line, inputs' SHA-256),
    the figures (``plots``: the record, the fit's misfit), ``report.html`` (atomically) and, with
    ``write_problem``, the calibrated problem file (an existing file, the input problem file
    included, is refused unless ``force``, and then kept as ``NAME.bak``). Returns ``(out_dir,
    problem path or None, backup or None)``."""
    if not isinstance(run, CalibrationRun):
        raise InputError(f"run = {type(run).__name__}: expected the CalibrationRun of calibrate_membrane")
    inputs = calibration_inputs(run.problem, run.source if run.source != "<memory>" else None)
    text = calibrated_problem_text(run) if write_problem is not None else None
    if write_problem is not None:
        check_new_file(write_problem, "--write-problem", force=force, inputs=inputs)
    run.outputs = {"provenance": provenance(inputs), "problem_file": problem_record(run.problem)}
    with ResultDirectory(out_dir, inputs=[*inputs, ("--write-problem", write_problem)]) as tmp:
        summary = to_jsonable(run.summary())
        write_json(tmp / "summary.json", summary)
        if text is not None:
            (tmp / "calibrated.toml").write_text(text)
        figures = {}
        if plots:
            from wingopt.plots.calibration import plot_calibration  # matplotlib: only when drawing

            figures = plot_calibration(tmp, run, f"{Path(run.source).name} · calibration")
        calibration_report(tmp / "report.html", summary, figures)
    written = backup = None
    if text is not None:
        written, backup = write_text_atomic(write_problem, text, what="--write-problem", force=force, inputs=inputs)
    return Path(out_dir), written, backup
