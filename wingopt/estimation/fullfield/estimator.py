"""The full-field estimator: the pressure on the membrane from DIC frames of its shape.

1. every frame is fitted in the estimator's deflection space; the mean field and the noise of a
   point come from the fits (:mod:`.data`);
2. steady fit: the mean field's implied load under each load prior (zero on the frame; acting up
   to it; optionally thin-airfoil shapes), the priors weighed by their evidence (:mod:`.steady`,
   :mod:`.system`); the prestrains from their prior (the problem file's ±20 %, or a calibration's),
   whose uncertainty is part of the band: a steady field does not identify them;
3. a buffeting record's frames do: the load keeps its shape while the membrane's stiffness and
   inertia shape its response (:mod:`.tension`): their lift combination is fitted when the record
   fluctuates enough and no calibration is given (``prestrain="auto"``, time-resolved mode);
4. time-resolved (``mode="frames"``, the default with several frames): every frame's own load
   with the inertia and damping forces in the balance (:mod:`.frames`);
5. a mean field that misfits the load space systematically (chi-square per datum above
   :data:`ADEQUATE_CHI2`: a load outside the priors' families): the lifts of richer spaces, the
   other priors and held-out fits are added to the band, the lift unmoved (:mod:`.model_form`);
6. a load that moves over the frames (a gust, a drift: the frames' loads' windows against their
   scatter): the steady fit of the mean field is not the record's load; the band takes in the
   windows' lifts, the status is ``misfit`` and a warning says what moved (:mod:`.motion`).

The result is the package's one :class:`~wingopt.estimation.core.result.IdentificationResult`; ``info``
says where the tension came from, what the field itself says about it, how well the model fits
(chi-square per datum), the in-plane check and the frames used.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.load_prior import load_priors, prior_kinds
from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.fullfield.data import FieldData, field_data, inplane_check
from wingopt.estimation.fullfield.frames import FrameLoads, frame_loads
from wingopt.estimation.fullfield.model_form import model_form
from wingopt.estimation.fullfield.modes import ModalCheck, modal_check
from wingopt.estimation.fullfield.motion import MIN_WINDOW, LoadMotion, load_motion
from wingopt.estimation.fullfield.settings import AUTO_PRIORS, FullFieldSettings
from wingopt.estimation.fullfield.steady import PrestrainPrior, SteadyFit, fit_prior
from wingopt.estimation.fullfield.system import PressureFromShape
from wingopt.estimation.fullfield.tension import MIN_FLUCTUATION, DynamicTension, dynamic_tension, fluctuation
from wingopt.measurements.dic import DICFrames
from wingopt.membrane.forward import FullStructure, full_model
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters

__all__ = ["fullfield_identify", "ADEQUATE_CHI2"]

log = logging.getLogger(__name__)

ADEQUATE_CHI2 = 4.0
"""The model is called adequate while the steady fit's chi-square per datum is below this."""


def _priors(model: MembraneModel, s: FullFieldSettings, p0: float) -> list[tuple[str, LoadShapes]]:
    """The settings' load priors, else the declared ``pressure_prior`` (under ``auto``:
    :data:`.settings.AUTO_PRIORS`)."""
    d = s.declaration
    kinds = s.priors or prior_kinds(d, AUTO_PRIORS)
    return load_priors(model, kinds, p0, s.prior_scales, s.leading_edge or d.leading_edge)


@dataclass(frozen=True, eq=False)
class _MeanField:
    """The steady fit's data: the frames' fits, the data ``y0`` and weights of the mean field, and
    the FvK membrane at the prestrain prior's mean."""

    data: FieldData
    y0: np.ndarray
    weight: np.ndarray
    prestrain: PrestrainPrior
    fvk: FullStructure

    @classmethod
    def of(cls, model: MembraneModel, frames: DICFrames, s: FullFieldSettings) -> _MeanField:
        data = field_data(frames, model, s.smoothing, s.min_valid)
        prior = ParameterPrior.from_problem(model.problem)
        pp = PrestrainPrior.of(prior, s.declaration.prestrain_std is not None)
        fvk = full_model(model, "fvk", MembraneParameters(*pp.mean, prior.damping, prior.damping))
        y0 = data.mean_w - data.basis @ data.mean_z
        return cls(data, y0, np.full(y0.size, 1.0 / data.tau**2), pp, fvk)


