"""Morphing as a constrained finite-horizon QP (spec §4): open loop and receding horizon.

Model. The plate is reduced by :func:`wingopt.dynamics.reduction.reduce_system` (modal truncation,
full projected damping block, quasi-static residual correction so that every steady state is
exact; the number of modes from a frequency-response tolerance on the loop's Nyquist band) and
discretised exactly (ZOH) at the control period. Everything is solved in scaled units: fields
divided by ``s = ||z_d||_M`` and voltages in kV (``w = u / 1000``), so costs and unknowns are O(1).

Cost. Over ``N`` periods, with ``x_k = [q_k; q_k']`` and the field at the end of period ``k``
``z_{k+1} = Phi q_{k+1} + R u_k`` (the quasi-static part follows the held input)::

    sum_{k=0}^{N-1}  ||z_{k+1} - z_d||_M^2 + beta ||z'_{k+1}||_M^2 + rho ||w_k||^2 + sigma ||w_k - w_{k-1}||^2
                     + V_f(x_N, w_{N-1})

The shape term is the exact M-norm error of the reduced field (modal part plus residual part
plus the constant part of ``z_d`` outside the reduced space). Constraints: ``vmin <= u_k <= vmax``
per patch and ``|u_k - u_{k-1}| <= slew * period`` (``u_{-1}`` the voltage applied last).

Terminal cost. ``V_f(xi) = (xi - xi_s)^T P (xi - xi_s) - lambda^T (xi - xi_s)`` with ``xi = (x, w_prev)``:
``P`` is the Riccati solution of the reduced discrete LQR on the same stage cost (with the rate
term, hence the augmented state), ``(xi_s, w_s)`` the static optimum
(:mod:`wingopt.control.static_optimum`, within the limits), and ``lambda`` the steady-state
multiplier ``-(I - F)^-T grad_x l``. The linear term is what makes the target shape ``z_d``, which
no admissible voltage reaches, compatible with a quadratic tail: it *rotates* the stage cost
into a deviation cost about the best reachable steady state (the standard economic-MPC
construction), so the receding-horizon loop settles exactly at the static optimum and, without
active limits, the whole scheme is the infinite-horizon LQR. ``terminal="static"`` replaces
``V_f`` by the equality ``x_N = x_s``.

QP. Written once with the states as variables (``formulation="sparse"``, banded KKT: the default
for Clarabel, OSQP, IPOPT and the sparse CasADi plugins), and condensed by eliminating the states
(``"condensed"``, dense ``N m`` Hessian: the default for the dense solvers, DAQP (the default
backend), PIQP, ProxQP and the dense active-set CasADi plugins); the
parameter ``p = (x_0, w_prev)`` enters the linear term and the bounds only
(:class:`~wingopt.optim.qp.ParametricQP`), so each backend is built once and re-solved
each period, warm-started from the shifted previous plan.

Use. Closed loop: a steady-state Kalman filter on the nine patch sensors estimates ``x`` (the
sensor model carries the residual feedthrough ``C R u_{k-1}``), one QP per period, the first input
applied. Open loop: one QP over the manoeuvre from rest, replayed, the static optimum held after it.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict

import numpy as np

from wingopt.control.disturbance import TargetCalculator, assemble_offset_free_qp, make_disturbance_filter
from wingopt.control.kalman import SteadyStateKalman
from wingopt.control.mpc_assembly import _shift, assemble_qp, condense
from wingopt.control.mpc_problem import TrackingProblem
from wingopt.control.mpc_settings import FORMULATIONS, MODES, QPSettings
from wingopt.control.static_optimum import VOLT_SCALE
from wingopt.errors import InputError
from wingopt.optim.qp import ParametricQP, QPBackend
from wingopt.optim.registry import make_backend, preferred_formulation

__all__ = [
    "QPSettings",
    "TrackingProblem",
    "QPController",
    "make_qp_controller",
    "make_filter",
    "assemble_qp",
    "condense",
    "MODES",
    "FORMULATIONS",
]

log = logging.getLogger(__name__)


def make_filter(problem: TrackingProblem, process_noise: float, measurement_noise: float):
    """The steady-state Kalman filter of the reduced model on the patch sensors (scaled units).

    ``x_{k+1} = F x_k + G (w_k + d_k)``, ``y_k = C x_k + D w_{k-1} + v_k`` (the quasi-static residual
    reads the voltage still held): an input-referred disturbance ``d`` (std ``process_noise`` kV)
    and white sensor noise, each sensor scaled by its response to 1 kV on its own patch, with the
    relative std ``measurement_noise``. The sensors see, besides the modelled modes, every higher
    mode that each voltage step rings, aliased by the sampling: measured on 7x31, that mismatch is
    as large as the modal part of the signal, so the default (1.0) trusts the model and lets the
    sensors correct slowly (``docs/control_qp.md``, sweep). Returns ``(filter, y_scale)``.
    """
    red = problem.reduced
    if red.output_matrix is None:
        raise InputError("closed-loop QP: the reduced model has no sensor output (reduce with output=model.sensing)")
    static_y = (red.output_matrix @ red.static_gain() + red.output_feedthrough) * VOLT_SCALE
    y_scale = np.maximum(np.abs(np.diag(static_y)), 1e-12 * np.abs(static_y).max())
    Cq = red.output_matrix * problem.scale / y_scale[:, None]
    C = np.hstack([Cq, np.zeros_like(Cq)])
    D = red.output_feedthrough * VOLT_SCALE / y_scale[:, None]
    G = problem.G
    W = max(process_noise, 1e-9) ** 2 * (G @ G.T) + 1e-12 * np.eye(problem.nx)
    V = max(measurement_noise, 1e-9) ** 2 * np.eye(C.shape[0])
    return SteadyStateKalman(problem.F, G, C, W, V, D=D), y_scale


class QPController:
    """Receding-horizon (or open-loop) morphing QP with the harness's ``Controller`` interface.

    ``reset(model, target)`` builds everything once (reduction, static optimum, terminal cost, QP,
    backend, filter); ``step(y)`` takes the patch-sensor sample at the start of a period and
    returns the voltages to hold over it. Diagnostics are collected in :attr:`extras`.
    """

    name = "qp"

    def __init__(self, settings: QPSettings, *, period: float, vmin=None, vmax=None) -> None:
        self.settings = settings
        self.period = float(period)
        self.vmin, self.vmax = vmin, vmax
        self.problem: TrackingProblem | None = None
        self.qp: ParametricQP | None = None
        self.backend: QPBackend | None = None
        self._key = None
        self.info: dict = {}
        self.solve_times: list[float] = []

    # -- setup ------------------------------------------------------------------------------------
    def setup(self, model, target: np.ndarray) -> None:
        """Build the problem, the QP and the backend (skipped when model and target are unchanged)."""
        target = np.asarray(target, dtype=float)
        key = (id(model), target.tobytes())
        if key == self._key:
            return
        t0 = time.perf_counter()
        st = self.settings
        self.problem = TrackingProblem.build(
            model, target, period=self.period, vmin=self.vmin, vmax=self.vmax, settings=st
        )
        N = st.steps(self.period)
        form = st.formulation
        if form == "auto":
            # Measured (docs/control_qp.md): interior-point and ADMM solvers are fastest on the sparse
            # form, the dense solvers (active set, dense IP) on the condensed one while it stays small.
            # The dense solvers of wingopt.optim (daqp, piqp, proxqp) stay on the condensed form even
            # when it is large: their sparse form is a dense matrix of states and inputs (7x31 open
            # loop, 1800 inputs: DAQP 15 s condensed, 100 s sparse; Clarabel 0.13 s sparse).
            dense = preferred_formulation(st.solver, st.plugin) == "condensed"
            small = N * self.problem.m <= 600 or st.solver != "casadi-qp"
            form = "condensed" if dense and small else "sparse"
        t1 = time.perf_counter()
        self.offset_free = st.offset_free and st.mode == "closed-loop"
        self.qp = (assemble_offset_free_qp if self.offset_free else assemble_qp)(self.problem, N, form)
        t2 = time.perf_counter()
        self.backend = make_backend(st.solver, self.qp, tolerance=st.tolerance, plugin=st.plugin)
        self.filter, self._y_scale, self.target = None, None, None
        if st.mode == "closed-loop":
            self.filter, self._y_scale = make_filter(self.problem, st.process_noise, st.measurement_noise)
        if self.offset_free:
            self.filter = make_disturbance_filter(self.problem, self.filter, st.disturbance_noise)
            self.target = TargetCalculator(self.problem)
        self._key = key
        pb = self.problem
        self.info = {
            "static_optimum_error": pb.static.shape_error,
            "static_optimum_voltages_V": pb.static.voltages.tolist(),
            "qp_mode": st.mode,
            "qp_solver": self.backend.name + (f"/{st.plugin or 'qpoases'}" if st.solver == "casadi-qp" else ""),
            "qp_horizon": N,
            "qp_formulation": form,
            "qp_variables": self.qp.n_variables,
            "qp_offset_free": self.offset_free,
            "reduced_modes": pb.reduced.n_modes,
            "reduced_states": pb.nx,
            "reduction_error": pb.reduced.error,
            "reduction_band_hz": pb.reduced.band_hz,
            "build_s": {
                **{k: round(v, 4) for k, v in pb.timings.items()},
                "assemble_s": round(t2 - t1, 4),
                "backend_s": round(self.backend.build_seconds, 4),
                "total_s": round(time.perf_counter() - t0, 4),
            },
            "settings": asdict(st),
        }

    def reset(self, model, target: np.ndarray) -> None:
        """Prepare a run from rest (``Controller`` protocol)."""
        self.setup(model, target)
        m = self.problem.m
        self._w_prev = np.zeros(m)
        self._warm = None
        self._k = 0
        self.solve_times: list[float] = []
        self.iterations: list[int] = []
        self.statuses: set[str] = set()  # each distinct SolveStatus of the run's solves (for its status)
        self.objectives: list[float] = []
        self.max_violation_V = 0.0
        self.disturbance = self.target_w = None
        if self.filter is not None:
            self.filter.reset()
        self._plan = None
        if self.settings.mode == "open-loop":
            sol = self._solve(np.zeros(self.problem.nx), self._w_prev)
            self._plan = sol.v[: self.qp.names["horizon"] * m].reshape(-1, m)
            self.info["open_loop_objective"] = sol.objective
            self.info["open_loop_solve_s"] = sol.seconds

    # -- stepping ---------------------------------------------------------------------------------
    def _solve(self, x0, w_prev, *extra):
        sol = self.backend.solve(np.r_[(x0, w_prev, *extra)], warm=self._warm)
        self._warm = _shift(sol.v, self.qp)
        self.solve_times.append(sol.seconds)
        self.iterations.append(sol.iterations)
        self.statuses.add(sol.status.value)
        self.objectives.append(sol.objective)
        return sol

    def _admissible(self, w: np.ndarray) -> np.ndarray:
        """Project a solver's answer onto the limits (it may sit ~tolerance outside them)."""
        pb = self.problem
        lo, hi = pb.w_min, pb.w_max
        if pb.slew is not None:
            lo = np.maximum(lo, self._w_prev - pb.slew)
            hi = np.minimum(hi, self._w_prev + pb.slew)
        self.max_violation_V = max(self.max_violation_V, float(np.max(np.r_[lo - w, w - hi, 0.0])) * VOLT_SCALE)
        return np.clip(w, lo, hi)

    def step(self, y: np.ndarray) -> np.ndarray:
        """Voltages (V) to hold over the next period, given the patch-sensor sample ``y``."""
        if self.problem is None:
            raise InputError("QPController.step: call reset(model, target) first")
        m = self.problem.m
        if self._plan is not None:
            w = self._plan[self._k] if self._k < len(self._plan) else self.problem.w_s
            w = self._admissible(np.asarray(w, dtype=float))
        else:
            x_hat = self.filter.update(np.asarray(y, dtype=float) / self._y_scale)
            if self.offset_free:
                nx = self.problem.nx
                x_hat, d_hat = x_hat[:nx], x_hat[nx:]
                x_s, w_s = self.target.solve(d_hat)
                sol = self._solve(x_hat, self._w_prev, d_hat, x_s, w_s)
                self.disturbance, self.target_w = d_hat * VOLT_SCALE, w_s * VOLT_SCALE
            else:
                sol = self._solve(x_hat, self._w_prev)
            w = self._admissible(sol.v[:m])
            self.filter.predict(w)
        self._w_prev = w
        self._k += 1
        return w * VOLT_SCALE

    def run(self, model, target: np.ndarray, measurements) -> np.ndarray:
        """Convenience: ``reset`` then ``step`` over a sequence of sensor samples; voltages (nt, m)."""
        self.reset(model, target)
        return np.array([self.step(y) for y in measurements])

    @property
    def extras(self) -> dict:
        """Method-specific numbers for :class:`~wingopt.workflows.morph.MorphResult` (= :meth:`summary`)."""
        return self.summary()

    def summary(self) -> dict:
        """Build information (static optimum, sizes, timings) plus the step statistics of the last run."""
        out = dict(self.info)
        if getattr(self, "solve_times", None):
            t = np.asarray(self.solve_times)
            out.update(
                qp_solves=len(t),
                qp_step_median_s=float(np.median(t)),
                qp_step_max_s=float(t.max()),
                qp_step_median_over_period=float(np.median(t) / self.period),
                qp_iterations_median=float(np.median(self.iterations)),
                qp_max_bound_violation_V=self.max_violation_V,
                qp_statuses=sorted(self.statuses),
            )
            if self.offset_free and getattr(self, "disturbance", None) is not None:
                out.update(
                    offset_free_disturbance_V=[float(v) for v in self.disturbance],
                    offset_free_target_V=[float(v) for v in self.target_w],
                )
        return out


def make_qp_controller(model, target, *, vmin, vmax, period: float, **options) -> QPController:
    """The morphing QP as a harness ``Controller`` (``wingopt.workflows.morph.METHODS["qp"]``).

    Parameters
    ----------
    model : PlateModel
    target : ndarray (n,)
        Target coefficients ``z_d``.
    vmin, vmax : float, array or None
        Voltage limits (V).
    period : float
        Control period (s).
    **options
        Fields of :class:`QPSettings` (``horizon``, ``solver``, ``mode``, ...); ``None`` values
        are ignored so that a command line can pass its unset options through.
    """
    known = QPSettings.__dataclass_fields__
    unknown = sorted(k for k in options if k not in known)
    if unknown:
        raise InputError(f"qp option(s) {', '.join(unknown)}: expected some of {', '.join(known)}")
    # Built afresh (not replace()d from the defaults): the default solver depends on the mode.
    settings = QPSettings(**{k: v for k, v in options.items() if v is not None})
    ctrl = QPController(settings, period=period, vmin=vmin, vmax=vmax)
    ctrl.setup(model, target)
    return ctrl
