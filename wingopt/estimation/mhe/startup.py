"""Start-up of the moving-horizon estimator: state prior, lambda path, first window, restarts.

Mixed into :class:`~wingopt.estimation.mhe.estimator.MovingHorizonEstimator`: everything that
happens before the estimator can simply slide its window on (and again when the data contradict
the estimate and it must start afresh). Nothing here looks at the true load.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import scipy.linalg as sla

from wingopt.estimation.mhe.consistency import leading_onset, segment_profile
from wingopt.estimation.mhe.load_model import RandomWalk
from wingopt.estimation.mhe.solvers import WindowSolution
from wingopt.estimation.mhe.start import SignPrior, start_window
from wingopt.estimation.mhe.window import WindowProblem
from wingopt.estimation.regularization import LambdaPoint, choose_lambda

__all__ = ["StartUp"]

log = logging.getLogger(__name__)


class StartUp:
    """First window, lambda and state prior (mixin of the estimator)."""

    def _first_window(self):
        """State prior, lambda and the first window, after the load's onset.

        The first window is solved as configured (state prior, lambda path and rule, start-up); then
        its residuals are tested segment by segment (:func:`~wingopt.estimation.mhe.consistency.leading_onset`).
        When the record *starts* with samples the load model cannot explain (the flow starting and
        the load ramping up from rest), those samples are left out and everything is redone from
        the first consistent segment: a first window the model cannot fit would otherwise become
        the arrival cost of every later window (measured: a 40 ms ramp from rest put the final lift
        37 % low). The prior initial deflection applies to the record's first sample only, so a
        later start has an unknown initial state. Returns ``(solution, start report)``.
        """
        s = self.settings
        while True:
            self.lambda_info = {}
            self.state_prior_info = {"chosen": s.state_prior, "rule": "fixed"}
            self._set_state_prior(s.state_prior)
            if s.state_prior_choices:
                sol, report = self._choose_state_prior()
                # The onset test judges the load model, not the prior on the initial state: it
                # uses the weakest candidate's fit (a tight prior that is slightly off misfits
                # the first samples by itself: measured on a 13x7 estimator).
                chosen, lam = self.state_prior, self.lam
                rel, theta, self.lam = self._weakest
                self._set_state_prior(rel)
                prof = self._profile(theta, self.start, leverage=True)
                self._set_state_prior(chosen)
                self.lam = lam
            else:
                if s.regularization is not None:
                    self.lam = float(s.regularization)
                    sol, report = self._start(self.lam)
                else:
                    sol, report = self._choose_lambda()
                prof = self._profile(sol.theta, self.start, leverage=True)
            self._level = prof.level
            skip = leading_onset(prof) if s.consistency else 0
            self.onset["attempts"].append(
                {"start": self.start, "level": prof.level, "skip": skip, "chi2_per_datum": prof.per_datum.tolist()}
            )
            if skip == 0:
                break
            if self.start + skip + self.N > self.K:
                self.warnings.append(
                    "the load model does not explain the start of the record and too little data is left "
                    "to skip it: keeping the first window as it is"
                )
                break
            self.start += skip
            log.info(
                "the first %d samples (to t = %.4g s) are not explained by a constant load (load onset?): "
                "starting the estimate there",
                self.start,
                self.t[self.start],
            )
            # The prior initial state (e.g. the protocol's bubble) belongs to the record's start.
            self.x_prior = np.zeros_like(self.x_prior)
            self.sign_prior = SignPrior(self.sign_prior.load, None)
        self.onset.update(samples_skipped=self.start, t_start=float(self.t[self.start]))
        self._origin = self.start
        if self._blocks > 1:
            sol = self._to_random_walk(sol)
        return sol, report

    def _profile(self, theta: np.ndarray, start: int, level: float | None = None, leverage: bool = False):
        """Segment misfit profile of the window starting at ``start`` at ``theta``.

        ``leverage``: account for the noise the fit absorbs (hat-matrix diagonal, Gauss–Newton at
        ``theta``); needed where the window's own unknowns dominate (a start-up, whose free initial
        state fits the first samples), negligible behind a strong arrival cost.
        """
        red, N = self.reduced, self.N
        sl = slice(start, start + N)
        pred = red.outputs(red.modal_trajectory(self.basis, theta))
        r2 = self.w[sl] * (self.y[sl] - pred) ** 2
        h = None
        if leverage:
            problem = self._window_problem(start, self.lam)
            _, J = problem.linearize(theta)
            D = problem.scale
            Js = J * D[None, :]
            H, _ = problem.normal_equations(theta)
            Hs = D[:, None] * H * D[None, :]
            try:
                X = sla.cho_solve(sla.cho_factor(0.5 * (Hs + Hs.T)), Js.T)
                h = np.einsum("ij,ji->i", Js, X).reshape(N, red.p).sum(axis=1)
            except np.linalg.LinAlgError:
                h = None
        return segment_profile(r2, self.w[sl] > 0, self._seg, level, leverage=h)

    def _to_random_walk(self, sol: WindowSolution) -> WindowSolution:
        """Switch the first window from one load to the random walk's blocks and re-solve it.

        Lambda (a property of the load's spatial prior) and the start-up are found with a constant
        load over the first window: 4x fewer unknowns on the lambda path, and the consistency test
        has already checked that a constant load explains the window. The random walk is sized by
        that estimate (:class:`~wingopt.estimation.mhe.load_model.RandomWalk`), every block starts
        from it.
        """
        m, s = self.reduced.m, self.settings
        u = sol.theta[2 * m : 3 * m]
        self._rw = RandomWalk.build(self.reduced, s.load_timescale, s.shape_timescale, u, self._rw_metric)
        self.B = self._blocks
        self.basis = self.reduced.window(self.N, self.B)
        theta = np.concatenate([sol.theta[: 2 * m]] + [u] * self.B)
        return self.solver.solve(self._window_problem(self.start, self.lam), theta)

    def _set_state_prior(self, rel: float) -> None:
        """Arrival cost of the first window: the prior on the initial modal state only.

        Std ``rel * A / omega_j`` (displacements) and ``rel * A`` (velocities) around ``x_prior``;
        information form over ``(x, u_1)`` in physical units.
        """
        m = self.reduced.m
        sx = rel * self._Dx
        Ia = np.zeros((3 * m, 3 * m))
        Ia[: 2 * m, : 2 * m] = np.diag(1.0 / sx**2)
        self._arrival = (Ia, np.concatenate([self.x_prior / sx**2, np.zeros(m)]))
        self.state_prior = float(rel)

    def _choose_state_prior(self):
        """Pick ``state_prior`` among ``state_prior_choices`` by the first window's evidence.

        For each candidate the first window's lambda path is computed as usual and the Laplace log
        evidence (:meth:`~wingopt.estimation.mhe.window.WindowProblem.log_evidence`) is maximised
        over the path's lambdas (type-II maximum likelihood; with a fixed lambda, the evidence at
        it). The evidence must be compared at lambdas that fit the data: at an over-regularised
        lambda the initial state absorbs the misfit and a weak state prior wins (measured). Of the
        candidates the one with the largest evidence is kept, with its lambda and start-up. Data
        only: how well the prior initial state (the problem's ``initial_deflection``, or rest)
        explains the transient. Returns ``(solution, start report)`` of the chosen candidate.
        """
        s = self.settings
        evid, runs = {}, {}
        for rel in s.state_prior_choices:
            self._set_state_prior(rel)
            if s.regularization is not None:
                self.lam = float(s.regularization)
                sol, report = self._start(self.lam)
                ev = self._window_problem(self.start, self.lam).log_evidence(sol.theta)
            else:
                sol, report = self._choose_lambda()
                ev = max(p["log_evidence"] for p in self.lambda_info["path"] if p["log_evidence"] is not None)
            evid[float(rel)] = float(ev)
            runs[float(rel)] = (sol, report, self.lam, self.lambda_info)
        best = max(evid, key=evid.get)
        self._set_state_prior(best)
        sol, report, self.lam, self.lambda_info = runs[best]
        weak = max(runs)
        self._weakest = (weak, runs[weak][0].theta, runs[weak][2])
        self.state_prior_info = {"chosen": best, "rule": "evidence", "log_evidence": evid}
        log.info("state prior %g chosen by the evidence %s", best, evid)
        return sol, report

    def _natural(self, theta: np.ndarray, v: np.ndarray) -> float:
        """``(v^T H_data v) / (v^T S^-1 v)`` at ``theta`` (see :meth:`natural_lambda`)."""
        m = self.reduced.m
        _, J = self._window_problem(self.start, 0.0).linearize(theta)
        Ju = J[:, 2 * m : 3 * m] @ v
        return float(Ju @ Ju) / float(v @ self.reduced.roughness @ v)

    def _probe_lambda(self) -> float:
        """A moderate first lambda: the grid's geometric middle times the scale at the prior guess."""
        from wingopt.estimation.mhe.start import smooth_load_shapes

        v = smooth_load_shapes(self.reduced, 1)[0]
        grid = sorted(self.settings.lambda_grid)
        return self._natural(self._guess(v), v) * float(np.sqrt(grid[0] * grid[-1]))

    # -- start-up and lambda -----------------------------------------------------------------
    def _start(self, lam: float, extra_starts: tuple = ()):
        problem = self._window_problem(self.start, lam)
        s = self.settings
        return start_window(
            problem,
            self.solver,
            self._coarse_solver,
            self.sign_prior,
            self.x_prior,
            self._lift_scale,
            state_modes=s.start_state_modes,
            shapes=s.start_shapes,
            amplitudes=s.start_amplitudes,
            extra_starts=extra_starts,
        )

    def natural_lambda(self) -> float | None:
        """Scale of lambda at which roughness and data information balance along the smoothest shape.

        ``lambda_nat = (v^T H_data v) / (v^T S^-1 v)`` for the modal forces ``v`` of the smoothest
        load shape, with ``H_data`` the data's Gauss–Newton matrix at the start-up estimate; the
        lambda grid is relative to it. ``None`` when lambda was given (no path was computed).
        """
        return getattr(self, "_lam_nat", None)

    def _choose_lambda(self):
        """Lambda path on the first window (continuation from the start-up) and the data-only rule."""
        s = self.settings
        # Start-up at a moderate weight, measured in the problem's natural scale.
        from wingopt.estimation.mhe.start import smooth_load_shapes

        v = smooth_load_shapes(self.reduced, 1)[0]
        grid = sorted(s.lambda_grid)
        # A first guess of the scale from the prior state and a smooth load of the prior's size,
        # the start-up there, then the scale at the start-up's answer (what the grid is built on).
        lam_probe = self._probe_lambda()
        sol0, report = self._start(lam_probe)
        lam_nat = self._natural(sol0.theta, v)
        self._lam_nat = lam_nat
        path: list[LambdaPoint] = []
        sols: dict[float, np.ndarray] = {}
        lams = [lam_nat * g for g in grid]

        def solve_at(lam, theta0):
            problem = self._window_problem(self.start, lam)
            sol = self.solver.solve(problem, theta0)
            sols[lam] = sol.theta
            path.append(self._path_point(problem, sol, lam))
            return sol

        # Continuation outwards from the probe, each solve warm-started from its neighbour.
        i0 = int(np.argmin([abs(np.log(lam / lam_probe)) for lam in lams]))
        theta = sol0.theta
        for i in range(i0, len(lams)):
            theta = solve_at(lams[i], theta).theta
        theta = sols[lams[i0]]
        for i in range(i0 - 1, -1, -1):
            theta = solve_at(lams[i], theta).theta
        # Refine once inside the bracket of the chosen lambda (the grid is coarse, the knee sharp).
        lam, info = choose_lambda(path, s.lambda_rule)
        known = sorted(sols)
        lo = max((x for x in known if x <= lam), default=known[0])
        hi = min((x for x in known if x >= lam), default=known[-1])
        if hi > lo * 1.5:
            mid_lam = float(np.sqrt(lo * hi))
            solve_at(mid_lam, sols[lo])
            lam, info = choose_lambda(path, s.lambda_rule)
        # At the chosen weight, start afresh (scan, both signs) and from the nearest path
        # solution: the orientation and the family of the probe's minimum need not be the best
        # at this lambda (the probe is far more regularised).
        near = min(sols, key=lambda x: abs(np.log(x / lam)))
        sol, report = self._start(lam, extra_starts=(sols[near],))
        self.lam = lam
        info["natural_scale"] = lam_nat
        info["path"] = [dataclasses.asdict(p) for p in sorted(path, key=lambda p: p.lam)]
        self.lambda_info = info
        return sol, report

    def _guess(self, v: np.ndarray) -> np.ndarray:
        theta = np.zeros(self.dim)
        theta[: 2 * self.reduced.m] = self.x_prior
        for b in range(self.B):
            theta[(2 + b) * self.reduced.m : (3 + b) * self.reduced.m] = v * self._lift_scale
        return theta

    @staticmethod
    def _path_point(problem: WindowProblem, sol: WindowSolution, lam: float) -> LambdaPoint:
        _, J = problem.linearize(sol.theta)
        D = problem.scale
        Hs = D[:, None] * sol.hessian * D[None, :]
        Js = J * D[None, :]
        c = sla.cho_factor(Hs)
        dof = float(np.trace(sla.cho_solve(c, Js.T @ Js)))
        try:
            evidence = problem.log_evidence(sol.theta)
        except np.linalg.LinAlgError:  # a singular prior (free space without edge term): no evidence
            evidence = None
        return LambdaPoint(float(lam), problem.data_cost(sol.theta), dof, problem.n_data, evidence)

    def _restart(self, k: int, theta: np.ndarray) -> bool:
        """Start the estimate afresh at sample ``k``, where the data stopped being consistent with it.

        The window's data contradict the estimate and its arrival cost (the load changed faster
        than the load model allows: a gust, or any change under the constant model). The arrival
        cost is dropped (the weak prior on the state only) and the start-up (scan, coarse-to-fine,
        sign) is redone at the chosen lambda from ``k`` on. Unlike the record's onset nothing is
        skipped: a load that keeps changing faster than the model allows is then followed by
        repeated restarts (a piecewise-constant estimate under the constant model) instead of
        leaving a gap in the history. The sign prior is the user's ``initial_load`` and the
        deflection at ``k`` of the rejected window (``theta``; its sign is known by now). The
        window keeps its length, so a change within the last ``window`` samples restarts at
        ``K - window``. Returns ``False`` (nothing done) when no later start is possible.
        """
        m, N = self.reduced.m, self.N
        origin = min(int(k), self.K - N)
        if origin <= self._origin:
            return False
        q_now = self.reduced.modal_trajectory(self.basis, theta)[origin - self.start]
        self.x_prior = np.zeros(2 * m)
        self.x_prior[:m] = q_now
        self.sign_prior = SignPrior(self.sign_prior.load, q_now)
        self.start = origin
        self._set_state_prior(self.state_prior)
        sol, report = self._start(self.lam)
        self.restarts.append(
            {
                "detected_at": int(k),
                "t_detected": float(self.t[k]),
                "start": self.start,
                "t_start": float(self.t[self.start]),
            }
        )
        log.info(
            "data inconsistent with the estimate at t = %.4g s: restarted at t = %.4g s", self.t[k], self.t[self.start]
        )
        self._origin = self.start
        self._shift = self.stride
        self._accept(sol, first=True)
        return True
