"""Choosing ``lambda`` for the JEKF, and the noise level ``R`` from the data.

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

The noise level: ``R`` comes from the settings, else ``Measurements.noise_std``, else the problem's
``identification.noise_std``, else :func:`estimate_noise_std` (robust scale of third differences).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from math import comb
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.stats import chi2

from wingopt.errors import InputError
from wingopt.estimation.data import IdentificationResult, Measurements
from wingopt.estimation.jekf import JEKFSettings, JointEKF
from wingopt.membrane.model import MembraneModel

__all__ = [
    "DEFAULT_GRID",
    "LAMBDA_RULES",
    "LambdaSearch",
    "LambdaSelection",
    "estimate_noise_std",
    "noise_variance",
    "seed_lambda",
    "select_lambda",
    "tuned_identify",
]

log = logging.getLogger(__name__)

DEFAULT_GRID = tuple(10.0**k for k in range(-10, -2))
"""Default coarse grid of ``lambda`` (one per decade; refined by bisection for the discrepancy rule).

``lambda`` multiplies ``Lam`` in SI units (Pa^-2 m^2 per coefficient^2) against ``R`` in sensor
units: on the seed's membrane the useful range is ~1e-9 .. 1e-4."""

LAMBDA_RULES = ("discrepancy", "evidence", "quasi-optimality")

SEED_SCAN = tuple(10.0**k for k in range(-15, -5, 2))
"""Coarse start scan of :func:`seed_lambda` (seed settings: the optimum is near 1e-12 .. 1e-11)."""

_NOISE_ORDER = 3  # third differences: var = C(6, 3) sigma^2 = 20 sigma^2 for white noise
_NOISE_FLOOR = 1e-6  # relative floor of the noise std (noise-free data would give R = 0)


# -- noise level -----------------------------------------------------------------------------------------
def estimate_noise_std(measurements: Measurements) -> np.ndarray:
    """Per-sensor noise standard deviation estimated from the data alone.

    Robust scale (median absolute deviation, ``1.4826 MAD``) of the third differences of each
    sensor's series divided by ``sqrt(20)``: differencing removes the smooth response (the
    membrane's modes are sampled many times per period) and the median ignores the few samples of
    the start-up transient. On the simulated protocol it overestimates by ~3 % (1 % noise) and
    ~2 % (5 %). Missing samples are dropped (which slightly mixes neighbours across a gap).
    """
    v = np.asarray(measurements.values, dtype=float)
    out = np.empty(v.shape[1])
    for i in range(v.shape[1]):
        col = v[np.isfinite(v[:, i]), i]
        if col.size < _NOISE_ORDER + 8:
            raise InputError(
                f"measurements: sensor {measurements.sensor_names[i]!r} has {col.size} samples; "
                "too few to estimate its noise (give noise_std)"
            )
        d = np.diff(col, _NOISE_ORDER)
        out[i] = 1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(comb(2 * _NOISE_ORDER, _NOISE_ORDER))
    return out


def noise_variance(measurements: Measurements, model: MembraneModel | None = None) -> tuple[np.ndarray, str]:
    """Measurement variances ``R_i`` for a record, and where they came from.

    Order: ``measurements.noise_std``, the problem's ``identification.noise_std`` (when ``model`` is
    given), else :func:`estimate_noise_std`. A floor of ``1e-6 max_t |y_i|`` keeps ``R > 0`` on
    noise-free data.
    """
    p = measurements.values.shape[1]
    if measurements.noise_std is not None:
        std, source = np.broadcast_to(np.asarray(measurements.noise_std, float), (p,)), "measurements.noise_std"
    elif model is not None and model.problem.identification.noise_std is not None:
        std = np.broadcast_to(np.asarray(model.problem.identification.noise_std, float), (p,))
        source = "problem identification.noise_std"
    else:
        std, source = estimate_noise_std(measurements), "estimated (MAD of third differences)"
    scale = np.nanmax(np.abs(measurements.values), axis=0)
    floor = _NOISE_FLOOR * np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
    if np.any(std < floor):
        source += " (floored)"
    return np.maximum(std, floor) ** 2, source


