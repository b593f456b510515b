"""Streaming load identification: one sample in, one estimate out, bounded memory and work.

:class:`StreamingEstimator` turns the moving-horizon estimator (:mod:`wingopt.estimation.mhe`)
into an online one for a data-acquisition stream::

    est = StreamingEstimator(model, StreamSettings())
    for t, y in stream:                    # y: one value per sensor, NaN where missing
        e = est.push(t, y)                 # Estimate: lift ± lift_std, load, chi2 per datum, adequate
        print(e.t, e.lift, e.lift_std)

Phases (``Estimate.phase``):

* ``waiting`` — fewer than ``min_samples`` samples: no estimate (lift NaN, std inf); the noise
  level cannot be estimated yet.
* ``provisional`` — until ``startup_windows`` windows of samples have arrived: a real-time
  iteration on all samples so far, from the prior (uniform ``initial_load``, the problem's initial
  bubble) with a provisional lambda (the batch's natural scale at the grid's geometric middle) and
  the noise level of the data so far. Its ``lift_std`` says how sure it is (large at first).
* ``startup`` / ``tracking`` — once, on the buffered samples, the batch estimator's ``setup``
  runs: noise level, lambda path and rule, load onset, scan / coarse-to-fine start and sign
  (reused, not copied: :meth:`MovingHorizonEstimator.setup`). Noise level and lambda are then
  kept. This one sample costs the batch start-up (0.30–0.36 s of CPU on the 25x13 protocol, measured in
  ``benchmarks/bench_streaming.py``); the caller buffers the samples meanwhile. From then on, per
  sample: the new row enters the window, the oldest leaves it (frozen into the arrival cost),
  ``relinearize`` window rows are re-linearised (a full pass every ``window / relinearize``
  samples), and one Gauss–Newton step is taken (a Cholesky factorisation of the active unknowns:
  up to 3m at first, the m modal forces once the initial states have decayed and are marginalised).

Work per sample is O(m^2 (relinearize + 2) p + m^3): no loop over the window. Memory: the window's
rows and Jacobians and one ``3m x 3m`` information matrix; nothing grows with the record.

The lift's band integrates lambda out like the batch (:attr:`MHESettings.band_decades`, 9 points),
one of the 9 lambda points per sample (the band is the mean over the latest 9 samples).
Adequacy: the misfit per datum of the window (residuals at the rows' latest linearisations)
against ``level * chi2_{1-a}(n) / n`` with the start-up's misfit level
(:mod:`wingopt.estimation.mhe.consistency`, ``a = SIGNIFICANCE``); a ``False`` flag means the data
of the last window are not explained by a constant load (the streaming estimator does not restart;
the batch does).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.linalg import lapack

from wingopt.errors import InputError
from wingopt.estimation.core.distributions import chi2_isf
from wingopt.estimation.core.noise import resolve_noise_std
from wingopt.estimation.core.result import Estimate
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.mhe import MovingHorizonEstimator
from wingopt.estimation.mhe.cold_start import smooth_load_shapes
from wingopt.estimation.mhe.consistency import SIGNIFICANCE
from wingopt.estimation.mhe.model import MHEModel
from wingopt.estimation.streaming.rows import LinearRows, RtiNormalEquations
from wingopt.estimation.streaming.types import SampleClock, StreamSettings
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel, bubble

__all__ = ["StreamSettings", "Estimate", "StreamingEstimator"]

log = logging.getLogger(__name__)


class StreamingEstimator:
    """Online moving-horizon load estimator (real-time iteration), see the module docstring.

    Parameters
    ----------
    model : MembraneModel
        The estimator's model (mesh).
    settings : StreamSettings, optional
    noise_std : float or array, optional
        Sensor noise std; default: the problem's ``noise_std``, else estimated from the data.
    initial_load, initial_deflection : float, optional
        Sign prior and prior initial bubble, as for :meth:`MovingHorizonEstimator.setup`.
    rows : callable, optional
        ``rows(reduced) -> row model`` (:mod:`wingopt.estimation.streaming.rows`: ``dim``, ``p``,
        ``m``, ``row_shape``, ``lift_row``, ``load_slice``, ``reduced``, ``row_data()``,
        ``evaluate(theta, rows, columns)``, optionally ``decay_schedule()``); default
        :class:`~wingopt.estimation.streaming.rows.LinearRows`, the linear membrane.
    """

    def __init__(
        self,
        model: MembraneModel,
        settings: StreamSettings | None = None,
        noise_std: np.ndarray | float | None = None,
        initial_load: float | None = None,
        initial_deflection: float | None = None,
        rows: Callable[[MHEModel], Any] = LinearRows,
    ) -> None:
        self.model = model
        self._make_rows = rows
        self.settings = s = with_declaration(settings or StreamSettings(), model.problem)
        self._batch = MovingHorizonEstimator(model, s.mhe)
        self.reduced = self._batch.reduced
        ident = s.declaration
        self.names = tuple(model.problem.sensor_names)
        self.p = len(self.names)
        self._noise_arg = noise_std
        self.initial_load = ident.initial_load if initial_load is None else float(initial_load)
        if self.initial_load == 0 or not np.isfinite(self.initial_load):
            raise InputError(f"initial_load = {self.initial_load!r}: expected a non-zero pressure (its sign)")
        peak = getattr(ident, "initial_deflection", 0.0) if initial_deflection is None else initial_deflection
        self.initial_deflection = float(peak)
        self.count = 0
        self.phase = "waiting"
        self._clock = SampleClock(self.names)
        self._buf_t: list[float] = []
        self._buf_y: list[np.ndarray] = []
        self._core: RtiNormalEquations | None = None
        self.startup: dict[str, Any] = {}
        self._isf: dict[int, float] = {}
        self.last: Estimate | None = None

    @property
    def dt(self) -> float | None:
        """The sample period (s), fixed by the first two samples; ``None`` before."""
        return self._clock.dt

    # -- public ------------------------------------------------------------------------------
    def push(self, t: float, y) -> Estimate:
        """Add one sample (time ``t`` in s, one value per sensor, NaN = missing); return the estimate."""
        t, y = self._clock.accept(t, y)
        k = self.count
        self.count += 1
        if self.phase in ("waiting", "provisional"):
            self._buf_t.append(t)
            self._buf_y.append(y)
        if self.phase == "waiting":
            if self.count < self.settings.min_samples:
                self.last = Estimate(k, t, np.nan, np.inf, None, np.nan, True, "waiting")
                return self.last
            self._provisional_start()
            return self._estimate(k, t)
        if self.phase == "provisional" and self.count >= self._startup_at:
            self._run_startup()
            return self._estimate(k, t, phase="startup")
        self._push_row(*self._row(y), self.settings.relinearize)
        self._gauss_newton()
        return self._estimate(k, t)

    def _push_row(self, y: np.ndarray, sw: np.ndarray, relinearize: int) -> None:
        core = self._core
        core.push(self.theta, y, sw, relinearize)
        sched = self._decay
        while sched and core.oldest_offset >= sched[0][0]:
            core.deactivate(sched.pop(0)[1])

    @property
    def lift(self) -> float:
        return np.nan if self.last is None else self.last.lift

    def info(self) -> dict:
        """Diagnostics: phase, samples, the start-up's choices (lambda, noise level, onset, sign)."""
        out = {"phase": self.phase, "samples": self.count, "dt_s": self.dt, **self.startup}
        if self._core is not None:
            out.update(
                window=self._core.window,
                absorbed_rows=self._core.absorbed,
                relinearize_per_sample=self.settings.relinearize,
                normal_equations_drift=self._core.drift(),
            )
        return out

    # -- phases ------------------------------------------------------------------------------
    def _row(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        miss = ~np.isfinite(y)
        return np.where(miss, 0.0, y), np.where(miss, 0.0, 1.0 / self.sigma)

    def _setup_scales(self, red: MHEModel, ymax: float) -> None:
        """Scaled unknowns as in the batch: the data's largest output is O(1) for mode 1."""
        gain = np.max(np.stack([np.diag(C) for C in red.sensor_matrices]) / red.omega**2)
        A = np.sqrt(max(ymax, 1e-300) / gain)
        self._D = np.concatenate([A / red.omega, A * np.ones(red.m), A * red.omega])

    def _provisional_start(self) -> None:
        """First estimate: the prior, a provisional lambda and noise level, all samples so far."""
        s, model = self.settings, self.model
        problem = model.problem
        Y = np.array(self._buf_y)
        window, _ = s.mhe.samples(self.dt)
        self.window = window
        self._startup_at = max(window, int(round(s.startup_windows * window)))
        red = self.reduced
        if abs(self.dt - red.dt) > 1e-9 * red.dt:
            red = MHEModel.build(model, self._batch.load_space, s.mhe.modes, self.dt)
        self._red = red
        self.sigma = self._noise(Y)
        m = red.m
        self._setup_scales(red, float(np.nanmax(np.abs(Y))) if np.isfinite(Y).any() else 1.0)
        x_prior = np.zeros(2 * m)
        if self.initial_deflection != 0:
            z0 = model.project(bubble(problem.width, problem.height, self.initial_deflection))
            x_prior[:m] = red.to_modal(z0)
        v = smooth_load_shapes(red, 1)[0]
        lift_v = float(red.lift_row @ v)
        v = v * np.sign(lift_v * self.initial_load) if lift_v != 0 else v
        theta = np.concatenate([x_prior, v * abs(self.initial_load) * problem.width * problem.height])
        rows = self._make_rows(red)
        # Provisional lambda: the batch's natural scale (data information along the smoothest load
        # shape over its roughness) at the grid's geometric middle, from the samples so far.
        seqs = np.array([rows.row_data() for _ in range(Y.shape[0])])
        rows.restart()
        _, J = rows.evaluate(theta, seqs)
        yw, sw = self._row(Y)
        Ju = (J[:, :, 2 * m :] * sw[:, :, None]) @ v
        grid = sorted(s.mhe.lambda_grid)
        lam_nat = float(np.sum(Ju**2)) / float(v @ red.roughness @ v)
        lam = s.mhe.regularization or lam_nat * float(np.sqrt(grid[0] * grid[-1]))
        sx = s.mhe.state_prior * self._D[: 2 * m]
        self._begin(rows, window, lam, sx, x_prior, level=1.0)
        k = min(int(s.provisional_state_modes), m)
        self._core.deactivate(np.r_[k:m, m + k : 2 * m])  # held at the prior (before any data)
        self.theta = theta
        for k in range(Y.shape[0]):
            self._push_row(yw[k], sw[k], 0)
        self._gauss_newton()
        self.phase = "provisional"

    def _begin(self, rows, window, lam, sx, x_prior, level) -> None:
        """The real-time iteration's normal equations with the prior, in scaled unknowns."""
        m, D = rows.m, self._D
        Du = D[2 * m :]
        self._Ru = Du[:, None] * rows.reduced.roughness * Du[None, :]
        Dx = D[: 2 * m]
        H0 = np.zeros((3 * m, 3 * m))
        H0[: 2 * m, : 2 * m] = np.diag((Dx / sx) ** 2)
        H0[2 * m :, 2 * m :] = lam * self._Ru
        g0 = np.concatenate([Dx * x_prior / sx**2, np.zeros(m)])
        self._rows, self.lam, self._level = rows, float(lam), float(level)
        self._core = RtiNormalEquations(rows, window, H0, g0, D)
        self._decay = rows.decay_schedule() if hasattr(rows, "decay_schedule") else []
        d = self.settings.mhe.band_decades
        self._band_x = np.linspace(-d, d, 9) if d > 0 else np.zeros(1)
        self._band_var = np.full(self._band_x.size, np.nan)
        self._band_i = 0

    def _noise(self, Y: np.ndarray) -> np.ndarray:
        declared = self.settings.declaration.noise_std
        return resolve_noise_std(Y, self.model.problem.sensor_names, self._noise_arg, None, declared)[0]

    def _run_startup(self) -> None:
        """The batch start-up on the buffered samples, then the tracking window from its answer."""
        t0, c0 = time.perf_counter(), time.process_time()
        batch = self._batch
        K = len(self._buf_t)
        tt = self._buf_t[0] + self.dt * np.arange(K)
        Y = np.array(self._buf_y)
        meas = Measurements(t=tt, values=Y, sensor_names=self.names, source="stream start-up")
        batch.setup(meas, noise_std=self._noise_arg, initial_load=self.initial_load,
                    initial_deflection=self.initial_deflection)  # fmt: skip
        red = batch.reduced
        # The first window's optimum (state at the window start = our origin, constant load).
        # Private attribute of the batch estimator: it has no public accessor for its window solution.
        theta = np.array(batch.window_solution.theta, dtype=float)
        origin = int(batch.start)
        self.sigma = np.asarray(batch.noise_std, dtype=float)
        m = red.m
        self._D = np.asarray(batch.scale, dtype=float)[: 3 * m].copy()
        attempts = batch.onset.get("attempts") or [{}]
        rows = self._make_rows(red)
        sx = batch.state_prior * self._D[: 2 * m]
        self._begin(rows, batch.N, batch.lam, sx, np.asarray(batch.x_prior), attempts[-1].get("level", 1.0))
        yw, sw = self._row(Y[origin:])
        for k in range(yw.shape[0]):  # rows beyond the window are frozen at the batch optimum
            self._core.push(theta, yw[k], sw[k], 0)
        self.theta = theta
        for _ in range(2):  # converge on the samples after the batch's first window
            self._gauss_newton(trust=np.inf)
            self._core.relinearize_all(self.theta)
        self._gauss_newton(trust=np.inf)
        self._buf_t, self._buf_y = [], []
        self.phase = "tracking"
        rep = batch.start_report
        self.startup = {
            "startup_sample": self.count - 1,
            "startup_wall_s": time.perf_counter() - t0,
            "startup_cpu_s": time.process_time() - c0,
            "origin_sample": origin,
            "lambda": batch.lam,
            "lambda_selection": batch.lambda_info,
            "noise_std": self.sigma.tolist(),
            "noise_source": batch.noise_source,
            "onset": {k: v for k, v in batch.onset.items() if k != "attempts"},
            "consistency_level": self._level,
            "sign": {"score": rep.sign_score, "determined": bool(rep.sign_score >= 0.1)},
        }

    # -- one Gauss–Newton step and the estimate ----------------------------------------------
    def _gauss_newton(self, trust: float | None = None) -> None:
        """One Gauss–Newton step on the current normal equations (raw LAPACK: the per-sample path)."""
        core = self._core
        a = core.active
        D = self._D[a]
        Hs = core.H  # scaled unknowns, lower triangle
        L, info = lapack.dpotrf(Hs, lower=1, clean=1)
        if info != 0:  # not positive definite to working precision: a relative ridge
            Hs = Hs + 1e-12 * np.max(np.diag(Hs)) * np.eye(Hs.shape[0])
            L, info = lapack.dpotrf(Hs, lower=1, clean=1)
            if info != 0:
                raise np.linalg.LinAlgError("streaming estimator: normal equations not positive definite")
        xi = self.theta[a] / D
        sol, _ = lapack.dpotrs(L, core.g, lower=1)
        step = sol - xi
        limit = self.settings.trust if trust is None else trust
        norm = float(np.sqrt(step @ step))
        if norm > limit:
            step *= limit / norm
        self.theta[a] = D * (xi + step)
        self._L, self._Hs = L, Hs

    def _lift_std(self) -> float:
        """1-sigma of the lift: Laplace at this sample, lambda integrated over the latest 9 samples."""
        ls = (self._D * self._rows.lift_row)[self._core.active]
        v, _ = lapack.dtrtrs(self._L, ls, lower=1)
        x = self._band_x
        mid = x.size // 2
        self._band_var[mid] = float(v @ v)
        if x.size > 1:
            i = self._band_i = (self._band_i + 1) % x.size
            if i == mid:
                i = self._band_i = (i + 1) % x.size
            m = self._rows.m
            H = self._Hs.copy()
            H[-m:, -m:] += self.lam * (10.0 ** x[i] - 1.0) * self._Ru
            Li, info = lapack.dpotrf(H, lower=1, clean=1)
            if info == 0:
                w, _ = lapack.dtrtrs(Li, ls, lower=1)
                self._band_var[i] = float(w @ w)
        var = self._band_var
        if var[0] != var[0]:  # the first samples: the band points not computed yet count as the plain one
            var[np.isnan(var)] = var[mid]
        return float(np.sqrt(max(var.sum() / var.size, 0.0)))

    def _threshold(self, n: int) -> float:
        if n not in self._isf:
            if len(self._isf) > 64:
                self._isf.clear()
            self._isf[n] = float(chi2_isf(SIGNIFICANCE, max(n, 1)))
        return self._isf[n]

    def _estimate(self, k: int, t: float, phase: str | None = None) -> Estimate:
        core, rows = self._core, self._rows
        n = core.n_data
        chi = max(core.chi2, 0.0)
        adequate = bool(n == 0 or chi <= self._level * self._threshold(n))
        u = self.theta[rows.load_slice]
        self.last = Estimate(
            k,
            t,
            float(rows.lift_row @ self.theta),
            self._lift_std(),
            rows.reduced.load(u),
            chi / max(n, 1),
            adequate,
            phase or self.phase,
        )
        return self.last