def fullfield_identify(
    model: MembraneModel,
    frames: DICFrames,
    settings: FullFieldSettings | None = None,
    initial_load: float | None = None,
) -> IdentificationResult:
    """Estimate the pressure field and its lift from DIC frames (module docstring).

    Parameters
    ----------
    model : MembraneModel
        The estimator's mesh (its problem gives the material, the prestrain prior and ``[identification]``).
    frames : DICFrames
        In the wing's frame (a reader has mapped them).
    settings : FullFieldSettings, optional
        Its ``declaration`` is filled from ``model.problem`` when not given.
    initial_load : float, optional
        The load prior's pressure scale (Pa; its magnitude: DIC sees the sign); default the problem's.

    Returns
    -------
    IdentificationResult
        ``method="fullfield"``: per used frame (time-resolved) or the steady estimate repeated, the
        load coefficients in the chosen prior's basis (``load_space``), the deflections, the lift and
        its band; ``info`` holds the steady fit per prior, the prestrains and their source, the
        tension from the dynamics when fitted, the misfit and the in-plane check.
    """
    s = with_declaration(settings or FullFieldSettings(), model.problem)
    t0 = time.perf_counter()
    p0 = abs(s.pressure or (initial_load if initial_load is not None else s.declaration.initial_load))
    mf = _MeanField.of(model, frames, s)
    mode = s.mode if s.mode != "auto" else ("frames" if mf.data.count > 1 else "steady")
    fits, dyn = _steady_fits(_priors(model, s, p0), mf, s, mode)
    w, mean, std = _mixture(fits)
    best = fits[int(np.argmax(w))]
    form, std_before = None, std
    if best.post.chi2_per_datum > ADEQUATE_CHI2:
        # a systematic misfit: the band takes in the lifts of the spaces the evidence does not exclude
        # (:mod:`.model_form`); the lift does not move
        form = model_form(model, s, p0, mf.fvk, mf.data, mf.y0, mf.weight, best, mean)
        std = float(np.hypot(std, form.spread))
    fl = frame_loads(mf.data, best, s.inertia) if mode == "frames" or mf.data.count >= 2 * MIN_WINDOW else None
    motion = None if fl is None else load_motion(fl, best.shapes.forces, best.post.c, mean)
    steady_std = std if motion is None else float(np.hypot(std, motion.spread))
    h = _frames(fl, best, std) if mode == "frames" else _repeated(mf.data, best, mean, steady_std)
    modal = None
    if mode == "frames" and s.modes and fluctuation(mf.data) >= MIN_FLUCTUATION:
        modal = modal_check(mf.data, best.system, best.prestrain)
    info = _info(s, mode, mf.data, fits, w, best, mean, steady_std, mf.prestrain, mf.fvk, dyn, modal)
    info["model_form"] = None if form is None else form.as_dict(mean, std_before)
    if form is not None:
        info["warnings"].append(form.warning(mean, std_before))
    _motion_info(info, motion, mean, std)
    if h.chi2_median is not None:
        info["frames_chi2_per_datum_median"] = h.chi2_median
    return IdentificationResult(
        method="fullfield",
        t=h.t,
        load=np.asarray(h.load),
        deflection=np.asarray(h.deflection),
        lift=h.lift,
        lift_std=h.lift_std,
        regularization=float(s.kappa),
        wall_s=time.perf_counter() - t0,
        info=info,
        load_space=None if best.shapes.space is None else best.shapes.space.space,
    )


def _steady_fits(priors, mf: _MeanField, s: FullFieldSettings, mode: str):
    """Each prior's steady fit of the mean field, on the frames' dynamic tension where it is fitted
    (``prestrain="dynamics"``, or ``"auto"`` in the time-resolved mode without a calibration)."""
    systems = [(lb, sh, PressureFromShape(mf.fvk, mf.data.mean_z, mf.data.basis, sh.forces)) for lb, sh in priors]
    steady_mode = "fit" if s.prestrain == "fit" else "prior"
    pp, y0, weight = mf.prestrain, mf.y0, mf.weight
    fits = [fit_prior(lb, sh, sy, y0, weight, pp, steady_mode) for lb, sh, sy in systems]
    dyn = None
    if s.prestrain == "dynamics" or (s.prestrain == "auto" and mode == "frames" and not pp.calibrated):
        best = max(fits, key=lambda f: f.log_evidence)
        dyn = dynamic_tension(mf.data, best.shapes, best.system, y0, weight, pp)
        if dyn.used:
            fits = [fit_prior(lb, sh, sy, y0, weight, pp, "prior", (dyn.theta, dyn.cov)) for lb, sh, sy in systems]
        # (asked for the dynamics and not given them: _info's warnings say so, once, in the result)
    return fits, dyn