# -- the seed's method -------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LambdaSearch:
    """Outcome of :func:`seed_lambda` (Nelder–Mead on the truth: the seed's method).

    Attributes
    ----------
    regularization : float
        The ``lambda`` found.
    error : float
        Final relative L2 load error at that ``lambda`` (against the TRUE load).
    history : tuple of (float, float)
        ``(lambda, error)`` of every evaluation, in order.
    evaluations : int
    wall_s : float
    message : str
        The optimiser's message.
    """

    regularization: float
    error: float
    history: tuple[tuple[float, float], ...]
    evaluations: int
    wall_s: float
    message: str
    method: str = "nelder-mead on log10(lambda), final load error of a noise-free run (uses the truth)"


def seed_lambda(
    model: MembraneModel,
    case,
    settings: JEKFSettings | None = None,
    start: float | None = None,
    scan: Sequence[float] = SEED_SCAN,
    maxfev: int = 24,
    xatol: float = 0.05,
    fatol: float = 1e-4,
) -> LambdaSearch:
    """The seed's choice of ``lambda`` (section 6.3.2): Nelder–Mead minimising the TRUE final load error.

    **This uses the true load** (``case.load_error``): it is the seed's method, kept as the
    baseline ("seed-faithful JEKF"); it cannot be used on measured data. The seed ran it on a
    noise-free simulation (``simulate_case(problem, load, noise=0.0)``) and used the result for
    all noise levels.

    Parameters
    ----------
    model : MembraneModel
        Estimator model.
    case : SimulatedCase
        A simulated record with its truth (normally noise-free).
    settings : JEKFSettings, optional
        Filter settings (default :meth:`JEKFSettings.seed`); ``regularization`` is searched.
    start : float, optional
        Initial ``lambda`` of Nelder–Mead; the initial simplex spans half a decade above it.
        ``None`` (default): the best value of a coarse ``scan`` (one run per value) — the error
        is not unimodal in ``lambda`` (on L2 a plain start at ``1e-8`` ends in a local minimum
        with twice the error), and the seed does not say where its search started.
    scan : sequence of float
        Coarse values tried before Nelder–Mead when ``start`` is ``None``.
    maxfev, xatol, fatol :
        Nelder–Mead budget (runs, the scan included) and tolerances (``xatol`` in decades).
    """
    settings = JEKFSettings.seed() if settings is None else settings
    if start is not None:
        _as_lambda("start", start)
    if getattr(case, "noise_fraction", 0.0):
        log.warning("seed_lambda: the seed tuned on noise-free data; this case has %g noise", case.noise_fraction)
    history: list[tuple[float, float]] = []
    cache: dict[float, float] = {}

    def objective(x: np.ndarray) -> float:
        lam = float(10.0 ** np.clip(x[0], -30.0, 30.0))
        key = round(float(x[0]), 10)
        if key not in cache:
            res = JointEKF(model, settings.replace(regularization=lam)).run(case.measurements)
            cache[key] = case.load_error(model.field(res.final_load))
            history.append((lam, cache[key]))
            log.info("seed_lambda: lambda %.4g -> load error %.4g", lam, cache[key])
        return cache[key]

    t0 = time.perf_counter()
    if start is None:
        for lam in scan:
            objective(np.array([math.log10(_as_lambda("scan", lam))]))
        start = min(history, key=lambda h: h[1])[0]
    x0 = math.log10(start)
    opt = minimize(
        objective,
        np.array([x0]),
        method="Nelder-Mead",
        options={
            "initial_simplex": np.array([[x0], [x0 + 0.5]]),
            "xatol": xatol,
            "fatol": fatol,
            "maxfev": max(int(maxfev) - len(history), 2),
        },
    )
    best_lam, best_err = min(history, key=lambda h: h[1])
    return LambdaSearch(best_lam, best_err, tuple(history), len(history), time.perf_counter() - t0, str(opt.message))


# -- data-only rules ----------------------------------------------------------------------------------
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


