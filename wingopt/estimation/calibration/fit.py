"""Calibrate a membrane's tension and damping from a record without load (release, pluck or tap).

Before a wind-tunnel run the wing is plucked or released from a pushed shape with no flow: the
record's ringing holds the modal frequencies, hence the prestrains, and its decay the damping. The
same least-squares problem as the load estimator (:class:`.record_problem.RecordProblem`, exact
Jacobians, Levenberg–Marquardt) with no load unknowns: the initial modal state and the parameters
are identified, and the Gauss–Newton posterior of the parameters (chi-square cost, misfit-inflated,
the modal model's prestrain model-form term added) is what a later identification takes as its
prior (``[identification] prestrain, prestrain_std, damping, damping_std``).

The initial shape is the problem's bubble when it declares one (a release from a known push);
otherwise it is unknown: zero-mean with the data's scale, and the fit starts from the best of a
short scan of amplitudes along each of the lowest modes (the sensors are quadratic: at rest they
have no sensitivity to anything).

A record whose start the first fit does not follow (a tap's pulse, a localized pluck: the misfit is
the first segment's, or the fit does not converge) is refitted from later starts and with every
mode's initial motion unknown; the answer is the median of the fits that explain the record, its
band over all of them (:mod:`.refit`). A record the first fit explains keeps it unchanged.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.calibration.refit import Candidate, combine, later_starts, refit_warning
from wingopt.estimation.core.adequacy import assess
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.model_form import prestrain_std_with_model_form
from wingopt.estimation.core.noise import resolve_noise_std
from wingopt.estimation.core.onset import lead_note, quiet_lead
from wingopt.estimation.core.record_fit import levenberg_marquardt
from wingopt.estimation.core.record_problem import PARAMETERS, ParameterPrior, RecordProblem
from wingopt.estimation.core.start import initial_state_prior, modal_model, record_filter
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.transient.estimator import RecordSettings
from wingopt.measurements import Measurements
from wingopt.membrane import MembraneModel
from wingopt.status import RunStatus, from_info

__all__ = ["Calibration", "calibrate"]

log = logging.getLogger(__name__)

SCAN_MODES = 4
"""Modes the start-up scan tries the unknown initial shape along (one at a time)."""

SCAN_TENSION = (-1.5, 0.0, 1.5)
"""Prestrain starts, in prior stds from its mean: a ringing record sampled below its frequencies
(300 Hz) aliases, and the fit from one tension can end in another's local minimum."""

SHORTLIST = 3
"""Starts fitted briefly (``BRIEF`` iterations); the best is then fitted to convergence."""

BRIEF = 12

START_RATIO = 2.0
"""A misfit is the record's start's when its first segment misfits this many times the later ones
(a tap or a localized pluck at 300 Hz: 7-24 against 1.0-1.5)."""

WIDENING_AGREE = 1.1
"""A refitted calibration counts as adequate when its fits' spread widens no band beyond this."""


@dataclass(frozen=True)
class Calibration:
    """The identified parameters and their posterior.

    Attributes
    ----------
    parameters, parameters_std : dict
        ``prestrain_x``, ``prestrain_y`` (strain) and ``damping`` (factor on the problem's damping),
        and their 1-sigma (the damping's from its log-normal posterior).
    correlation : ndarray (3, 3)
        Posterior correlation of the three, in :data:`PARAMETERS` order.
    chi2_per_datum : float
    adequate : bool
        The model explains the record to its noise level (:mod:`.adequacy`).
    warnings : list of str
    info : dict
        Iterations, convergence, noise level and its source, the initial shape, wall time.
    """

    parameters: dict
    parameters_std: dict
    correlation: np.ndarray
    chi2_per_datum: float
    adequate: bool
    warnings: list[str] = field(default_factory=list)
    info: dict = field(default_factory=dict)

    @property
    def status(self) -> RunStatus:
        """One word (:class:`~wingopt.status.RunStatus`): ``failed`` (a non-finite parameter),
        ``not_converged`` (the fit stopped at its iteration cap), ``misfit`` (the model does not
        explain the record) or ``converged``."""
        return from_info({**self.info, "model_adequate": self.adequate}, *self.parameters.values())


def _starts(rp: RecordProblem, known: bool) -> list[np.ndarray]:
    """Starting points: the prior mean with a known shape, else amplitudes along the lowest modes;
    each at a few prestrain levels."""
    shapes = [np.zeros(rp.dim)]
    if not known:
        shapes = []
        for j in range(min(SCAN_MODES, rp.state_modes)):
            for a in (0.5, 1.0, 2.0):
                th = np.zeros(rp.dim)
                th[rp.slices["x0"].start + j] = a
                shapes.append(th)
    pars = [i for i, n in enumerate(rp.prior.free) if n.startswith("prestrain")]
    out = []
    for level in SCAN_TENSION:
        for th in shapes:
            th = th.copy()
            th[[rp.slices["par"].start + i for i in pars]] = level
            out.append(th)
    return out


