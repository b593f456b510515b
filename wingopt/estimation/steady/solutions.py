"""The solutions of a steady record under one load prior: the mean's static fits, then the buffeting's.

A steady record's sensors are quadratic: a load and one with some lobes flipped can make the same
mean, so the mean is fitted from each lobe start (:func:`~.steady.starts`) and every distinct
answer is a :class:`Solution`. When the flow buffets the wing, the fluctuation's spectrum shows the
loaded resonance (:func:`~.spectra.screen` near the static fit's loaded first frequency) and each
solution is refitted with the mean and the spectrum together (:mod:`.buffeting`): the spectrum
identifies the tension and tells the lobe patterns apart. Without a resonance the static fits are
corrected to the full order and the tension stays the prior's.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.record_fit import Fit
from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.steady.anti_aliasing import refit_anti_aliased
from wingopt.estimation.steady.buffeting import BuffetingProblem
from wingopt.estimation.steady.buffeting_fit import (
    TOL,
    BuffetingFit,
    fit_buffeting,
    modal_frequencies,
    objective,
    result,
    start,
    tension_ratio,
)
from wingopt.estimation.steady.problem import SteadyData, SteadyProblem, evidence, fit_steady, starts
from wingopt.estimation.steady.spectra import Screen, SpectralData, screen
from wingopt.membrane.model import MembraneModel

__all__ = [
    "Solution",
    "static_solutions",
    "resonance",
    "buffeted_all",
    "spectral_refits",
    "corrected",
    "weights",
    "mixture",
    "misfit_scale",
]

log = logging.getLogger(__name__)

BAND = (0.75, 1.25)
"""The screen's band, relative to the static fit's loaded first frequency (a prestrain two prior std
off moves it by ~12 % at fixed sensor means)."""

LOOK = 3
"""Scoring steps every solution gets before they are ranked by objective."""

ABANDON = 20.0
"""Nats of objective by which a solution's buffeting fit may trail the best one's before it is
abandoned: when even its local model's minimum lies this far above the best fit's objective, its
evidence weight is below ~e^-20 and it cannot move the mixture (the frame prior's other lobe pattern
ends 19 nats of evidence below on the tunnel stand-in, after 20 scoring steps that took 60 % of the
record's CPU)."""

KEEP = 0.05
"""Solutions below this evidence weight are not refitted (with the spectrum or the full order)."""

ADEQUATE = (4.0, 1.5)
"""Largest static chi-square per sensor and spectral residual mean square of an adequate fit (the load
prior cannot make the mean; the spectrum model is not the record's)."""

_FAILURES = (InputError, SolverError, ArithmeticError, np.linalg.LinAlgError)

SAME = 1e-3
"""Two fits whose lifts and costs agree to this (relative) are one solution, counted once."""


@dataclass(frozen=True, eq=False)
class Solution:
    """One answer to a steady record: its load prior and whether the fit started from the other lobe
    signs (``label`` names both, for the record), the static problem,
    the fit (the static one, or the buffeting fit's), the lift and its 1-sigma (N; widened by
    :func:`misfit_scale` when the prior misfits the mean), the Laplace
    log-evidence and the chi-squares (``static_chi2`` per sensor, ``spectral_chi2`` the Whittle
    residuals' mean square, NaN without buffeting)."""

    prior: str
    other_lobes: bool
    problem: SteadyProblem
    fit: Fit
    buffeting: BuffetingFit | None
    lift: float
    lift_std: float
    log_evidence: float
    static_chi2: float
    spectral_chi2: float = float("nan")

    @property
    def label(self) -> str:
        """The load prior, and ``", other lobes"`` for a fit from the other lobe signs."""
        return f"{self.prior}, other lobes" if self.other_lobes else self.prior

    @property
    def theta(self) -> np.ndarray:
        """The static problem's unknowns (load shapes and prestrains)."""
        return self.fit.theta[: self.problem.dim]

    @property
    def covariance(self) -> np.ndarray:
        """Their posterior covariance (the buffeting's marginal when the spectrum was fitted)."""
        k = self.problem.dim
        return self.fit.covariance[:k, :k]

    @property
    def adequate(self) -> bool:
        ok = self.static_chi2 <= ADEQUATE[0]
        return bool(ok and (np.isnan(self.spectral_chi2) or self.spectral_chi2 <= ADEQUATE[1]))

    @property
    def tension_ratio(self) -> float:
        """Posterior over prior std of the first mode's prestrain combination."""
        return tension_ratio(self.problem, self.fit.covariance)


def misfit_scale(static_chi2: float) -> float:
    """The factor on a solution's lift band when its load prior misfits the sensors' mean:
    ``sqrt(chi-square per sensor)`` when above 1 (the Birge ratio). Four sensor means fix a few
    load amplitudes to their standard error; a prior whose shapes cannot make the mean (the
    aerodynamic shapes on a load that is not quite thin-airfoil) would otherwise keep a band set by
    that standard error alone (measured: the stand-in's DIC virtual sensors at chi-square 3.1 per
    sensor, +3.8 % at 2.4 bands). The fit stays adequate up to :data:`ADEQUATE` (beyond, a warning);
    the factor is in ``info["adequacy"]["band_widening"]`` and each solution's ``band_widening``."""
    return float(np.sqrt(max(1.0, static_chi2))) if np.isfinite(static_chi2) else 1.0


def _static(prior: str, other_lobes: bool, sp_: SteadyProblem, fit: Fit) -> Solution:
    g = sp_.lift_gradient()
    chi2 = float(np.mean(fit.residuals[: sp_.data.mean.size] ** 2))
    lift_std = float(np.sqrt(max(g @ fit.covariance @ g, 0.0))) * misfit_scale(chi2)
    return Solution(prior, other_lobes, sp_, fit, None, sp_.lift(fit.theta), lift_std, evidence(fit), chi2)


def _negated(sp_: SteadyProblem, theta: np.ndarray) -> np.ndarray:
    th = theta.copy()
    th[: sp_.shapes.count] *= -1
    return th


def static_solutions(
    model: MembraneModel,
    label: str,
    shapes: LoadShapes,
    data: SteadyData,
    prior: ParameterPrior,
    sign: float,
    max_iter: int = 30,
    corrections: int = 0,
) -> list[Solution]:
    """The distinct static fits of the mean under ``shapes`` from each lobe start, with the prior's
    sign (the whole load and the state flip together: ``sign`` picks one)."""
    out: list[Solution] = []
    for k, th in enumerate(starts(SteadyProblem(model, shapes, data, prior), sign)):
        sp_ = SteadyProblem(model, shapes, data, prior)
        fit = fit_steady(sp_, [th], max_iter, corrections)
        if np.sign(sp_.lift(fit.theta)) * sign < 0:
            fit = Fit(**{**fit.__dict__, "theta": _negated(sp_, fit.theta)})
        sol = _static(label, k > 0, sp_, fit)
        if not any(_same(sol, o) for o in out):
            out.append(sol)
    return out


def _same(a: Solution, b: Solution) -> bool:
    cost_a, cost_b = a.fit.cost, b.fit.cost
    return abs(a.lift - b.lift) <= SAME * abs(a.lift) + 1e-12 and abs(cost_a - cost_b) <= SAME * max(cost_b, 1e-300)


def resonance(sol: Solution, spectra: SpectralData, aliases: int = 1) -> tuple[Screen, float]:
    """The screen of ``spectra`` near ``sol``'s loaded first frequency, and that frequency (Hz)."""
    probe = BuffetingProblem(sol.problem, spectra, aliases)
    th = np.zeros(probe.dim)
    th[: sol.problem.dim] = sol.theta
    f11 = float(modal_frequencies(probe, th, 1)[0])
    return screen(spectra, (BAND[0] * f11, min(BAND[1] * f11, spectra.nyquist))), f11


def _from_fit(sol: Solution, bf: BuffetingFit) -> Solution:
    band = bf.lift_std * misfit_scale(bf.static_chi2)
    return dataclasses.replace(
        sol,
        fit=bf.fit,
        buffeting=bf,
        lift=bf.lift,
        lift_std=band,
        log_evidence=bf.evidence,
        static_chi2=bf.static_chi2,
        spectral_chi2=bf.spectral_chi2,
    )


def corrected(sol: Solution, max_iter: int = 30) -> Solution:
    """``sol``'s static fit corrected to the full-order model (:func:`~.steady.fit_steady`)."""
    sp_ = sol.problem
    fit = fit_steady(sp_, [sol.theta], max_iter)
    return _static(sol.prior, sol.other_lobes, sp_, fit)


def weights(solutions: list[Solution]) -> np.ndarray:
    """Evidence weights of ``solutions`` (the same data: the normalisation cancels)."""
    z = np.array([s.log_evidence for s in solutions])
    w = np.exp(z - z.max())
    return w / w.sum()


def mixture(w: np.ndarray, solutions: list[Solution]) -> tuple[float, float]:
    """The mixture's lift and 1-sigma: the spread of the solutions' lifts is in the band."""
    lifts = np.array([s.lift for s in solutions])
    stds = np.array([s.lift_std for s in solutions])
    mean = float(w @ lifts)
    return mean, float(np.sqrt(max(w @ (stds**2 + lifts**2) - mean**2, 0.0)))


def buffeted_all(
    solutions: list[Solution], spectra: SpectralData, max_iter: int = 40, aliases: int = 1
) -> list[tuple[Solution, str | None]]:
    """Every solution refitted with the mean and the spectrum together: :data:`LOOK` scoring steps
    each, then, best objective first, each scored on to convergence (``max_iter`` steps a phase) or
    abandoned once it cannot come within :data:`ABANDON` nats of a better one. A spectral fit that
    fails falls back to the full-order static fit, with the reason (the second element)."""
    looked = []
    for sol in solutions:
        try:
            bp = BuffetingProblem(sol.problem, spectra, aliases)
            theta, _, its, _, _ = fit_buffeting(bp, start(bp, sol.theta), min(LOOK, max_iter), 0, TOL)
            looked.append((bp, theta, its, objective(bp, theta), None))
        except _FAILURES as exc:
            looked.append((None, None, 0, np.inf, exc))
    out: list = [None] * len(solutions)
    best = None
    for i in sorted(range(len(solutions)), key=lambda i: looked[i][3]):
        sol, (bp, theta, its, _, exc) = solutions[i], looked[i]
        if exc is None:
            try:
                level = None if best is None else best + ABANDON
                theta, fit, more, ok, gave_up = fit_buffeting(bp, theta, max_iter, 1, TOL, level)
                bf = result(bp, theta, fit, its + more, ok, gave_up)
                # the static fits keep the stated side; a spectral fit that crossed to the other is
                # no answer (fuzz #384: -0.118 N for +1.645 N, "adequate", not converged)
                crossed = np.sign(bf.lift) * np.sign(sol.lift) < 0
                if not crossed:
                    if not gave_up:
                        best = bf.objective if best is None else min(best, bf.objective)
                    out[i] = (_from_fit(sol, bf), None)
                    continue
                exc = f"it ended on the other side of the stated load, lift {bf.lift:.3g} N"
            except _FAILURES as err:
                exc = err
        log.info("buffeting fit from the %s solution failed: %s", sol.label, exc)
        out[i] = (corrected(sol), f"the buffeting fit from the {sol.label} solution failed ({exc})")
    return out


def spectral_refits(
    solutions: list[Solution], spectra: SpectralData, max_iter: int, notes: list[str]
) -> list[tuple[Solution, str | None]]:
    """:func:`buffeted_all`, then the test for an undeclared anti-aliasing filter on its best fit
    (:mod:`.anti_aliasing`): on a collapse near Nyquist the solutions are refitted as if the filter
    were declared, their bands take in both fits' lifts, and ``notes`` says so."""
    refits = buffeted_all(solutions, spectra, max_iter)
    out, _ = refit_anti_aliased(solutions, refits, spectra, lambda s, sp: buffeted_all(s, sp, max_iter), notes)
    return out
