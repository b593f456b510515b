"""The transient record fit: nonlinear membrane, unknown tension, gusts, honest band.

One record (batch over all samples; 1 s at 1 kHz is one problem) is fitted by
Levenberg–Marquardt with exact Jacobians (:mod:`.record_problem`, :mod:`.solver`):

1. noise level per sensor from the data (second differences, as the linear MHE) unless given;
2. start-up: an amplitude scan along the smoothest load shape, both signs, from the prior initial
   state and the prior parameters (one batched simulation), then LM from the best point;
3. ``load_model="auto"``: if the constant-load fit does not fit the data, the gust amplitude is
   added and kept when it lowers the chi-square by more than twice the unknowns it adds;
4. adequacy (:mod:`.adequacy`): chi-square per datum and per segment, the band widened by the
   misfit, ``model_adequate`` and warnings in ``info``. Nothing is dropped;
5. a load far outside its smoothness prior is refitted with wider priors (:mod:`.prior_check`),
   unless the frame prior, fitted first, explains it decisively (:mod:`.frame_check`);
6. a record that holds little on the tension (no transient) has its lift band checked by the
   lift's profile likelihood (:mod:`.tension_profile`).
"""

from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation import wiring
from wingopt.estimation.core.adequacy import assess
from wingopt.estimation.core.frame_check import (
    FRAME_SHAPES,
    decided,
    embed,
    extrapolated,
    frame_shapes,
    log_evidence,
    span_other,
    weigh,
)
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.model_form import PRESTRAIN_MODEL_FORM_REL, prestrain_std_with_model_form
from wingopt.estimation.core.prior_check import conflict_test, load_prior_check
from wingopt.estimation.core.record_fit import Budget, Fit, levenberg_marquardt
from wingopt.estimation.core.record_problem import PARAMETERS, ParameterPrior, RecordProblem
from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.core.start import initial_state_prior, modal_model, scan, short_start
from wingopt.estimation.noise import resolve_noise_std
from wingopt.estimation.result import IdentificationResult
from wingopt.estimation.transient.stopping import DECIDED_NATS, EarlyStop, behind, stalled
from wingopt.estimation.transient.tension_profile import tension_profile
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel

__all__ = ["transient_identify"]

log = logging.getLogger(__name__)


