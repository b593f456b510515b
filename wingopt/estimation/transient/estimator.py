"""The transient record fit: nonlinear membrane, unknown tension, gusts, honest band.

One record (batch over all samples; 1 s at 1 kHz is one problem) is fitted by
Levenberg–Marquardt with exact Jacobians (:mod:`.record_problem`, :mod:`.solver`):

1. noise level per sensor from the data (second differences, as the linear MHE) unless given; the
   declared initial shape checked against the record's first samples (:mod:`.initial_shape`);
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

:func:`transient_identify` runs these as named steps on one :class:`~.run.RecordRun` (the record's
noise, start, priors and work budget): the membrane's fit (1-2), the load model's (3), the checks
(4-6), and what the run reports (the budget, the initial shape's check, the routing, the wiring);
:mod:`.fit_result` turns a fit into its result and band.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from wingopt.estimation.core.adequacy import assess
from wingopt.estimation.core.frame_check import (
    decided,
    embed,
    extrapolated,
    frame_shapes,
    log_evidence,
    reach,
    span_other,
    weigh,
)
from wingopt.estimation.core.onset import lead_note
from wingopt.estimation.core.prior_check import conflict_test, load_prior_check
from wingopt.estimation.core.record_fit import Fit
from wingopt.estimation.core.record_problem import RecordProblem
from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.core.start import scan, short_start
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.steady.wiring import attach as attach_wiring
from wingopt.estimation.transient.fit_result import (
    cut_short,
    fit_result,
    half_gradient,
    residual_matrix,
    stalled_band,
    with_tension_profile,
)
from wingopt.estimation.transient.initial_shape import contradiction_note
from wingopt.estimation.transient.run import RecordRun
from wingopt.estimation.transient.stopping import DECIDED_NATS, behind, stalled
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel

__all__ = ["transient_identify"]

Heading = np.ndarray | None
"""The lift ``(N,)`` one Gauss–Newton step on from where a fit stopped short (``None``: it converged)."""


def transient_identify(
    model: MembraneModel,
    measurements: Measurements,
    settings: RecordSettings | None = None,
    initial_load: float | None = None,
    routing: str = "transient",
) -> IdentificationResult:
    """Identify load, initial state and model parameters of one record with the modal Berger or
    cubic FvK model (``settings.membrane_model``).

    ``settings.declaration`` is filled from ``model.problem`` when not given (this fit may be called
    directly). ``routing`` is what :func:`~wingopt.estimation.records.identify_record` decided,
    said in ``info["routing"]``.
    """
    s = with_declaration(settings or RecordSettings(), model.problem)
    run = RecordRun(model, measurements, s, initial_load)  # noise and start
    rp, fit, selection = _membrane_fit(run)
    rp, fit, fits, chosen, ad = _load_model_fit(run, rp, fit)
    res = _checked(run, rp, fit, fits, chosen, ad)
    return _reported(run, res, selection, routing)


def _membrane_fit(run: RecordRun) -> tuple[RecordProblem, Fit, dict]:
    """The constant-load fit from the start-up (scan and short start), of the nonlinear membrane and,
    under ``membrane="auto"``, of the linear one when the nonlinear misfits; the smaller cost wins."""
    s = run.s
    candidates = {}
    for i, kind in enumerate(("nonlinear", "linear") if s.membrane == "auto" else (s.membrane,)):
        if i > 0 and s.membrane_model == "fvk" and _fits_data(run.meas.t, *candidates["nonlinear"], s):
            # FvK's small-deflection limit is the linear membrane: when FvK fits the record the
            # linear variant cannot fit it better; it is fitted only when FvK misfits.
            break
        if i > 0 and run.budget.exhausted:
            run.skipped.append("the linear membrane")
            break
        rp = run.problem(run.shapes, kind == "nonlinear")
        # the alternative is fitted with few iterations first: it is finished only if it wins
        cap = s if i == 0 else s.replace(max_iter=min(s.max_iter, 12))
        candidates[kind] = (rp, run.fit(rp, short_start(rp, scan(rp, np.sign(run.p0))), cap, (stalled,)))
    if len(candidates) == 2 and candidates["linear"][1].cost < candidates["nonlinear"][1].cost:
        rp, f = candidates["linear"]
        candidates["linear"] = (rp, run.fit(rp, f.theta, rules=(stalled,)))
    kind = min(candidates, key=lambda k: candidates[k][1].cost)
    rp, fit = candidates[kind]
    selection = {k: {"chi2": f.data_cost, "cost": f.cost} for k, (_, f) in candidates.items()}
    selection["chosen"] = kind
    if s.membrane == "auto" and "linear" not in candidates:
        selection["linear"] = "not fitted: the FvK fit is adequate"
    return rp, fit, selection


def _load_model_fit(run: RecordRun, rp: RecordProblem, fit: Fit):
    """The gust amplitude added (``load_model="gust"``, or ``"auto"`` when the constant load misfits)
    and kept when it lowers the chi-square by more than twice the unknowns it adds; the adequacy of
    the kept fit. Returns ``(rp, fit, fits, chosen, ad)``."""
    s, t = run.s, run.meas.t
    fits, chosen = {"constant": fit}, "constant"
    ad = assess(t, residual_matrix(rp, fit), fit.effective_parameters, s.segment_s)
    if s.load_model == "auto" and not ad.adequate and run.budget.exhausted:
        run.skipped.append("the gust load model")
    elif s.load_model == "gust" or (s.load_model == "auto" and not ad.adequate):
        rg = dataclasses.replace(rp, gust=s.gust)
        th = np.zeros(rg.dim)
        for name in ("x0", "c", "par"):
            th[rg.slices[name]] = fit.theta[rp.slices[name]]
        fit_g = run.fit(rg, th, rules=(stalled,))
        fits["gust"] = fit_g
        added = rg.dim - rp.dim
        if s.load_model == "gust" or fit.cost - fit_g.cost > 2 * added:
            rp, fit, chosen = rg, fit_g, "gust"
            ad = assess(t, residual_matrix(rp, fit), fit.effective_parameters, s.segment_s)
    return rp, fit, fits, chosen, ad


def _checked(run: RecordRun, rp: RecordProblem, fit: Fit, fits, chosen, ad) -> IdentificationResult:
    """The fit's result with its checks: the load prior's (:mod:`.prior_check`), the frame prior's
    (:mod:`.frame_check`, fitted first on a conflict), a stall's band, the tension profile's."""
    s = run.s
    stall = run.stopped(fit)
    frame_first, resolved = None, None
    if run.weigh_frame and s.stop_early and not run.budget.exhausted and conflict_test(rp, fit)["conflict"]:
        # An edge load: the frame prior (the interior shapes and free-edge ones) is its remedy as much
        # as the interior prior's wider scales; fitted first, a decisive answer spares the ladder.
        frame_first, resolved = _frame_first(run, rp, fit)
    res, fit, _ = _finish(run, rp, fit, fits, chosen, ad, resolved)
    if stall is not None:
        res = stalled_band(res, fit, stall)
    if run.weigh_frame and run.budget.exhausted and frame_first is None:
        run.skipped.append("the frame load prior")
    elif run.weigh_frame:
        res = _weigh_frame(run, rp, fit, res, chosen, frame_first)
    return res


def _weigh_frame(run: RecordRun, rp, fit, res, chosen, frame_first) -> IdentificationResult:
    """The frame prior's fit (unless fitted first) weighed against ``res`` by evidence; a fit the
    evidence decided against early is not finished, its lift extrapolated into the band."""
    z = log_evidence(fit)
    if frame_first is None:
        rf = dataclasses.replace(rp, shapes=frame_shapes(run.model, run.shapes, run.s, run.p0))
        fit_f = run.fit(rf, embed(rp, fit.theta, rf), rules=(stalled, behind(z)))
    else:
        rf, fit_f = frame_first
    stop_f = run.stopped(fit_f)
    if stop_f is not None and stop_f.reason.startswith("decided"):
        res.info["frame_check"] = decided(z, stop_f)
        lift_f, chi2_f = extrapolated(rf, stop_f.last)
        return span_other(res, lift_f, fit.data_cost, chi2_f, "frame")
    ad_f = assess(run.meas.t, residual_matrix(rf, fit_f), fit_f.effective_parameters, run.s.segment_s)
    res_f, fit_f, heading = _finish(run, rf, fit_f, {chosen: fit_f}, chosen, ad_f)
    if stop_f is not None:
        res_f = stalled_band(res_f, fit_f, stop_f)
    return weigh(res, res_f, z, log_evidence(fit_f), (fit.data_cost, fit_f.data_cost), heading)


def _reported(run: RecordRun, res: IdentificationResult, selection: dict, routing: str) -> IdentificationResult:
    """What the record's run adds to its result: the membrane selection, the work budget, the
    initial shape's check, the routing and the wiring checks."""
    s, budget, skipped = run.s, run.budget, run.skipped
    res.info["membrane_selection"] = selection
    res.info["budget"] = {
        "iterations": budget.used,
        "max_total_iter": s.max_total_iter,
        "cpu_s": budget.spent,
        "exhausted": budget.exhausted,
        "not_fitted": skipped,
    }
    if budget.exhausted:
        res.info["converged"] = False  # the work was not finished, whichever fit was kept
        res.info["warnings"].append(
            f"stopped at the record's work budget ({budget.used} Levenberg-Marquardt iterations over all fits, "
            f"max_total_iter {s.max_total_iter}; {budget.spent:.1f} s CPU): a record this model explains poorly"
            + (f"; not fitted: {', '.join(skipped)}" if skipped else "")
        )
    res.info["initial_shape"] = run.initial_shape
    if run.lead:
        res.info["quiet_lead"] = {"samples": run.lead, "until_s": float(run.meas.t[0])}
        res.info["warnings"].append(lead_note(run.lead, run.meas.t))
    if run.initial_shape["contradicted"]:
        res.info["warnings"].append(contradiction_note(run.initial_shape))
    res.info["routing"] = routing
    attach_wiring(res.info, run.model, run.meas.t, run.meas.values, s, run.p0, steady=False)  # gains, offsets, swaps
    res.wall_s = time.perf_counter() - run.t0
    return res


