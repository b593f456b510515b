"""Closed-loop simulation of a sampled controller on the full-order plate model.

The harness every morphing controller plugs into (the seed's LQR/LQG and the QP/MPC of issue 4).
A controller sees only the nine patch-sensor samples ``y_k = C z(t_k) (+ noise)`` and answers with
nine voltages ``u_k``, held constant for one control period (zero-order hold)::

    t_k = k * period:   y_k = C z(t_k) + v_k,   u_k = clip(controller.step(y_k), vmin, vmax)
    plant:              M z'' + Kd z' + K z = b u_k    on [t_k, t_k + period)

The plant is the full finite-element model advanced by its *exact* zero-order hold, so a plant
step equal to the control period (the default) is exact at every control instant; a finer
``plant_dt`` only adds stored instants between them (for plots of the intersample motion).

The plant models (dense or modal exact ZOH) are in :mod:`wingopt.control.plant`. The plant need
not be the controller's model: ``plant_model`` (a plate of the same mesh and patches with other
parameters, issue 34) is what is simulated and what the sensors read; ``actuator`` (e.g. the
hysteresis and creep of :mod:`wingopt.control.hysteresis`) turns the applied voltage into the one
the patches act with; ``sensor_bias`` adds a constant offset to every sample. The shape error is
measured in the plant's mass norm (the plant's best, its static optimum, uses the same norm).

Why a 10 ms control period: 100 Hz is the real-time target of issue 4 (one QP per period on
13x61), it samples the first two bending and the first torsion modes (10, 38, 51 Hz) well above
their own periods' quarter, and the LQR/LQG of :mod:`wingopt.control.tracking` is designed in
discrete time for that period, so nothing is lost by sampling.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from wingopt.control.plant import DEFAULT_PLANT_BAND_HZ, make_plant
from wingopt.errors import InputError
from wingopt.status import RunStatus
from wingopt.values import VoltageLimits

__all__ = [
    "Controller",
    "ClosedLoopResult",
    "simulate_closed_loop",
    "DEFAULT_PERIOD",
    "check_limits",
]

log = logging.getLogger(__name__)

DEFAULT_PERIOD = 0.01
"""Control period, s (100 Hz, the real-time target of issue 4)."""


@runtime_checkable
class Controller(Protocol):
    """A sampled controller: patch-sensor samples in, patch voltages out.

    Attributes
    ----------
    name : str
        Short name (``"lqr"``, ``"qp"``) used in summaries and plots.
    period : float
        Control period (s); the harness requires it to be an integer multiple of the plant step.
    """

    name: str
    period: float

    def reset(self, model, target: np.ndarray) -> None:
        """Start a run on ``model`` towards the target deflection coefficients ``target`` (``z_d``)."""
        ...

    def step(self, y: np.ndarray) -> np.ndarray:
        """Sensor sample ``y_k`` (9,) -> voltages ``u_k`` (9,), held for one period."""
        ...


@dataclass(frozen=True, eq=False)
class ClosedLoopResult:
    """Histories of one closed-loop run.

    Attributes
    ----------
    t : ndarray (N+1,)
        Stored plant instants (s), ``0 .. t_end`` every ``plant_dt``.
    z, zdot : ndarray (N+1, n)
        Deflection coefficients and their rates at ``t``.
    t_u : ndarray (K,)
        Control instants (s); ``u[k]`` is held on ``[t_u[k], t_u[k] + period)``.
    u : ndarray (K, 9)
        Applied (post-clip) voltages, V.
    y : ndarray (K, 9)
        Sensor samples the controller saw (with noise).
    tip : ndarray (N+1, 2)
        Tip corners ``[w(0, 0), w(W, 0)]`` (m) at ``t``.
    shape_error : ndarray (N+1,)
        ``||z - z_d||_M / ||z_d||_M`` at ``t``.
    u_requested : ndarray (K, 9)
        Voltages the controller asked for (before the harness's clip).
    step_seconds : ndarray (K,)
        Wall time of each ``controller.step`` call.
    """

    t: np.ndarray
    z: np.ndarray
    zdot: np.ndarray
    t_u: np.ndarray
    u: np.ndarray
    y: np.ndarray
    tip: np.ndarray
    shape_error: np.ndarray
    u_requested: np.ndarray
    step_seconds: np.ndarray
    controller: str = ""
    period: float = DEFAULT_PERIOD
    plant_dt: float = DEFAULT_PERIOD
    plant: str = ""
    vmin: np.ndarray | None = None
    vmax: np.ndarray | None = None
    sensor_noise: float = 0.0
    info: dict = field(default_factory=dict)

    @property
    def final_shape_error(self) -> float:
        return float(self.shape_error[-1])

    @property
    def final_tip(self) -> np.ndarray:
        return self.tip[-1]

    @property
    def final_voltages(self) -> np.ndarray:
        return self.u[-1]

    @property
    def peak_voltage(self) -> tuple[float, float]:
        """``(min, max)`` of the applied voltages over the run and all patches, V."""
        return float(self.u.min()), float(self.u.max())

    def settling_time(self, band: float = 0.02) -> float:
        """First time after which the shape error stays within ``band`` of its final value (s)."""
        dev = np.abs(self.shape_error - self.shape_error[-1]) > band
        idx = np.flatnonzero(dev)
        return 0.0 if idx.size == 0 else float(self.t[min(idx[-1] + 1, self.t.size - 1)])

    @property
    def status(self) -> RunStatus:
        """One word for the run (:class:`~wingopt.status.RunStatus`): ``failed`` (a non-finite shape
        error or voltage), ``not_converged`` (the shape error still moves by more than its 2 %
        settling band in the last fifth of the run: too short for this controller) or ``converged``."""
        if not (np.all(np.isfinite(self.shape_error)) and np.all(np.isfinite(self.u))):
            return RunStatus.FAILED
        return RunStatus.CONVERGED if self.settling_time() <= 0.8 * self.t[-1] else RunStatus.NOT_CONVERGED

    def __repr__(self) -> str:
        # The dataclass repr prints every history (70 000 characters for 0.5 s of a 7x31 plate).
        lo, hi = self.peak_voltage
        return (
            f"ClosedLoopResult(controller={self.controller!r}, t_end={self.t[-1]:g} s, steps={self.t_u.size}, "
            f"shape_error={self.final_shape_error:.4g}, status='{self.status}', voltage {lo:.4g}..{hi:.4g} V)"
        )

    def tip_overshoot(self) -> np.ndarray:
        """Largest excursion of each tip corner beyond its final value, relative to it (0 = none)."""
        fin = self.tip[-1]
        out = np.zeros(2)
        for j in range(2):
            if abs(fin[j]) > 0:
                out[j] = max(0.0, float(np.max(self.tip[:, j] * np.sign(fin[j]))) / abs(fin[j]) - 1.0)
        return out


# -- the harness ------------------------------------------------------------------------------------


def check_limits(vmin, vmax, m: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Voltage limits as ``(lower, upper)`` arrays, ``None`` for an unlimited side (:class:`VoltageLimits`)."""
    limits = VoltageLimits.from_user(vmin, vmax, m)
    return limits.side("lower"), limits.side("upper")


def _steps(period: float, dt: float, what: str) -> int:
    ratio = period / dt
    k = int(round(ratio))
    if k < 1 or abs(ratio - k) > 1e-9 * max(ratio, 1.0):
        raise InputError(f"{what}: control period {period!r} s is not an integer multiple of the plant step {dt!r} s")
    return k


def simulate_closed_loop(
    model,
    controller: Controller,
    target: np.ndarray,
    t_end: float = 2.0,
    plant_dt: float | None = None,
    sensor_noise: float = 0.0,
    seed: int = 0,
    vmin=None,
    vmax=None,
    *,
    limits: VoltageLimits | None = None,
    plant: str = "auto",
    plant_band_hz: float = DEFAULT_PLANT_BAND_HZ,
    z0: np.ndarray | None = None,
    zdot0: np.ndarray | None = None,
    plant_model=None,
    actuator=None,
    sensor_bias=None,
) -> ClosedLoopResult:
    """Run ``controller`` on the full-order plant from rest (or ``z0, zdot0``) for ``t_end`` s.

    Parameters
    ----------
    model : PlateModel
    controller : Controller
        Reset here with ``(model, target)``; its ``period`` sets the control instants.
    target : ndarray (n,)
        Target deflection coefficients ``z_d`` (velocity target zero).
    t_end : float
        Duration (s); the last control instant is the last multiple of the period below ``t_end``.
    plant_dt : float, optional
        Plant step (s); default the control period (exact at the control instants).
    sensor_noise : float
        Standard deviation of white Gaussian noise added to each sensor sample, in the sensors'
        units (m, see :attr:`PlateModel.sensing`).
    seed : int
        Seed of the noise generator.
    vmin, vmax : float or array (9,), optional
        Saturation applied by the harness to the controller's output (``None``: unlimited).
    limits : VoltageLimits, optional
        The same, already validated (instead of ``vmin``/``vmax``).
    plant : {"auto", "dense", "modal"}
        Plant model (see :func:`make_plant`).
    plant_model : PlateModel, optional
        The simulated plate when it is not ``model`` (same mesh and patches, other parameters).
    actuator : optional
        Patch behaviour between the applied voltage and the acting one: an object with
        ``reset()`` and ``apply(u, dt) -> u_acting`` (:mod:`wingopt.control.hysteresis`).
    sensor_bias : float or array (9,), optional
        Constant offset added to every sensor sample (sensor units, m).

    Returns
    -------
    ClosedLoopResult
    """
    period, dt, sub = _timing(controller, t_end, sensor_noise, plant_dt)
    target, limits, truth, bias = _checked_setup(model, target, limits, vmin, vmax, plant_model, sensor_bias)
    m = model.n_inputs
    n_ctrl = int(np.floor(t_end / period + 1e-9))
    plant_model = make_plant(truth, dt, plant, plant_band_hz)
    z0 = np.zeros(model.n) if z0 is None else np.asarray(z0, dtype=float)
    zdot0 = np.zeros(model.n) if zdot0 is None else np.asarray(zdot0, dtype=float)
    x = plant_model.initial_state(z0, zdot0)
    rng = np.random.default_rng(seed)
    sensors = _Sensors(truth.sensing, None if sensor_bias is None else bias, float(sensor_noise), rng, m)
    if actuator is not None:
        actuator.reset()
    controller.reset(model, target)
    run = _Run.empty(n_ctrl, sub, model.n, m, acting=actuator is not None)
    _run(run, controller, plant_model, x, sensors, limits, actuator, sub, period)
    return _result(run, model, truth, target, controller, plant_model, limits, period, dt, float(sensor_noise))


def _checked_setup(model, target, limits, vmin, vmax, plant_model, sensor_bias) -> tuple:
    """``(target, limits, plant's plate, sensor bias)`` once checked against the controller's ``model``."""
    target = np.asarray(target, dtype=float)
    if target.shape != (model.n,):
        raise InputError(f"target: shape {target.shape}, expected ({model.n},)")
    m = model.n_inputs
    if limits is None:
        limits = VoltageLimits.from_user(vmin, vmax, m)
    elif vmin is not None or vmax is not None:
        raise InputError("simulate_closed_loop: give limits= or vmin/vmax, not both")
    truth = model if plant_model is None else plant_model
    if truth.n != model.n or truth.n_inputs != m:
        raise InputError(
            f"plant_model: {truth.n} dofs and {truth.n_inputs} patches, expected the model's {model.n} and {m}"
        )
    bias = np.zeros(m) if sensor_bias is None else np.broadcast_to(np.asarray(sensor_bias, dtype=float), (m,))
    if not np.all(np.isfinite(bias)):
        raise InputError(f"sensor_bias = {sensor_bias!r}: expected finite offsets (sensor units, m)")
    return target, limits, truth, bias


def _timing(controller: Controller, t_end: float, sensor_noise: float, plant_dt: float | None):
    """The control period, the plant step and the plant steps per period, once checked."""
    period = float(controller.period)
    if not (np.isfinite(period) and period > 0):
        raise InputError(f"period = {period!r}: expected a positive control period (s)")
    if not (np.isfinite(t_end) and t_end >= period):
        raise InputError(f"t_end = {t_end!r}: expected a duration of at least one control period ({period:g} s)")
    if not (np.isfinite(sensor_noise) and sensor_noise >= 0):
        raise InputError(f"sensor_noise = {sensor_noise!r}: expected a standard deviation >= 0")
    dt = period if plant_dt is None else float(plant_dt)
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"plant_dt = {plant_dt!r}: expected a positive step (s)")
    return period, dt, _steps(period, dt, "plant_dt")


