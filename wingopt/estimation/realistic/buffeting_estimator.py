"""The tension and the load of a steady record from its buffeting: :func:`buffeting_identify`.

A tunnel record without a calibration leaves the tension to the prior (:mod:`.steady_estimator`): the
static mean alone cannot tell a tauter wing under more load from a slacker one under less. When the
flow buffets the wing, the fluctuation's spectrum shows the loaded resonance, and the joint fit of
the mean and the spectrum (:mod:`.buffeting`) identifies the tension, hence the lift.

Steps: the static fits of the mean (:func:`~.steady.fit_steady`, from each lobe start of
:func:`~.steady.starts`, weighed by evidence); the cheap screen (:func:`~.spectra.screen`) of the
sensors' spectra for a resonance above the noise floor within ±25 % of the static fit's loaded
first frequency; the buffeting fit from each static solution of weight above 5 %, weighed by
evidence. When the screen finds no resonance, or the fit's posterior of the tension is not much
narrower than its prior (:data:`~.buffeting_fit.UNIDENTIFIED`), the result says so: the tension is
the prior's and the lift band carries it.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.estimation.realistic.buffeting import BuffetingProblem
from wingopt.estimation.realistic.buffeting_fit import (
    BuffetingFit,
    mean_prestrain,
    modal_frequencies,
    run,
    tension_ratio,
)
from wingopt.estimation.realistic.load_model import LoadShapes
from wingopt.estimation.realistic.record_problem import ParameterPrior
from wingopt.estimation.realistic.spectra import Screen, screen, spectral_data
from wingopt.estimation.realistic.steady import SteadyProblem, evidence, fit_steady, starts, steady_data
from wingopt.measurements import Measurements
from wingopt.membrane.model import MembraneModel

__all__ = ["BuffetingResult", "buffeting_identify", "BAND"]

log = logging.getLogger(__name__)

BAND = (0.75, 1.25)
"""The screen's band, relative to the static fit's loaded first frequency (a prestrain two prior std
off moves it by ~12 % at fixed sensor means)."""

KEEP = 0.05
"""Static solutions below this evidence weight are not refitted with the buffeting."""

ADEQUATE = (4.0, 1.5)
"""Largest static chi-square per sensor and spectral residual mean square of an adequate fit (the load
prior cannot make the mean; the spectrum model is not the record's)."""


@dataclass(frozen=True, eq=False)
class BuffetingResult:
    """The load and the tension of a steady record.

    ``lift``/``lift_std``: the evidence-weighted mixture over the solutions (N); ``prestrain``,
    ``prestrain_std``, ``mean_prestrain`` (``(ex + ey)/2``) and its std, ``damping``, ``damping_std``,
    ``f11_hz``, ``tension_ratio``: the heaviest solution's; ``informative``: the buffeting identified
    the tension; ``static``: the result is the static fit's (the screen found no resonance);
    ``adequate``: the fit's chi-squares are within :data:`ADEQUATE`; ``solutions``: ``(label,
    BuffetingFit or None, weight, lift, lift_std)``.
    """

    lift: float
    lift_std: float
    prestrain: tuple[float, float]
    prestrain_std: tuple[float, float]
    mean_prestrain: float
    mean_prestrain_std: float
    damping: float
    damping_std: float
    f11_hz: float
    tension_ratio: float
    informative: bool
    static: bool
    adequate: bool
    screen: Screen
    solutions: list
    warnings: list[str] = field(default_factory=list)
    cpu_s: float = 0.0

    @property
    def best(self) -> BuffetingFit | None:
        return max(self.solutions, key=lambda s: s[2])[1]


def _default_shapes(model: MembraneModel) -> LoadShapes:
    ident = model.problem.identification
    return LoadShapes.aerodynamic(model, ident.initial_load, ident.leading_edge or "x0")


def _mixture(weights: np.ndarray, lifts: np.ndarray, stds: np.ndarray) -> tuple[float, float]:
    mean = float(weights @ lifts)
    return mean, float(np.sqrt(max(weights @ (stds**2 + lifts**2) - mean**2, 0.0)))


def buffeting_identify(
    model: MembraneModel,
    measurements: Measurements,
    shapes: LoadShapes | None = None,
    prior: ParameterPrior | None = None,
    *,
    bin_hz: float = 1.0,
    fmin: float = 1.0,
    aliases: int = 1,
    force: bool = False,
    max_iter: int = 40,
) -> BuffetingResult:
    """Identify the load and the tension of a steady record from its mean and its buffeting.

    Parameters
    ----------
    model : MembraneModel
        The estimator's membrane model (its sensors are the record's columns).
    measurements : Measurements
        The steady record (evenly sampled; NaN rows are dropped frames).
    shapes : LoadShapes, optional
        Load prior; default the aerodynamic shapes of the problem's leading edge (``"x0"`` if unset).
    prior : ParameterPrior, optional
        Prestrain and damping prior; default the problem file's, prestrains and damping free.
    bin_hz, fmin, aliases
        Spectral bins (Hz), lowest frequency kept (Hz), aliased copies in the model spectrum.
    force : bool
        Fit the spectrum even when the screen finds no resonance.
    max_iter : int
        Fisher-scoring steps per fit.

    Returns
    -------
    BuffetingResult
    """
    t0 = time.process_time()
    problem = model.problem
    if measurements.values.shape[1] != len(model.sensors.matrices):
        raise InputError(
            f"buffeting: {measurements.values.shape[1]} sensor columns for {len(model.sensors.matrices)} sensors"
        )
    shapes = _default_shapes(model) if shapes is None else shapes
    if prior is None:
        prior = ParameterPrior.from_problem(problem, ("prestrain_x", "prestrain_y", "damping"))
    data = steady_data(measurements.values)
    spectra = spectral_data(measurements.t, measurements.values, bin_hz, fmin)
    sign = float(np.sign(problem.identification.initial_load) or 1.0)
    statics = []
    for k, th in enumerate(starts(SteadyProblem(model, shapes, data, prior), sign)):
        sp_ = SteadyProblem(model, shapes, data, prior)
        fit = fit_steady(sp_, [th])
        lift = sp_.lift(fit.theta)
        if any(abs(lift - s[3]) <= 1e-3 * abs(lift) and abs(fit.cost - s[2].cost) <= 1e-3 * s[2].cost for s in statics):
            continue  # both starts found the same solution
        statics.append(("static" if k == 0 else "static, other lobes", sp_, fit, lift))
    z = np.array([evidence(s[2]) for s in statics])
    w = np.exp(z - z.max())
    w /= w.sum()
    best = int(np.argmax(w))
    probe = BuffetingProblem(statics[best][1], spectra, aliases)
    th0 = np.zeros(probe.dim)
    th0[: probe.steady.dim] = statics[best][2].theta
    f11 = float(modal_frequencies(probe, th0, 1)[0])
    band = (BAND[0] * f11, min(BAND[1] * f11, spectra.nyquist))
    scr = screen(spectra, band)
    warnings = []
    fits = []
    for (label, sp_, fit, _), wi in zip(statics, w):
        if wi < KEEP or not (scr.informative or force):
            continue
        try:
            fits.append(
                (
                    label.replace("static", "buffeting"),
                    run(BuffetingProblem(sp_, spectra, aliases), fit.theta, max_iter),
                    sp_,
                )
            )
        except (InputError, SolverError, ArithmeticError, np.linalg.LinAlgError) as exc:
            log.info("buffeting fit from the %s solution failed: %s", label, exc)
            warnings.append(f"the buffeting fit from the {label} solution failed ({exc})")
    if not fits:
        out = _static_result(statics, w, scr, f11)
        if not out.adequate:
            warnings.append(
                "the load prior does not make the sensors' mean (chi-square above "
                f"{ADEQUATE[0]:g} per sensor): the load is the nearest one it allows"
            )
        why = (
            f"no resonance above the noise floor near the first loaded mode ({scr.ratio:.2f} < {scr.threshold:.2f} "
            f"within {band[0]:.0f}-{band[1]:.0f} Hz)"
            if not (scr.informative or force)
            else "its fit failed"
        )
        warnings.append(
            f"the buffeting does not identify the tension: {why}; the prestrain is the prior's and the lift band "
            "carries it"
        )
        return _finish(out, warnings, t0)
    zb = np.array([f.evidence for _, f, _ in fits])
    wb = np.exp(zb - zb.max())
    wb /= wb.sum()
    lift, lift_std = _mixture(wb, np.array([f.lift for _, f, _ in fits]), np.array([f.lift_std for _, f, _ in fits]))
    _, top, top_problem = fits[int(np.argmax(wb))]
    if not top.informative:
        warnings.append(
            f"the buffeting does not identify the tension (its posterior is {top.tension_ratio:.0%} of the prior's): "
            "the lift band carries the prior's tension"
        )
    if not top.converged:
        warnings.append(f"the buffeting fit did not converge in {max_iter} steps")
    adequate = top.static_chi2 <= ADEQUATE[0] and top.spectral_chi2 <= ADEQUATE[1]
    if top.static_chi2 > ADEQUATE[0]:
        warnings.append(
            f"the load prior does not make the sensors' mean (chi-square {top.static_chi2:.1f} per sensor): the load "
            "and the tension are those of the nearest load it allows"
        )
    if top.spectral_chi2 > ADEQUATE[1]:
        warnings.append(
            f"the model spectrum does not fit the record's (residual mean square {top.spectral_chi2:.2f}, expected 1)"
        )
    em, em_std = mean_prestrain(top_problem, top.theta, top.covariance)
    out = BuffetingResult(
        lift=lift,
        lift_std=lift_std,
        prestrain=top.prestrain,
        prestrain_std=top.prestrain_std,
        mean_prestrain=em,
        mean_prestrain_std=em_std,
        damping=top.damping,
        damping_std=top.damping_std,
        f11_hz=top.f11_hz,
        tension_ratio=top.tension_ratio,
        informative=top.informative,
        static=False,
        adequate=bool(adequate),
        screen=scr,
        solutions=[(lab, f, float(wi), f.lift, f.lift_std) for (lab, f, _), wi in zip(fits, wb)],
    )
    return _finish(out, warnings, t0)


def _static_result(statics, w, scr: Screen, f11: float) -> BuffetingResult:
    """The static fits' answer: the tension is the prior's."""
    stds = []
    for _, sp_, fit, _ in statics:
        g = sp_.lift_gradient()
        stds.append(float(np.sqrt(g @ fit.covariance @ g)))
    lift, lift_std = _mixture(w, np.array([s[3] for s in statics]), np.array(stds))
    _, sp_, fit, _ = statics[int(np.argmax(w))]
    _, par = sp_.physical(fit.theta)
    k = sp_.shapes.count
    std = {n: float(sp_.prior.mean_std(n)[1] * np.sqrt(fit.covariance[k + i, k + i])) for i, n in enumerate(sp_.pars)}
    md, sd = sp_.prior.mean_std("damping")
    em, em_std = mean_prestrain(sp_, fit.theta, fit.covariance)
    chi2 = fit.data_cost / fit.residuals.size
    return BuffetingResult(
        lift=lift,
        lift_std=lift_std,
        prestrain=(par.eps0_x, par.eps0_y),
        prestrain_std=(std.get("prestrain_x", 0.0), std.get("prestrain_y", 0.0)),
        mean_prestrain=em,
        mean_prestrain_std=em_std,
        damping=float(np.exp(md)),
        damping_std=float(np.exp(md) * sd),
        f11_hz=f11,
        tension_ratio=tension_ratio(sp_, fit.covariance),
        informative=False,
        static=True,
        adequate=bool(chi2 <= ADEQUATE[0]),
        screen=scr,
        solutions=[(lab, None, float(wi), s3, sd_) for (lab, _, _, s3), wi, sd_ in zip(statics, w, stds)],
    )


def _finish(out: BuffetingResult, warnings: list[str], t0: float) -> BuffetingResult:
    for msg in warnings:
        log.info("buffeting: %s", msg)
    object.__setattr__(out, "warnings", warnings)
    object.__setattr__(out, "cpu_s", time.process_time() - t0)
    return out
