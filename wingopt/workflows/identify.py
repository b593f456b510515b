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

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wingopt import resources
from wingopt.errors import InputError
from wingopt.estimation import sanity
from wingopt.estimation.options import IdentifyOptions
from wingopt.estimation.registry import check_options, resolve
from wingopt.estimation.result import IdentificationResult
from wingopt.estimation.runners import build
from wingopt.measurements import ChannelMap, Measurements, read_measurements
from wingopt.measurements.dic import DICFrames
from wingopt.membrane import MembraneModel, TruthRecord
from wingopt.membrane.loads import LOAD_CASES
from wingopt.problem import load_problem
from wingopt.progress import fmt_duration
from wingopt.results import ResultDirectory, write_csv, write_json
from wingopt.status import RunStatus
from wingopt.validate import check_nodes, check_number, check_seed
from wingopt.values import LambdaChoice, NoiseLevel
from wingopt.workflows.dic import dic_record
from wingopt.workflows.protocols import TRUTH_NODES, check_truth_settings, estimator_model, simulate_case
from wingopt.workflows.studies import evaluate, load_field, protocol_sign

log = logging.getLogger(__name__)
progress = logging.getLogger("wingopt.progress.identify")  # stage lines (wingopt.progress), shown by the CLI

__all__ = ["IdentifyRun", "identify", "write_identify_outputs", "LOAD_GRID"]

LOAD_GRID = (57, 29)
"""Points (x, y) of the uniform grid of ``load.csv``, edges included."""


@dataclass(eq=False)
class IdentifyRun:
    """One identification run: its inputs, the estimate and, for simulated records, the truth."""

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

    def load_field(self, k: int = -1):
        """Callable ``(x, y) -> P`` of the estimated pressure at sample ``k`` (Pa)."""
        return load_field(self.result, self.model, k)

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
        out.update(self.errors())
        out["estimator"] = {k: v for k, v in res.info.items() if k != "iterations_per_window"}
        # issue 11: adequacy flag, warnings, identified parameters and left-out data at top level
        out["model"] = res.info.get("model", "linear")
        out["model_adequate"] = res.info.get("model_adequate")
        out["dropped"] = res.info.get("dropped", [])
        if "adequacy" in res.info:
            out["chi2_per_datum"] = res.info["adequacy"]["chi2_per_datum"]
        if "parameters" in res.info:
            out["parameters"] = res.info["parameters"]
            out["parameters_std"] = res.info["parameters_std"]
            if self.case is not None and getattr(self.case, "parameters", None):
                out["true_parameters"] = self.case.parameters
        return out


def _with_noise_std(meas: Measurements, std: float | None) -> Measurements:
    if std is None:
        return dataclasses.replace(meas, noise_std=None)
    return dataclasses.replace(meas, noise_std=np.full(len(meas.sensor_names), float(std)))


