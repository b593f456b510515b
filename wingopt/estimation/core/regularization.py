"""Choosing the MHE's Tikhonov weight lambda from the data only (the noise level: :mod:`wingopt.estimation.core.noise`).

The estimator solves its first window for a geometric grid of lambdas (warm-started one from
the next) and records, for each, the data misfit ``chi2(lambda) = sum w r^2`` and the effective
number of fitted parameters ``dof(lambda) = tr(H^-1 J^T W J)`` (Gauss–Newton at the optimum).
The rules:

* ``discrepancy`` — Morozov: the largest lambda whose misfit is within the noise,
  ``chi2 <= tau (n - dof)`` (``tau = 1``). Needs the noise level. **Fails** when the model error
  (estimator mesh vs the finer truth, modal truncation) keeps the misfit above ``n - dof`` for
  every lambda: measured on the protocol, it finds no lambda in most 1 % cases.
* ``gcv`` — minimiser of ``n chi2 / (n - dof)^2``; needs no noise level, but the misfit barely
  changes over decades of small lambdas (only 4–7 load directions are resolved) and ``dof`` is
  dominated by the initial state, so the minimum is flat and lands far too low: measured errors
  up to 40x the oracle's (L1, 5 % noise).
* ``robust`` (default) — the **misfit knee**: ``chi2_floor`` is the misfit of the least
  regularised fit on the grid (noise *plus* model error, whatever they are), the knee is the
  largest lambda with ``chi2 <= chi2_floor + c sqrt(2 n)`` (``c = 0.5``: half the statistical
  spread of a chi-square with ``n`` terms, i.e. regularisation that no test on the residuals could
  detect), and lambda is the knee divided by a safety factor ``s = 3``. The safety factor reflects
  the asymmetry of the error curve: too small a lambda costs a factor 2–10, too large a lambda can
  jump to a wrong local minimum (L2, two decades above the knee). Because the threshold is
  relative to the observed floor, the rule needs the noise level only for the relative weights of
  the sensors; a 10 % error in an estimated noise level moves lambda by far less than the safety
  factor. Measured on the protocol: within 1.2x of the oracle lambda's error on every case
  (``docs/estimation.md``).

Nothing here looks at the true load: the oracle lambda of the studies is computed separately
in :mod:`wingopt.workflows.studies`.
"""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError

__all__ = [
    "LambdaRule",
    "LambdaPoint",
    "choose_lambda",
    "knee_lambda",
    "discrepancy_lambda",
    "gcv_lambda",
]

log = logging.getLogger(__name__)


class LambdaRule(enum.StrEnum):
    """How lambda is chosen from the data."""

    ROBUST = "robust"
    DISCREPANCY = "discrepancy"
    GCV = "gcv"


KNEE_EXCESS = 0.5
"""Misfit increase allowed over the floor, in units of ``sqrt(2 n)`` (the chi-square's spread)."""

KNEE_SAFETY = 3.0
"""The robust rule's lambda is the knee divided by this (half a decade)."""


@dataclass(frozen=True)
class LambdaPoint:
    """One point of the lambda path: weight, data misfit, effective dof, number of data and the
    window's Laplace log evidence (``None`` when not computed)."""

    lam: float
    chi2: float
    dof: float
    n: int
    log_evidence: float | None = None

    @property
    def gcv(self) -> float:
        return self.n * self.chi2 / max(self.n - self.dof, 1e-9) ** 2

    @property
    def ratio(self) -> float:
        """``chi2 / (n - dof)``: 1 when the misfit is exactly the noise."""
        return self.chi2 / max(self.n - self.dof, 1e-9)


def _log_interp(x0, y0, x1, y1, y):
    """Geometric interpolation of lambda where a monotone quantity crosses ``y``."""
    if y1 == y0:
        return np.sqrt(x0 * x1)
    t = (y - y0) / (y1 - y0)
    return float(np.exp(np.log(x0) + t * (np.log(x1) - np.log(x0))))


def discrepancy_lambda(path: list[LambdaPoint], tau: float) -> float | None:
    """Largest lambda with ``chi2 <= tau (n - dof)`` (interpolated on the grid); ``None`` if none fits."""
    pts = sorted(path, key=lambda p: p.lam)
    ok = [p.ratio <= tau for p in pts]
    if not any(ok):
        return None
    last = max(i for i, v in enumerate(ok) if v)
    if last == len(pts) - 1:
        return pts[-1].lam
    a, b = pts[last], pts[last + 1]
    return _log_interp(a.lam, a.ratio, b.lam, b.ratio, tau)


def gcv_lambda(path: list[LambdaPoint]) -> float:
    """Grid minimiser of GCV, refined by a parabola in ``log lambda``."""
    pts = sorted(path, key=lambda p: p.lam)
    g = np.array([p.gcv for p in pts])
    i = int(np.argmin(g))
    if 0 < i < len(pts) - 1:
        x = np.log([pts[i - 1].lam, pts[i].lam, pts[i + 1].lam])
        c = np.polyfit(x, g[i - 1 : i + 2], 2)
        if c[0] > 0:
            return float(np.exp(np.clip(-c[1] / (2 * c[0]), x[0], x[2])))
    return pts[i].lam


def knee_lambda(path: list[LambdaPoint], excess: float = KNEE_EXCESS) -> float:
    """Largest lambda, scanning up from the smallest, with ``chi2 <= min chi2 + excess sqrt(2 n)``."""
    pts = sorted(path, key=lambda p: p.lam)
    chi = np.array([p.chi2 for p in pts])
    thr = chi.min() + excess * np.sqrt(2.0 * pts[0].n)
    above = np.flatnonzero(chi > thr)
    if above.size == 0:
        return pts[-1].lam
    i = int(above[0])
    if i == 0:
        return pts[0].lam
    a, b = pts[i - 1], pts[i]
    return _log_interp(a.lam, a.chi2, b.lam, b.chi2, thr)


def choose_lambda(
    path: list[LambdaPoint],
    rule: LambdaRule | str = LambdaRule.ROBUST,
    tau: float = 1.0,
    excess: float = KNEE_EXCESS,
    safety: float = KNEE_SAFETY,
) -> tuple[float, dict]:
    """Apply ``rule`` to a lambda path; returns lambda and what every rule gave (for reports).

    A ``discrepancy`` rule that finds no lambda within the noise falls back to the best-fitting
    (smallest) lambda of the grid and says so in the returned dict.
    """
    try:
        rule = LambdaRule(rule)
    except ValueError:
        raise InputError(f"lambda rule = {rule!r}: expected robust, discrepancy or gcv") from None
    if len(path) < 3:
        raise InputError("lambda path: need at least 3 points")
    lam_d = discrepancy_lambda(path, tau)
    lam_g = gcv_lambda(path)
    lam_k = knee_lambda(path, excess)
    info = {"rule": str(rule), "discrepancy": lam_d, "gcv": lam_g, "knee": lam_k, "robust": lam_k / safety}
    if rule is LambdaRule.DISCREPANCY:
        if lam_d is None:
            info["fallback"] = "no lambda fits within the noise: smallest lambda of the grid"
        lam = lam_d if lam_d is not None else min(p.lam for p in path)
    elif rule is LambdaRule.GCV:
        lam = lam_g
    else:
        lam = lam_k / safety
    info["lambda"] = float(lam)
    return float(lam), info