def _as_lambda(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} = {value!r}: expected a positive regularization weight")
    return v


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
        Default :meth:`JEKFSettings.tuned` (zero initial load, ``R`` from the data).
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
    settings = JEKFSettings.tuned() if settings is None else settings
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
    if settings.measurement_variance is not None:
        R = np.broadcast_to(np.asarray(settings.measurement_variance, float), (len(model.sensors),))
        R_source = "settings"
    else:
        R, R_source = noise_variance(measurements, model)
    t0 = time.perf_counter()
    run = _Runner(model, measurements, settings, R, window, progress)
    p = len(model.sensors)
    threshold = float("nan")

    if rule == "discrepancy":
        threshold = float(chi2.ppf(level, p))

        def accepted(lam: float) -> bool:
            best = min(s["late_chi2"] for s in run.stats.values())
            return run(lam)["late_chi2"] - best <= threshold

        lo, hi = None, None
        for lam in grid_arr:
            run(lam)
            if accepted(lam):
                lo = lam
            else:
                hi = lam
                break
        if lo is None:  # the smallest lambda already fits worse than later ones: take the best fit
            lo = min(run.stats, key=lambda k: run.stats[k]["late_chi2"])
        elif hi is not None:
            for _ in range(int(refine)):
                mid = float(10.0 ** (0.5 * (math.log10(lo) + math.log10(hi))))
                run(mid)
                lo, hi = (mid, hi) if accepted(mid) else (lo, mid)
        # the reference may have dropped during the scan: the choice must still pass
        while not accepted(lo):
            smaller = [k for k in run.stats if k < lo]
            if not smaller:
                break
            lo = max(smaller)
        chosen = lo
    elif rule == "evidence":
        for lam in grid_arr:
            run(lam)
        lams = sorted(run.stats)
        for _ in range(int(refine)):
            lams = sorted(run.stats)
            i = int(np.argmax([run.stats[k]["loglik"] for k in lams]))
            for j in (i - 1, i + 1):
                if 0 <= j < len(lams):
                    run(float(10.0 ** (0.5 * (math.log10(lams[i]) + math.log10(lams[j])))))
        lams = sorted(run.stats)
        chosen = lams[int(np.argmax([run.stats[k]["loglik"] for k in lams]))]
    else:  # quasi-optimality
        for lam in grid_arr:
            run(lam)
        lams = sorted(run.stats)
        steps = [run.final_change(a, b) for a, b in zip(lams[:-1], lams[1:])]
        chosen = lams[int(np.argmin(steps))]

    lams = sorted(run.stats)
    edge = ""
    if chosen == lams[0] or chosen == lams[-1]:
        edge = "smallest" if chosen == lams[0] else "largest"
        log.warning("jekf lambda (%s): chose the %s value tried (%.3g); consider a wider grid", rule, edge, chosen)
    best = min(s["late_chi2"] for s in run.stats.values())
    steps = [run.final_change(a, b) for a, b in zip(lams[:-1], lams[1:])] + [float("nan")]
    table = {
        "lambda": np.array(lams),
        "late_chi2": np.array([run.stats[k]["late_chi2"] for k in lams]),
        "late_count": np.array([run.stats[k]["late_count"] for k in lams], dtype=float),
        "lr_stat": np.array([run.stats[k]["late_chi2"] - best for k in lams]),
        "loglik": np.array([run.stats[k]["loglik"] for k in lams]),
        "mean_nis": np.array([run.stats[k]["mean_nis"] for k in lams]),
        "lift": np.array([run.stats[k]["lift"] for k in lams]),
        "step_change": np.array(steps),
    }
    result = run.results[chosen]
    wall = time.perf_counter() - t0
    log.info("jekf lambda (%s): %.3g after %d runs in %.1f s", rule, chosen, len(lams), wall)
    return LambdaSelection(
        chosen,
        rule,
        result,
        table,
        threshold,
        wall,
        {
            "R": [float(r) for r in R],
            "R_source": R_source,
            "level": level,
            "window": window,
            "at_grid_edge": edge or None,
        },
    )


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


# -- entry point for the command line and the studies -------------------------------------------------
VARIANTS = ("seed", "tuned")

DEFAULT_SEED_LAMBDA = 1.0e-12
"""``lambda`` of the seed-faithful filter when there is no truth to tune it on (measured data): about what
:func:`seed_lambda` finds on the noise-free L1 protocol (25x13 estimator, 49x25 truth)."""

_SEED_CACHE: dict[Any, LambdaSearch] = {}