def identify(
    problem,
    *,
    load: str | None = None,
    noise_percent: float = 1.0,
    seed: int = 0,
    data: str | Path | Measurements | np.ndarray | None = None,
    dic: str | Path | DICFrames | None = None,
    method: str = "auto",
    model: str = "auto",
    options: IdentifyOptions | None = None,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    t_end: float = 1.0,
    nodes: tuple[int, int] | None = None,
    truth: str = "linear",
    truth_prestrain: tuple[float, float] | None = None,
    truth_damping: float = 1.0,
    gust=None,
    max_memory: float | None = None,
    settings=None,
    initial_load: float | None = None,
    noise_std: float | None = None,
    lam: LambdaChoice | None = None,
    noise: float | None = None,
    channels: ChannelMap | None = None,
) -> IdentifyRun:
    """Estimate the load of a membrane problem from a simulated (``load``) or measured (``data``) record.

    Parameters
    ----------
    problem : MembraneProblem or str
        From :func:`wingopt.problem.load_problem`, or a built-in name / path to load.
    load : {"L1", "L2", "L3", "consistency", "LE"}, optional
        Simulate the protocol with this load (truth on ``truth_nodes``; ``None`` there means the
        seed's same-mesh protocol).
    noise_percent : float
        Simulated noise in PERCENT of each sensor's peak output (1 = 1 %), as ``--noise``.
    seed : int
        Noise seed.
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
    truth : {"linear", "berger", "fvk"}
        Simulated truth physics (full order); ``truth_prestrain`` ``(ex, ey)``, ``truth_damping``
        (factor) and ``gust`` (:class:`~wingopt.membrane.Gust`) put it off the problem file.
    max_memory : float, optional
        Refuse (``InputError``, before any work) a run estimated to need more bytes than this
        (default: the memory the machine has available); see :mod:`wingopt.resources`.
    settings : MHESettings or RealisticSettings, optional
        Advanced: the estimator's settings to start from (the options are applied on top).
    initial_load, noise_std, lam :
        Shorthands for the same fields of ``options``: the sign prior (Pa), the sensor noise std
        (sensor units; default: estimated from the data) and the lambda choice.
    noise : float, optional
        No longer accepted (it was a fraction, the command line's a percentage): an ``InputError`` names
        ``noise_percent`` (simulated noise) and ``noise_std`` (the sensors' noise).

    Returns
    -------
    IdentifyRun
        The estimate, the measurements, the truth (simulated records) and the summary.
    """
    if noise is not None:
        raise InputError(
            f"noise = {noise!r}: ambiguous unit; give noise_percent (simulated noise, 1 = 1 % of each sensor's "
            "peak, as wingopt identify --noise 1) or noise_std (the sensors' noise std, sensor units)"
        )
    if isinstance(problem, (str, Path)):
        problem = load_problem(problem)
    if getattr(problem, "kind", None) != "membrane":
        raise InputError(f"problem: identify needs a membrane problem, got kind {getattr(problem, 'kind', None)!r}")
    if not problem.sensors:
        raise InputError(f"problem {problem.name!r}: no [[sensors]]: identification needs stretch sensors")
    check_seed(seed)
    if sum(v is not None for v in (load, data, dic)) != 1:
        raise InputError(
            "identify: give exactly one of load= (simulated protocol), data= (measured CSV) or dic= (frames)"
        )
    if load is not None and (not isinstance(load, str) or load not in LOAD_CASES):
        raise InputError(f"load = {load!r}: expected one of {', '.join(LOAD_CASES)}")
    if not isinstance(method, str) or not isinstance(model, str):
        raise InputError(f"method = {method!r}, model = {model!r}: expected names (see wingopt.estimation.registry)")
    check_truth_settings(truth, truth_prestrain, truth_damping)
    check_number("t_end", t_end, positive=True)
    check_number("noise_percent", noise_percent, lo=0.0, hi=100.0)
    check_number("max_memory", max_memory, positive=True, allow_none=True)
    if truth_nodes is not None:
        truth_nodes = check_nodes(truth_nodes, "truth_nodes")
    if gust is not None and not callable(getattr(gust, "factor", None)):
        raise InputError(f"gust = {gust!r}: expected a wingopt.membrane.Gust or None")
    if settings is not None and type(settings).__name__ not in (
        "MHESettings",
        "RealisticSettings",
        "FullFieldSettings",
    ):
        raise InputError(
            f"settings = {settings!r}: expected an MHESettings, RealisticSettings or FullFieldSettings (or None)"
        )
    opts = IdentifyOptions.merged(options, initial_load=initial_load, noise_std=noise_std, lam=lam)
    spec = resolve(method, model, simulated=truth if load is not None else None, frames=dic is not None)
    check_options(spec, opts)
    if settings is not None and spec.method not in ("mhe", "batch", "fullfield"):
        raise InputError(f"settings: the {spec.label} takes no settings object")
    if nodes is not None:
        problem = problem.with_mesh(nodes)
    samples, truth_mesh = 1, None
    if load is not None:
        fraction = NoiseLevel.from_percent(noise_percent).fraction
        sanity.check_duration(t_end, problem.identification.dt)
        samples, truth_mesh = int(round(t_end / problem.identification.dt)) + 1, truth_nodes or problem.nodes
    est = resources.check(
        resources.estimate_identify(problem.nodes, samples, truth_nodes=truth_mesh, method=spec.method), max_memory
    )
    membrane = estimator_model(problem)
    case, report, protocol, frames = None, None, {}, None
    if load is not None:
        progress.info("simulating the %s truth of %s on %dx%d, %d samples (the whole run: about %s)", truth,
                      getattr(load, "name", load), *truth_mesh, samples, fmt_duration(est.seconds))  # fmt: skip
        case = simulate_case(
            problem, load, fraction, seed, truth_nodes, t_end,
            truth=truth, prestrain=truth_prestrain, damping=truth_damping, gust=gust, tell_noise=False,
        )  # fmt: skip
        meas = _with_noise_std(case.measurements, opts.noise_std)
        if opts.initial_load is None:
            opts = opts.replace(initial_load=protocol_sign(load) * abs(problem.identification.initial_load))
        off_file = truth != "linear" or truth_prestrain is not None or truth_damping != 1.0 or gust is not None
        protocol = {
            "load_case": load,
            "noise_percent": 100 * fraction,
            "seed": seed,
            "truth_mesh": list(truth_nodes or problem.nodes),
            "protocol": "same-mesh (seed)" if truth_nodes is None else "fine-mesh truth",
            "truth": truth
            if not off_file
            else f"{truth} (prestrain {truth_prestrain}, damping x{truth_damping:g}"
            + (", gust)" if gust is not None else ")"),
        }
    elif dic is not None:
        problem, frames, meas, report = dic_record(
            problem, dic, "fullfield" if spec.method == "fullfield" else "sensors"
        )
        membrane = MembraneModel.from_problem(problem)  # the first frame's shape may be its initial deflection
        meas = meas if opts.noise_std is None else _with_noise_std(meas, opts.noise_std)
    elif isinstance(data, (str, Path)):  # read_measurements refuses a directory (one line naming data)
        meas, report = read_measurements(data, problem.sensor_names, channels or problem.measurements)
        meas, report = _with_noise_std(meas, opts.noise_std), report.as_dict()
    else:
        meas = _with_noise_std(sanity.as_measurements(data, problem.sensor_names), opts.noise_std)
    if load is None:
        resources.check(resources.estimate_identify(problem.nodes, meas.count, method=spec.method), max_memory)
    prior = opts.initial_load if opts.initial_load is not None else problem.identification.initial_load
    warnings = sanity.sourced("data check", sanity.record_checks(membrane, meas, prior))
    t0 = time.perf_counter()
    progress.info("%s on %d samples of %d sensors", spec.label, meas.count, len(meas.sensor_names))
    result = build(spec, membrane, opts, truth=case, settings=settings, frames=frames).run(meas)
    wall = time.perf_counter() - t0
    warnings += sanity.sourced("fit check", sanity.fit_checks(membrane, meas, result, sanity.used_sigma(meas, result)))
    own = sanity.sourced(f"{spec.model} {spec.method}", result.info.get("warnings", []))  # its adequacy
    warnings += [w for w in own if w not in warnings]
    for w in warnings:  # each once, here: the engines return theirs, they do not print them
        log.warning("%s", w)
    protocol["estimator"] = {"method": spec.method, "membrane": spec.model, "options": opts.as_dict()}
    return IdentifyRun(problem, membrane, spec.method, meas, result, wall, case, report, protocol, warnings)


