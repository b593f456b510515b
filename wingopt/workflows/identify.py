"""Identify the membrane load from one record: the ``wingopt identify`` engine, as a Python API.

``identify(problem, load="L1", noise_percent=1)`` simulates the protocol (truth on a finer mesh)
and runs an estimator; ``identify(problem, data="run.csv")`` reads a measured record instead. The
estimator is a pair of the registry (:mod:`wingopt.estimation.registry`): a method and the membrane
physics it assumes, ``auto`` by default (the FvK whole-record estimator on measured data and on
nonlinear truth, the seed's linear MHE on the seed's linear protocol). Options
(:class:`~wingopt.estimation.options.IdentifyOptions`) the chosen pair does not use are refused.
The returned :class:`IdentifyRun` holds the estimate, the truth when known, and a spec §7
:meth:`~IdentifyRun.summary`; :func:`write_identify_outputs` writes ``summary.json``,
``load.csv``, ``lift.csv`` and figures atomically.

Stretch sensors cannot see the sign of the load: ``initial_load`` (default: the problem's
``[identification] initial_load``, 200 Pa) decides it.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wingopt import resources
from wingopt.errors import InputError
from wingopt.estimation.core import sanity
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.options import IdentifyOptions
from wingopt.estimation.registry import FRAME_METHODS, check_options, resolve
from wingopt.estimation.runners import build, check_settings
from wingopt.measurements import Acquisition, ChannelMap, Measurements
from wingopt.measurements.dic import DICFrames
from wingopt.membrane import MembraneModel, TruthRecord
from wingopt.problem import load_problem
from wingopt.progress import fmt_duration
from wingopt.results import ResultDirectory, write_csv, write_json
from wingopt.results.field import grid
from wingopt.results.identify_files import route_name, write_identify_files
from wingopt.results.provenance import problem_record, provenance
from wingopt.results.run_api import RunExports
from wingopt.status import RunStatus
from wingopt.validate import check_number
from wingopt.values import LambdaChoice
from wingopt.workflows.protocols import estimator_model
from wingopt.workflows.sources import DICRecord, MeasuredRecord, SimulatedCase, SourceRecord, data_source
from wingopt.workflows.studies import evaluate, load_field

log = logging.getLogger(__name__)
progress = logging.getLogger("wingopt.progress.identify")  # stage lines (wingopt.progress), shown by the CLI

__all__ = ["IdentifyRun", "identify", "write_identify_outputs", "LOAD_GRID"]

LOAD_GRID = (57, 29)
"""Points (x, y) of the uniform grid of ``load.csv``, edges included."""
LOAD_COLUMNS = ("x", "y", "pressure_Pa", "pressure_std_Pa")
"""``load.csv``: the field behind the reported lift and its 1-sigma (:mod:`wingopt.results.field`)."""
LIFT_COLUMNS = ("t", "lift_N", "lift_std_N", "reported_lift_N", "reported_lift_std_N")
"""``lift.csv``: the lift history and its band (NaN: none), the reported lift and its band on every row."""


@dataclass(eq=False)
class IdentifyRun(RunExports):
    """One identification run: its inputs, the estimate and, for simulated records, the truth.

    ``lift`` is the reported lift, ``lift_std`` its 1-sigma, ``lift_history`` the estimate over time;
    ``mean_field()``, ``to_dataframe()`` and ``to_xarray()``: :class:`~wingopt.results.run_api.RunExports`.
    """

    problem: Any
    model: MembraneModel
    method: str
    measurements: Measurements
    result: IdentificationResult
    wall_s: float
    case: TruthRecord | None = None
    data_report: dict | None = None
    protocol: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    _errors: tuple | None = field(default=None, init=False, repr=False)
    outputs: dict = field(default_factory=dict, init=False, repr=False)  # provenance, once written

    def load_field(self, k: int | None = None):
        """Callable ``(x, y) -> P`` (Pa): the field behind the reported lift (``load.csv``), or sample ``k``'s."""
        return self.mean_field() if k is None else load_field(self.result, self.model, k)

    @property
    def lift(self) -> float:
        return self.result.reported_lift[0]

    @property
    def status(self) -> RunStatus:
        """The estimate's :class:`~wingopt.status.RunStatus` (``summary()["status"]``)."""
        return self.result.status

    def __repr__(self) -> str:
        # The dataclass repr prints the problem, the model and every array (34 000 characters).
        lift, std = self.result.reported_lift
        band = "" if std is None else f" ± {std:.3g}"
        src = self.protocol.get("load_case") or self.measurements.source.rsplit("/", 1)[-1] or "data"
        nx, ny = self.problem.nodes
        return (
            f"IdentifyRun(problem={self.problem.name!r}, mesh {nx}x{ny}, record={src!r}, method={self.method!r}, "
            f"lift={lift:.4g}{band} N, status='{self.status}', samples={self.measurements.count}, "
            f"warnings={len(self.warnings)}, wall={self.wall_s:.3g} s)"
        )

    def errors(self) -> dict:
        """Final relative L2 errors against the truth (simulated records only)."""
        if self.case is None:
            return {}
        # Kept for the same result and truth: summary() is asked for twice per run (the outputs'
        # summary.json and the caller's), and each evaluation integrates both fields on the truth mesh.
        key = (self.result, self.case, self.model, self.method)
        if self._errors is not None and all(a is b for a, b in zip(self._errors[0], key)):
            return dict(self._errors[1])
        rec = evaluate(self.case, self.result, self.model, self.method)
        out = {
            "load_error": rec.load_error,
            "deflection_error": rec.deflection_error,
            "true_lift_N": rec.true_lift,
            "lift_error": rec.lift_error,
            "lift_error_note": "|lift - true lift| / ∫|P| (L2 has no net lift)",
            "sign_ok": rec.sign_ok,
        }
        self._errors = (key, out)
        return dict(out)

    def summary(self) -> dict:
        """The spec §7 summary: ``lift_N``, ``method``, ``wall_s`` and, with a truth, the errors."""
        res = self.result
        out: dict[str, Any] = {
            "problem": self.problem.name,
            "method": self.method,
            "status": str(self.status),
            "mesh": list(self.problem.nodes),
            **self.protocol,
            "lift_N": self.lift,
            "lift_std_N": res.reported_lift[1],
            "wall_s": self.wall_s,
            "regularization": res.regularization,
            "samples": int(self.measurements.count),
            "missing_samples": int(np.count_nonzero(self.measurements.missing)),
            "warnings": list(self.warnings),
        }
        if self.data_report is not None:
            out["data"] = self.data_report
        out["route"], out["mean_field"] = route_name(res), self.mean_field().as_dict()
        out.update(self.outputs)
        out.update(self.errors())
        out["estimator"] = {k: v for k, v in res.info.items() if k != "iterations_per_window"}
        # issue 11: adequacy flag, warnings, identified parameters and left-out data at top level
        diagnostics = res.diagnostics
        out.update(diagnostics.summary())
        if diagnostics.parameters is not None:
            if self.case is not None and getattr(self.case, "parameters", None):
                out["true_parameters"] = self.case.parameters
        return out