def calibrate(
    model: MembraneModel,
    measurements: Measurements,
    settings: RecordSettings | None = None,
    noise_std: float | None = None,
) -> Calibration:
    """Identify the prestrains and the damping factor of ``model``'s membrane from an unloaded record.

    Parameters
    ----------
    model : MembraneModel
        The estimator's model (its problem's prior on the parameters is the starting prior).
    measurements : Measurements
        The calibration record: free vibration after a release, a pluck or a tap, no load.
    settings : RecordSettings, optional
        Modal model and fit settings (default: the FvK membrane of the load estimator); its
        ``declaration`` (the priors, the noise, the initial shape) is filled from the model's
        problem when ``None``.
    noise_std : float, optional
        Sensor noise std; default: the measurements', the declared one, else estimated from the data.

    Returns
    -------
    Calibration
        The parameters, their posterior std and correlation, the fit's adequacy.
    """
    s = with_declaration(settings or RecordSettings(membrane_model="fvk"), model.problem)
    t0 = time.perf_counter()
    meas = measurements
    if meas.count < 20:
        raise InputError(f"calibration record: {meas.count} samples, need at least 20 (a ringing of ~0.1 s)")
    acquisition, fs = model.problem.acquisition, 1.0 / float(np.median(np.diff(meas.t)))
    declared = s.declaration.noise_std
    sigma, noise_source = resolve_noise_std(
        meas.values, meas.sensor_names, noise_std, meas.noise_std, declared, acquisition=acquisition, fs=fs
    )
    lead = quiet_lead(meas.values, sigma, 1.0 / fs, acquisition)  # a pre-trigger: the fit starts where the pluck does
    if lead:
        meas = meas.since(lead)
    first = _candidate(model, meas, s, sigma, 0, None, "first")
    fits, chosen = [first], first
    est, std, corr = first.parameters, first.parameters_std, first.correlation
    adequate, warnings = first.adequate, []
    if _start_not_followed(first):
        fits = fits + _refits(model, meas, s, sigma)
        combined = combine(fits)
        chosen, est, std, corr = combined.closest, combined.parameters, combined.parameters_std, combined.correlation
        adequate = first.adequate and combined.widening <= WIDENING_AGREE
        warnings.append(refit_warning(first, combined, fits))
    rp, known, fit, ad = chosen.payload
    info = {
        "iterations": fit.iterations,
        "converged": fit.converged,
        "noise_std": [float(x) for x in sigma],
        "noise_source": noise_source,
        "initial_shape": "the problem's bubble" if known else "unknown (identified)",
        "model": f"FvK cubic, {getattr(rp.model, 'cubic_modes', 0)} modes" if s.membrane_model == "fvk" else "Berger",
        "adequacy": ad.as_dict(),
        "prior": {n: rp.prior.mean_std(n) for n in PARAMETERS},
        "wall_s": time.perf_counter() - t0,
    }
    if len(fits) > 1:
        info["fit"] = chosen.label
        info["fits"] = [f.as_dict() for f in fits]
        info["iterations_total"] = sum(f.payload[2].iterations for f in fits)
    warnings = _warnings(rp, fit, ad, std) + warnings
    if lead:
        info["quiet_lead"] = {"samples": lead, "until_s": float(meas.t[0])}
        warnings.append(lead_note(lead, meas.t))
    return Calibration(est, std, corr, float(first.chi2_per_datum), bool(adequate), warnings, info)


def _start_not_followed(first: Candidate) -> bool:
    """Whether the first fit says the model does not follow the record's start: a misfit that is the
    start's (its first segment's chi-square per datum over ``START_RATIO`` times the later segments'
    median; a misfit all along, a load on the wing, is no start's and a refit would not mend it), or
    an adequate fit that did not converge (a cost with several minima, a localized pluck's)."""
    if first.adequate:
        return not first.converged
    seg = first.payload[3].segment_chi2_per_datum
    return len(seg) > 2 and seg[0] > START_RATIO * float(np.median(seg[1:]))


def _candidate(
    model: MembraneModel,
    meas: Measurements,
    s: RecordSettings,
    sigma: np.ndarray,
    k: int,
    modes: int | None,
    label: str,
) -> Candidate:
    """The calibration fit of the record from its sample ``k`` on (the initial state there unknown in
    its ``modes`` lowest modes; ``None``: the settings' ``state_modes``)."""
    part = meas if k == 0 else Measurements(meas.t[k:], meas.values[k:], meas.sensor_names, None, meas.source)
    rp, known = _calibration_problem(model, part, s, sigma, modes)
    fit = _best_fit(rp, known, 2 * s.max_iter)
    resid = np.full(rp.y.shape, np.nan)
    resid[rp.valid] = fit.residuals
    ad = assess(part.t, resid, fit.effective_parameters, s.segment_s)
    est, std, corr = _posterior(rp, fit, ad.inflation)
    log.debug("calibration fit %s: %s ± %s, chi2 %.3f", label, est, std, ad.chi2_per_datum)
    start_s = float(part.t[0] - meas.t[0])
    return Candidate(
        label, start_s, est, std, corr, float(ad.chi2_per_datum), bool(ad.adequate), fit.converged, (rp, known, fit, ad)
    )


