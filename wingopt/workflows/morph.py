"""Morph the plate into a Table 5.1 shape with a chosen controller: the ``wingopt morph`` engine.

``morph(problem, shape, method)`` builds the model, the target and the controller of ``method``
(:data:`METHODS`), runs :func:`simulate_closed_loop` on the full-order plant and returns a
:class:`MorphResult`; :func:`write_morph_outputs` writes the spec §7 outputs (``summary.json``,
``voltages.csv``, figures) atomically. :func:`morph_to_directory` is the ``wingopt morph`` use
case: a problem file, the run (and the saturated LQR beside a QP run), the outputs.

Voltage limits: ``method="lqr"`` saturates at ``vmin``/``vmax`` when given (each side on its own)
and is unlimited otherwise (the seed's controller); every other method defaults to the problem's
``[actuators]`` limits (-500/+1500 V for the plate). The factory receives finite limits as arrays
(one per patch) or ``-inf``/``+inf`` when unlimited, and the harness clips to the same limits.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wingopt import resources
from wingopt.control.closed_loop import DEFAULT_PERIOD, ClosedLoopResult, simulate_closed_loop
from wingopt.control.mpc import make_qp_controller
from wingopt.control.tracking import make_lqr_controller
from wingopt.errors import InputError, OutputError
from wingopt.plate import PlateModel
from wingopt.plate.shapes import SHAPES
from wingopt.plots.morph import figure_names, plot_morph
from wingopt.problem import load_problem
from wingopt.results import ResultDirectory, check_writable, write_csv, write_json
from wingopt.status import RunStatus, from_solver_statuses, worst
from wingopt.validate import check_nodes, check_number, check_seed
from wingopt.values import VoltageLimits
from wingopt.workflows.morph_plant import build_actuator, build_plant_model, plant_extras

__all__ = [
    "METHODS",
    "MorphResult",
    "morph",
    "morph_to_directory",
    "load_factory",
    "write_morph_outputs",
    "resolve_limits",
]

log = logging.getLogger(__name__)

METHODS = {"lqr": make_lqr_controller, "qp": make_qp_controller}
"""Controller factories by method name.