def _mixture(fits: list[SteadyFit]) -> tuple[np.ndarray, float, float]:
    """The priors' evidence weights, and the lift's mixture mean and std."""
    z = np.array([f.log_evidence for f in fits])
    w = np.exp(z - z.max())
    w /= w.sum()
    lifts = np.array([f.lift for f in fits])
    stds = np.array([f.lift_std for f in fits])
    mean = float(w @ lifts)
    return w, mean, float(np.sqrt(max(w @ (stds**2 + lifts**2) - mean**2, 0.0)))


class _History(NamedTuple):
    """The result's per-frame answer (``chi2_median``: the time-resolved frames' median misfit)."""

    t: np.ndarray
    load: np.ndarray
    deflection: np.ndarray
    lift: np.ndarray
    lift_std: np.ndarray
    chi2_median: float | None = None


def _frames(fl: FrameLoads, best: SteadyFit, std: float) -> _History:
    """Time-resolved: every used frame's own load about the steady fit (:func:`.frames.frame_loads`), the
    other priors' spread (the steady band beyond the chosen prior's) scaled with the load."""
    extra = max(std**2 - best.lift_std**2, 0.0)
    lift_std = np.sqrt(fl.lift_std**2 + extra * (fl.lift / best.lift) ** 2)
    chi2 = float(np.median(fl.chi2_per_datum))
    return _History(fl.t, best.shapes.coefficients(fl.c), fl.z, fl.lift, lift_std, chi2)


def _repeated(data: FieldData, best: SteadyFit, mean: float, std: float) -> _History:
    """Steady: the steady estimate at every used frame's time."""
    idx = np.flatnonzero(data.used)
    load, z = best.load(), best.deflection()
    return _History(
        data.frames.t[idx],
        np.broadcast_to(load, (idx.size, load.size)),
        np.broadcast_to(z, (idx.size, z.size)),
        np.full(idx.size, mean),
        np.full(idx.size, std),
    )


def _motion_info(info: dict, motion: LoadMotion | None, lift: float, band_before: float) -> None:
    """The load-motion check in ``info`` (:mod:`.motion`): a load that moves flags the answer (``misfit``:
    the steady fit of the mean field is not the record's load) with a warning; the band is widened."""
    info["load_motion"] = None if motion is None else motion.as_dict(band_before)
    if motion is not None and motion.moves:
        info["warnings"].append(motion.warning(lift, band_before))
        info["model_adequate"] = False


def _warnings(best: SteadyFit, pp: PrestrainPrior, data, dynamic: bool) -> list[str]:
    out = []
    if not pp.calibrated and not dynamic:
        rel = pp.std / pp.mean
        out.append(
            f"the DIC field does not identify the tension (a steady shape implies a pressure for any prestrain): "
            f"the prestrains are the problem file's prior (±{100 * rel[0]:.0f} %, ±{100 * rel[1]:.0f} %) and the "
            f"lift's band carries it (±{best.lift_std / abs(best.lift):.1%}); a calibration record "
            "(wingopt calibrate) narrows it"
        )
    if best.post.chi2_per_datum > ADEQUATE_CHI2:
        out.append(
            f"the steady field is not fitted to its noise (chi-square per datum {best.post.chi2_per_datum:.3g}, "
            f"noise {1e6 * data.tau:.3g} µm per point): the band is widened by the misfit"
        )
    skipped = int(data.frames.n_frames - data.count)
    if skipped:
        out.append(f"{skipped} frame(s) with too few valid points left out")
    return out


def _source(pp: PrestrainPrior, dyn: DynamicTension | None) -> str:
    prior = "calibration prior" if pp.calibrated else "problem file prior"
    return f"the frames' dynamics (buffeting) on the {prior}" if dyn is not None and dyn.used else prior


