"""Moving-horizon Tikhonov estimation of the membrane load (spec §4).

Over a window of ``N`` samples (0.2 s by default, whatever the sample rate) the unknowns are the
modal state at the window start and the load (constant over the window, or ``B`` piecewise-constant
blocks of a random walk). The cost is::

    arrival cost  +  sum_k |y_k - h(x_k)|^2_{R^-1}  +  lambda sum_b f_b^T Lam f_b  (+ random walk)

with the exact discrete dynamics (per-mode zero-order hold, :mod:`wingopt.estimation.mhe.model`).
The arrival cost is a Gaussian in information form that summarises all data before the window:
after each window the first ``stride`` samples are absorbed (linearised at the window's optimum),
the state is propagated with a small process noise, and, for a random-walk load, the dropped
block is marginalised through the random walk's increment (the load's process noise,
:mod:`wingopt.estimation.mhe.load_model`). For a constant load, a linear model and no process noise
this makes the final window's answer equal to the batch Tikhonov estimate over the whole record.

Consistency (:mod:`wingopt.estimation.mhe.consistency`): the window cost is a chi-square, so data the
load model cannot explain show up as localised excess misfit. A record that *starts* with such
data (the flow starting, the load ramping up from rest) has them left out of the start-up — a
first window the model cannot fit would otherwise become every later window's arrival cost — and a
later window whose data contradict the estimate restarts it there.

Step-able use (PyLops style)::

    mhe = MovingHorizonEstimator(model, MHESettings(window_s=0.2, stride_s=0.05))
    mhe.setup(measurements)           # noise level, lambda, start-up (onset, scan, coarse-to-fine, sign)
    while mhe.step():                 # one window per step
        print(mhe.current_lift)
    result = mhe.result()

or one shot: ``mhe_identify(model, measurements, settings)``.

**Sign.** Stretch sensors are sign-blind: a load and its negative give the same data (with the
initial state negated too). The sign is fixed by the prior, explicitly: the declared
``initial_load`` (the estimate's load must correlate positively with it) and, when known, the
prior initial deflection (``initial_deflection``, the protocol's bubble). See
:mod:`wingopt.estimation.mhe.cold_start`.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.load_space import build_load_space
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.mhe.cold_start import initial_priors
from wingopt.estimation.mhe.consistency import first_inconsistent
from wingopt.estimation.mhe.information import WindowPrior
from wingopt.estimation.mhe.model import MHEModel
from wingopt.estimation.mhe.record import weighted_record
from wingopt.estimation.mhe.settings import LOAD_MODELS, SIGN_MARGIN, STATE_PRIOR_EVIDENCE, MHESettings
from wingopt.estimation.mhe.solvers import NumpySolver, WindowSolution, make_solver
from wingopt.estimation.mhe.startup import StartUp
from wingopt.estimation.mhe.window import WindowProblem
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel

__all__ = ["MHESettings", "MovingHorizonEstimator", "mhe_identify", "LOAD_MODELS", "STATE_PRIOR_EVIDENCE"]

log = logging.getLogger(__name__)


def _owned(owner: str, name: str, doc: str) -> property:
    """The read-only attribute ``name`` of the estimator's ``owner`` (its start-up or window prior)."""
    return property(lambda self: getattr(getattr(self, owner), name), doc=doc)