def _refits(model: MembraneModel, meas: Measurements, s: RecordSettings, sigma: np.ndarray) -> list[Candidate]:
    """The record fitted from its later starts, and from its first sample with every mode's initial
    motion unknown (a localized shape rings in all of them)."""
    fits = [
        _candidate(model, meas, s, sigma, k, None, f"from {1e3 * (meas.t[k] - meas.t[0]):.0f} ms")
        for k in later_starts(meas.t)
    ]
    return fits + [_candidate(model, meas, s, sigma, 0, s.modes, "every mode's initial motion")]


def _calibration_problem(
    model: MembraneModel, meas: Measurements, s: RecordSettings, sigma: np.ndarray, modes: int | None = None
) -> tuple[RecordProblem, bool]:
    """The record's least-squares problem without load unknowns (the modal model at the record's
    sample period, the declared priors, the initial state unknown in its ``modes`` lowest modes,
    default the settings' ``state_modes``); and whether the initial shape is known."""
    dt = float(np.median(np.diff(meas.t)))
    substeps = max(s.substeps, int(np.ceil(dt / s.substep_s - 1e-9)))
    bm = modal_model(model, s.membrane_model, min(s.modes, model.n), dt, substeps, s.stretch_gain, s.cubic_modes)
    problem, declared = model.problem, s.declaration
    prior = ParameterPrior.from_problem(problem, PARAMETERS, s.prestrain_rel, s.damping_rel, declaration=declared)
    x_mean, x_std, known = initial_state_prior(bm, problem, meas.values, declared.initial_deflection)
    shapes, ms = LoadShapes.none(model), min(s.state_modes if modes is None else modes, bm.m)
    daq = record_filter(problem)
    rp = RecordProblem(bm, shapes, meas.t, meas.values, sigma, prior, x_mean, x_std, state_modes=ms, daq=daq)
    return rp, known


def _best_fit(rp: RecordProblem, known: bool, max_iter: int):
    """The fit from the best of the starts: each start scored by its cost, the cheapest few fitted
    briefly, the best of those to convergence (``max_iter``)."""
    scored = []
    for th in _starts(rp, known):
        with np.errstate(over="ignore", invalid="ignore"):
            rd, rprior = rp.residuals(th)
        cost = float(rd @ rd + rprior @ rprior)
        scored.append((cost if np.isfinite(cost) else np.inf, th))
    scored.sort(key=lambda f: f[0])
    brief = [levenberg_marquardt(rp, th, BRIEF) for _, th in scored[:SHORTLIST]]
    best = min(brief, key=lambda f: f.cost)
    return levenberg_marquardt(rp, best.theta, max_iter)


def _posterior(rp: RecordProblem, fit, inflation: float) -> tuple[dict, dict, np.ndarray]:
    """The parameters, their 1-sigma (misfit-inflated, the prestrains' model-form floor added) and
    their correlation."""
    cov = fit.covariance * inflation**2
    par = rp.physical(fit.theta)
    sl = rp.slices["par"]
    idx = [sl.start + rp.prior.free.index(n) for n in PARAMETERS]
    block = cov[np.ix_(idx, idx)]
    d = np.sqrt(np.diag(block))
    corr = block / np.outer(d, d)
    est, std, share = {}, {}, np.ones(len(PARAMETERS))
    for i, name in enumerate(PARAMETERS):
        value = float(np.real(par[name][0]))
        sd = rp.prior.mean_std(name)[1] * d[i]
        sd = sd * value if name == "damping" else prestrain_std_with_model_form(name, value, sd)
        est[name], std[name] = value, float(sd)
        share[i] = rp.prior.mean_std(name)[1] * d[i] * (value if name == "damping" else 1.0) / max(sd, 1e-300)
    # The model-form floor is each prestrain's own (a different mesh, a different membrane): it does
    # not share the fit's correlation. Without it, the -0.95 of a ringing record made the prestrains'
    # common scale, which sets the lift, 4x tighter than the floor on either (on the stand-in: a DIC
    # lift 3.2 % off at 5.8 bands).
    corr = corr * np.outer(share, share)
    np.fill_diagonal(corr, 1.0)
    return est, std, corr


def _warnings(rp: RecordProblem, fit, ad, std: dict) -> list[str]:
    """What the calibration says about itself: a misfit record, a fit that did not converge, a
    prestrain the record holds little on."""
    warnings = []
    if not ad.adequate:
        warnings.append(
            f"the membrane model does not explain the calibration record (chi-square per datum "
            f"{ad.chi2_per_datum:.2f}): the posterior is widened x{ad.inflation:.2f}; check that the record has no load"
        )
    if not fit.converged:
        warnings.append(f"the calibration fit did not converge in {fit.iterations} iterations")
    for name in ("prestrain_x", "prestrain_y"):
        prior_sd = rp.prior.mean_std(name)[1]
        if std[name] > 0.5 * prior_sd:
            warnings.append(
                f"{name}: the record holds little on it (posterior std {std[name]:.2g}, prior {prior_sd:.2g}): "
                "a longer or stronger ringing (a harder pluck, a higher sample rate) would identify it"
            )
    return warnings
