"""The seed's choice of the JEKF's ``lambda``: Nelder–Mead on the final error against the TRUE load.

Section 6.3.2 of the dissertation (MATLAB ``fminsearch``; here ``scipy.optimize.minimize(method=
"Nelder-Mead")`` on ``log10 lambda``) minimising the *final load error against the true load* of a
noise-free simulated run. It uses the truth, so it is not available on measured data; it is kept
only as the seed-faithful baseline. The data-only rules are in :mod:`wingopt.estimation.jekf.tuning`.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from wingopt.errors import InputError
from wingopt.estimation.jekf.filter import JointEKF
from wingopt.estimation.jekf.settings import JEKFSettings
from wingopt.membrane.model import MembraneModel

__all__ = ["LambdaSearch", "seed_lambda", "SEED_SCAN"]

log = logging.getLogger(__name__)

SEED_SCAN = tuple(10.0**k for k in range(-15, -5, 2))
"""Coarse start scan of :func:`seed_lambda` (seed settings: the optimum is near 1e-12 .. 1e-11)."""


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
    noise-free simulation (``simulate_case(problem, load, noise_fraction=0.0)``) and used the result for
    all noise levels.

    Parameters
    ----------
    model : MembraneModel
        Estimator model.
    case : TruthRecord
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


def _as_lambda(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} = {value!r}: expected a positive regularization weight")
    return v
