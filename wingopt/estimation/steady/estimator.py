"""The whole-record estimator for steady records: a loaded wing in steady flow, no transient.

:func:`steady_identify` fits the sensors' mean with the static FvK membrane (:mod:`.steady`) under
the load prior of ``[identification] pressure_prior`` and from both lobe patterns (the sensors see
the slopes squared); when the flow's buffeting shows the loaded resonance it refits every answer
with the mean and the fluctuation's spectrum together (:mod:`.buffeting`), which identifies the
tension and tells the lobe patterns apart. The answers are weighed by their Laplace evidence and
the lift is their mixture. The lift history is the steady lift times the record's relative load
fluctuation, read off the sensors linearised about the static shape. What the record cannot tell
is said: an unidentified tension (no calibration, no resonance), unresolved lobes or edges, a load
prior that cannot make the mean (an aerodynamic prior then gives way to the frame prior).
"""

from __future__ import annotations

import logging
import time

import numpy as np
import scipy.sparse.linalg as spla

from wingopt.errors import InputError
from wingopt.estimation.core.load_prior import PriorScales, load_priors, prior_kinds
from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.steady.buffeting_fit import UNIDENTIFIED, mean_prestrain
from wingopt.estimation.steady.problem import SteadyProblem, steady_data
from wingopt.estimation.steady.solutions import (
    ADEQUATE,
    KEEP,
    Solution,
    corrected,
    misfit_scale,
    mixture,
    resonance,
    spectral_refits,
    static_solutions,
    weights,
)
from wingopt.estimation.steady.spectra import spectral_data
from wingopt.estimation.steady.wiring import attach as attach_wiring
from wingopt.measurements import Measurements
from wingopt.membrane.model import MembraneModel

__all__ = ["steady_identify", "UNIDENTIFIED", "is_steady", "mean_moves"]

log = logging.getLogger(__name__)

AUTO_PRIORS = ("frame", "aerodynamic")
"""The load priors of a steady record whose problem file declares ``pressure_prior = "auto"``.

A steady record's four means cannot tell a load that vanishes on the frame from one that acts up
to it (a pressure near the frame hardly deflects the membrane, yet carries lift), and evidence
then favours the narrower prior whatever the truth (measured: a uniform pressure read 42 % low at
15 bands under the interior prior); so the frame prior is always one of ``auto``'s. Under it
alone, though, the lift is set by the prior: the shapes the sensors do not resolve shrink to
zero, and the lobes' signs stay open (measured on FvK truth, 25 vs 49x25 mesh: a leading-edge
tunnel load 12 % low from its buffeting, 7 % low with a calibration). A tunnel record is an
aerodynamic load, the seed's own complaint is a load map unlike aerodynamic theory, and the
thin-airfoil shapes are three amplitudes that four sensors resolve: ``auto`` weighs both priors
by evidence (at either leading edge unless the problem file declares it). A load of another
shape (an off-centre bump, zero net lift) is not made by the aerodynamic shapes and the frame
prior takes it; where the record cannot tell, the band holds both. ``aerodynamic`` alone is
the user's assumption of a thin-airfoil load; ``interior`` (or the settings' ``frame = "off"``)
a load that vanishes on the frame.
"""


STEADY_WINDOWS = 10
"""Windows :func:`is_steady` and :func:`mean_moves` cut a record into (fewer on a short record: at
least ``MIN_WINDOW`` samples each)."""

MIN_WINDOW = 20


