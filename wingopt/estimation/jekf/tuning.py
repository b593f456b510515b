"""Choosing the JEKF's ``lambda`` from the data only (the "tuned JEKF").

Two ways of choosing the regularisation weight ``lambda`` of ``P0_d = (P0d_tilde^-1 + lambda Lam)^-1``:

* :func:`seed_lambda` — **the seed's method** (section 6.3.2): Nelder–Mead (MATLAB ``fminsearch``;
  here ``scipy.optimize.minimize(method="Nelder-Mead")`` on ``log10 lambda``) minimising the
  *final load error against the true load* of a noise-free simulated run. It uses the truth, so it
  is not available on measured data; it is kept only as the seed-faithful baseline.
* :func:`select_lambda` / :func:`tuned_identify` — **data only** (the "tuned JEKF"). The filter is
  run over a log-grid of ``lambda`` and one rule picks the value:

  ``"discrepancy"`` (default): the discrepancy principle on the filter's *late* innovations.
      In the last ``window`` fraction of the record the load has settled and the innovations
      ``e_k = y_k - h(x_k^-)`` are noise plus the steady misfit of the estimate. Let
      ``chi2(lambda) = Σ_late Σ_i e_ik^2 / R_i`` (the late-window ``-2 log``-likelihood). The rule
      takes the **largest** ``lambda`` whose late fit is not significantly worse than the best fit
      found on the grid, by a likelihood-ratio test with ``p`` degrees of freedom (one steady level
      per sensor): ``chi2(lambda) - min chi2 <= chi2_p^-1(level)`` (``level = 0.95``). It favours
      the smoothest load the data cannot reject; the comparison with the best achievable fit
      (instead of with the nominal noise level) makes it insensitive to a mis-estimated ``R`` and
      to the small model error of a finer-mesh truth. The grid is scanned upwards from the
      smallest ``lambda`` and refined by bisection in ``log10 lambda`` between the last accepted
      and the first rejected value.
  ``"evidence"``: maximise the Gaussian prediction-error log-likelihood of the whole record
      (type-II maximum likelihood; the filter gives it for free). It tends to under-regularise
      here (it rewards fitting the transient): kept for comparison.
  ``"quasi-optimality"``: minimise the change of the final load between neighbouring grid values,
      ``||f(lambda_{i+1}) - f(lambda_i)||_L2``.

The noise level: ``R`` comes from the settings, else ``Measurements.noise_std``, else the declared
``noise_std`` (the settings' ``declaration``: the problem's ``[identification]``), else
:func:`estimate_noise_std` (robust scale of third differences).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.distributions import chi2_ppf
from wingopt.estimation.core.noise import JEKF_NOISE, noise_variance
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.jekf.filter import JointEKF
from wingopt.estimation.jekf.settings import JEKFSettings
from wingopt.measurements.series import Measurements
from wingopt.membrane.model import MembraneModel

__all__ = ["DEFAULT_GRID", "LAMBDA_RULES", "LambdaSelection", "select_lambda", "tuned_identify"]

log = logging.getLogger(__name__)

DEFAULT_GRID = tuple(10.0**k for k in range(-10, -2))
"""Default coarse grid of ``lambda`` (one per decade; refined by bisection for the discrepancy rule).

``lambda`` multiplies ``Lam`` in SI units (Pa^-2 m^2 per coefficient^2) against ``R`` in sensor
units: on the seed's membrane the useful range is ~1e-9 .. 1e-4."""


LAMBDA_RULES = ("discrepancy", "evidence", "quasi-optimality")


@dataclass(frozen=True, eq=False)
class LambdaSelection:
    """Outcome of :func:`select_lambda` (data only).

    Attributes
    ----------
    regularization : float
        The ``lambda`` chosen.
    rule : str
    result : IdentificationResult
        The filter's run at that ``lambda``.
    table : dict of str -> ndarray
        One entry per evaluated ``lambda`` (ascending): ``lambda``, ``late_chi2`` (late-window
        ``Σ e^2/R``), ``late_count`` (scalar samples in it), ``lr_stat`` (``late_chi2 - min``),
        ``loglik``, ``mean_nis``, ``lift``, ``step_change`` (quasi-optimality distance to the next
        value; NaN for the last).
    threshold : float
        The likelihood-ratio threshold (discrepancy rule; NaN otherwise).
    wall_s : float
    """

    regularization: float
    rule: str
    result: IdentificationResult
    table: dict[str, np.ndarray]
    threshold: float = float("nan")
    wall_s: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """JSON-friendly summary (for ``IdentificationResult.info`` and reports)."""
        return {
            "rule": self.rule,
            "lambda": self.regularization,
            "threshold": self.threshold,
            "evaluations": int(self.table["lambda"].size),
            "table": {k: [float(x) for x in v] for k, v in self.table.items()},
            "wall_s": self.wall_s,
            **self.info,
        }


def _late_chi2(result: IdentificationResult, window: float) -> tuple[float, int]:
    e = np.asarray(result.info["innovations"], dtype=float)
    R = np.asarray(result.info["R"], dtype=float)
    late = e[int(math.floor(e.shape[0] * (1.0 - window))) :]
    ok = np.isfinite(late)
    return float(np.sum(np.where(ok, late, 0.0) ** 2 / R)), int(ok.sum())