def transient_identify(
    model: MembraneModel,
    measurements: Measurements,
    settings: RecordSettings | None = None,
    initial_load: float | None = None,
    routing: str = "transient",
) -> IdentificationResult:
    """Identify load, initial state and model parameters of one record with the modal Berger or
    cubic FvK model (``settings.membrane_model``).

    ``routing`` is what :func:`~wingopt.estimation.records.identify_record` decided, said in
    ``info["routing"]``.
    """
    s = settings or RecordSettings()
    meas = measurements
    t0 = time.perf_counter()
    budget = Budget(s.max_total_iter, s.cpu_s)  # every fit of this record draws on it
    stops: dict[int, tuple[EarlyStop, Fit]] = {}  # id(fit) -> its monitor, when it stopped early (:mod:`.stopping`);
    # the fit itself is kept in the value, so that its id is not reused while the record is estimated

    def fit_(r: RecordProblem, theta0: np.ndarray, cap: RecordSettings = s, rules=()) -> Fit:
        if not (rules and s.stop_early):
            return levenberg_marquardt(r, theta0, cap.max_iter, budget=budget)
        monitor = EarlyStop(rules)
        f = levenberg_marquardt(r, theta0, cap.max_iter, budget=budget, monitor=monitor)
        if f.stopped is not None:
            stops[id(f)] = (monitor, f)
        return f

    skipped: list[str] = []
    problem = model.problem
    sigma, noise_source = resolve_noise_std(
        meas.values, meas.sensor_names, None, meas.noise_std, problem.identification.noise_std
    )
    sigma = np.asarray(sigma, float)
    p0 = problem.identification.initial_load if initial_load is None else float(initial_load)
    dt = float(np.median(np.diff(meas.t)))
    substeps = max(s.substeps, int(np.ceil(dt / s.substep_s - 1e-9)))
    bm = modal_model(model, s.membrane_model, min(s.modes, model.n), dt, substeps, s.stretch_gain, s.cubic_modes)
    shapes, weigh_frame = _load_prior(model, p0, s)
    prior = ParameterPrior.from_problem(problem, s.free, s.prestrain_rel, s.damping_rel)
    x_mean, x_std, bubble_known = initial_state_prior(bm, problem, meas.values)
    candidates = {}
    for i, kind in enumerate(("nonlinear", "linear") if s.membrane == "auto" else (s.membrane,)):
        if i > 0 and s.membrane_model == "fvk" and _fits_data(meas.t, *candidates["nonlinear"], s):
            # FvK's small-deflection limit is the linear membrane: when FvK fits the record the
            # linear variant cannot fit it better; it is fitted only when FvK misfits.
            break
        if i > 0 and budget.exhausted:
            skipped.append("the linear membrane")
            break
        rp = RecordProblem(
            bm,
            shapes,
            meas.t,
            meas.values,
            sigma,
            prior,
            x_mean,
            x_std,
            None,
            kind == "nonlinear",
            min(s.state_modes, bm.m),
        )
        # the alternative is fitted with few iterations first: it is finished only if it wins
        cap = s if i == 0 else s.replace(max_iter=min(s.max_iter, 12))
        candidates[kind] = (rp, fit_(rp, short_start(rp, scan(rp, np.sign(p0))), cap, (stalled,)))
    if len(candidates) == 2 and candidates["linear"][1].cost < candidates["nonlinear"][1].cost:
        rp, f = candidates["linear"]
        candidates["linear"] = (rp, fit_(rp, f.theta, rules=(stalled,)))
    kind = min(candidates, key=lambda k: candidates[k][1].cost)
    rp, fit = candidates[kind]
    selection = {k: {"chi2": f.data_cost, "cost": f.cost} for k, (_, f) in candidates.items()}
    selection["chosen"] = kind
    if s.membrane == "auto" and "linear" not in candidates:
        selection["linear"] = "not fitted: the FvK fit is adequate"
    fits = {"constant": fit}
    chosen = "constant"
    ad = assess(meas.t, _residual_matrix(rp, fit), fit.effective_parameters, s.segment_s)
    if s.load_model == "auto" and not ad.adequate and budget.exhausted:
        skipped.append("the gust load model")
    elif s.load_model == "gust" or (s.load_model == "auto" and not ad.adequate):
        rg = dataclasses.replace(rp, gust=s.gust)
        th = np.zeros(rg.dim)
        for name in ("x0", "c", "par"):
            th[rg.slices[name]] = fit.theta[rp.slices[name]]
        fit_g = fit_(rg, th, rules=(stalled,))
        fits["gust"] = fit_g
        added = rg.dim - rp.dim
        if s.load_model == "gust" or fit.cost - fit_g.cost > 2 * added:
            rp, fit, chosen = rg, fit_g, "gust"
            ad = assess(meas.t, _residual_matrix(rp, fit), fit.effective_parameters, s.segment_s)
    stall = stops.get(id(fit), (None,))[0]
    frame_first, resolved = None, None
    if weigh_frame and s.stop_early and not budget.exhausted and conflict_test(rp, fit)["conflict"]:
        # An edge load: the frame prior (the interior shapes and free-edge ones) is its remedy as much
        # as the interior prior's wider scales; fitted first, a decisive answer spares the ladder.
        frame_first, resolved = _frame_first(rp, fit, model, shapes, s, p0, fit_)
    res, fit = _finish(rp, fit, fits, chosen, ad, sigma, noise_source, t0, s, bubble_known, p0, fit_, resolved)
    if stall is not None:
        res = _stalled(res, fit, stall)
    if weigh_frame and budget.exhausted and frame_first is None:
        skipped.append("the frame load prior")
    elif weigh_frame:
        z = log_evidence(fit)
        if frame_first is None:
            rf = dataclasses.replace(rp, shapes=frame_shapes(model, shapes, s, p0))
            fit_f = fit_(rf, embed(rp, fit.theta, rf), rules=(stalled, behind(z)))
        else:
            rf, fit_f = frame_first
        stop_f = stops.get(id(fit_f), (None,))[0]
        if stop_f is not None and stop_f.reason.startswith("decided"):
            res.info["frame_check"] = decided(z, stop_f)
            lift_f, chi2_f = extrapolated(rf, stop_f.last)
            res = span_other(res, lift_f, fit.data_cost, chi2_f, "frame")
        else:
            ad_f = assess(meas.t, _residual_matrix(rf, fit_f), fit_f.effective_parameters, s.segment_s)
            res_f, fit_f = _finish(rf, fit_f, {chosen: fit_f}, chosen, ad_f, sigma, noise_source, t0, s, bubble_known,
                                   p0, fit_)  # fmt: skip
            if stop_f is not None:
                res_f = _stalled(res_f, fit_f, stop_f)
            res = weigh(res, res_f, z, log_evidence(fit_f), (fit.data_cost, fit_f.data_cost))
    res.info["membrane_selection"] = selection
    res.info["budget"] = {"iterations": budget.used, "max_total_iter": s.max_total_iter, "cpu_s": budget.spent,
                          "exhausted": budget.exhausted, "not_fitted": skipped}  # fmt: skip
    if budget.exhausted:
        res.info["converged"] = False  # the work was not finished, whichever fit was kept
        res.info["warnings"].append(
            f"stopped at the record's work budget ({budget.used} Levenberg-Marquardt iterations over all fits, "
            f"max_total_iter {s.max_total_iter}; {budget.spent:.1f} s CPU): a record this model explains poorly"
            + (f"; not fitted: {', '.join(skipped)}" if skipped else "")
        )
    res.info["routing"] = routing
    wiring.attach(res.info, model, meas.t, meas.values, s, p0, steady=False)  # gains, offsets, swaps: warned
    res.wall_s = time.perf_counter() - t0
    return res


