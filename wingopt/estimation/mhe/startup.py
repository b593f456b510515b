"""Start-up of the moving-horizon estimator: state prior, lambda path, first window, restarts.

:class:`StartUp` is held by :class:`~wingopt.estimation.mhe.estimator.MovingHorizonEstimator`:
everything that happens before the estimator can simply slide its window on (and again when the
data contradict the estimate and it must start afresh). It owns the start-up's choices (lambda,
state prior, the priors on the initial state and the sign) and sets the arrival cost of the
:class:`~wingopt.estimation.mhe.information.WindowPrior` it is given for every first window it
solves. Nothing here looks at the true load.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg as sla

from wingopt.estimation.mhe.cold_start import SignPrior, StartReport, smooth_load_shapes, start_window
from wingopt.estimation.mhe.consistency import SegmentProfile, leading_onset, segment_profile
from wingopt.estimation.mhe.information import WindowPrior
from wingopt.estimation.mhe.lambda_path import lambda_path, natural_scale
from wingopt.estimation.mhe.record import Record
from wingopt.estimation.mhe.settings import MHESettings
from wingopt.estimation.mhe.solvers import WindowSolution, WindowSolver
from wingopt.estimation.mhe.window import WindowProblem

__all__ = ["StartUp"]

log = logging.getLogger(__name__)


class StartUp:
    """First window, lambda and state prior of one record; restarts.

    Parameters
    ----------
    prior : WindowPrior
        The estimator's window prior; its arrival cost is set to the state prior of each first window.
    record : Record
        The record (outputs, weights, sample times).
    settings : MHESettings
    solver, coarse_solver : WindowSolver
        The window solver and the fast dense one of the coarse start-up problems.
    sign_prior : SignPrior
        Sign prior of the record's start (the prior load and, when known, initial deflection).
    x_prior : ndarray
        Prior initial modal state (displacements, velocities) at the record's start.
    lift_scale : float
        Lift (N) of the prior load spread over the membrane (the size of a start-up guess).

    Attributes
    ----------
    lam : float
        The chosen lambda (after :meth:`first_window`).
    lambda_info : dict
        How it was chosen (rule, path); empty when lambda was given.
    state_prior, state_prior_info
        The chosen relative std of the initial state's prior and how it was chosen.
    natural_scale : float or None
        ``lambda_nat`` of the latest lambda path (``None`` when lambda was given).
    level : float
        The first window's chi-square level (the later consistency tests are relative to it).
    origin : int
        First sample of the current estimate (the record's onset, or the latest restart).
    onset : dict
        Samples left out at the record's start (``samples_skipped``, ``t_start``) and every attempt.
    restarts : list of dict
        Where the data contradicted the estimate and where it was started afresh.
    """

    def __init__(
        self,
        prior: WindowPrior,
        record: Record,
        settings: MHESettings,
        solver: WindowSolver,
        coarse_solver: WindowSolver,
        sign_prior: SignPrior,
        x_prior: np.ndarray,
        lift_scale: float,
    ) -> None:
        self.prior, self.reduced = prior, prior.reduced
        self.y, self.w, self.t = record.y, record.w, record.t
        self.settings, self.solver, self.coarse_solver = settings, solver, coarse_solver
        self.sign_prior, self.x_prior = sign_prior, x_prior
        self.lift_scale = lift_scale
        # Samples per segment of the consistency tests.
        self.segment = max(3, int(round(settings.consistency_segment_s / record.dt)))
        self.lam: float | None = None
        self.lambda_info: dict = {}
        self.state_prior = float(settings.state_prior)
        self.state_prior_info: dict = {}
        self.natural_scale: float | None = None
        self.level: float | None = None
        self.origin = 0
        self.onset: dict = {"samples_skipped": 0, "t_start": float(record.t[0]), "attempts": []}
        self.restarts: list[dict] = []
        self.set_state_prior(self.state_prior)

    def problem(self, start: int, lam: float) -> WindowProblem:
        """The window starting at ``start`` with the window prior's current arrival cost."""
        return self.prior.problem(self.y, self.w, start, lam)

    def set_state_prior(self, rel: float) -> None:
        """Arrival cost of a first window: the prior (relative std ``rel``) on the initial state only."""
        self.prior.reset(self.x_prior, rel)
        self.state_prior = float(rel)

    def first_window(self, warnings: list[str]) -> tuple[WindowSolution, StartReport, int]:
        """State prior, lambda and the first window, after the load's onset.

        The first window is solved as configured (state prior, lambda path and rule, start-up); then
        its residuals are tested segment by segment (:func:`~wingopt.estimation.mhe.consistency.leading_onset`).
        When the record *starts* with samples the load model cannot explain (the flow starting and
        the load ramping up from rest), those samples are left out and everything is redone from
        the first consistent segment: a first window the model cannot fit would otherwise become
        the arrival cost of every later window (measured: a 40 ms ramp from rest put the final lift
        37 % low). The prior initial deflection applies to the record's first sample only, so a
        later start has an unknown initial state.

        Parameters
        ----------
        warnings : list of str
            The estimator's warnings (a start that cannot be skipped is warned).

        Returns
        -------
        tuple
            ``(solution, start report, first sample of the window)``.
        """
        s, N, K = self.settings, self.prior.N, self.y.shape[0]
        start = 0
        while True:
            self.lambda_info = {}
            self.state_prior_info = {"chosen": s.state_prior, "rule": "fixed"}
            self.set_state_prior(s.state_prior)
            if s.state_prior_choices:
                sol, report, (rel, theta, lam) = self._choose_state_prior(start)
                # The onset test judges the load model, not the prior on the initial state: it
                # uses the weakest candidate's fit (a tight prior that is slightly off misfits
                # the first samples by itself: measured on a 13x7 estimator).
                chosen = self.state_prior
                self.set_state_prior(rel)
                prof = self.profile(theta, start, lam, leverage=True)
                self.set_state_prior(chosen)
            else:
                if s.regularization is not None:
                    self.lam = float(s.regularization)
                    sol, report = self.start_window(start, self.lam)
                else:
                    sol, report = self._choose_lambda(start)
                prof = self.profile(sol.theta, start, self.lam, leverage=True)
            self.level = prof.level
            skip = leading_onset(prof) if s.consistency else 0
            self.onset["attempts"].append(
                {"start": start, "level": prof.level, "skip": skip, "chi2_per_datum": prof.per_datum.tolist()}
            )
            if skip == 0:
                break
            if start + skip + N > K:
                warnings.append(
                    "the load model does not explain the start of the record and too little data is left "
                    "to skip it: keeping the first window as it is"
                )
                break
            start += skip
            log.info(
                "the first %d samples (to t = %.4g s) are not explained by a constant load (load onset?): "
                "starting the estimate there",
                start,
                self.t[start],
            )
            # The prior initial state (e.g. the protocol's bubble) belongs to the record's start.
            self.x_prior = np.zeros_like(self.x_prior)
            self.sign_prior = SignPrior(self.sign_prior.load, None)
        self.onset.update(samples_skipped=start, t_start=float(self.t[start]))
        self.origin = start
        if self.prior.blocks > 1:
            sol = self._to_random_walk(sol, start)
        return sol, report, start

    def profile(
        self,
        theta: np.ndarray,
        start: int,
        lam: float | None = None,
        level: float | None = None,
        leverage: bool = False,
    ) -> SegmentProfile:
        """Segment misfit profile of the window starting at ``start`` at ``theta``.

        ``leverage``: account for the noise the fit absorbs (hat-matrix diagonal, Gauss–Newton at
        ``theta`` with the weight ``lam``); needed where the window's own unknowns dominate (a
        start-up, whose free initial state fits the first samples), negligible behind a strong
        arrival cost.
        """
        red, N = self.reduced, self.prior.N
        sl = slice(start, start + N)
        pred = red.outputs(red.modal_trajectory(self.prior.basis, theta))
        r2 = self.w[sl] * (self.y[sl] - pred) ** 2
        h = None
        if leverage:
            problem = self.problem(start, lam)
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
        return segment_profile(r2, self.w[sl] > 0, self.segment, level, leverage=h)

    def _to_random_walk(self, sol: WindowSolution, start: int) -> WindowSolution:
        """Switch the first window from one load to the random walk's blocks and re-solve it.

        Lambda (a property of the load's spatial prior) and the start-up are found with a constant
        load over the first window: 4x fewer unknowns on the lambda path, and the consistency test
        has already checked that a constant load explains the window. The random walk is sized by
        that estimate (:class:`~wingopt.estimation.mhe.load_model.RandomWalk`), every block starts
        from it.
        """
        m = self.reduced.m
        u = sol.theta[2 * m : 3 * m]
        self.prior.to_random_walk(u)
        theta = np.concatenate([sol.theta[: 2 * m]] + [u] * self.prior.B)
        return self.solver.solve(self.problem(start, self.lam), theta)

    def _choose_state_prior(self, start: int):
        """Pick ``state_prior`` among ``state_prior_choices`` by the first window's evidence.

        For each candidate the first window's lambda path is computed as usual and the Laplace log
        evidence (:meth:`~wingopt.estimation.mhe.window.WindowProblem.log_evidence`) is maximised
        over the path's lambdas (type-II maximum likelihood; with a fixed lambda, the evidence at
        it). The evidence must be compared at lambdas that fit the data: at an over-regularised
        lambda the initial state absorbs the misfit and a weak state prior wins (measured). Of the
        candidates the one with the largest evidence is kept, with its lambda and start-up. Data
        only: how well the prior initial state (the problem's ``initial_deflection``, or rest)
        explains the transient. Returns ``(solution, start report, (rel, theta, lambda))`` of the
        chosen candidate, the last item the weakest candidate's (for the onset test).
        """
        s = self.settings
        evid, runs = {}, {}
        for rel in s.state_prior_choices:
            self.set_state_prior(rel)
            if s.regularization is not None:
                self.lam = float(s.regularization)
                sol, report = self.start_window(start, self.lam)
                ev = self.problem(start, self.lam).log_evidence(sol.theta)
            else:
                sol, report = self._choose_lambda(start)
                ev = max(p["log_evidence"] for p in self.lambda_info["path"] if p["log_evidence"] is not None)
            evid[float(rel)] = float(ev)
            runs[float(rel)] = (sol, report, self.lam, self.lambda_info)
        best = max(evid, key=evid.get)
        self.set_state_prior(best)
        sol, report, self.lam, self.lambda_info = runs[best]
        weak = max(runs)
        self.state_prior_info = {"chosen": best, "rule": "evidence", "log_evidence": evid}
        log.info("state prior %g chosen by the evidence %s", best, evid)
        return sol, report, (weak, runs[weak][0].theta, runs[weak][2])

    def _probe_lambda(self, start: int) -> float:
        """A moderate first lambda: the grid's geometric middle times the scale at the prior guess."""
        v = smooth_load_shapes(self.reduced, 1)[0]
        grid = sorted(self.settings.lambda_grid)
        return natural_scale(self.problem(start, 0.0), self._guess(v), v) * float(np.sqrt(grid[0] * grid[-1]))

    def start_window(self, start: int, lam: float, extra_starts: tuple = ()) -> tuple[WindowSolution, StartReport]:
        """The start-up (scan, coarse-to-fine, sign) of the window at ``start`` with weight ``lam``."""
        problem = self.problem(start, lam)
        s = self.settings
        return start_window(
            problem,
            self.solver,
            self.coarse_solver,
            self.sign_prior,
            self.x_prior,
            self.lift_scale,
            state_modes=s.start_state_modes,
            shapes=s.start_shapes,
            amplitudes=s.start_amplitudes,
            extra_starts=extra_starts,
        )

    def _choose_lambda(self, start: int) -> tuple[WindowSolution, StartReport]:
        """Lambda path on the first window (continuation from the start-up) and the data-only rule."""
        s = self.settings
        # Start-up at a moderate weight, measured in the problem's natural scale.
        v = smooth_load_shapes(self.reduced, 1)[0]
        grid = sorted(s.lambda_grid)
        # A first guess of the scale from the prior state and a smooth load of the prior's size,
        # the start-up there, then the scale at the start-up's answer (what the grid is built on).
        lam_probe = self._probe_lambda(start)
        sol0, report = self.start_window(start, lam_probe)
        lam_nat = natural_scale(self.problem(start, 0.0), sol0.theta, v)
        self.natural_scale = lam_nat
        lam, info, sols = lambda_path(
            lambda x: self.problem(start, x), self.solver, sol0.theta, lam_nat, lam_probe, grid, s.lambda_rule
        )
        # At the chosen weight, start afresh (scan, both signs) and from the nearest path
        # solution: the orientation and the family of the probe's minimum need not be the best
        # at this lambda (the probe is far more regularised).
        near = min(sols, key=lambda x: abs(np.log(x / lam)))
        sol, report = self.start_window(start, lam, extra_starts=(sols[near],))
        self.lam, self.lambda_info = lam, info
        return sol, report

    def _guess(self, v: np.ndarray) -> np.ndarray:
        """Unknowns at the prior state with the load shape ``v`` of the prior's lift in every block."""
        m = self.reduced.m
        theta = np.zeros(self.prior.dim)
        theta[: 2 * m] = self.x_prior
        for b in range(self.prior.B):
            theta[(2 + b) * m : (3 + b) * m] = v * self.lift_scale
        return theta

    def restart(self, k: int, theta: np.ndarray, start: int) -> tuple[int, WindowSolution] | None:
        """Start the estimate afresh at sample ``k``, where the data stopped being consistent with it.

        The window's data contradict the estimate and its arrival cost (the load changed faster
        than the load model allows: a gust, or any change under the constant model). The arrival
        cost is dropped (the weak prior on the state only) and the start-up (scan, coarse-to-fine,
        sign) is redone at the chosen lambda from ``k`` on. Unlike the record's onset nothing is
        skipped: a load that keeps changing faster than the model allows is then followed by
        repeated restarts (a piecewise-constant estimate under the constant model) instead of
        leaving a gap in the history. The sign prior is the user's ``initial_load`` and the
        deflection at ``k`` of the rejected window (``theta``, the window at ``start``; its sign
        is known by now). The window keeps its length, so a change within the last ``window``
        samples restarts at ``K - window``. The restart is recorded in :attr:`restarts`.

        Returns
        -------
        tuple or None
            ``(new start, its window's solution)``; ``None`` (nothing done) when no later start
            is possible.
        """
        m, N = self.reduced.m, self.prior.N
        origin = min(int(k), self.y.shape[0] - N)
        if origin <= self.origin:
            return None
        q_now = self.reduced.modal_trajectory(self.prior.basis, theta)[origin - start]
        self.x_prior = np.zeros(2 * m)
        self.x_prior[:m] = q_now
        self.sign_prior = SignPrior(self.sign_prior.load, q_now)
        self.set_state_prior(self.state_prior)
        sol, _ = self.start_window(origin, self.lam)
        self.restarts.append(
            {"detected_at": int(k), "t_detected": float(self.t[k]), "start": origin, "t_start": float(self.t[origin])}
        )
        log.info(
            "data inconsistent with the estimate at t = %.4g s: restarted at t = %.4g s", self.t[k], self.t[origin]
        )
        self.origin = origin
        return origin, sol