def identify(
    problem,
    source: SimulatedCase | MeasuredRecord | DICRecord | None = None,
    *,
    load: str | None = None,
    data: str | Path | Measurements | np.ndarray | None = None,
    dic: str | Path | DICFrames | None = None,
    method: str = "auto",
    model: str = "auto",
    options: IdentifyOptions | None = None,
    nodes: tuple[int, int] | None = None,
    max_memory: float | None = None,
    settings=None,
    initial_load: float | None = None,
    noise_std: float | None = None,
    lam: LambdaChoice | None = None,
    noise: float | None = None,
    channels: ChannelMap | None = None,
    acquisition: Acquisition | str | None = None,
    **simulated,
) -> IdentifyRun:
    """Estimate the load of a membrane problem from a simulated (``load``) or measured (``data``) record.

    Parameters
    ----------
    problem : MembraneProblem or str
        From :func:`wingopt.problem.load_problem`, or a built-in name / path to load.
    source : SimulatedCase, MeasuredRecord or DICRecord, optional
        The data (:mod:`wingopt.workflows.sources`); or one of the shorthands ``load``, ``data``, ``dic``.
    load : {"L1", "L2", "L3", "consistency", "LE"}, optional
        Simulate the protocol with this load, ``SimulatedCase(load, **simulated)``, whose options only a simulated
        case takes (refused with ``data`` or ``dic``): ``noise_percent`` (PERCENT of each sensor's peak output, as
        ``--noise``; default 1), ``seed`` (0), ``truth`` (``"linear"``, ``"berger"``, ``"fvk"``), ``truth_nodes``
        (49x25; ``None``: the seed's same-mesh protocol), ``truth_prestrain`` ``(ex, ey)``, ``truth_damping`` (a
        factor), ``t_end`` (1 s) and ``gust`` (:class:`~wingopt.membrane.Gust`).
    data, channels : path, Measurements or array; ChannelMap, optional
        Measured record instead of ``load``: a CSV file (``t`` + one column per sensor, or a DAQ's columns,
        gains, offsets by ``channels``, default the problem's ``[measurements]``; recorded in ``data.channels``),
        a :class:`Measurements`, or an array ``(N, 1 + p)`` of rows ``t, s_1 .. s_p`` (problem's sensor order).
    dic : path or DICFrames, optional
        DIC frames instead (:mod:`wingopt.workflows.dic`, mapped by the problem's ``[dic]``): the
        full-field estimator by default (``method="fullfield"``); any other method gets the frames'
        virtual stretch sensors (slope route) with the first frame's shape as its initial deflection.
    method, model : str
        The estimator and the membrane it assumes (:data:`wingopt.estimation.registry.METHODS`,
        :data:`~wingopt.estimation.registry.MODELS`); ``auto``: see the module docstring.
    options : IdentifyOptions, optional
        Window, lambda, modes, load model, ... Options the chosen estimator does not use are
        refused (``InputError`` naming the option and the estimator).
    nodes : (int, int), optional
        Estimator mesh (default: the problem's).
    max_memory : float, optional
        Refuse (``InputError``, before any work) a run estimated to need more bytes than this (default: the
        memory the machine has available); see :mod:`wingopt.resources`.
    settings : MHESettings or RecordSettings, optional
        Advanced: the estimator's settings to start from (the options are applied on top).
    initial_load, noise_std, lam :
        Shorthands for the same fields of ``options``: the sign prior (Pa), the sensor noise std (sensor units;
        default: estimated from the data) and the lambda choice.
    acquisition : Acquisition or str, optional
        How the DAQ sampled the record (a kind, e.g. ``"delta-sigma"``): overrides the problem's
        ``[measurements] acquisition`` (:mod:`wingopt.measurements.acquisition`).
    noise : float, optional
        No longer accepted (a fraction; ``--noise`` is a percentage): refused, naming ``noise_percent``, ``noise_std``.

    Returns
    -------
    IdentifyRun
        The estimate, the measurements, the truth (simulated records) and the summary.
    """
    shorthand = {"load": load, "data": data, "dic": dic, "channels": channels, **simulated}
    problem, source = _problem_and_source(problem, source, noise, acquisition, shorthand)
    spec, opts = _estimator(method, model, source, options, settings, max_memory, initial_load, noise_std, lam)
    record = _read(problem if nodes is None else problem.with_mesh(nodes), source, spec, opts, max_memory)
    return _estimate(record, spec, record.options, settings)