def _load_prior(model: MembraneModel, p0: float, s: RecordSettings) -> tuple[LoadShapes, bool]:
    """The load shapes of a transient record and whether the frame prior is weighed against them
    (``[identification] pressure_prior``: ``auto`` weighs, ``interior``/``frame``/``aerodynamic`` take one)."""
    ident = model.problem.identification
    kind = ident.pressure_prior
    if kind == "aerodynamic":
        if not ident.leading_edge:
            raise InputError(
                "[identification] pressure_prior = 'aerodynamic' on a transient record: needs leading_edge = 'x0' "
                "or 'x1' (which edge the flow meets)"
            )
        return LoadShapes.aerodynamic(model, p0, ident.leading_edge, s.kappa), False
    edge = s.edge_shapes or (FRAME_SHAPES if kind == "frame" else 0)
    shapes = LoadShapes.build(model, s.shapes, p0, s.kappa, s.prior_power, edge)
    return shapes, s.frame == "auto" and kind == "auto" and edge == 0


def _stalled(res: IdentificationResult, fit: Fit, w: EarlyStop) -> IdentificationResult:
    """A fit stopped by a stall (:func:`.stopping.stalled`): its band widened by ``sqrt(1 + decrement)``
    (the local model's minimum is within ``sqrt(decrement)`` posterior sigma), and a warning."""
    widen, reason = float(np.sqrt(1.0 + w.stall_decrement)), w.reason
    res.info["stopped_early"] = {"reason": reason, "iterations": fit.iterations, "band_widening": widen}
    res.info["warnings"].append(
        f"the fit {reason}: stopped after {fit.iterations} iterations, not converged; band widened x{widen:.2f}"
    )
    return dataclasses.replace(res, lift_std=res.lift_std * widen)


def _frame_first(rp, fit, model, shapes, s, p0, fit_) -> tuple[tuple[RecordProblem, Fit], str | None]:
    """The frame prior's fit of a record whose interior fit conflicts with its prior, and, when it
    explains the record without a conflict of its own and :data:`.stopping.DECIDED_NATS` better
    than the conflicting fit, the note that resolves the conflict (the interior prior's wider scales
    are then not fitted: measured on L3, FvK truth 49x25, 1 s, they reach 7 nats below the frame
    prior, which is 36 above the conflicting fit; 92 of the record's 128 iterations)."""
    rf = dataclasses.replace(rp, shapes=frame_shapes(model, shapes, s, p0))
    fit_f = fit_(rf, short_start(rf, embed(rp, fit.theta, rf)), rules=(stalled,))
    gap = log_evidence(fit_f) - log_evidence(fit)
    if fit_f.out_of_budget or conflict_test(rf, fit_f)["conflict"] or gap <= DECIDED_NATS:
        return (rf, fit_f), None
    return (rf, fit_f), f"the frame load prior explains the record without one, {gap:.0f} nats better"


def _finish(rp, fit, fits, chosen, ad, sigma, noise_source, t0, s, bubble_known, p0, fit_, resolved=None):
    """The prior check, the sign and the result of a fit, with the tension profile's band check."""
    rp, fit, spread, prior_info = load_prior_check(rp, fit, fit_, resolved)
    if prior_info["conflict"]:
        ad = assess(rp.t, _residual_matrix(rp, fit), fit.effective_parameters, s.segment_s)
    c, _ = rp.load_history(fit.theta)
    if not bubble_known and rp.shapes.lift_row @ c * np.sign(p0) < 0:
        # Sign-blind sensors: state and load flip together; the prior load's sign decides.
        fit = dataclasses.replace(fit, theta=_flip(rp, fit.theta))
    res = _result(rp, fit, fits, chosen, ad, sigma, noise_source, time.perf_counter() - t0, s, spread, prior_info)
    if fit.out_of_budget:
        res = _cut_short(res, rp, fit)
    return _with_tension_profile(res, rp, fit, ad, fit_), fit