Every factory has the signature ``make_<method>_controller(model, target, *, vmin, vmax, period,
**options) -> Controller`` (see :class:`~wingopt.control.closed_loop.Controller`).
"""


def load_factory(method: str):
    """The factory of ``method``; an :class:`InputError` lists the methods if it is unknown."""
    if method not in METHODS:
        raise InputError(f"method = {method!r}: expected one of {', '.join(METHODS)}")
    return METHODS[method]


def resolve_limits(problem, method: str, vmin=None, vmax=None, patches: int | None = None) -> VoltageLimits:
    """Voltage limits of a run, validated once (:class:`~wingopt.values.VoltageLimits`).

    ``lqr``: as given (``None``: unlimited, the seed's controller). Other methods: the problem's
    ``[actuators]`` limits where not given.
    """
    if method != "lqr":
        act = getattr(problem, "actuators", None)
        if vmin is None and act is not None:
            vmin = act.vmin
        if vmax is None and act is not None:
            vmax = act.vmax
    if patches is None:
        patches = len(getattr(problem, "patches", ()) or ())
    return VoltageLimits.from_user(vmin, vmax, patches)


@dataclass(eq=False)
class MorphResult:
    """One morphing run.

    Attributes
    ----------
    method, shape : str
    model : PlateModel
    target : ndarray (n,)
        Target deflection coefficients ``z_d`` (L2 projection of the Table 5.1 shape).
    closed_loop : ClosedLoopResult
    wall_s : float
        Wall time of the whole run (model, controller design, simulation).
    vmin, vmax : float or None
        Limits the run used (``None``: unlimited).
    extras : dict
        Method-specific numbers (e.g. ``static_optimum_error`` of the QP), merged into :meth:`summary`.
    """

    method: str
    shape: str
    model: object
    target: np.ndarray
    closed_loop: ClosedLoopResult
    wall_s: float
    vmin: float | None = None
    vmax: float | None = None
    t_end: float = 2.0
    options: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    @property
    def status(self) -> RunStatus:
        """One word for the run (:class:`~wingopt.status.RunStatus`, ``summary()["status"]``).

        ``failed``: a non-finite shape error or voltage; ``not_converged``: a QP solve came back
        inaccurate or at its iteration cap, or the shape error still moves by more than its 2 %
        settling band in the last fifth of the run (``t_end`` too short for this controller);
        else ``converged``.
        """
        return worst(self.closed_loop.status, from_solver_statuses(self.extras.get("qp_statuses")))

    def __repr__(self) -> str:
        # The dataclass repr prints the plate model and every history (100 000+ characters).
        nx, ny = self.model.problem.nodes
        lo, hi = self.closed_loop.peak_voltage
        return (
            f"MorphResult(shape={self.shape!r}, method={self.method!r}, mesh {nx}x{ny}, "
            f"shape_error={self.closed_loop.final_shape_error:.4g}, status='{self.status}', "
            f"voltage {lo:.4g}..{hi:.4g} V, t_end={self.t_end:g} s, wall={self.wall_s:.3g} s)"
        )

    def summary(self) -> dict:
        """The spec §7 summary (plus run settings and settling information)."""
        cl = self.closed_loop
        prob = self.model.problem
        lo, hi = cl.peak_voltage
        out = {
            "problem": getattr(prob, "name", "plate"),
            "method": self.method,
            "status": str(self.status),
            "shape": self.shape,
            "mesh": list(prob.nodes),
            "dofs": int(self.model.n),
            "shape_error": cl.final_shape_error,
            "tip_corners_m": [float(v) for v in cl.final_tip],
            "target_tip_corners_m": [float(v) for v in self.model.tip_corners(self.target)],
            "voltages_final_V": [float(v) for v in cl.final_voltages],
            "patches": list(self.model.patch_names),
            "peak_voltage_V": [lo, hi],
            "vmin_V": self.vmin,
            "vmax_V": self.vmax,
            "t_end_s": self.t_end,
            "period_s": cl.period,
            "plant_dt_s": cl.plant_dt,
            "plant": cl.plant,
            "sensor_noise": cl.sensor_noise,
            "settling_time_s": cl.settling_time(),
            "settling_band": 0.02,
            "tip_overshoot": [float(v) for v in cl.tip_overshoot()],
            "shape_error_at": {
                f"{t:g}": float(np.interp(t, cl.t, cl.shape_error)) for t in (0.5, 1.0, 2.0) if t <= cl.t[-1]
            },
            "controller_step_s_median": float(np.median(cl.step_seconds)) if cl.step_seconds.size else 0.0,
            "wall_s": self.wall_s,
            "options": dict(self.options),
            "warnings": list(self.warnings),
        }
        out.update(self.extras)
        return out


def morph(
    problem,
    shape: str,
    method: str = "qp",
    *,
    vmin: float | None = None,
    vmax: float | None = None,
    t_end: float = 2.0,
    nodes: tuple[int, int] | None = None,
    sensor_noise: float = 0.0,
    seed: int = 0,
    period: float = DEFAULT_PERIOD,
    plant: str = "auto",
    model=None,
    max_memory: float | None = None,
    plant_problem=None,
    plant_scale=None,
    plant_model=None,
    actuator=None,
    sensor_bias=None,
    **options,
) -> MorphResult:
    """Morph ``problem``'s plate into ``shape`` with ``method``, from rest, for ``t_end`` s.

    Parameters
    ----------
    problem : PlateProblem
    shape : {"twist", "camber", "bending"}
    method : {"qp", "lqr"}
    vmin, vmax : float, optional
        Voltage limits (V); see :func:`resolve_limits` for the defaults per method.
    t_end : float
        Duration (s).
    nodes : (int, int), optional
        Mesh (default: the problem's).
    sensor_noise, seed : float, int
        Standard deviation of the patch-sensor noise (sensor units, m), and the noise's seed.
    period : float
        Control period (s), default 10 ms.
    plant : {"auto", "dense", "modal"}
        Full-order plant (see :func:`~wingopt.control.closed_loop.make_plant`).
    model : PlateModel, optional
        A model already built for ``problem`` (and ``nodes``), to share between runs.
    max_memory : float, optional
        Refuse (``InputError``, before any work) a run estimated to need more bytes than this
        (default: the memory available); see :mod:`wingopt.resources`.
    plant_problem, plant_scale, plant_model, actuator, sensor_bias : optional
        A plant that is not the model (:mod:`wingopt.workflows.morph_plant`): its problem (or
        file), parameter factors (``"moduli=1.1,d33=0.8"``), or its model already built; patch
        hysteresis/creep (:mod:`wingopt.control.hysteresis`); a constant sensor offset (m).
    **options
        Passed to the method's factory (e.g. ``r`` for lqr; ``horizon, solver, mode`` for qp).

    Returns
    -------
    MorphResult
        The closed-loop run, its target, limits and timing; :meth:`MorphResult.summary` is the spec §7 summary.
    """
    t0 = time.perf_counter()
    factory = _checked_request(problem, shape, method, t_end, period, sensor_noise, vmin, vmax, seed)
    nodes = None if nodes is None else check_nodes(nodes)
    mesh = nodes or (model.problem.nodes if model is not None else problem.nodes)
    resources.check(resources.estimate_morph(mesh, t_end, period, horizon=_horizon(options)), max_memory)
    model = PlateModel.from_problem(problem, nodes) if model is None else model
    limits = resolve_limits(problem, method, vmin, vmax, model.n_inputs)
    target = model.target(shape)
    if plant_model is None:
        plant_model = build_plant_model(problem, plant_problem, plant_scale, nodes)
    actuator = build_actuator(actuator, (plant_model or model).problem, model.n_inputs)
    controller = factory(model, target, vmin=limits.lower, vmax=limits.upper, period=period, **options)
    plant_kw = {"plant": plant, "plant_model": plant_model, "actuator": actuator, "sensor_bias": sensor_bias}
    cl = simulate_closed_loop(
        model, controller, target, t_end=t_end, sensor_noise=sensor_noise, seed=seed, limits=limits, **plant_kw
    )
    extras = dict(getattr(controller, "extras", {}) or {})
    extras.update(plant_extras(model, plant_model, target, limits, cl, actuator, sensor_bias))
    wall = time.perf_counter() - t0
    log.info("morph %s/%s: shape error %.4f in %.2f s", shape, method, cl.final_shape_error, wall)
    lo, hi = limits.scalar("lower"), limits.scalar("upper")
    return MorphResult(method, shape, model, target, cl, wall, lo, hi, float(t_end), dict(options), extras)


def _checked_request(problem, shape, method, t_end, period, sensor_noise, vmin, vmax, seed):
    """The method's controller factory, once the plate, the shape, the numbers and the method are checked."""
    if getattr(problem, "kind", None) != "plate":
        raise InputError(f"problem: morph needs a plate problem, got kind {getattr(problem, 'kind', None)!r}")
    if not isinstance(shape, str) or shape not in SHAPES:
        raise InputError(f"shape = {shape!r}: expected one of {', '.join(SHAPES)}")
    check_morph_numbers(t_end=t_end, period=period, sensor_noise=sensor_noise, vmin=vmin, vmax=vmax)
    check_seed(seed)
    if not problem.patches:
        raise InputError(f"problem {problem.name!r}: no [[patches]]: morphing needs piezo patch pairs as actuators")
    if not isinstance(method, str):
        raise InputError(f"method = {method!r}: expected one of {', '.join(METHODS)}")
    return load_factory(method)


def check_morph_numbers(*, t_end, period, sensor_noise, vmin=None, vmax=None) -> None:
    """The numbers of a morph run: finite, positive where they must be, the period within ``t_end``."""
    check_number("t_end", t_end, positive=True)
    check_number("period", period, positive=True)
    check_number("sensor_noise", sensor_noise, lo=0.0, hi=1.0)  # m: a metre of noise is no sensor
    check_number("vmin", vmin, allow_none=True, lo=-1e6, hi=1e6)
    check_number("vmax", vmax, allow_none=True, lo=-1e6, hi=1e6)
    if period > t_end:
        raise InputError(f"period = {period!r}: expected a control period no longer than t_end = {t_end!r}")


def _horizon(options: dict) -> int | None:
    h = options.get("horizon")
    if h is None:
        return None
    if isinstance(h, bool) or not isinstance(h, (int, np.integer)) or h < 1:
        raise InputError(f"horizon = {h!r}: expected a positive whole number of steps")
    return int(h)


def write_morph_outputs(
    result: MorphResult,
    out_dir: Path,
    compare_with: MorphResult | None = None,
    *,
    plots: bool = True,
    figures: tuple[str, ...] | None = None,
    extra_summary: dict | None = None,
) -> dict:
    """Write ``summary.json``, ``voltages.csv``, ``history.csv`` and figures into ``out_dir`` (atomically).

    Parameters
    ----------
    result : MorphResult
        The run to write.
    out_dir : path
        Output directory; replaced atomically (a failed write leaves the earlier one intact).
    compare_with : MorphResult, optional
        A second run (e.g. LQR saturated at the same limits): its summary goes under
        ``"compare_with"`` and the figures compare both.
    plots : bool
        Write the figures.
    figures : tuple of str, optional
        Which figures (names from :data:`wingopt.plots.morph.FIGURES`); default all.
    extra_summary : dict, optional
        Merged into the summary before it is written.

    Returns
    -------
    dict
        The summary written to ``summary.json``.
    """
    if not isinstance(result, MorphResult):
        raise InputError(f"result = {type(result).__name__}: expected the MorphResult of wingopt.morph")
    if compare_with is not None and not isinstance(compare_with, MorphResult):
        raise InputError(f"compare_with = {type(compare_with).__name__}: expected a MorphResult or None")
    figures = figure_names(figures)  # checked before anything is written
    summary = result.summary()
    if compare_with is not None:
        summary["compare_with"] = compare_with.summary()
    if extra_summary:
        summary.update(extra_summary)
    cl = result.closed_loop
    try:
        with ResultDirectory(out_dir, inputs=[("problem", getattr(result.model.problem, "source", None))]) as tmp:
            write_json(tmp / "summary.json", summary)
            header = ["t"] + list(result.model.patch_names)
            write_csv(tmp / "voltages.csv", header, np.column_stack([cl.t_u, cl.u]))
            write_csv(
                tmp / "history.csv",
                ["t", "tip_x0_m", "tip_xW_m", "shape_error"],
                np.column_stack([cl.t, cl.tip, cl.shape_error]),
            )
            if plots:
                plot_morph(tmp, result, compare_with, figures)
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"out = {str(out_dir)!r}: cannot write ({exc.strerror or exc})") from None
    return summary


def morph_to_directory(
    problem: str | Path,
    shape: str,
    method: str,
    out: str | Path,
    *,
    nodes: tuple[int, int] | None = None,
    compare: bool = True,
    plots: bool = True,
    max_memory: float | None = None,
    **kwargs,
) -> dict:
    """The ``wingopt morph`` use case: read ``problem``, morph, write the outputs into ``out``.

    A QP run (any method but ``lqr``) is compared with the LQR saturated at the same limits unless
    ``compare=False``. ``out`` is checked before any work, the run's memory estimated against
    ``max_memory`` before the model is built. ``kwargs`` go to :func:`morph` (limits, ``t_end``,
    noise, period, plant, and the method's options). Returns the summary written.
    """
    check_writable(out, inputs=[("problem", str(problem))])
    prob = load_problem(problem)
    if prob.kind != "plate":
        raise InputError(f"problem = {str(problem)!r}: morph needs a plate problem, got kind {prob.kind!r}")
    load_factory(method)  # an unknown method fails before anything is built
    t_end, period = kwargs.get("t_end", 2.0), kwargs.get("period", DEFAULT_PERIOD)
    noise, vmin, vmax = kwargs.get("sensor_noise", 0.0), kwargs.get("vmin"), kwargs.get("vmax")
    check_morph_numbers(t_end=t_end, period=period, sensor_noise=noise, vmin=vmin, vmax=vmax)
    horizon = _horizon(kwargs)
    resources.check(resources.estimate_morph(nodes or prob.nodes, t_end, period, horizon=horizon), max_memory)
    model = PlateModel.from_problem(prob, nodes)
    plant_model = build_plant_model(prob, kwargs.pop("plant_problem", None), kwargs.pop("plant_scale", None), nodes)
    kwargs["plant_model"] = plant_model
    result = morph(prob, shape, method, model=model, max_memory=max_memory, **kwargs)
    baseline = None
    if method != "lqr" and compare:
        # The baseline, saturated at the QP's limits: the same limits, read off the QP's run.
        shared = ("t_end", "sensor_noise", "seed", "period", "plant", "plant_model", "actuator", "sensor_bias")
        common = {k: v for k, v in kwargs.items() if k in shared}
        baseline = morph(
            prob, shape, "lqr", vmin=result.vmin, vmax=result.vmax, model=model, max_memory=max_memory, **common
        )
    return write_morph_outputs(result, out, baseline, plots=plots)