class _Runner:
    """Runs the filter at given lambdas, caching the results and their statistics."""

    def __init__(self, model, measurements, settings, R, window, progress) -> None:
        self.model, self.measurements, self.settings, self.R = model, measurements, settings, R
        self.window, self.progress = window, progress
        self.results: dict[float, IdentificationResult] = {}
        self.stats: dict[float, dict[str, float]] = {}

    def __call__(self, lam: float) -> dict[str, float]:
        if lam not in self.stats:
            ekf = JointEKF(self.model, self.settings.replace(regularization=lam))
            ekf.setup(measurement_variance=self.R, t0=float(self.measurements.t[0]))
            res = ekf.run(self.measurements, setup=False, progress=self.progress)
            c2, cnt = _late_chi2(res, self.window)
            self.results[lam] = res
            self.stats[lam] = {
                "late_chi2": c2,
                "late_count": cnt,
                "loglik": float(res.info["loglik"]),
                "mean_nis": float(res.info["mean_nis"]),
                "lift": float(res.lift[-1]),
            }
            log.info("jekf lambda %.3g: late chi2/m %.5f, loglik %.1f", lam, c2 / max(cnt, 1), res.info["loglik"])
        return self.stats[lam]

    def final_change(self, a: float, b: float) -> float:
        d = self.results[b].final_load - self.results[a].final_load
        return self.model.l2_norm(d)


def select_lambda(
    model: MembraneModel,
    measurements: Measurements,
    settings: JEKFSettings | None = None,
    rule: str = "discrepancy",
    grid: Sequence[float] | None = None,
    refine: int = 2,
    level: float = 0.95,
    window: float = 0.5,
    progress: bool = False,
) -> LambdaSelection:
    """Choose ``lambda`` from the data only (no truth) by one of :data:`LAMBDA_RULES`.

    Parameters
    ----------
    model : MembraneModel
        Estimator model.
    measurements : Measurements
        The record; ``R`` is fixed once (see :func:`noise_variance`) for all ``lambda``.
    settings : JEKFSettings, optional
        Default :meth:`JEKFSettings.tuned` (zero initial load, ``R`` from the data); its
        ``declaration`` is filled from the model's problem when ``None``.
    rule : {"discrepancy", "evidence", "quasi-optimality"}
        See the module docstring.
    grid : sequence of float, optional
        Candidate ``lambda`` values (default :data:`DEFAULT_GRID`, one per decade).
    refine : int
        Bisection steps in ``log10 lambda`` after the grid (discrepancy: between the last accepted
        and the first rejected value; evidence: around the best value); each costs one run.
    level : float
        Confidence level of the discrepancy rule's likelihood-ratio test.
    window : float
        Fraction of the record (its end) used by the discrepancy rule.
    """
    settings = with_declaration(JEKFSettings.tuned() if settings is None else settings, model.problem)
    grid_arr = _checked_grid(rule, grid, refine, level, window)
    R, R_source = _fixed_noise(model, measurements, settings)
    t0 = time.perf_counter()
    run = _Runner(model, measurements, settings, R, window, progress)
    threshold = float("nan")
    if rule == "discrepancy":
        threshold = float(chi2_ppf(level, len(model.sensors)))
        chosen = _by_discrepancy(run, grid_arr, int(refine), threshold)
    elif rule == "evidence":
        chosen = _by_evidence(run, grid_arr, int(refine))
    else:
        chosen = _by_quasi_optimality(run, grid_arr)
    edge = _grid_edge(run, chosen, rule)
    table = _table(run)
    result = run.results[chosen]
    wall = time.perf_counter() - t0
    log.info("jekf lambda (%s): %.3g after %d runs in %.1f s", rule, chosen, len(run.stats), wall)
    info = {
        "R": [float(r) for r in R],
        "R_source": R_source,
        "level": level,
        "window": window,
        "at_grid_edge": edge or None,
    }
    return LambdaSelection(chosen, rule, result, table, threshold, wall, info)


def _checked_grid(rule: str, grid, refine: int, level: float, window: float) -> np.ndarray:
    """The candidate lambdas, ascending, after the arguments of :func:`select_lambda` are checked."""
    if rule not in LAMBDA_RULES:
        raise InputError(f"rule = {rule!r}: expected one of {', '.join(LAMBDA_RULES)}")
    grid_arr = np.sort(np.asarray(DEFAULT_GRID if grid is None else grid, dtype=float))
    if grid_arr.ndim != 1 or grid_arr.size < 2 or not np.all(np.isfinite(grid_arr) & (grid_arr > 0)):
        raise InputError(f"grid = {grid!r}: expected at least two positive lambda values")
    if not 0.0 < level < 1.0:
        raise InputError(f"level = {level!r}: expected a confidence level in (0, 1)")
    if not 0.0 < window <= 1.0:
        raise InputError(f"window = {window!r}: expected a fraction of the record in (0, 1]")
    if int(refine) != refine or refine < 0:
        raise InputError(f"refine = {refine!r}: expected a non-negative integer")
    return grid_arr