def write_identify_outputs(run: IdentifyRun, out_dir: str | Path, plots: bool = True) -> Path:
    """Write ``summary.json``, ``load.csv`` (uniform grid, edges included), ``lift.csv`` and figures.

    Parameters
    ----------
    run : IdentifyRun
        From :func:`identify`.
    out_dir : path
        Output directory; replaced atomically (a failed write leaves the earlier one intact).
    plots : bool
        Write the figures (load field, lift history with its band, error histories with a truth).

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
    xs = np.linspace(0, problem.width, LOAD_GRID[0])
    ys = np.linspace(0, problem.height, LOAD_GRID[1])
    X, Y = np.meshgrid(xs, ys)
    Pg = run.load_field()(X, Y)
    inputs = [("--data", (run.data_report or {}).get("file")), ("problem", getattr(problem, "source", None))]
    progress.info("writing the outputs%s (the estimate took %s)", " and figures" * plots, fmt_duration(run.wall_s))
    with ResultDirectory(out_dir, inputs=inputs) as tmp:
        write_json(tmp / "summary.json", to_jsonable(run.summary()))
        write_csv(tmp / "load.csv", ["x", "y", "pressure_Pa"], zip(X.ravel(), Y.ravel(), Pg.ravel()))
        if result.lift_std is not None:
            write_csv(tmp / "lift.csv", ["t", "lift_N", "lift_std_N"], zip(result.t, result.lift, result.lift_std))
        else:
            write_csv(tmp / "lift.csv", ["t", "lift_N"], zip(result.t, result.lift))
        if plots:
            from wingopt.plots.identify import plot_identification

            plot_identification(tmp, run, X, Y, Pg)
    return Path(out_dir)
