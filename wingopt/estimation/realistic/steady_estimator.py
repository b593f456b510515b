"""The whole-record estimator for steady records: static fits weighed by evidence, and the lift history.

:func:`steady_identify` fits the sensors' mean with the static FvK membrane (:mod:`.steady`) under
two load priors (zero on the frame; acting up to it) and from two lobe patterns (the sensors cannot
tell a load's lobes' signs), weighs the fits by their Laplace evidence and reports the mixture's
lift and band. The lift history is the steady lift times the record's relative load fluctuation,
read off the sensors linearised about the static shape (``ds_i / s_i = alpha_i d(load) / load``).
Whether the tension is identified is said: without a calibration or another source the record's
band is set by the prestrain prior, and a warning says so.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse.linalg as spla

from wingopt.estimation.realistic.frame_check import FRAME_SHAPES
from wingopt.estimation.realistic.load_model import LoadShapes
from wingopt.estimation.realistic.record_problem import ParameterPrior
from wingopt.estimation.realistic.settings import RealisticSettings
from wingopt.estimation.realistic.steady import SteadyProblem, evidence, fit_steady, starts, steady_data
from wingopt.estimation.result import IdentificationResult
from wingopt.measurements import Measurements
from wingopt.membrane.model import MembraneModel

__all__ = ["steady_identify", "UNIDENTIFIED", "is_steady"]

log = logging.getLogger(__name__)

UNIDENTIFIED = 0.7
"""The tension is called unidentified when the posterior std of the first mode's prestrain
combination is above this fraction of its prior's."""

LIFT_UNRESOLVED = 0.3
"""The lift is called unresolved when its posterior std is above this fraction of its prior's."""

SAME = 1e-3
"""Two fits whose lifts and costs agree to this (relative) are one solution, counted once."""