def _fixed_noise(model: MembraneModel, measurements: Measurements, settings: JEKFSettings) -> tuple[np.ndarray, str]:
    """``R``, fixed once for every lambda, and where it came from (the settings, else :func:`noise_variance`)."""
    if settings.measurement_variance is not None:
        return np.broadcast_to(np.asarray(settings.measurement_variance, float), (len(model.sensors),)), "settings"
    return noise_variance(measurements, settings.declaration.noise_std, JEKF_NOISE)


def _log_midpoint(a: float, b: float) -> float:
    return float(10.0 ** (0.5 * (math.log10(a) + math.log10(b))))


def _by_discrepancy(run: _Runner, grid: np.ndarray, refine: int, threshold: float) -> float:
    """The largest lambda whose late fit is within ``threshold`` of the best one (module docstring):
    scanned upwards, then bisected between the last accepted and the first rejected value."""

    def accepted(lam: float) -> bool:
        best = min(s["late_chi2"] for s in run.stats.values())
        return run(lam)["late_chi2"] - best <= threshold

    lo, hi = None, None
    for lam in grid:
        run(lam)
        if accepted(lam):
            lo = lam
        else:
            hi = lam
            break
    if lo is None:  # the smallest lambda already fits worse than later ones: take the best fit
        lo = min(run.stats, key=lambda k: run.stats[k]["late_chi2"])
    elif hi is not None:
        for _ in range(refine):
            mid = _log_midpoint(lo, hi)
            run(mid)
            lo, hi = (mid, hi) if accepted(mid) else (lo, mid)
    # the reference may have dropped during the scan: the choice must still pass
    while not accepted(lo):
        smaller = [k for k in run.stats if k < lo]
        if not smaller:
            break
        lo = max(smaller)
    return lo


def _by_evidence(run: _Runner, grid: np.ndarray, refine: int) -> float:
    """The lambda of the largest log-likelihood, refined by bisection around the best value."""
    for lam in grid:
        run(lam)
    for _ in range(refine):
        lams = sorted(run.stats)
        i = int(np.argmax([run.stats[k]["loglik"] for k in lams]))
        for j in (i - 1, i + 1):
            if 0 <= j < len(lams):
                run(_log_midpoint(lams[i], lams[j]))
    lams = sorted(run.stats)
    return lams[int(np.argmax([run.stats[k]["loglik"] for k in lams]))]


def _by_quasi_optimality(run: _Runner, grid: np.ndarray) -> float:
    """The lambda after which the final load changes least."""
    for lam in grid:
        run(lam)
    lams = sorted(run.stats)
    steps = [run.final_change(a, b) for a, b in zip(lams[:-1], lams[1:])]
    return lams[int(np.argmin(steps))]


def _grid_edge(run: _Runner, chosen: float, rule: str) -> str:
    """``"smallest"`` or ``"largest"`` when ``chosen`` is at the edge of the values tried (warned), else ``""``."""
    lams = sorted(run.stats)
    if chosen != lams[0] and chosen != lams[-1]:
        return ""
    edge = "smallest" if chosen == lams[0] else "largest"
    log.warning("jekf lambda (%s): chose the %s value tried (%.3g); consider a wider grid", rule, edge, chosen)
    return edge


def _table(run: _Runner) -> dict[str, np.ndarray]:
    """One entry per lambda tried, ascending (:attr:`LambdaSelection.table`)."""
    lams = sorted(run.stats)
    best = min(s["late_chi2"] for s in run.stats.values())
    steps = [run.final_change(a, b) for a, b in zip(lams[:-1], lams[1:])] + [float("nan")]
    return {
        "lambda": np.array(lams),
        "late_chi2": np.array([run.stats[k]["late_chi2"] for k in lams]),
        "late_count": np.array([run.stats[k]["late_count"] for k in lams], dtype=float),
        "lr_stat": np.array([run.stats[k]["late_chi2"] - best for k in lams]),
        "loglik": np.array([run.stats[k]["loglik"] for k in lams]),
        "mean_nis": np.array([run.stats[k]["mean_nis"] for k in lams]),
        "lift": np.array([run.stats[k]["lift"] for k in lams]),
        "step_change": np.array(steps),
    }


def tuned_identify(
    model: MembraneModel,
    measurements: Measurements,
    rule: str = "discrepancy",
    settings: JEKFSettings | None = None,
    **kwargs: Any,
) -> IdentificationResult:
    """The "tuned JEKF": zero initial load, ``R`` from the data, ``lambda`` by a data-only rule.

    Returns the run at the chosen ``lambda``; ``info["lambda_selection"]`` holds
    :meth:`LambdaSelection.summary` and ``wall_s`` covers the whole selection (all runs).
    Keyword arguments go to :func:`select_lambda` (``grid``, ``refine``, ``level``, ``window``).
    """
    sel = select_lambda(model, measurements, settings, rule=rule, **kwargs)
    res = sel.result
    res.info["lambda_selection"] = sel.summary()
    res.info["single_run_wall_s"] = res.wall_s
    res.wall_s = sel.wall_s
    res.method = "jekf"
    return res
