"""A transient record fit as an :class:`~wingopt.estimation.core.result.IdentificationResult`: the lift
and its band, the parameters, the warnings, and the band's widenings when a fit stopped short (a
stall, the work budget) or the record holds little on the tension."""

from __future__ import annotations

import dataclasses

import numpy as np

from wingopt.estimation.core.model_form import PRESTRAIN_MODEL_FORM_REL, prestrain_std_with_model_form
from wingopt.estimation.core.record_fit import Fit
from wingopt.estimation.core.record_problem import PARAMETERS, RecordProblem
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.transient.lift_sensitivity import lift_jacobian
from wingopt.estimation.transient.stopping import EarlyStop
from wingopt.estimation.transient.tension_profile import tension_profile

__all__ = [
    "fit_result",
    "band_parts",
    "stalled_band",
    "cut_short",
    "with_tension_profile",
    "residual_matrix",
    "half_gradient",
]


def residual_matrix(rp: RecordProblem, fit: Fit) -> np.ndarray:
    """The fit's data residuals ``(N, p)`` (NaN where a sample is missing)."""
    out = np.full(rp.y.shape, np.nan)
    out[rp.valid] = fit.residuals
    return out


def half_gradient(rp: RecordProblem, fit: Fit) -> np.ndarray:
    """The cost's half gradient ``J^T r`` (data and prior rows) where ``fit`` stopped."""
    R = rp.prior_matrix
    return fit.data_jacobian.T @ fit.residuals + R.T @ (R @ fit.theta)


def fit_result(
    rp, fit: Fit, fits, chosen, ad, sigma, noise_source, wall, s, spread, prior_info
) -> IdentificationResult:
    """The result of ``fit`` of ``rp`` (its covariance inflated by the misfit ``ad``; ``spread``:
    the lift's dependence on the load prior, added to the band in quadrature)."""
    bm, shapes = rp.model, rp.shapes
    cov = fit.covariance * ad.inflation**2
    c, amp = rp.load_history(fit.theta)
    Q, _ = rp.predicted(fit.theta)
    loads = amp[:, None] * shapes.coefficients(c)[None]
    G = lift_jacobian(rp, c, amp)
    lift, lift_std = _lift_band(rp, c, amp, G, cov, spread)
    est, std = _parameters(rp, fit, cov)
    fvk = bm.physics == "fvk"
    name = f"FvK cubic, {bm.cubic_modes} modes" if fvk else "Berger"
    info = {
        "backend": f"realistic (modal {name}, exact forward-sensitivity Jacobian, Levenberg-Marquardt)",
        "model": f"nonlinear ({name})" if rp.nonlinear else "linear",
        "modes": bm.m,
        "load_shapes": shapes.count,
        "load_model": chosen,
        "iterations": fit.iterations,
        "converged": fit.converged,
        "noise_std": [float(x) for x in sigma],
        "noise_source": noise_source,
        "parameters": est,
        "parameters_std": std,
        "parameters_model_form_rel": {"prestrain": PRESTRAIN_MODEL_FORM_REL} if fvk and rp.nonlinear else {},
        "free_parameters": list(rp.prior.free),
        "prior": {"prestrain_rel": rp.prior.prestrain_rel, "damping_rel": rp.prior.damping_rel},
        "fits": {k: {"chi2": f.data_cost, "prior": f.prior_cost, "iterations": f.iterations} for k, f in fits.items()},
        "log_evidence": float(-0.5 * fit.cost - 0.5 * np.linalg.slogdet(fit.precision)[1]),
        "adequacy": ad.as_dict(),
        "load_prior": prior_info,
        "model_adequate": ad.adequate,
        "warnings": _warnings(fit, ad, prior_info),
        "dropped": [],
        "missing_samples": int(np.count_nonzero(~rp.valid.all(axis=1))),
    }
    info["lift_band_parts"] = band_parts(rp, fit, G[-1], ad.inflation, spread)
    if fit.arrived is not None:
        info["converged_by"] = fit.arrived  # the lift's test (:func:`.stopping.arrived`), not the decrement's
    return IdentificationResult(
        method="realistic",
        t=rp.t,
        load=loads,
        deflection=bm.deflection(Q),
        lift=lift,
        lift_std=lift_std,
        regularization=float(s.kappa),
        wall_s=wall,
        info=info,
        load_space=None if shapes.space is None else shapes.space.space,
    )


def _lift_band(rp: RecordProblem, c, amp, G, cov, spread) -> tuple[np.ndarray, np.ndarray]:
    """The lift history and its band: linearised in the unknowns (``G``: the lift's sensitivity,
    :func:`.lift_sensitivity.lift_jacobian`), the prior's ``spread`` added."""
    lift = amp * float(rp.shapes.lift_row @ c)
    lift_std = np.sqrt(np.einsum("ki,ij,kj->k", G, cov, G) + (0.0 if spread is None else spread**2))
    return lift, lift_std


def band_parts(rp: RecordProblem, fit: Fit, lift_row: np.ndarray, inflation: float, spread) -> dict:
    """The reported lift's band before its widenings, in parts (N): ``noise``, what the data's noise
    puts in the posterior (``G P^-1 J_d^T J_d P^-1 G^T``: the scatter of the answer over noise
    draws), ``prior``, what the priors put in (``G P^-1 R^T R P^-1 G^T``: the load shapes and
    parameters the data leave to their prior; for one load, a bias common to all draws), their
    ``misfit_inflation`` and the load prior's ``spread``. The band is
    ``sqrt(inflation^2 (noise^2 + prior^2) + spread^2)``; a stall's, the budget's, the tension
    profile's and the frame prior's widenings come after (their own ``info`` entries). ``lift_row``:
    the final lift's sensitivity to the unknowns."""
    g = lift_row @ fit.covariance
    R = rp.prior_matrix
    noise, prior = fit.data_jacobian @ g, R @ g
    return {
        "noise_N": float(np.sqrt(noise @ noise)),
        "prior_N": float(np.sqrt(prior @ prior)),
        "misfit_inflation": float(inflation),
        "load_prior_spread_N": 0.0 if spread is None else float(np.atleast_1d(spread)[-1]),
    }