def is_steady(values: np.ndarray, head: float = 0.1, tolerance: float = 0.1, ringing: float = 3.0) -> bool:
    """A record without a transient: over its first ``head`` fraction, every sensor's mean is within
    ``tolerance`` (relative) of its second half's and its fluctuation at most ``ringing`` times the
    second half's. A release rings: its early RMS is 20-40x the late one (the protocol's bubble under
    L1, whose mean is within 10 %), a buffeted record's is about 1."""
    y = np.asarray(values, dtype=float)
    n = y.shape[0]
    if n < 40:
        return False
    early, late = y[: max(int(head * n), 5)], y[n // 2 :]
    first, last = np.nanmean(early, axis=0), np.nanmean(late, axis=0)
    scale = np.maximum(np.abs(last), 1e-300)
    stationary = np.nanstd(early, axis=0) <= ringing * np.maximum(np.nanstd(late, axis=0), 1e-12 * scale)
    return bool(np.all(np.abs(first - last) <= tolerance * scale) and np.all(stationary))


def _mode1_weights(problem) -> np.ndarray:
    """The first mode's prestrain combination: its stiffness ``C((ex + nu ey) kx + (ey + nu ex) ky)``."""
    nu = problem.material.poisson_ratio
    kx, ky = (np.pi / problem.width) ** 2, (np.pi / problem.height) ** 2
    w = np.array([kx + nu * ky, ky + nu * kx])
    return w / w.sum()


def _fluctuation(model: MembraneModel, sp_: SteadyProblem, fit, meas: Measurements, data) -> np.ndarray:
    """The relative load fluctuation ``eps(t)`` read off the sensors linearised about the static state."""
    fvk, sol = sp_.equilibrium(fit.theta)
    c, _ = sp_.physical(fit.theta)
    K = fvk.tangent(sol.z, sol.u, sol.v).tocsc()
    rhs = np.zeros(3 * fvk.n)
    rhs[: fvk.n] = sp_.shapes.forces @ c
    dz = spla.splu(K).solve(rhs)[: fvk.n]
    Cs = model.sensors.matrices
    s = np.array([sol.z @ (C @ sol.z) for C in Cs])
    alpha = np.array([2.0 * sol.z @ (C @ dz) for C in Cs]) / np.maximum(np.abs(s), 1e-300)
    rel = meas.values / data.mean[None, :] - 1.0  # about the record's mean: the steady lift is its mean
    w = alpha**2 / np.maximum((data.fluctuation / np.abs(s)) ** 2, 1e-12)
    ok = np.isfinite(rel)
    num = np.where(ok, rel * (w / alpha)[None, :], 0.0).sum(axis=1)
    den = np.where(ok, w[None, :], 0.0).sum(axis=1)
    return np.where(den > 0, num / np.maximum(den, 1e-300), np.nan)


def steady_identify(
    model: MembraneModel, measurements: Measurements, settings=None, initial_load: float | None = None
) -> IdentificationResult:
    """The load of a steady record (see the module docstring); settings as the realistic estimator's."""
    s = settings or RealisticSettings(membrane_model="fvk")
    t0 = time.perf_counter()
    problem, meas = model.problem, measurements
    p0 = problem.identification.initial_load if initial_load is None else float(initial_load)
    prior = ParameterPrior.from_problem(problem, s.free, s.prestrain_rel, s.damping_rel)
    data = steady_data(meas.values)
    priors = _priors(model, p0, s)
    found = []
    for label, shapes in priors:
        for k, th in enumerate(starts(SteadyProblem(model, shapes, data, prior), np.sign(p0))):
            sp_ = SteadyProblem(model, shapes, data, prior)
            fit = fit_steady(sp_, [th], s.max_iter)
            lift = sp_.lift(fit.theta)
            if np.sign(lift) * np.sign(p0) < 0:  # the whole load and the state flip together: the prior's sign
                fit = type(fit)(**{**fit.__dict__, "theta": _negated(sp_, fit.theta)})
                lift = -lift
            dup = any(abs(lift - f[3]) <= SAME * abs(lift) + 1e-12 and abs(fit.cost - f[2].cost) <= SAME * f[2].cost
                      for f in found if f[0].split(",")[0] == label)  # fmt: skip
            if not dup:
                found.append((label + ("" if k == 0 else ", other lobes"), sp_, fit, lift))
    z = np.array([evidence(f[2]) for f in found])
    w = np.exp(z - z.max())
    w /= w.sum()
    g = [f[1].lift_gradient() for f in found]
    stds = np.array([float(np.sqrt(gi @ f[2].covariance @ gi)) for gi, f in zip(g, found)])
    lifts = np.array([f[3] for f in found])
    mean = float(w @ lifts)
    std = float(np.sqrt(max(w @ (stds**2 + lifts**2) - mean**2, 0.0)))
    best = int(np.argmax(w))
    label, sp_, fit, _ = found[best]
    warnings = _warnings(sp_, fit, prior, problem, found, w)
    eps = _fluctuation(model, sp_, fit, meas, data)
    c, par = sp_.physical(fit.theta)
    coef = sp_.shapes.coefficients(c)
    amp = 1.0 + np.nan_to_num(eps, nan=0.0)
    fvk, sol = sp_.equilibrium(fit.theta)
    info = _info(sp_, fit, found, w, z, stds, data, warnings, label)
    info["steady_lift_N"], info["steady_lift_std_N"] = mean, std
    return IdentificationResult(
        method="steady",
        t=meas.t,
        load=amp[:, None] * coef[None],
        deflection=np.broadcast_to(sol.z, (meas.count, sol.z.size)),
        lift=mean * amp,
        lift_std=std * amp,
        regularization=float(s.kappa),
        wall_s=time.perf_counter() - t0,
        info=info,
        load_space=None if sp_.shapes.space is None else sp_.shapes.space.space,
    )


def _priors(model: MembraneModel, p0: float, s) -> list[tuple[str, LoadShapes]]:
    """The load priors of a steady record (``[identification] pressure_prior``).

    A steady record's four means cannot tell a load that vanishes on the frame from one that acts up
    to it (a pressure near the frame hardly deflects the membrane, yet carries lift), and evidence
    then favours the narrower prior whatever the truth (measured: a uniform pressure read 42 % low at
    15 bands under the interior prior). So ``auto`` takes the prior that holds both, and the band
    carries what the means leave open; ``aerodynamic`` is the user's assumption of a thin-airfoil load.
    """
    ident = model.problem.identification
    kind = "interior" if s.frame == "off" else ident.pressure_prior
    if kind == "interior":
        return [("interior", LoadShapes.build(model, s.shapes, p0, s.kappa, s.prior_power))]
    if kind == "aerodynamic":
        edges = (ident.leading_edge,) if ident.leading_edge else ("x0", "x1")
        return [(f"aerodynamic {e}", LoadShapes.aerodynamic(model, p0, e, s.kappa)) for e in edges]
    return [("frame", LoadShapes.build(model, s.shapes, p0, s.kappa, s.prior_power, FRAME_SHAPES))]


def _negated(sp_: SteadyProblem, theta: np.ndarray) -> np.ndarray:
    th = theta.copy()
    th[: sp_.shapes.count] *= -1
    return th


def _tension_ratio(sp_: SteadyProblem, fit, prior: ParameterPrior, problem) -> float | None:
    """Posterior / prior std of the first mode's prestrain combination (``None``: none is free)."""
    if len(sp_.pars) < 1:
        return None
    k = sp_.shapes.count
    wts = _mode1_weights(problem)
    idx = {"prestrain_x": 0, "prestrain_y": 1}
    a = np.zeros(len(sp_.pars))
    for i, name in enumerate(sp_.pars):
        a[i] = wts[idx[name]] * prior.mean_std(name)[1]
    post = a @ fit.covariance[k:, k:] @ a
    R = np.linalg.inv(sp_.prior_matrix[k:, k:].T @ sp_.prior_matrix[k:, k:])
    return float(np.sqrt(post / (a @ R @ a)))


def _lift_resolution(sp_: SteadyProblem, fit) -> float:
    """Posterior / prior std of the lift (the load shapes only): near 1, the prior sets the lift."""
    g = sp_.lift_gradient()
    prior = float(np.linalg.norm(g))
    return float(np.sqrt(g @ fit.covariance @ g)) / max(prior, 1e-300)


def _warnings(sp_, fit, prior, problem, found, w) -> list[str]:
    out = []
    resolved = _lift_resolution(sp_, fit)
    if resolved > LIFT_UNRESOLVED:
        out.append(
            f"the sensors' means do not resolve how the pressure is spread (near the frame it carries lift but "
            f"hardly deflects the membrane): the lift's band is {resolved:.0%} of its prior's; a record whose "
            "buffeting identifies the shape, DIC frames, or a declared aerodynamic load ([identification] "
            "pressure_prior = 'aerodynamic', leading_edge) narrow it"
        )
    ratio = _tension_ratio(sp_, fit, prior, problem)
    calibrated = problem.identification.prestrain_std is not None
    if ratio is not None and ratio > UNIDENTIFIED and not calibrated:
        source = "the problem file"
        out.append(
            f"the record does not identify the tension (a steady record: its prestrain posterior is {ratio:.0%} of "
            f"the prior from {source}): the lift scales with the tension, and its band is the prior's; a "
            "calibration record (wingopt calibrate) identifies it"
        )
    labels = {f[0].split(",")[0] for f, wi in zip(found, w) if wi > 0.05}
    if "interior" in labels and len(labels) > 1:
        out.append("the sensors do not tell whether the pressure reaches the frame: the lift and its band mix both")
    if {"aerodynamic x0", "aerodynamic x1"} <= labels:
        out.append(
            "the sensors do not tell which edge is the leading edge: the lift and its band mix both; declare it "
            "([identification] leading_edge = 'x0' or 'x1')"
        )
    lobes = [f for f, wi in zip(found, w) if wi > 0.05 and "other lobes" in f[0]]
    if lobes and any(wi > 0.05 and "other lobes" not in f[0] for f, wi in zip(found, w)):
        out.append(
            "the sensors do not tell the load's lobe signs apart (they see the slopes squared): the band spans "
            "both patterns"
        )
    return out


def _info(sp_, fit, found, w, z, stds, data, warnings, label) -> dict:
    c, par = sp_.physical(fit.theta)
    k = sp_.shapes.count
    cov = fit.covariance
    std = {n: float(sp_.prior.mean_std(n)[1] * np.sqrt(cov[k + i, k + i])) for i, n in enumerate(sp_.pars)}
    dof = max(data.mean.size - fit.effective_parameters, 1.0)
    chi2 = fit.data_cost / dof
    return {
        "backend": "steady record: static FvK (full order) fits weighed by evidence",
        "model": "nonlinear (FvK, static, full order)",
        "record": "steady",
        "solutions": [
            {
                "prior": f[0],
                "lift_N": float(f[3]),
                "lift_std_N": float(sd),
                "log_evidence": float(zi),
                "weight": float(wi),
            }
            for f, sd, zi, wi in zip(found, stds, z, w.tolist())
        ],
        "chosen": label,
        "parameters": {"prestrain_x": par.eps0_x, "prestrain_y": par.eps0_y, "damping": float(sp_.prior.damping)},
        "parameters_std": {**{"prestrain_x": 0.0, "prestrain_y": 0.0, "damping": 0.0}, **std},
        "sensor_mean": data.mean.tolist(),
        "sensor_fit": sp_.outputs(fit.theta).tolist(),
        "sensor_mean_std": data.std_error.tolist(),
        "fluctuation_rms": (data.fluctuation / np.abs(data.mean)).tolist(),
        "iterations": fit.iterations,
        "converged": fit.converged,
        "adequacy": {"chi2_per_datum": float(chi2), "data": int(data.mean.size)},
        "model_adequate": bool(chi2 < 4.0),
        "warnings": warnings,
        "dropped": [],
    }
