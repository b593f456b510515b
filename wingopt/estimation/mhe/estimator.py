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
initial state negated too). The sign is fixed by the prior, explicitly: the problem's
``initial_load`` (the estimate's load must correlate positively with it) and, when known, the
prior initial deflection (``initial_deflection``, the protocol's bubble). See
:mod:`wingopt.estimation.mhe.start`.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.load_space import build_load_space
from wingopt.estimation.mhe.consistency import first_inconsistent
from wingopt.estimation.mhe.information import WindowInformation
from wingopt.estimation.mhe.load_model import l2_metric
from wingopt.estimation.mhe.model import MHEModel
from wingopt.estimation.mhe.settings import LOAD_MODELS, SIGN_MARGIN, STATE_PRIOR_EVIDENCE, MHESettings
from wingopt.estimation.mhe.solvers import NumpySolver, WindowSolution, make_solver
from wingopt.estimation.mhe.start import SignPrior
from wingopt.estimation.mhe.startup import StartUp
from wingopt.estimation.noise import resolve_noise_std
from wingopt.estimation.result import IdentificationResult
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel, bubble

__all__ = ["MHESettings", "MovingHorizonEstimator", "mhe_identify", "LOAD_MODELS", "STATE_PRIOR_EVIDENCE"]

log = logging.getLogger(__name__)


class MovingHorizonEstimator(StartUp, WindowInformation):
    """Step-able moving-horizon load estimator on a :class:`~wingopt.membrane.MembraneModel`.

    Parameters
    ----------
    model : MembraneModel
        The estimator's model (its mesh is the estimation mesh).
    settings : MHESettings
    """

    def __init__(self, model: MembraneModel, settings: MHESettings | None = None) -> None:
        if not isinstance(model, MembraneModel):
            raise InputError(f"model = {type(model).__name__}: expected a MembraneModel (MembraneModel.from_problem)")
        if settings is not None and not isinstance(settings, MHESettings):
            raise InputError(f"settings = {settings!r}: expected an MHESettings or None")
        self.model = model
        self.settings = settings or MHESettings()
        s = self.settings
        self.load_space = build_load_space(model, s.load_space)
        self.reduced = MHEModel.build(model, self.load_space, s.modes)
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
            Sensor noise std; default: the measurements', else the problem's ``noise_std``, else
            estimated from the data (:func:`~wingopt.estimation.noise.estimate_noise_std`).
        initial_load : float, optional
            Sign prior (Pa); default: the problem's ``identification.initial_load``.
        initial_deflection : float, optional
            Peak (m) of the prior initial bubble; ``0``: unknown. Default: the problem's
            ``identification.initial_deflection`` when it has one, else 0.
        """
        if not isinstance(measurements, Measurements):
            raise InputError(f"measurements = {type(measurements).__name__}: expected a Measurements")
        t0 = time.perf_counter()
        s, red = self.settings, self.reduced
        problem = self.model.problem
        ident = problem.identification
        meas = measurements
        if tuple(meas.sensor_names) != tuple(problem.sensor_names):
            raise InputError(
                f"measurements: sensors {list(meas.sensor_names)} do not match the problem's "
                f"{list(problem.sensor_names)}"
            )
        if meas.count < 2:
            raise InputError("measurements: need at least 2 samples")
        dt = float(np.median(np.diff(meas.t)))
        if np.max(np.abs(np.diff(meas.t) - dt)) > 1e-6 * dt:
            raise InputError("measurements: irregular sampling; resample to a uniform time step first")
        if abs(dt - red.dt) > 1e-9 * red.dt:
            log.info("data sampled at dt = %g s (problem: %g s): rebuilding the reduced model", dt, red.dt)
            self.reduced = red = MHEModel.build(self.model, self.load_space, s.modes, dt)
        self.dt = dt
        y = np.array(meas.values, dtype=float)
        missing = ~np.isfinite(y)
        self.missing_rows = int(np.count_nonzero(missing.any(axis=1)))
        if missing.all():
            raise InputError("measurements: every sample is missing")
        sigma, source = resolve_noise_std(y, problem.sensor_names, noise_std, meas.noise_std, ident.noise_std)
        self.noise_std, self.noise_source = sigma, source
        self.y = np.where(missing, 0.0, y)
        self.w = np.where(missing, 0.0, 1.0 / sigma**2)
        self.t = meas.t
        K = y.shape[0]
        self.K = K
        m = red.m
        # Scaling: modal amplitude A such that the data's largest output is O(1) for mode 1.
        ymax = float(np.nanmax(np.abs(y)))
        gain = np.max(np.stack([np.diag(C) for C in red.sensor_matrices]) / red.omega**2)
        A = np.sqrt(max(ymax, 1e-300) / gain)
        self.amplitude = A
        self._Dx = np.concatenate([A / red.omega, A * np.ones(m)])
        self._Du = A * red.omega
        # Priors: initial modal state (weak, 1/omega) and the sign prior.
        p0 = ident.initial_load if initial_load is None else float(initial_load)
        if p0 == 0 or not np.isfinite(p0):
            raise InputError(f"initial_load = {p0!r}: expected a non-zero pressure (its sign fixes the sign)")
        peak = getattr(ident, "initial_deflection", 0.0) if initial_deflection is None else initial_deflection
        self.initial_load, self.initial_deflection = p0, float(peak)
        f_prior = self.load_space.project(lambda x, yy: np.full_like(x, p0))
        x_prior = np.zeros(2 * m)
        q_prior = None
        if self.initial_deflection != 0:
            z0 = self.model.project(bubble(problem.width, problem.height, self.initial_deflection))
            q_prior = red.to_modal(z0)
            x_prior[:m] = q_prior
        self.sign_prior = SignPrior(f_prior, q_prior)
        self.x_prior = x_prior
        self._set_state_prior(s.state_prior)
        self._lift_scale = abs(p0) * problem.width * problem.height
        # Window geometry (seconds or samples, see MHESettings.samples).
        window, self.stride = s.samples(dt)
        self.N = min(window, K)
        self.stride = min(self.stride, self.N)
        blocks = window // self.stride if (s.load_model == "random_walk" and self.N == window) else 1
        # The start-up (scan, lambda path, onset) treats the first window's load as constant; a
        # random walk switches to its blocks afterwards (_first_window).
        self._blocks = blocks
        self.basis = red.window(self.N, 1)
        self.B = 1
        self._seg = max(3, int(round(s.consistency_segment_s / dt)))
        self.bounds_points = self._bound_rows() if s.pressure_bounds else None
        self._rw = None
        self._rw_metric = l2_metric(red) if blocks > 1 else None
        # History (per sample): modal forces, modal displacement, lift std.
        self._u = np.full((K, m), np.nan)
        self._q = np.full((K, m), np.nan)
        self._lift_std = np.full(K, np.nan)
        self._windows: list[dict] = []
        self.restarts: list[dict] = []
        self.onset: dict = {"samples_skipped": 0, "t_start": float(meas.t[0]), "attempts": []}
        self.start = 0
        self._shift = self.stride
        # Warnings go into the result (info["warnings"]) for the workflow to report once; logging
        # them here as well printed them twice on the command line.
        self.warnings: list[str] = []
        sol, report = self._first_window()
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

    # -- start-up and lambda -----------------------------------------------------------------

    # -- stepping ----------------------------------------------------------------------------
    def _accept(self, sol: WindowSolution, first: bool = False) -> None:
        """Record a window's answer in the histories."""
        red = self.reduced
        m, B, N = red.m, self.B, self.N
        self._sol = sol
        theta = sol.theta
        Q = red.modal_trajectory(self.basis, theta)
        window = slice(self.start, self.start + N)
        w = self.w[window]
        chi2 = float(np.sum(w * (self.y[window] - red.outputs(Q)) ** 2))
        U = theta[2 * m :].reshape(B, m)
        L = self.basis.block_length
        block_of = np.minimum(np.arange(N) // L, B - 1)
        lift_std = self._lift_band(sol.hessian)
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
        self._absorb(shift)
        m, B = self.reduced.m, self.B
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
            k = first_inconsistent(self._profile(sol.theta, self.start, self._level))
            if k is not None and self._restart(self.start + k, sol.theta):
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