def _problem_and_source(problem, source, noise, acquisition, shorthand: dict) -> tuple:
    """The membrane problem (with its DAQ's ``acquisition``) and the one source of data, once checked."""
    if noise is not None:
        raise InputError(
            f"noise = {noise!r}: ambiguous unit; give noise_percent (simulated noise, 1 = 1 % of each sensor's "
            "peak, as wingopt identify --noise 1) or noise_std (the sensors' noise std, sensor units)"
        )
    problem = _membrane_problem(problem)
    if acquisition is not None:  # the DAQ's filter, as [measurements] acquisition declares it
        problem = replace(problem, acquisition=Acquisition.from_value(acquisition))
    if source is None:
        source = data_source(**shorthand)
    elif any(v is not None for v in shorthand.values()):
        raise InputError("identify: give the data once, as source= or as load=/data=/dic= and their options")
    elif not isinstance(source, (SimulatedCase, MeasuredRecord, DICRecord)):
        raise InputError(f"source = {source!r}: expected a SimulatedCase, MeasuredRecord or DICRecord")
    return problem, source


def _estimator(method, model, source, options, settings, max_memory, initial_load, noise_std, lam) -> tuple:
    """The registry's estimator of ``method`` and ``model`` for ``source``, and its checked options."""
    if not isinstance(method, str) or not isinstance(model, str):
        raise InputError(f"method = {method!r}, model = {model!r}: expected names (see wingopt.estimation.registry)")
    check_number("max_memory", max_memory, positive=True, allow_none=True)
    opts = IdentifyOptions.merged(options, initial_load=initial_load, noise_std=noise_std, lam=lam)
    simulated_truth = source.truth if isinstance(source, SimulatedCase) else None
    spec = resolve(method, model, simulated=simulated_truth, frames=isinstance(source, DICRecord))
    check_options(spec, opts)
    check_settings(spec, settings)
    return spec, opts