class MovingHorizonEstimator:
    """Step-able moving-horizon load estimator on a :class:`~wingopt.membrane.MembraneModel`.

    Parameters
    ----------
    model : MembraneModel
        The estimator's model (its mesh is the estimation mesh).
    settings : MHESettings
        Default :class:`MHESettings`; its ``declaration`` is filled from the model's problem when ``None``.

    Notes
    -----
    The estimator owns the record (data, weights, histories) and the window's position; a
    :class:`~wingopt.estimation.mhe.information.WindowPrior` (``window_prior``) owns the window's
    geometry and arrival cost, a :class:`~wingopt.estimation.mhe.startup.StartUp` (``startup``)
    the start-up's choices (lambda, state prior, the priors on the initial state and the sign).
    Both are built by :meth:`setup`.
    """

    def __init__(self, model: MembraneModel, settings: MHESettings | None = None) -> None:
        if not isinstance(model, MembraneModel):
            raise InputError(f"model = {type(model).__name__}: expected a MembraneModel (MembraneModel.from_problem)")
        if settings is not None and not isinstance(settings, MHESettings):
            raise InputError(f"settings = {settings!r}: expected an MHESettings or None")
        self.model = model
        self.settings = with_declaration(settings or MHESettings(), model.problem)
        s = self.settings
        self.load_space = build_load_space(model, s.load_space)
        self.reduced = MHEModel.build(model, self.load_space, s.modes, s.declaration.dt)
        self.solver = make_solver(s.backend, s.qp_solver, max_iterations=s.max_iterations, tolerance=s.tolerance)
        # The start-up's coarse problem is tiny and always solved with the fast dense solver.
        self._coarse_solver = NumpySolver(max_iterations=200, tolerance=s.tolerance)
        # Warm-started windows sit next to their optimum, where the exact Hessian buys nothing
        # (measured: the same 2 iterations per window) but costs a third of the time.
        self._step_solver = (
            NumpySolver(max_iterations=s.max_iterations, tolerance=s.tolerance, hessian="gauss-newton")
            if s.backend == "numpy"
            else self.solver
        )
        self._ready = False

    # -- setup -------------------------------------------------------------------------------
    def setup(
        self,
        measurements: Measurements,
        noise_std: np.ndarray | float | None = None,
        initial_load: float | None = None,
        initial_deflection: float | None = None,
    ) -> MovingHorizonEstimator:
        """Prepare a run on ``measurements`` and solve the first window.

        Parameters
        ----------
        measurements : Measurements
            Uniformly sampled; NaN entries are missing samples (weight 0).
        noise_std : float or array, optional
            Sensor noise std; default: the measurements', else the declared ``noise_std``
            (``settings.declaration``), else estimated from the data
            (:func:`~wingopt.estimation.core.noise.estimate_noise_std`).
        initial_load : float, optional
            Sign prior (Pa); default: the declared ``initial_load``.
        initial_deflection : float, optional
            Peak (m) of the prior initial bubble; ``0``: unknown. Default: the declared
            ``initial_deflection``.
        """
        t0 = time.perf_counter()
        s, red = self.settings, self.reduced
        problem, ident = self.model.problem, s.declaration
        rec = weighted_record(measurements, problem.sensor_names, noise_std, ident.noise_std)
        dt = rec.dt
        if abs(dt - red.dt) > 1e-9 * red.dt:
            log.info("data sampled at dt = %g s (problem: %g s): rebuilding the reduced model", dt, red.dt)
            self.reduced = red = MHEModel.build(self.model, self.load_space, s.modes, dt)
        self.dt, self.t, self.y, self.w = dt, rec.t, rec.y, rec.w
        self.noise_std, self.noise_source, self.missing_rows = rec.noise_std, rec.noise_source, rec.missing_rows
        self.K = K = self.y.shape[0]
        m = red.m
        # Scaling: modal amplitude A such that the data's largest output is O(1) for mode 1.
        gain = np.max(np.stack([np.diag(C) for C in red.sensor_matrices]) / red.omega**2)
        A = np.sqrt(max(rec.peak, 1e-300) / gain)
        self.amplitude = A
        # Priors: initial modal state (weak, 1/omega) and the sign prior.
        p0 = ident.initial_load if initial_load is None else float(initial_load)
        if p0 == 0 or not np.isfinite(p0):
            raise InputError(f"initial_load = {p0!r}: expected a non-zero pressure (its sign fixes the sign)")
        peak = ident.initial_deflection if initial_deflection is None else initial_deflection
        self.initial_load, self.initial_deflection = p0, float(peak)
        sign_prior, x_prior = initial_priors(self.model, self.load_space, red, p0, self.initial_deflection)
        # Window geometry (seconds or samples, see MHESettings.samples).
        window, self.stride = s.samples(dt)
        self.N = min(window, K)
        self.stride = min(self.stride, self.N)
        blocks = window // self.stride if (s.load_model == "random_walk" and self.N == window) else 1
        Dx, Du = np.concatenate([A / red.omega, A * np.ones(m)]), A * red.omega
        self.window_prior = WindowPrior(red, self.load_space, s, self.N, self.stride, dt, blocks, Dx, Du)
        lift_scale = abs(p0) * problem.width * problem.height
        solvers = (self.solver, self._coarse_solver)
        self.startup = StartUp(self.window_prior, rec, s, *solvers, sign_prior, x_prior, lift_scale)
        # History (per sample): modal forces, modal displacement, lift std.
        self._u = np.full((K, m), np.nan)
        self._q = np.full((K, m), np.nan)
        self._lift_std = np.full(K, np.nan)
        self._windows: list[dict] = []
        self._shift = self.stride
        # Warnings go into the result (info["warnings"]) for the workflow to report once; logging
        # them here as well printed them twice on the command line.
        self.warnings: list[str] = []
        sol, report, self.start = self.startup.first_window(self.warnings)
        self.start_report = report
        if report.sign_score < SIGN_MARGIN:
            self.warnings.append(
                f"the sign of the load is not determined by the prior (score {report.sign_score:.3f}): a load "
                "without net lift needs the initial-deflection prior (initial_deflection) to fix its sign"
            )
        self._accept(sol, first=True)
        self.setup_seconds = time.perf_counter() - t0
        self._t_start = t0
        self._ready = True
        return self

    # -- what the window prior and the start-up own (read-only here) -----------------------
    lam = _owned("startup", "lam", "The chosen lambda (the weight of the load's roughness).")
    lambda_info = _owned("startup", "lambda_info", "How lambda was chosen (rule, path); empty when it was given.")
    state_prior = _owned("startup", "state_prior", "The chosen relative std of the initial state's prior.")
    x_prior = _owned("startup", "x_prior", "Prior initial modal state of the current estimate (start or restart).")
    sign_prior = _owned("startup", "sign_prior", "Sign prior of the current estimate.")
    onset = _owned("startup", "onset", "The record's onset: samples left out at its start, the attempts.")
    restarts = _owned("startup", "restarts", "Where the estimate was started afresh (data inconsistent with it).")
    bounds_points = _owned("window_prior", "bounds_points", "Modal forces to pressures at the bound points.")
    state_prior_info = _owned("startup", "state_prior_info", "How the state prior was chosen (rule, evidence).")
    scale = _owned("window_prior", "scale", "Scale of every unknown of a window (solved as theta / scale).")
    dim = _owned("window_prior", "dim", "Number of unknowns of a window (initial state and B load blocks).")
    B = _owned("window_prior", "B", "Load blocks of a window (1: constant load; the random walk's after start-up).")
    basis = _owned("window_prior", "basis", "The window's response basis.")

    def natural_lambda(self) -> float | None:
        """Scale of lambda at which roughness and data information balance along the smoothest shape.

        ``lambda_nat = (v^T H_data v) / (v^T S^-1 v)`` for the modal forces ``v`` of the smoothest
        load shape, with ``H_data`` the data's Gauss–Newton matrix at the start-up estimate; the
        lambda grid is relative to it. ``None`` when lambda was given (no path was computed).
        """
        return self.startup.natural_scale

    def _window_problem(self, start: int, lam: float) -> WindowProblem:
        """The window starting at sample ``start`` with the current arrival cost."""
        return self.window_prior.problem(self.y, self.w, start, lam)

    # -- stepping ----------------------------------------------------------------------------
    def _accept(self, sol: WindowSolution, first: bool = False) -> None:
        """Record a window's answer in the histories."""
        red, wp = self.reduced, self.window_prior
        m, B, N = red.m, wp.B, self.N
        self._sol = sol
        theta = sol.theta
        Q = red.modal_trajectory(wp.basis, theta)
        window = slice(self.start, self.start + N)
        w = self.w[window]
        chi2 = float(np.sum(w * (self.y[window] - red.outputs(Q)) ** 2))
        U = theta[2 * m :].reshape(B, m)
        L = wp.basis.block_length
        block_of = np.minimum(np.arange(N) // L, B - 1)
        lift_std = wp.lift_band(sol.hessian, self.lam)
        new = slice(self.start, self.start + N) if first else slice(self.start + N - self._shift, self.start + N)
        idx = np.arange(N)[new.start - self.start : new.stop - self.start]
        self._u[new] = U[block_of[idx]]
        self._q[new] = Q[idx]
        self._lift_std[new] = lift_std[block_of[idx]]
        self._windows.append(
            {
                "start": self.start,
                "iterations": sol.iterations,
                # Data misfit of the window (the total cost carries the arrival cost's constant).
                "chi2": chi2,
                "n_data": int(np.count_nonzero(w)),
                "status": sol.status.value,
                "raw_status": sol.raw_status,
                "seconds": sol.seconds,
            }
        )

    def step(self) -> bool:
        """Advance one window; ``False`` (and no work) when the record is exhausted."""
        if not self._ready:
            raise InputError("MovingHorizonEstimator.step: call setup(measurements) first")
        end = self.start + self.N
        if end >= self.K:
            return False
        shift = min(self.stride, self.K - end)
        # The samples leaving the window go into the arrival cost (linearised at its optimum).
        self.window_prior.absorb(self._window_problem(self.start, self.lam), self._sol.theta, shift)
        self._shift = shift
        m, B = self.reduced.m, self.window_prior.B
        # Warm start: the previous optimum propagated over `shift` samples.
        theta = self._sol.theta
        Fs, Gs = self.reduced.transition(shift)
        q, v, u1 = theta[:m], theta[m : 2 * m], theta[2 * m : 3 * m]
        x_new = np.concatenate(
            [Fs[:, 0, 0] * q + Fs[:, 0, 1] * v + Gs[:, 0] * u1, Fs[:, 1, 0] * q + Fs[:, 1, 1] * v + Gs[:, 1] * u1]
        )
        U = theta[2 * m :].reshape(B, m)
        if B > 1:
            U = np.vstack([U[1:], U[-1:]])
        theta0 = np.concatenate([x_new, U.ravel()])
        self.start += shift
        problem = self._window_problem(self.start, self.lam)
        sol = self._step_solver.solve(problem, theta0)
        if self.settings.consistency:
            k = first_inconsistent(self.startup.profile(sol.theta, self.start, level=self.startup.level))
            # Data that contradict the estimate: start afresh there (the start-up, lambda kept).
            new = None if k is None else self.startup.restart(self.start + k, sol.theta, self.start)
            if new is not None:
                self.start, sol = new
                self._shift = self.stride
                self._accept(sol, first=True)
                return True
        self._accept(sol)
        return True

    def run(self) -> IdentificationResult:
        """Step to the end of the record and return the result."""
        while self.step():
            pass
        return self.result()

    @property
    def window_solution(self) -> WindowSolution:
        """The latest window's solution (unknowns ``theta``, Hessian, status)."""
        return self._sol

    @property
    def current_lift(self) -> float:
        """Lift (N) of the latest window's load estimate."""
        m = self.reduced.m
        return float(self.reduced.lift_row @ self._sol.theta[-m:])

    def result(self) -> IdentificationResult:
        """The histories so far as an :class:`IdentificationResult`."""
        red = self.reduced
        done = np.isfinite(self._u[:, 0])
        U, Qm = self._u[done], self._q[done]
        F = red.load(U)
        # Deflection: retained modes + static response of the dropped modes to the load (per window).
        Z = red.deflection(Qm)
        if red.m < self.model.n:
            uniq, inv = np.unique(U, axis=0, return_inverse=True)
            corr = np.stack([red.residual_static(red.load(u)) for u in uniq])
            Z = Z + corr[inv.ravel()]
        lift = self.load_space.lift(F)
        iters = [w["iterations"] for w in self._windows]
        info = {
            "backend": self.solver.name if self.settings.backend != "cvxpy" else f"cvxpy-{self.settings.qp_solver}",
            "load_space": str(self.load_space.kind),
            "modes": red.m,
            "window": self.N,
            "stride": self.stride,
            "window_s": self.N * self.dt,
            "stride_s": self.stride * self.dt,
            "load_model": self.settings.load_model,
            "load_timescale": self.settings.load_timescale if self.B > 1 else None,
            "onset": self.onset,
            "restarts": self.restarts,
            "windows": len(self._windows),
            "iterations_total": int(np.sum(iters)),
            "iterations_per_window": iters,
            "final_window_chi2_per_datum": self._windows[-1]["chi2"] / max(self._windows[-1]["n_data"], 1),
            "noise_std": self.noise_std,
            "noise_source": self.noise_source,
            "missing_samples": self.missing_rows,
            "lambda": self.lam,
            "lambda_selection": self.lambda_info,
            "state_prior": self.state_prior_info,
            "setup_s": self.setup_seconds,
            "sign": {
                "initial_load": self.initial_load,
                "initial_deflection": self.initial_deflection,
                "score": self.start_report.sign_score,
                "determined": bool(self.start_report.sign_score >= SIGN_MARGIN),
                "candidates": self.start_report.candidates,
            },
            "statuses": sorted({w["status"] for w in self._windows}),
            "warnings": list(self.warnings),
        }
        res = IdentificationResult(
            method="mhe",
            t=self.t[done],
            load=F,
            deflection=Z,
            lift=lift,
            lift_std=self._lift_std[done],
            regularization=self.lam,
            wall_s=time.perf_counter() - self._t_start,
            info=info,
            load_space=self.load_space.space,
        )
        return res


def mhe_identify(
    model: MembraneModel,
    measurements: Measurements,
    settings: MHESettings | None = None,
    **setup_kwargs: Any,
) -> IdentificationResult:
    """One-shot moving-horizon identification: ``setup`` + ``run``.

    Parameters
    ----------
    model : MembraneModel
        Estimation model (mesh).
    measurements : Measurements
    settings : MHESettings, optional
    **setup_kwargs
        ``noise_std``, ``initial_load``, ``initial_deflection`` (see :meth:`MovingHorizonEstimator.setup`).

    Returns
    -------
    IdentificationResult
        Load, deflection and lift histories with the lift's 1-sigma band; ``info`` holds the
        window statistics (chi-square), lambda selection, onset and restarts.
    """
    est = MovingHorizonEstimator(model, settings)
    est.setup(measurements, **setup_kwargs)
    return est.run()
