"""Fitting a :class:`~.buffeting.BuffetingProblem`: start, Fisher scoring, full-order correction, posterior.

The start is the static fit's load and prestrains (:func:`~.steady.fit_steady`), the prior damping, the
forcing spectrum's prior corner and order, the noise floor of the spectra and the forcing level that
matches the low-frequency sensor spectra. Fisher scoring is :func:`~.solver.levenberg_marquardt` on
the frozen-weight residuals, one step per freeze (each step is a Fisher-scoring step with
Levenberg–Marquardt damping; refreezing at the new point makes the fixed point Whittle's estimate);
the true objective (Whittle + static chi-square + prior) is watched, and a step that raises it is
halved. At the optimum the fit is corrected to the full order as :func:`~.steady.fit_steady` does
(the full FvK model's static outputs and sensor gains ``2 z̄^T C_i Phi`` at the optimum replace the
modal model's, as frozen defects) and scoring resumed. The modal tangent's two lowest loaded
frequencies match the full order's to 5e-4 at every optimum of the tunnel study (LE, TE, anti,
prestrain 0.04-0.06; 108.04 against 108.03 Hz on the nominal LE record), so the transfer's dynamics
need no correction; :func:`full_order_frequencies` checks it.

The posterior is Laplace's: the inverse of the Fisher information plus the prior precision at the
optimum (the precision of the last Levenberg–Marquardt fit, weights frozen there).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import InputError, SolverError
from wingopt.estimation.core.record_fit import Fit, levenberg_marquardt
from wingopt.estimation.steady.buffeting import FC_REF, BuffetingProblem

__all__ = [
    "BuffetingFit",
    "fit_buffeting",
    "objective",
    "result",
    "start",
    "full_order_frequencies",
    "modal_frequencies",
    "tension_ratio",
    "mean_prestrain",
    "UNIDENTIFIED",
]

log = logging.getLogger(__name__)

TOL = 0.1
"""Scoring stops when a step is predicted to lower the chi-square by less than this (0.05 nats of
evidence: the 25-shape frame prior's weakly determined directions otherwise take 30-40 steps)."""

UNIDENTIFIED = 0.7
"""The tension is identified when the posterior std of the first mode's prestrain combination is
below this fraction of its prior's (as the steady estimator's)."""


@dataclass(frozen=True, eq=False)
class BuffetingFit:
    """A converged buffeting fit and its Laplace posterior.

    ``theta``/``covariance``: scaled unknowns (:attr:`BuffetingProblem.names`); ``prestrain`` and
    ``prestrain_std`` ``(x, y)``; ``tension_ratio``: posterior over prior std of the first mode's
    prestrain combination, ``informative`` when below :data:`UNIDENTIFIED`; ``f11_hz``: the loaded
    first frequency (modal tangent); ``forcing``: ``(A, fc, n)``; ``evidence``: Laplace log-evidence
    (up to the data's normalisation); ``objective``: Whittle's negative log-likelihood plus half the
    static chi-square and half the prior's; ``static_chi2``: the mean's chi-square per sensor;
    ``spectral_chi2``: the frozen-weight Whittle residuals' mean square (1 when the model spectrum is
    right: ``E |W (Ī - S) W^H|_F^2 = p^2 / n_b``); ``problem``: the fitted problem (its full-order defects);
    ``abandoned``: stopped short of its optimum because even that would lie far below a better fit's
    (:func:`fit_buffeting`'s ``abandon``).
    """

    theta: np.ndarray
    covariance: np.ndarray
    names: list
    prestrain: tuple[float, float]
    prestrain_std: tuple[float, float]
    tension_ratio: float
    informative: bool
    damping: float
    damping_std: float
    lift: float
    lift_std: float
    f11_hz: float
    forcing: tuple[float, float, float]
    noise: np.ndarray
    objective: float
    evidence: float
    static_chi2: float
    spectral_chi2: float
    iterations: int
    converged: bool
    fit: Fit
    problem: BuffetingProblem
    abandoned: bool = False


def objective(bp: BuffetingProblem, theta: np.ndarray) -> float:
    """Whittle's negative log-likelihood + half the static chi-square + half the prior's."""
    ev = bp.evaluate(theta)
    rs = (bp.steady.data.mean - ev["s"]) / bp.steady.tau
    rp = bp.prior_matrix @ theta
    return bp.whittle(theta) + 0.5 * float(rs @ rs + rp @ rp)


def start(bp: BuffetingProblem, theta_static: np.ndarray) -> np.ndarray:
    """Start from a static fit's unknowns: prior damping, corner and order, the spectra's noise floor,
    and ``log A`` (and its prior centre) from the sensors' spectra below the corner."""
    th = np.zeros(bp.dim)
    th[: bp.steady.dim] = theta_static
    bp.log_a_ref = 0.0
    st = bp.structure(th, derivatives=False)
    spec = bp.spectra
    low = spec.freq <= 0.5 * FC_REF
    if low.sum() < 3:
        low = np.arange(spec.bins) < 3
    h, _ = bp.transfer(st, 2 * np.pi * spec.freq[low], derivatives=False)
    _, fc, n = bp.forcing(th)
    shape = (1.0 + (spec.freq[low] / fc) ** 2) ** (-n)
    auto = np.real(np.einsum("bii->bi", spec.periodogram[low])) - spec.dt * np.outer(
        bp.noise_shape[low], bp.noise(th) ** 2
    )
    gain = bp.filter_power[low, bp.aliases]  # the DAQ's filter on the bins themselves (k = 0)
    ratio = np.maximum(auto, 0.0) / np.maximum(np.abs(h) ** 2 * (shape * gain)[:, None], 1e-300)
    level = float(np.median(ratio))
    if not (np.isfinite(level) and level > 0):
        raise InputError("buffeting: the record has no fluctuation above its noise floor")
    bp.log_a_ref = float(np.log(level))
    bp._cache.clear()
    return th


def fit_buffeting(
    bp: BuffetingProblem,
    theta0: np.ndarray,
    max_iter: int = 40,
    corrections: int = 1,
    tol: float = 1e-2,
    abandon: float | None = None,
) -> tuple[np.ndarray, Fit, int, bool, bool]:
    """Fisher scoring from ``theta0`` (module docstring); returns ``(theta, fit, iterations, converged,
    abandoned)``. With ``abandon`` (an objective level) scoring stops as soon as the local model's
    minimum, the objective less half the Newton decrement, lies above it: that fit cannot matter
    beside one that reached the level."""
    theta = np.asarray(theta0, dtype=float)
    its, converged, fit = 0, False, None
    for k in range(corrections + 1):
        phi = objective(bp, theta)
        converged = False
        for _ in range(max_iter):
            bp.freeze(theta)
            fit = levenberg_marquardt(bp, theta, max_iter=1, tol=tol)
            if fit.iterations == 0:
                converged = fit.converged
                break
            its += 1
            hopeless = abandon is not None and phi - 0.5 * fit.decrement > abandon
            step = fit.theta - theta
            for _half in range(8):  # the frozen cost fell; the true objective must too
                try:
                    phi_new = objective(bp, theta + step)
                except (InputError, ArithmeticError, SolverError, np.linalg.LinAlgError):
                    phi_new = np.inf
                if phi_new <= phi + 1e-9 * abs(phi):
                    break
                step = 0.5 * step
            else:
                log.debug("buffeting fit: no step lowers the objective; stopped at %.6g", phi)
                break
            theta, phi = theta + step, phi_new
            log.debug("buffeting fit %d: objective %.6g (decrement %.3g)", its, phi, fit.decrement)
            if hopeless:
                log.debug("buffeting fit abandoned: its local minimum lies above %.6g", abandon)
                bp.freeze(theta)
                return theta, levenberg_marquardt(bp, theta, max_iter=0, tol=tol), its, False, True
        if k < corrections:
            correct(bp, theta)
    bp.freeze(theta)
    fit = levenberg_marquardt(bp, theta, max_iter=0, tol=tol)  # precision and Jacobian at theta
    return theta, fit, its, converged, False


def correct(bp: BuffetingProblem, theta: np.ndarray) -> None:
    """Full-order defects at ``theta``: the static outputs and the sensor gains ``2 z̄^T C_i Phi``."""
    sp_ = bp.steady
    th = theta[: sp_.dim]
    sp_._z = None
    try:
        _, sol = sp_.equilibrium(th)
    except (InputError, ArithmeticError, SolverError) as exc:
        log.debug("full-order correction failed: %s", exc)
        return
    q, _ = sp_.modal_state(th)
    fm, Cs = sp_.modal, sp_.model.sensors.matrices
    s_full = np.array([sol.z @ (C @ sol.z) for C in Cs])
    sp_.defect = s_full - fm.outputs(q[None])[0]
    gains = 2.0 * np.stack([fm.shapes.T @ (C @ sol.z) for C in Cs])  # (p, m): 2 z̄^T C_i Phi
    bp.jacobian_defect = gains - 2.0 * fm.sensor_products(q[None])[0]
    bp._cache.clear()
    log.debug("full-order defects: outputs %s", np.round(sp_.defect / np.maximum(np.abs(s_full), 1e-300), 4))


def full_order_frequencies(bp: BuffetingProblem, theta: np.ndarray, count: int = 3) -> np.ndarray:
    """Lowest ``count`` loaded frequencies (Hz) of the full-order FvK tangent at ``theta`` (in-plane condensed)."""
    sp_ = bp.steady
    fvk, sol = sp_.equilibrium(theta[: sp_.dim])
    n = fvk.n
    K = fvk.tangent(sol.z, sol.u, sol.v).tocsc()
    Kwu = K[:n, n:].toarray()
    Kred = K[:n, :n].toarray() - Kwu @ fvk._inplane[1].solve(np.ascontiguousarray(Kwu.T))
    M = (sp_.model.problem.material.areal_density * sp_.model.gram).toarray()
    lam = sla.eigh(0.5 * (Kred + Kred.T), M, eigvals_only=True, subset_by_index=(0, count - 1))
    return np.sqrt(np.maximum(lam, 0.0)) / (2 * np.pi)


def modal_frequencies(bp: BuffetingProblem, theta: np.ndarray, count: int = 3) -> np.ndarray:
    """Lowest ``count`` loaded frequencies (Hz) of the modal tangent at ``theta``."""
    st = bp.structure(np.asarray(theta, dtype=float), derivatives=False)
    r = bp.steady.modal.cubic_modes
    lam = np.sort(np.concatenate([np.linalg.eigvalsh(st["Kc"]), st["k0"][r:]]))[:count]
    return np.sqrt(np.maximum(lam, 0.0)) / (2 * np.pi)


def _mode1_weights(problem) -> np.ndarray:
    """The first mode's prestrain combination (its stiffness ``C((ex + nu ey) kx + (ey + nu ex) ky)``)."""
    nu = problem.material.poisson_ratio
    kx, ky = (np.pi / problem.width) ** 2, (np.pi / problem.height) ** 2
    w = np.array([kx + nu * ky, ky + nu * kx])
    return w / w.sum()


def tension_ratio(sp_, cov: np.ndarray) -> float:
    """Posterior over prior std of the first mode's prestrain combination; ``cov`` the scaled
    unknowns' covariance with the steady problem's unknowns first (NaN: no prestrain is free)."""
    k, ne = sp_.shapes.count, len(sp_.pars)
    if not ne:
        return float("nan")
    wts = _mode1_weights(sp_.model.problem)
    a = np.array([wts[0 if n == "prestrain_x" else 1] * sp_.prior.mean_std(n)[1] for n in sp_.pars])
    R = sp_.prior_matrix[k : k + ne, k : k + ne]
    prior_var = float(a @ np.linalg.inv(R.T @ R) @ a)
    return float(np.sqrt(a @ cov[k : k + ne, k : k + ne] @ a / prior_var))


def mean_prestrain(sp_, theta: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """``(ex + ey)/2`` and its posterior std (``cov`` as in :func:`tension_ratio`)."""
    _, par = sp_.physical(theta[: sp_.dim])
    k = sp_.shapes.count
    g = np.zeros(cov.shape[0])
    for i, name in enumerate(sp_.pars):
        g[k + i] = 0.5 * sp_.prior.mean_std(name)[1]
    return 0.5 * (par.eps0_x + par.eps0_y), float(np.sqrt(g @ cov @ g))


def result(
    bp: BuffetingProblem, theta: np.ndarray, fit: Fit, iterations: int, converged: bool, abandoned: bool = False
) -> BuffetingFit:
    """The posterior of a fit (Laplace: ``fit.covariance``)."""
    sp_ = bp.steady
    cov = fit.covariance
    k = sp_.shapes.count
    _, par = sp_.physical(theta[: sp_.dim])
    std = {n: float(sp_.prior.mean_std(n)[1] * np.sqrt(cov[k + i, k + i])) for i, n in enumerate(sp_.pars)}
    ratio = tension_ratio(sp_, cov)
    g = np.zeros(bp.dim)
    g[: sp_.dim] = sp_.lift_gradient()
    d = bp.damping(theta)
    phi = objective(bp, theta)
    p = bp.spectra.p
    return BuffetingFit(
        theta=theta,
        covariance=cov,
        names=bp.names,
        prestrain=(par.eps0_x, par.eps0_y),
        prestrain_std=(std.get("prestrain_x", 0.0), std.get("prestrain_y", 0.0)),
        tension_ratio=ratio,
        informative=bool(ratio < UNIDENTIFIED),
        damping=d,
        damping_std=float(d * sp_.prior.mean_std("damping")[1] * np.sqrt(cov[bp.i_d, bp.i_d])),
        lift=sp_.lift(theta[: sp_.dim]),
        lift_std=float(np.sqrt(g @ cov @ g)),
        f11_hz=float(modal_frequencies(bp, theta, 1)[0]),
        forcing=bp.forcing(theta),
        noise=bp.noise(theta),
        objective=phi,
        evidence=float(-phi - 0.5 * np.linalg.slogdet(fit.precision)[1]),
        static_chi2=float(np.mean(fit.residuals[:p] ** 2)),
        spectral_chi2=float(np.mean(fit.residuals[p:] ** 2)),
        iterations=iterations,
        converged=converged,
        fit=fit,
        problem=bp,
        abandoned=abandoned,
    )