def calibration_checks(problem) -> list[str]:
    """A warning when the run's prestrain prior comes from a calibration that misfit its record."""
    ident = problem.identification
    if ident.calibration_misfit is None:
        return []
    return [
        f"[calibration] this run's prestrain prior comes from a calibration that did not explain its record "
        f"(chi-square per datum {ident.calibration_misfit:.3g}; {ident.calibration or 'no source named'}): its "
        "band was widened for the misfit, but a model-form error in it moves this run's lift too; recalibrate "
        "with a release or pluck the model follows (docs/tunnel.md)"
    ]


def _membrane_problem(problem):
    if isinstance(problem, (str, Path)):
        problem = load_problem(problem)
    if getattr(problem, "kind", None) != "membrane":
        raise InputError(f"problem: identify needs a membrane problem, got kind {getattr(problem, 'kind', None)!r}")
    if not problem.sensors:
        raise InputError(f"problem {problem.name!r}: no [[sensors]]: identification needs stretch sensors")
    return problem


def _read(problem, source, spec, opts: IdentifyOptions, max_memory) -> SourceRecord:
    """The source's record, after the size check (a simulation's before it runs, data's once read)."""
    if isinstance(source, SimulatedCase):
        truth_mesh = source.truth_nodes or problem.nodes
        samples = source.samples(problem)
        est = resources.check(
            resources.estimate_identify(problem.nodes, samples, truth_nodes=truth_mesh, method=spec.method),
            max_memory,
        )
        stage = "simulating the %s truth of %s on %dx%d, %d samples (the whole run: about %s)"
        progress.info(stage, source.truth, source.load, *truth_mesh, samples, fmt_duration(est.seconds))
        return source.read(problem, opts)
    resources.check(resources.estimate_identify(problem.nodes, 1, method=spec.method), max_memory)
    if isinstance(source, DICRecord):
        record = source.read(problem, opts, full_field=spec.method in FRAME_METHODS)
    else:
        record = source.read(problem, opts)
    size = resources.estimate_identify(problem.nodes, record.measurements.count, method=spec.method)
    resources.check(size, max_memory)
    return record