def _frame_first(run: RecordRun, rp: RecordProblem, fit: Fit) -> tuple[tuple[RecordProblem, Fit], str | None]:
    """The frame prior's fit of a record whose interior fit conflicts with its prior, and, when it
    explains the record without a conflict of its own and :data:`.stopping.DECIDED_NATS` better
    than the conflicting fit, the note that resolves the conflict (the interior prior's wider scales
    are then not fitted: measured on L3, FvK truth 49x25, 1 s, they reach 7 nats below the frame
    prior, which is 36 above the conflicting fit; 92 of the record's 128 iterations)."""
    rf = dataclasses.replace(rp, shapes=frame_shapes(run.model, run.shapes, run.s, run.p0))
    fit_f = run.fit(rf, short_start(rf, embed(rp, fit.theta, rf)), rules=(stalled,))
    gap = log_evidence(fit_f) - log_evidence(fit)
    if fit_f.out_of_budget or conflict_test(rf, fit_f)["conflict"] or gap <= DECIDED_NATS:
        return (rf, fit_f), None
    return (rf, fit_f), f"the frame load prior explains the record without one, {gap:.0f} nats better"


def _finish(run: RecordRun, rp, fit, fits, chosen, ad, resolved=None) -> tuple[IdentificationResult, Fit, Heading]:
    """The prior check, the sign and the result of a fit, with the tension profile's band check;
    and, for a fit that stopped short of its optimum, the lift one Gauss–Newton step on (:func:`.reach`)."""
    s = run.s
    rp, fit, spread, prior_info = load_prior_check(rp, fit, run.fit, resolved)
    if prior_info["conflict"]:
        ad = assess(rp.t, residual_matrix(rp, fit), fit.effective_parameters, s.segment_s)
    heading = None if fit.converged else reach(rp, fit.theta, fit.precision, half_gradient(rp, fit))
    c, _ = rp.load_history(fit.theta)
    if not run.bubble_known and rp.shapes.lift_row @ c * np.sign(run.p0) < 0:
        # Sign-blind sensors: state and load flip together; the prior load's sign decides.
        fit = dataclasses.replace(fit, theta=_flip(rp, fit.theta))
        heading = None if heading is None else -heading  # the mirrored fit's step: the lift is odd in the load
    wall = time.perf_counter() - run.t0
    res = fit_result(rp, fit, fits, chosen, ad, run.sigma, run.noise_source, wall, s, spread, prior_info)
    if fit.out_of_budget or (not fit.converged and fit.stopped is None):  # a stop's band is widened by its rule
        res = cut_short(res, rp, fit)
    return with_tension_profile(res, rp, fit, ad, run.fit), fit, heading


def _fits_data(t: np.ndarray, rp: RecordProblem, fit: Fit, s: RecordSettings) -> bool:
    return assess(t, residual_matrix(rp, fit), fit.effective_parameters, s.segment_s).adequate


def _flip(rp: RecordProblem, theta: np.ndarray) -> np.ndarray:
    """``theta`` with the load and the initial state mirrored (``x0 -> -x0``, ``c -> -c``).

    The unknowns hold the state modes' part of the initial state only, scaled about its prior
    (:meth:`RecordProblem.physical`): their entries are the state modes' displacements and velocities
    of the prior's full ``(2m,)`` mean.
    """
    th = theta.copy()
    for name in ("x0", "c"):
        th[rp.slices[name]] *= -1
    m, ms = rp.model.m, rp.state_modes
    held = np.r_[0:ms, m : m + ms]
    th[rp.slices["x0"]] -= 2 * rp.x0_mean[held] / rp.x0_std[held]
    return th