@dataclass
class _Sensors:
    """What the controller reads: the plant's patch sensors, offset by ``bias`` (``None``: none) and noisy."""

    C: np.ndarray
    bias: np.ndarray | None
    noise: float
    rng: np.random.Generator
    m: int

    def read(self, z: np.ndarray) -> np.ndarray:
        y = self.C @ z
        if self.bias is not None:
            y = y + self.bias
        if self.noise > 0:
            y = y + self.noise * self.rng.standard_normal(self.m)
        return y


@dataclass
class _Run:
    """The loop's histories: fields at every plant step, voltages and samples at every control instant."""

    Z: np.ndarray
    Zd: np.ndarray
    U: np.ndarray
    Ureq: np.ndarray
    Y: np.ndarray
    step_s: np.ndarray
    U_act: np.ndarray | None

    @classmethod
    def empty(cls, n_ctrl: int, sub: int, n: int, m: int, acting: bool) -> _Run:
        fields = (np.empty((n_ctrl * sub + 1, n)) for _ in range(2))
        per_instant = (np.empty((n_ctrl, m)) for _ in range(3))
        return cls(*fields, *per_instant, np.empty(n_ctrl), np.empty((n_ctrl, m)) if acting else None)


def _run(run: _Run, controller, plant, x, sensors: _Sensors, limits: VoltageLimits, actuator, sub, period) -> None:
    """Sample, ask the controller, clip, hold for one period (``sub`` plant steps), at every instant of ``run``."""
    m = sensors.m
    run.Z[0], run.Zd[0] = plant.fields(x)
    for k in range(run.U.shape[0]):
        y = sensors.read(run.Z[k * sub])
        t0 = time.perf_counter()
        u = np.asarray(controller.step(y), dtype=float).reshape(m)
        run.step_s[k] = time.perf_counter() - t0
        if not np.all(np.isfinite(u)):
            raise InputError(f"controller {controller.name!r} returned non-finite voltages at t = {k * period:g} s")
        run.Ureq[k] = u
        u = limits.clip(u)
        run.U[k], run.Y[k] = u, y
        u_act = u
        if actuator is not None:
            u_act = run.U_act[k] = np.asarray(actuator.apply(u, period), dtype=float)
        for s in range(sub):
            x = plant.step(x, u_act)
            run.Z[k * sub + s + 1], run.Zd[k * sub + s + 1] = plant.fields(x)


def _result(run, model, truth, target, controller, plant_model, limits, period, dt, sensor_noise) -> ClosedLoopResult:
    """The run's histories as a :class:`ClosedLoopResult`, with the shape error in the plant's mass norm."""
    n_ctrl = run.U.shape[0]
    norm_d = float(truth.m_norm(target))
    err = np.asarray(truth.m_norm(run.Z - target)) / (norm_d if norm_d > 0 else 1.0)
    info = {"plant_build_s": plant_model.build_seconds}
    if run.U_act is not None:
        info["u_acting"] = run.U_act
    return ClosedLoopResult(
        t=np.arange(run.Z.shape[0]) * dt,
        z=run.Z,
        zdot=run.Zd,
        t_u=np.arange(n_ctrl) * period,
        u=run.U,
        y=run.Y,
        tip=np.asarray(model.tip_corners(run.Z)),
        shape_error=err,
        u_requested=run.Ureq,
        step_seconds=run.step_s,
        controller=str(getattr(controller, "name", type(controller).__name__)),
        period=period,
        plant_dt=dt,
        plant=plant_model.description,
        vmin=limits.side("lower"),
        vmax=limits.side("upper"),
        sensor_noise=sensor_noise,
        info=info,
    )
