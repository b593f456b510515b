"""The lift's band from its profile likelihood when the record holds little on the tension.

The lift scales with the tension: the data fix the deflection, ``p ~ T w``. A record with a
transient fixes the tension through the ringing frequencies, and the Gauss–Newton (Laplace) band
at the optimum is right (coverage 17/20 on FvK truth). A record without one — the wing already
loaded when the recording starts — fixes it only through the FvK stiffening, weakly: the cost is
flat and curved along the tensions and the load shapes that trade against them, and the tangent
band can be too narrow.

Trigger: the posterior of the mean prestrain scale ``s`` (``e_x, e_y -> (1 + s) e_x, (1 + s) e_y``)
keeps more than ``TRIGGER`` of its prior sigma (measured on FvK truth: bubble-start records of the
protocol 0.02–0.14, 0.21–0.27 with the damping x2; records without a transient 0.39–0.84). Then the
final lift's profile is computed at the band's two ends ``L* ± b``: the record is refitted with the
lift held there (every other unknown free, on the affine subspace of that lift, started from the
linearised constrained optimum). For a Gaussian posterior each refit's cost is one chi-square unit
above the optimum; a smaller rise ``r`` says the band is too narrow, and the side's band becomes
``b / sqrt(r)`` (the larger side is kept, never narrower than ``b``, at most ``MAX_WIDENING`` times).
Constant loads and converged fits only (a gust's lift is not linear in the unknowns; a fit stopped
by the iteration cap has no optimum to measure from, and says so). ``info["tension_profile"]``
keeps the numbers.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from wingopt.estimation.core.record_fit import Fit
    from wingopt.estimation.core.record_problem import RecordProblem

__all__ = ["TRIGGER", "MAX_WIDENING", "APPLY_ABOVE", "tension_profile"]

log = logging.getLogger(__name__)

TRIGGER = 0.35
"""Posterior / prior sigma of the mean prestrain scale above which the lift's profile is computed."""

MAX_WIDENING = 4.0
"""The profile widens the band at most this many times (a flat profile is bounded by the priors)."""

APPLY_ABOVE = 1.05
"""A widening up to this factor is within the profile's own noise: the band is kept."""

PRESTRAINS = ("prestrain_x", "prestrain_y")


@dataclass(frozen=True, eq=False)
class _Restricted:
    """``problem`` on the affine subspace ``theta = offset + basis @ phi`` (what the solver needs)."""

    problem: RecordProblem
    offset: np.ndarray
    basis: np.ndarray

    def residuals(self, phi: np.ndarray, jacobian: bool = False):
        out = self.problem.residuals(self.offset + self.basis @ phi, jacobian)
        if not jacobian:
            return out
        rd, rp, Jd, Rp = out
        return rd, rp, Jd @ self.basis, Rp @ self.basis


def _scale_ratio(rp: RecordProblem, fit: Fit, cov: np.ndarray) -> tuple[float, float]:
    """Posterior sigma of the mean prestrain scale and its ratio to the prior's."""
    ph = rp.physical(fit.theta)
    grad = np.zeros(rp.dim)
    prior_var = 0.0
    for i, name in enumerate(rp.prior.free):
        if name in PRESTRAINS:
            ds = 0.5 * rp.prior.mean_std(name)[1] / float(np.real(ph[name][0]))
            grad[rp.slices["par"].start + i] = ds
            prior_var += ds * ds
    d = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
    return d, d / float(np.sqrt(prior_var))


def tension_profile(
    rp: RecordProblem, fit: Fit, cov: np.ndarray, lift_std: float, refit: Callable[[object, np.ndarray], Fit]
) -> tuple[float, dict]:
    """Profile-checked 1-sigma of the final lift (see the module docstring).

    Parameters
    ----------
    rp, fit : the kept problem and fit.
    cov : ndarray
        Covariance of the unknowns (misfit inflation included).
    lift_std : float
        The Laplace band ``b`` of the final lift.
    refit : callable ``(problem, theta0) -> Fit``
        The solver, for a problem with ``residuals(theta, jacobian)``.

    Returns
    -------
    lift_std : float
        The band, never narrower than ``lift_std``.
    info : dict
        ``computed``, ``applied``; the scale's sigma and ratio; when computed the cost rises, the
        lifts held and the widening factor (applied above ``APPLY_ABOVE``).
    """
    if not (all(n in rp.prior.free for n in PRESTRAINS) and rp.nonlinear and rp.hats is None and lift_std > 0):
        reason = "prestrains fixed, a linear membrane or a gust load"
        return lift_std, {"computed": False, "applied": False, "reason": reason}
    d, ratio = _scale_ratio(rp, fit, cov)
    info = {"computed": False, "applied": False, "scale_std": d, "ratio": ratio, "trigger": TRIGGER}
    if ratio <= TRIGGER:
        return lift_std, info
    if not fit.converged:  # the profile is measured from the optimum; a capped fit has none (it warns)
        info["reason"] = "the fit did not converge"
        return lift_std, info
    sl = rp.slices["c"]
    a = np.zeros(rp.dim)
    a[sl] = rp.shapes.lift_row * rp.shapes.prior_std  # lift = a @ theta (constant load)
    ca = cov @ a
    # an orthonormal basis of the unknowns that keep the lift: the complement of a
    q, _ = np.linalg.qr(np.column_stack([a, np.eye(rp.dim)]))
    basis = q[:, 1 : rp.dim]
    rises, lifts = [], []
    for sign in (-1.0, 1.0):
        offset = fit.theta + sign * lift_std * ca / (a @ ca)
        fq = refit(_Restricted(rp, offset, basis), np.zeros(rp.dim - 1))
        rises.append(fq.cost - fit.cost)
        lifts.append(float(a @ (offset + basis @ fq.theta)))
    widen = max(1.0 / np.sqrt(r) if r > 0 else np.inf for r in rises)
    widen = float(min(max(widen, 1.0), MAX_WIDENING))
    applied = widen > APPLY_ABOVE
    info.update(computed=True, applied=applied, cost_rises=[float(r) for r in rises], lifts_N=lifts, widening=widen)
    log.info("lift profile: cost rises %.2f / %.2f at the band's ends: band x%.2f", *rises, widen)
    return lift_std * (widen if applied else 1.0), info