def _cut_short(res: IdentificationResult, rp: RecordProblem, fit: Fit) -> IdentificationResult:
    """A fit the work budget stopped: its band widened by ``sqrt(1 + decrement)`` at its last point
    (as a stall's: the local model's minimum is within ``sqrt(decrement)`` posterior sigma)."""
    R = rp.prior_matrix
    g = fit.data_jacobian.T @ fit.residuals + R.T @ (R @ fit.theta)
    dec = float(g @ np.linalg.solve(fit.precision, g))
    widen = float(np.sqrt(1.0 + dec))
    res.info["budget_widening"] = widen
    res.info["warnings"].append(
        f"the work budget stopped the fit {dec:.3g} chi-square units short of its local model's minimum: "
        f"band widened x{widen:.2f}"
    )
    return dataclasses.replace(res, lift_std=res.lift_std * widen)


def _with_tension_profile(res: IdentificationResult, rp: RecordProblem, fit: Fit, ad, fit_) -> IdentificationResult:
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


def _fits_data(t: np.ndarray, rp: RecordProblem, fit: Fit, s: RecordSettings) -> bool:
    return assess(t, _residual_matrix(rp, fit), fit.effective_parameters, s.segment_s).adequate


def _flip(rp: RecordProblem, theta: np.ndarray) -> np.ndarray:
    th = theta.copy()
    for name in ("x0", "c"):
        th[rp.slices[name]] *= -1
    th[rp.slices["x0"]] -= 2 * rp.x0_mean / rp.x0_std
    return th


def _residual_matrix(rp: RecordProblem, fit: Fit) -> np.ndarray:
    out = np.full(rp.y.shape, np.nan)
    out[rp.valid] = fit.residuals
    return out


def _result(rp, fit: Fit, fits, chosen, ad, sigma, noise_source, wall, s, spread, prior_info) -> IdentificationResult:
    bm, shapes = rp.model, rp.shapes
    cov = fit.covariance * ad.inflation**2
    c, amp = rp.load_history(fit.theta)
    Q, _ = rp.predicted(fit.theta)
    loads = amp[:, None] * shapes.coefficients(c)[None]
    base = float(shapes.lift_row @ c)
    lift = amp * base
    # d lift_k / d theta: shape part a_k l * std_c, gust part base * hat row
    G = np.zeros((rp.t.size, rp.dim))
    G[:, rp.slices["c"]] = amp[:, None] * (shapes.lift_row * shapes.prior_std)[None]
    if rp.hats is not None:
        G[:, rp.slices["g"]] = base * rp.hats
    lift_std = np.sqrt(np.einsum("ki,ij,kj->k", G, cov, G) + (0.0 if spread is None else spread**2))
    params = rp.physical(fit.theta)
    est, std = {}, {}
    for name in PARAMETERS:
        est[name] = float(np.real(params[name][0]))
        std[name] = 0.0
    fvk = bm.physics == "fvk"
    for i, name in enumerate(rp.prior.free):
        j = rp.slices["par"].start + i
        sd = rp.prior.mean_std(name)[1] * np.sqrt(cov[j, j])
        std[name] = float(sd * est[name]) if name == "damping" else float(sd)
        if fvk and rp.nonlinear:
            std[name] = prestrain_std_with_model_form(name, est[name], std[name])
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
    if prior_info["conflict"] and "resolved" in prior_info:
        warnings.append(
            f"load outside its prior (chi-square {prior_info['load_chi2']:.0f} over {prior_info['shapes']} shapes > "
            f"{prior_info['threshold']:.0f}): not refitted with wider priors, {prior_info['resolved']}"
        )
    elif prior_info["conflict"]:
        warnings.append(
            f"load outside its prior (chi-square {prior_info['load_chi2']:.0f} over {prior_info['shapes']} shapes > "
            f"{prior_info['threshold']:.0f}): refitted with wider load priors, kept x{prior_info['kept']} "
            f"(largest evidence); the lift depends on the prior by {prior_info['lift_spread']:.3g} N, added to the band"
            + (f" ({prior_info['cut']})" if "cut" in prior_info else "")
        )
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
        "warnings": warnings,
        "dropped": [],
        "missing_samples": int(np.count_nonzero(~rp.valid.all(axis=1))),
    }
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