def _parameters(rp: RecordProblem, fit: Fit, cov: np.ndarray) -> tuple[dict, dict]:
    """The model parameters' estimates and standard deviations (the free ones' from ``cov``; the
    prestrains' with the FvK model's form error)."""
    params = rp.physical(fit.theta)
    est, std = {}, {}
    for name in PARAMETERS:
        est[name] = float(np.real(params[name][0]))
        std[name] = 0.0
    fvk = rp.model.physics == "fvk"
    for i, name in enumerate(rp.prior.free):
        j = rp.slices["par"].start + i
        sd = rp.prior.mean_std(name)[1] * np.sqrt(cov[j, j])
        std[name] = float(sd * est[name]) if name == "damping" else float(sd)
        if fvk and rp.nonlinear:
            std[name] = prestrain_std_with_model_form(name, est[name], std[name])
    return est, std


def _warnings(fit: Fit, ad, prior_info: dict) -> list[str]:
    """What the reader must know of the fit: a misfit, no convergence, a load outside its prior."""
    warnings = []
    if not ad.adequate:
        warnings.append(
            f"model inadequate: chi-square per datum {ad.chi2_per_datum:.2f} (tolerance 1 + {ad.tolerance:g}), "
            f"{len(ad.bad_segments)} segment(s) misfit; band widened x{ad.inflation:.2f}"
        )
        if ad.chi2_per_datum > 4.0:
            warnings.append("cannot identify this record with this model: the data contradict it")
    if not fit.converged:
        warnings.append(
            f"the fit did not converge in {fit.iterations} Levenberg-Marquardt iterations: the estimate and its "
            "band are not those of the optimum (a record this model explains poorly, or max_iter too small)"
        )
    outside = (
        f"load outside its prior (chi-square {prior_info['load_chi2']:.0f} over {prior_info['shapes']} shapes > "
        f"{prior_info['threshold']:.0f}): "
    )
    if prior_info["conflict"] and "resolved" in prior_info:
        warnings.append(outside + f"not refitted with wider priors, {prior_info['resolved']}")
    elif prior_info["conflict"]:
        warnings.append(
            outside + f"refitted with wider load priors, kept x{prior_info['kept']} (largest evidence); the lift "
            f"depends on the prior by {prior_info['lift_spread']:.3g} N, added to the band"
            + (f" ({prior_info['cut']})" if "cut" in prior_info else "")
        )
    return warnings


def stalled_band(res: IdentificationResult, fit: Fit, w: EarlyStop) -> IdentificationResult:
    """A fit stopped by a stall (:func:`.stopping.stalled`): its band widened by ``sqrt(1 + decrement)``
    (the local model's minimum is within ``sqrt(decrement)`` posterior sigma), and a warning."""
    widen, reason = float(np.sqrt(1.0 + w.stall_decrement)), w.reason
    res.info["stopped_early"] = {"reason": reason, "iterations": fit.iterations, "band_widening": widen}
    res.info["warnings"].append(
        f"the fit {reason}: stopped after {fit.iterations} iterations, not converged; band widened x{widen:.2f}"
    )
    return dataclasses.replace(res, lift_std=res.lift_std * widen)


def cut_short(res: IdentificationResult, rp: RecordProblem, fit: Fit) -> IdentificationResult:
    """A fit the work budget or its iteration cap stopped: its band widened by ``sqrt(1 + decrement)``
    at its last point (as a stall's: the local model's minimum is within ``sqrt(decrement)`` posterior
    sigma). Why the cap too: fuzz #12 (``benchmarks/fuzz_records.py``) ended its frame prior's fit at
    40 iterations, decrement 2, at 2.087 ± 0.136 N; run to the end it gave 2.300 ± 0.139 N."""
    g = half_gradient(rp, fit)
    dec = float(g @ np.linalg.solve(fit.precision, g))
    widen = float(np.sqrt(1.0 + dec))
    what = "the work budget" if fit.out_of_budget else f"its iteration cap ({fit.iterations})"
    res.info["budget_widening" if fit.out_of_budget else "cap_widening"] = widen
    res.info["warnings"].append(
        f"{what} stopped the fit {dec:.3g} chi-square units short of its local model's minimum: "
        f"band widened x{widen:.2f}"
    )
    return dataclasses.replace(res, lift_std=res.lift_std * widen)


def with_tension_profile(res: IdentificationResult, rp: RecordProblem, fit: Fit, ad, fit_) -> IdentificationResult:
    """Check the band by the lift's profile when the record holds little on the tension."""
    band = float(res.lift_std[-1])
    wide, info = tension_profile(rp, fit, fit.covariance * ad.inflation**2, band, fit_)
    res.info["tension_profile"] = info
    if not info["applied"]:
        return res
    msg = (
        f"the record holds little on the tension (mean prestrain sigma {info['scale_std']:.0%}, "
        f"{info['ratio']:.0%} of the prior's: no transient?) and the lift scales with it: the lift's profile "
        f"rises less than the band says (chi-square {min(info['cost_rises']):.2f} at one band); band widened "
        f"x{info['widening']:.2f}"
    )
    res.info["warnings"].append(msg)
    return dataclasses.replace(res, lift_std=res.lift_std * (wide / band))