def _estimate(record: SourceRecord, spec, opts: IdentifyOptions, settings) -> IdentifyRun:
    """Run the estimator ``spec`` on a source's record, with the data and fit checks around it."""
    problem, meas = record.problem, record.measurements
    # DIC: the first frame's shape may be the initial deflection, so the model is the record's problem's
    membrane = estimator_model(problem) if record.frames is None else MembraneModel.from_problem(problem)
    prior = opts.initial_load if opts.initial_load is not None else problem.identification.initial_load
    full_field = record.frames is not None and spec.method in FRAME_METHODS  # the frames are the data
    warnings = sanity.sourced("data check", sanity.record_checks(membrane, meas, prior, frames=full_field))
    warnings += calibration_checks(problem)
    t0 = time.perf_counter()
    if full_field:
        progress.info("%s on %d frames x %d points", spec.label, *np.shape(record.frames.w))
    else:
        progress.info("%s on %d samples of %d sensors", spec.label, meas.count, len(meas.sensor_names))
    result = build(spec, membrane, opts, truth=record.case, settings=settings, frames=record.frames).run(meas)
    wall = time.perf_counter() - t0
    warnings += sanity.sourced("fit check", sanity.fit_checks(membrane, meas, result, sanity.used_sigma(meas, result)))
    own = sanity.sourced(f"{spec.model} {spec.method}", list(result.diagnostics.warnings))  # its adequacy
    warnings += [w for w in own if w not in warnings]
    for w in warnings:  # each once, here: the engines return theirs, they do not print them
        log.warning("%s", w)
    protocol = dict(record.protocol)
    protocol["estimator"] = {"method": spec.method, "membrane": spec.model, "options": opts.as_dict()}
    return IdentifyRun(
        problem, membrane, spec.method, meas, result, wall, record.case, record.report, protocol, warnings
    )


def write_identify_outputs(run: IdentifyRun, out_dir: str | Path, plots: bool = True) -> Path:
    """Write ``summary.json`` (with the provenance), ``load.csv`` (the field behind the reported lift and
    its band on a uniform grid, edges included), ``lift.csv``, ``field.nc`` (the field over time; the
    ``data`` extra), the figures and ``report.html`` (docs/results.md).

    Parameters
    ----------
    run : IdentifyRun
        From :func:`identify`.
    out_dir : path
        Output directory; replaced atomically (a failed write leaves the earlier one intact).
    plots : bool
        Write the figures (the field and its band, the lift history with the reported lift, the misfit,
        error histories with a truth); ``report.html`` is written either way.

    Returns
    -------
    Path
        ``out_dir``.
    """
    from wingopt.results.writer import to_jsonable

    if not isinstance(run, IdentifyRun):
        raise InputError(f"run = {type(run).__name__}: expected the IdentifyRun that wingopt.identify returned")
    if not isinstance(plots, bool):
        raise InputError(f"plots = {plots!r}: expected True or False")
    problem, result = run.problem, run.result
    X, Y = grid(problem, LOAD_GRID)
    mf = run.mean_field()
    P, S = mf(X, Y), mf.std(X, Y)
    read = [("--data", (run.data_report or {}).get("file")), ("--dic", (run.data_report or {}).get("frames_source"))]
    inputs = [("--data", (run.data_report or {}).get("file")), ("problem", getattr(problem, "source", None))]
    run.outputs = {
        "provenance": provenance([*read, ("problem", getattr(problem, "source", None))]),
        "problem_file": problem_record(problem),
    }
    progress.info("writing the outputs%s (the estimate took %s)", " and figures" * plots, fmt_duration(run.wall_s))
    with ResultDirectory(out_dir, inputs=inputs) as tmp:
        summary = to_jsonable(run.summary())
        write_json(tmp / "summary.json", summary)
        write_csv(tmp / "load.csv", LOAD_COLUMNS, zip(X.ravel(), Y.ravel(), P.ravel(), S.ravel()))
        n, (lift, band) = len(result.t), result.reported_lift
        std = result.lift_std if result.lift_std is not None else np.full(n, np.nan)
        rows = zip(result.t, result.lift, std, np.full(n, lift), np.full(n, np.nan if band is None else band))
        write_csv(tmp / "lift.csv", LIFT_COLUMNS, rows)
        write_identify_files(tmp, run, summary, X, Y, P, S, plots=plots)
    return Path(out_dir)