def _windows(n: int, head: float = 1.0 / STEADY_WINDOWS) -> list[np.ndarray]:
    count = int(min(max(round(1.0 / head), 2), max(n // MIN_WINDOW, 2)))
    return np.array_split(np.arange(n), count)


def is_steady(values: np.ndarray, head: float = 0.1, tolerance: float = 0.08, ringing: float = 3.0) -> bool:
    """A record without a transient, a gust or a drift: cut into windows of ``head`` of its length
    each, every window's mean is within ``tolerance`` (relative) of the windows' median mean, and its
    fluctuation at most ``ringing`` times the windows' median fluctuation, on every sensor.

    The whole record is compared, not its start against its second half: a gust after a release
    (L1 with +60 % at 0.5 s on FvK truth) put half its rise into the "late" half, whose fluctuation
    then hid the release's ringing, and the record went to the steady route (-75 %, 18 bands). The
    medians are what a steady record holds in most windows: a release rings 18x the median in its
    first tenth (its mean 6-9 % off), a +60 % gust moves two windows' means by 50 % (sensors about
    ``p^(2/3)``), a +30 % one by 25 %; a buffeted record's windows are within a few % and 1.2x.
    ``tolerance`` 0.08 on the sensors is about 12 % on the load (twice the largest window move of
    the buffeting records, 3.9 %); a smaller move is the steady route's own check's
    (:func:`mean_moves`, on the load). Fewer than 40 samples: not steady (the transient route takes
    them).
    """
    y = np.asarray(values, dtype=float)
    n = y.shape[0]
    if n < 40:
        return False
    win = _windows(n, head)
    means = np.array([np.nanmean(y[i], axis=0) for i in win])
    spread = np.array([np.nanstd(y[i], axis=0) for i in win])
    ref, typical = np.nanmedian(means, axis=0), np.nanmedian(spread, axis=0)
    scale = np.maximum(np.abs(ref), 1e-300)
    level = np.abs(means - ref) <= tolerance * scale[None, :]
    quiet = spread <= ringing * np.maximum(typical, 1e-12 * scale)[None, :]
    return bool(np.all(level | np.isnan(means)) and np.all(quiet | np.isnan(spread)))


MOVING_MEAN = 0.05
"""Relative load a window's mean may move from the record's median before the steady route refuses
the record (:func:`mean_moves`). Measured on the linearised fluctuation: the buffeting records'
windows move 1.4-1.9 %, L1 with a +60 % gust at 0.5 s 29 %, a +30 % one at 0.8 s 15 %."""


def mean_moves(eps: np.ndarray, threshold: float = MOVING_MEAN) -> tuple[bool, float]:
    """The steady route's own check on its answer: whether the relative load fluctuation ``eps(t)``
    (read off the sensors about the static state) has a window mean more than ``threshold`` from
    the windows' median, and the largest such move. A steady record's load is its mean; a moving
    one (a gust, a drift, a release) is not, and the transient route models it."""
    e = np.asarray(eps, dtype=float)
    if e.size < 2 * MIN_WINDOW or not np.any(np.isfinite(e)):
        return False, 0.0
    means = np.array([np.nanmean(e[i]) if np.any(np.isfinite(e[i])) else np.nan for i in _windows(e.size)])
    move = float(np.nanmax(np.abs(means - np.nanmedian(means))))
    return move > threshold, move


def _fluctuation(model: MembraneModel, sp_: SteadyProblem, theta, meas: Measurements, data):
    """The relative load fluctuation ``eps(t)`` read off the sensors linearised about the static state,
    and that state."""
    fvk, sol = sp_.equilibrium(theta)
    c, _ = sp_.physical(theta)
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
    return np.where(den > 0, num / np.maximum(den, 1e-300), np.nan), sol


def steady_identify(
    model: MembraneModel, measurements: Measurements, settings=None, initial_load: float | None = None
) -> IdentificationResult:
    """The load of a steady record (see the module docstring); settings as the transient fit's (their
    ``declaration`` filled from ``model.problem`` when not given)."""
    s = with_declaration(settings or RecordSettings(membrane_model="fvk"), model.problem)
    t0 = time.perf_counter()
    problem, meas, d = model.problem, measurements, s.declaration
    p0 = d.initial_load if initial_load is None else float(initial_load)
    prior = ParameterPrior.from_problem(problem, s.free, s.prestrain_rel, s.damping_rel, declaration=s.declaration)
    data = steady_data(meas.values)
    notes: list[str] = []
    try:
        spectra = spectral_data(meas.t, meas.values, s.spectrum_bin_hz, acquisition=problem.acquisition)
    except InputError as exc:  # uneven times, too many dropped frames: the mean still holds
        spectra = None
        notes.append(f"the record's spectrum is not used ({exc})")
    kinds = ("interior",) if s.frame == "off" else prior_kinds(d, AUTO_PRIORS)
    scales = PriorScales.of(s)
    priors = load_priors(model, kinds, p0, scales, d.leading_edge)
    sols, w, scr, f11 = _solve(model, priors, data, spectra, prior, p0, s, notes)
    if kinds == ("aerodynamic",) and not sols[int(np.argmax(w))].adequate:
        notes.append(
            "the aerodynamic load prior cannot make the sensors' mean: the answer is the frame prior's (a load "
            "that acts up to the frame)"
        )
        priors = load_priors(model, ("frame",), p0, scales)
        sols, w, scr, f11 = _solve(model, priors, data, spectra, prior, p0, s, notes)
    mean, std = mixture(w, sols)
    best = sols[int(np.argmax(w))]
    sp_, theta = best.problem, best.theta
    calibrated = d.prestrain_std is not None
    warnings = notes + _warnings(best, sols, w, scr, calibrated)
    eps, state = _fluctuation(model, sp_, theta, meas, data)
    c, _ = sp_.physical(theta)
    amp = 1.0 + np.nan_to_num(eps, nan=0.0)
    moved, move = mean_moves(eps)
    if moved:
        warnings.append(
            f"the load's mean moves over the record (a window's mean {move:.0%} off the record's median: a gust, a "
            "drift or a release): a steady record's answer is its mean load, not this record's"
        )
    info = _info(best, sols, w, data, scr, f11, warnings, calibrated)
    info["steady_lift_N"], info["steady_lift_std_N"] = mean, std
    info["mean_moves"] = {"moved": moved, "largest_window_move": move, "threshold": MOVING_MEAN}
    attach_wiring(info, model, meas.t, meas.values, s, p0)  # gains, offsets, swaps: warned, the answer kept
    return IdentificationResult(
        method="steady",
        t=meas.t,
        load=amp[:, None] * sp_.shapes.coefficients(c)[None],
        deflection=np.broadcast_to(state.z, (meas.count, state.z.size)),
        lift=mean * amp,
        lift_std=std * amp,
        regularization=float(s.kappa),
        wall_s=time.perf_counter() - t0,
        info=info,
        load_space=None if sp_.shapes.space is None else sp_.shapes.space.space,
    )


def _solve(model, priors, data, spectra, prior, p0, s, notes):
    """Static solutions under each prior, the resonance screen, the buffeting (or full-order) refits."""
    sign = float(np.sign(p0) or 1.0)
    sols = [
        x for label, shapes in priors for x in static_solutions(model, label, shapes, data, prior, sign, s.max_iter)
    ]
    w = weights(sols)
    kept = [x for x, wi in zip(sols, w) if wi >= KEEP]
    scr, f11 = resonance(sols[int(np.argmax(w))], spectra) if spectra is not None else (None, float("nan"))
    if scr is not None and scr.informative:
        refits = spectral_refits(kept, spectra, s.max_iter, notes)  # an undeclared anti-aliasing filter: said
        spectral = [x for x, why in refits if why is None]
        notes.extend(why for _, why in refits if why is not None)
        sols = spectral or [x for x, _ in refits]
    else:
        sols = [corrected(x, s.max_iter) for x in kept]
    return sols, weights(sols), scr, f11


def _warnings(best: Solution, sols: list[Solution], w: np.ndarray, scr, calibrated: bool) -> list[str]:
    out = []
    if best.buffeting is None and not calibrated and best.tension_ratio > UNIDENTIFIED:
        why = "no resonance above the noise floor near the first loaded mode" if scr is not None else "no spectrum"
        out.append(
            f"the record does not identify the tension ({why}; its prestrain posterior is {best.tension_ratio:.0%} "
            "of the problem file's prior): the lift scales with the tension, and its band is the prior's; a "
            "calibration record (wingopt calibrate) identifies it"
        )
    elif best.buffeting is not None and not calibrated and best.tension_ratio > UNIDENTIFIED:
        out.append(
            f"the buffeting does not identify the tension (its posterior is {best.tension_ratio:.0%} of the prior's): "
            "the lift band carries the prior's tension"
        )
    if best.static_chi2 > ADEQUATE[0]:
        out.append(
            f"the load prior cannot make the sensors' mean (chi-square {best.static_chi2:.1f} per sensor): the load is "
            "the nearest one it allows"
        )
    elif misfit_scale(best.static_chi2) > 1.05:  # a widened band is said, as every widening is (docs/dic.md)
        out.append(
            f"the sensors' mean misfits the load prior (chi-square {best.static_chi2:.2f} per sensor): the band is "
            f"widened x{misfit_scale(best.static_chi2):.2f} for it"
        )
    converged = best.buffeting.converged if best.buffeting is not None else best.fit.converged
    if not converged:  # the status says not_converged; a user reads why here (fuzz #64: it said nothing)
        what = "buffeting fit" if best.buffeting is not None else "static fit (or its full-order correction)"
        out.append(
            f"the {what} did not settle within its iterations: the lift is not the optimum's, and its band "
            "does not hold the distance to it"
        )
    if best.spectral_chi2 > ADEQUATE[1]:
        out.append(
            f"the model spectrum does not fit the record's (residual mean square {best.spectral_chi2:.2f}, expected 1)"
        )
    heavy = [x for x, wi in zip(sols, w) if wi > KEEP]
    priors = {x.prior for x in heavy}
    if {"aerodynamic x0", "aerodynamic x1"} <= priors:
        out.append(
            "the sensors do not tell which edge is the leading edge: the lift and its band mix both; declare it "
            "([identification] leading_edge = 'x0' or 'x1')"
        )
    if any({True, False} <= {x.other_lobes for x in heavy if x.prior == p} for p in priors):
        out.append(
            "the sensors do not tell the load's lobe signs apart (they see the slopes squared): the band spans "
            "both patterns"
        )
    if "frame" in priors and any(p.startswith("aerodynamic") for p in priors):
        out.append(
            "the sensors do not tell an aerodynamic (thin-airfoil) load from one of another shape: the lift and its "
            "band mix both; a calibration record or a DIC frame set narrows it"
        )
    return out


def _info(best: Solution, sols, w, data, scr, f11: float, warnings: list[str], calibrated: bool) -> dict:
    sp_ = best.problem
    _, par = sp_.physical(best.theta)
    k = sp_.shapes.count
    cov = best.covariance
    std = {n: float(sp_.prior.mean_std(n)[1] * np.sqrt(cov[k + i, k + i])) for i, n in enumerate(sp_.pars)}
    bf = best.buffeting
    em, em_std = mean_prestrain(sp_, best.theta, cov)
    damping = (bf.damping, bf.damping_std) if bf is not None else (float(sp_.prior.damping), 0.0)
    return {
        "backend": "steady record: static FvK fits of the mean"
        + (" and the buffeting's spectrum (Whittle)" if bf is not None else "")
        + ", weighed by evidence",
        "model": "nonlinear (FvK, static, full order)",
        "record": "steady",
        "solutions": [
            {
                "prior": x.label,
                "lift_N": x.lift,
                "lift_std_N": x.lift_std,
                "log_evidence": x.log_evidence,
                "weight": float(wi),
                "buffeting": x.buffeting is not None,
                "abandoned": x.buffeting is not None and x.buffeting.abandoned,
                "band_widening": misfit_scale(x.static_chi2),
            }
            for x, wi in zip(sols, w.tolist())
        ],
        "chosen": best.label,
        "tension": {
            "source": "buffeting" if bf is not None and bf.informative else ("calibration" if calibrated else "prior"),
            "posterior_over_prior": best.tension_ratio,
            "mean_prestrain": em,
            "mean_prestrain_std": em_std,
            "loaded_f11_hz": bf.f11_hz if bf is not None else f11,
            "screen": None if scr is None else {"ratio": scr.ratio, "threshold": scr.threshold, "peak_hz": scr.peak_hz},
        },
        "parameters": {"prestrain_x": par.eps0_x, "prestrain_y": par.eps0_y, "damping": damping[0]},
        "parameters_std": {**{"prestrain_x": 0.0, "prestrain_y": 0.0, "damping": damping[1]}, **std},
        "sensor_mean": data.mean.tolist(),
        "sensor_fit": sp_.outputs(best.theta).tolist(),
        "sensor_mean_std": data.std_error.tolist(),
        "fluctuation_rms": (data.fluctuation / np.abs(data.mean)).tolist(),
        "iterations": bf.iterations if bf is not None else best.fit.iterations,
        "converged": bf.converged if bf is not None else best.fit.converged,
        "adequacy": {
            "chi2_per_datum": best.static_chi2,
            "spectral_chi2": best.spectral_chi2,
            "data": data.mean.size,
            # the band's factor for a fit to the mean above chi-square 1 (adequate up to ADEQUATE[0])
            "band_widening": misfit_scale(best.static_chi2),
        },
        "model_adequate": best.adequate,
        "warnings": warnings,
        "dropped": [],
    }