def _modal_warnings(modal: ModalCheck | None, pp: PrestrainPrior) -> list[str]:
    if modal is None:
        return []
    out = []
    f, sf = modal.measured, modal.measured_std
    if not pp.calibrated and not modal.identifies:
        rel = 100 * modal.prestrain_std_rel
        out.append(
            f"the frames do not identify the prestrains' ratio (it is the prior's): the loaded f11 = {f[0]:.1f} "
            f"± {sf[0]:.2f} Hz and f21 = {f[1]:.1f} ± {sf[1]:.2f} Hz constrain each prestrain to ±{rel[0]:.3g} %, "
            f"±{rel[1]:.3g} % (within 3 % needs each frequency to ±{100 * modal.needed_rel:.2g} %); a calibration "
            "record (wingopt calibrate) fixes it"
        )
    if _frequencies_off(modal):
        p = modal.predicted
        out.append(
            f"the loaded frequencies measured ({f[0]:.1f}, {f[1]:.1f} Hz) are {np.max(np.abs(modal.misfit)):.2g} sd "
            f"off the model's ({p[0]:.1f}, {p[1]:.1f} Hz): its stiffness or mass is off (an air's added mass, a "
            "wrong density or thickness)"
        )
    return out


def _frequencies_off(modal: ModalCheck | None) -> bool:
    """Whether the frames' loaded frequencies lie beyond 3 sd of the model's: its stiffness or mass
    is not the wing's, and neither is the pressure its static balance reads off the shape."""
    return modal is not None and bool(np.any(np.abs(modal.misfit) > 3.0))


def _info(s, mode, data, fits, w, best: SteadyFit, mean, std, pp: PrestrainPrior, fvk, dyn, modal=None) -> dict:
    ex, ey = best.prestrain
    sx, sy = best.prestrain_std
    fr = data.frames
    warnings = _warnings(best, pp, data, dyn is not None and dyn.used) + _modal_warnings(modal, pp)
    if s.prestrain == "dynamics" and dyn is not None and not dyn.used:
        warnings.append(f"the frames' dynamics do not give the tension ({dyn.reason}): the prior's is used")
    return {
        "backend": "full field (DIC): pressure from shape, static FvK balance (full order), priors weighed by evidence",
        "model": "nonlinear (FvK, full order)",
        "record": "DIC frames",
        "mode": mode,
        "frames": {
            "total": fr.n_frames,
            "used": data.count,
            "points": fr.n_points,
            "valid_fraction": fr.valid_fraction,
            "source": fr.source,
        },
        "noise_w_m": data.sigma,
        "mean_field_noise_m": data.tau,
        "solutions": [
            {
                "prior": f.label,
                "lift_N": f.lift,
                "lift_std_N": f.lift_std,
                "log_evidence": f.log_evidence,
                "weight": float(wi),
                "chi2_per_datum": f.post.chi2_per_datum,
            }
            for f, wi in zip(fits, w)
        ],
        "chosen": best.label,
        "steady_lift_N": mean,  # the reported lift (IdentificationResult.reported_lift): the frames' steady part
        "steady_lift_std_N": std,
        "steady": {
            "lift_N": mean,
            "lift_std_N": std,
            "lift_std_load_N": best.lift_std_load,
            "lift_per_prior_std": best.lift_grad.tolist(),
        },
        "parameters": {"prestrain_x": ex, "prestrain_y": ey, "damping": float(fvk.params.viscous_scale)},
        "parameters_std": {"prestrain_x": float(sx), "prestrain_y": float(sy), "damping": 0.0},
        "prestrain_source": _source(pp, dyn),
        "prestrain_mode": s.prestrain,
        "tension_from_dynamics": None if dyn is None else dyn.as_dict(pp),
        "loaded_modes": None if modal is None else modal.as_dict(),
        "prestrain_field_pull": best.pull,
        "adequacy": {"chi2_per_datum": best.post.chi2_per_datum, "data": best.post.data},
        # a model whose loaded frequencies are not the frames' misfits them, whatever the mean field's fit
        # (fuzz #363: 33 sd off, "converged" at 7 bands)
        "model_adequate": bool(best.post.chi2_per_datum < ADEQUATE_CHI2) and not _frequencies_off(modal),
        "inplane": inplane_check(data, fvk),
        "warnings": warnings,
        "dropped": [],
    }
