"""Settings of the morphing QP (:class:`QPSettings`): horizon, weights, limits, solver, filter."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.dynamics.reduction import CORRECTIONS
from wingopt.errors import InputError
from wingopt.optim.registry import BACKENDS, FALLBACK, default_backend

__all__ = ["QPSettings", "MODES", "FORMULATIONS"]

MODES = ("closed-loop", "open-loop")
FORMULATIONS = ("auto", "condensed", "sparse")


@dataclass(frozen=True)
class QPSettings:
    """Settings of the morphing QP.

    Attributes
    ----------
    horizon : int or None
        Steps of the prediction horizon. Default: 10 in closed loop (0.1 s at 10 ms, one period of
        the first mode: the economic Riccati terminal cost carries the tail, and 20 or 40 steps
        change the 13x61 shape errors by < 0.4 % at twice and four times the cost, see
        ``docs/control_qp.md``), or the whole manoeuvre ``plan_time / period`` (open loop).
    plan_time : float
        Length of the open-loop manoeuvre (s) when ``horizon`` is not given.
    velocity_weight : float or None
        ``beta`` (s^2) of the velocity term ``beta ||z'||_M^2``; default 1e-2 s^2 (about
        ``40 / omega_1^2`` on the plate: residual vibration costs more than a static shape error,
        which makes the loop settle at the static optimum when every patch ends at a limit, e.g.
        bending; ``None`` for ``1 / omega_1^2``).
    input_weight, rate_weight : float
        ``rho`` and ``sigma``, relative to the mean curvature of the shape term per kV^2
        (:func:`~wingopt.control.static_optimum.input_weight_absolute`).
    input_weight_si : float or None
        ``rho`` as the seed LQR's ``r`` instead (V^-2 against ``||z - z_d||_M^2`` in kg m^2; e.g.
        :data:`wingopt.control.tracking.R_DEFAULT`), so that both settle at the same fit.
    slew_rate : float or None
        Largest voltage rate per patch (V/s); ``None`` for none.
    terminal : str
        ``"lqr"`` (Riccati terminal cost, default) or ``"static"`` (``x_N`` = static optimum).
    formulation : str
        ``"condensed"`` (states eliminated, dense Hessian), ``"sparse"`` (states kept, banded KKT)
        or ``"auto"``: the form the backend is fastest on (measured, ``docs/control_qp.md``):
        condensed for the dense solvers (DAQP, PIQP, ProxQP, the qpoases/daqp CasADi plugins) up to
        600 input unknowns, sparse otherwise (Clarabel, OSQP, IPOPT).
    solver : str
        A name of :data:`wingopt.optim.registry.BACKENDS`: ``"daqp"``, ``"clarabel"``, ``"osqp"``,
        ``"piqp"``, ``"proxqp"``, ``"ipopt"`` or ``"casadi-qp"``. Default (``None``): in closed loop
        ``"daqp"`` when installed (the fastest measured, ``benchmarks/bench_latency.py``), else
        ``"clarabel"``; in open loop ``"clarabel"`` (one large sparse QP).
    plugin : str or None
        CasADi QP plugin for ``casadi-qp`` (default ``qpoases``).
    tolerance : float or None
        Backend tolerance (backend default if ``None``).
    mode : str
        ``"closed-loop"`` or ``"open-loop"``.
    reduction_tol : float
        Frequency-response tolerance of the reduced model (relative M-norm).
    band_hz : float or None
        Band of that tolerance; default the Nyquist frequency ``1 / (2 period)``.
    correction : str
        Static correction of the reduction (:data:`wingopt.dynamics.reduction.CORRECTIONS`).
    max_modes : int
        Most modes the reduction may keep.
    process_noise : float
        Kalman filter: standard deviation of an input-referred disturbance (kV).
    measurement_noise : float
        Kalman filter: sensor noise standard deviation relative to each sensor's response to 1 kV
        on its own patch (default 1.0: see :func:`make_filter`).
    offset_free : bool or None
        Closed loop: estimate a constant input disturbance per patch and move the steady-state
        target with it (:mod:`wingopt.control.disturbance`), so that a plant that is not the model
        settles at its own best shape; ``False`` is the QP without it (bit-for-bit the one before).
        Default (``None``): on in closed loop with the Riccati terminal cost, off otherwise (open
        loop has no feedback; a terminal equality cannot follow a moving target).
    disturbance_noise : float
        Offset-free filter: standard deviation of the disturbance's random walk (kV per period);
        larger is faster integral action and more noise in the voltages. Default 0.05: with 15 %
        patch hysteresis the camber loop is within 0.1 % of the plant's best at 2 s (0.02: 1-3 %,
        the disturbance settling in 4 s), the nominal plate's shapes within 0.4 % of the QP
        without it (7x31, docs/control_qp.md §8).
    """

    horizon: int | None = None
    plan_time: float = 2.0
    velocity_weight: float | None = 1e-2
    input_weight: float = 1e-6
    input_weight_si: float | None = None
    rate_weight: float = 1e-3
    slew_rate: float | None = 1.0e5
    terminal: str = "lqr"
    formulation: str = "auto"
    solver: str | None = None
    plugin: str | None = None
    tolerance: float | None = None
    mode: str = "closed-loop"
    reduction_tol: float = 1e-2
    band_hz: float | None = None
    correction: str = "residual"
    max_modes: int = 60
    process_noise: float = 0.05
    measurement_noise: float = 1.0
    offset_free: bool | None = None
    disturbance_noise: float = 0.05

    def __post_init__(self) -> None:
        if self.solver is None:
            # Closed loop: many small QPs, the fastest measured backend. Open loop: one large sparse
            # QP (3400 unknowns), where the interior point is fastest (0.13 s on 7x31 against 15 s
            # for DAQP on the condensed form).
            solver = default_backend() if self.mode == "closed-loop" else FALLBACK
            object.__setattr__(self, "solver", solver)
        checks = [
            ("mode", self.mode, MODES),
            ("solver", self.solver, BACKENDS),
            ("formulation", self.formulation, FORMULATIONS),
            ("terminal", self.terminal, ("lqr", "static")),
            ("correction", self.correction, CORRECTIONS),
        ]
        for name, value, allowed in checks:
            if value not in allowed:
                raise InputError(f"{name} = {value!r}: expected one of {', '.join(allowed)}")
        if self.horizon is not None and int(self.horizon) < 1:
            raise InputError(f"horizon = {self.horizon!r}: expected a positive number of steps")
        if self.offset_free is None:
            object.__setattr__(self, "offset_free", self.mode == "closed-loop" and self.terminal == "lqr")
        if not isinstance(self.offset_free, (bool, np.bool_)):
            raise InputError(f"offset_free = {self.offset_free!r}: expected true or false")
        if self.offset_free and self.mode == "closed-loop" and self.terminal != "lqr":
            raise InputError(f"terminal = {self.terminal!r}: offset_free needs terminal = 'lqr' (or offset_free off)")
        for name in ("input_weight", "rate_weight", "process_noise", "measurement_noise", "disturbance_noise"):
            if not getattr(self, name) >= 0:
                raise InputError(f"{name} = {getattr(self, name)!r}: expected a non-negative number")
        if self.input_weight_si is not None and not self.input_weight_si > 0:
            raise InputError(f"input_weight_si = {self.input_weight_si!r}: expected a positive weight (V^-2)")
        if self.input_weight <= 0 and self.rate_weight <= 0 and self.input_weight_si is None:
            raise InputError("input_weight and rate_weight are both zero: the QP needs one to be positive")
        if self.slew_rate is not None and not self.slew_rate > 0:
            raise InputError(f"slew_rate = {self.slew_rate!r}: expected a positive rate (V/s) or None")

    def steps(self, period: float) -> int:
        """Horizon length in periods."""
        if self.horizon is not None:
            return int(self.horizon)
        return max(1, int(round(self.plan_time / period))) if self.mode == "open-loop" else 10