def noise_free(case):
    """The noise-free twin of a :class:`~wingopt.estimation.protocol.SimulatedCase` (same truth)."""
    meas = Measurements(
        t=case.trajectory.t,
        values=case.trajectory.outputs,
        sensor_names=case.measurements.sensor_names,
        noise_std=np.zeros(case.trajectory.outputs.shape[1]),
        source=f"noise-free {case.load.name}",
    )
    return dataclasses.replace(case, measurements=meas, noise_fraction=0.0, seed=None)


def cached_seed_lambda(model: MembraneModel, case, settings: JEKFSettings | None = None, **kwargs: Any) -> LambdaSearch:
    """:func:`seed_lambda` on the noise-free twin of ``case``, cached per (problem, settings, truth)."""
    settings = (JEKFSettings.seed() if settings is None else settings).replace(regularization=1.0)
    key = (model.problem, settings, hash(case.trajectory.outputs.tobytes()), tuple(sorted(kwargs.items())))
    if key not in _SEED_CACHE:
        _SEED_CACHE[key] = seed_lambda(model, noise_free(case), settings, **kwargs)
    return _SEED_CACHE[key]


def identify(
    model: MembraneModel,
    measurements: Measurements,
    variant: str = "tuned",
    truth=None,
    initial_load: float | None = None,
    regularization: float | None = None,
    rule: str = "discrepancy",
    modes: int | None = None,
    **kwargs: Any,
) -> IdentificationResult:
    """The JEKF as the command line and the comparison studies run it.

    Parameters
    ----------
    variant : {"seed", "tuned"}
        ``"seed"``: the seed-faithful filter (``R = 1e-4``, uniform ``initial_load`` prior, the
        bubble); ``lambda`` from :func:`seed_lambda` on the noise-free twin of ``truth`` (USES THE
        TRUTH, as the seed did), or :data:`DEFAULT_SEED_LAMBDA` without a truth.
        ``"tuned"``: zero initial load, ``R`` from the data, ``lambda`` by the data-only ``rule``.
    truth : SimulatedCase, optional
        The simulated case (only the seed variant uses it, and only to tune ``lambda``).
    initial_load : float, optional
        Signed prior pressure (Pa): the seed's uniform prior mean, and for both variants the sign
        prior when the problem states no initial deflection. Default: the problem's.
    regularization : float, optional
        Fixed ``lambda`` (skips the tuning).
    modes : int, optional
        Keep only the lowest ``modes`` membrane modes (:attr:`JEKFSettings.modes`; faster,
        approximate); default: all (exact).
    kwargs :
        Passed to :func:`select_lambda` (tuned) or :func:`seed_lambda` (seed).
    """
    if variant not in VARIANTS:
        raise InputError(f"variant = {variant!r}: expected one of {', '.join(VARIANTS)}")
    if initial_load is not None and not (math.isfinite(initial_load) and initial_load != 0):
        raise InputError(f"initial_load = {initial_load!r}: expected a non-zero pressure (Pa)")
    if variant == "seed":
        settings = JEKFSettings.seed(initial_load=initial_load).replace(modes=modes)
        t0 = time.perf_counter()
        if regularization is not None:
            lam, source, search = _as_lambda("regularization", regularization), "given", None
        elif truth is not None:
            search = cached_seed_lambda(model, truth, settings, **kwargs)
            lam, source = search.regularization, "seed method: Nelder-Mead on the noise-free truth (uses the truth)"
        else:
            lam, source, search = DEFAULT_SEED_LAMBDA, "default (no truth to tune on)", None
        tune_s = time.perf_counter() - t0
        res = JointEKF(model, settings.replace(regularization=lam)).run(measurements)
        res.info.update(variant="seed", lambda_source=source, tuning_wall_s=tune_s)
        if search is not None:
            res.info["seed_search"] = {
                "lambda": search.regularization,
                "noise_free_error": search.error,
                "evaluations": search.evaluations,
                "history": [list(h) for h in search.history],
                "method": search.method,
            }
        return res
    settings = JEKFSettings.tuned(sign_prior=initial_load).replace(modes=modes)
    if regularization is not None:
        res = JointEKF(model, settings.replace(regularization=_as_lambda("regularization", regularization))).run(
            measurements
        )
        res.info.update(variant="tuned", lambda_source="given")
        return res
    res = tuned_identify(model, measurements, rule=rule, settings=settings, **kwargs)
    res.info.update(variant="tuned", lambda_source=f"data-only rule: {rule}")
    return res
