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
   other priors and held-out fits are added to the band, the lift unmoved (:mod:`.model_form`).

The result is the package's one :class:`~wingopt.estimation.result.IdentificationResult`; ``info``
says where the tension came from, what the field itself says about it, how well the model fits
(chi-square per datum), the in-plane check and the frames used.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.fullfield.data import field_data, inplane_check
from wingopt.estimation.fullfield.frames import frame_loads
from wingopt.estimation.fullfield.model_form import model_form
from wingopt.estimation.fullfield.modes import ModalCheck, modal_check
from wingopt.estimation.fullfield.settings import FullFieldSettings
from wingopt.estimation.fullfield.steady import PrestrainPrior, SteadyFit, fit_prior
from wingopt.estimation.fullfield.system import PressureFromShape
from wingopt.estimation.fullfield.tension import MIN_FLUCTUATION, DynamicTension, dynamic_tension, fluctuation
from wingopt.estimation.result import IdentificationResult
from wingopt.measurements.dic import DICFrames
from wingopt.membrane.forward import full_model
from wingopt.membrane.model import MembraneModel
from wingopt.membrane.parameters import MembraneParameters

__all__ = ["fullfield_identify", "ADEQUATE_CHI2"]

log = logging.getLogger(__name__)

ADEQUATE_CHI2 = 4.0
"""The model is called adequate while the steady fit's chi-square per datum is below this."""


def _priors(model: MembraneModel, s: FullFieldSettings, p0: float) -> list[tuple[str, LoadShapes]]:
    out = []
    for name in s.priors:
        if name == "interior":
            out.append(("interior", LoadShapes.build(model, s.shapes, p0, s.kappa)))
        elif name == "frame":
            out.append(("frame", LoadShapes.build(model, s.shapes, p0, s.kappa, 1.0, s.edge_shapes)))
        else:
            le = s.leading_edge or model.problem.identification.leading_edge
            for edge in (le,) if le else ("x0", "x1"):
                out.append((f"aerodynamic {edge}", LoadShapes.aerodynamic(model, p0, edge, s.kappa)))
    return out


def fullfield_identify(
    model: MembraneModel, frames: DICFrames, settings: FullFieldSettings | None = None,
    initial_load: float | None = None,
) -> IdentificationResult:  # fmt: skip
    """Estimate the pressure field and its lift from DIC frames (module docstring).

    Parameters
    ----------
    model : MembraneModel
        The estimator's mesh (its problem gives the material, the prestrain prior and ``[identification]``).
    frames : DICFrames
        In the wing's frame (a reader has mapped them).
    settings : FullFieldSettings, optional
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
    s = settings or FullFieldSettings()
    t0 = time.perf_counter()
    problem = model.problem
    p0 = abs(s.pressure or (initial_load if initial_load is not None else problem.identification.initial_load))
    data = field_data(frames, model, s.smoothing, s.min_valid)
    prior = ParameterPrior.from_problem(problem)
    pp = PrestrainPrior.of(prior, problem.identification.prestrain_std is not None)
    damping = prior.damping
    fvk = full_model(model, "fvk", MembraneParameters(*pp.mean, damping, damping))
    B = data.basis
    y0 = data.mean_w - B @ data.mean_z
    weight = np.full(y0.size, 1.0 / data.tau**2)
    mode = s.mode if s.mode != "auto" else ("frames" if data.count > 1 else "steady")
    systems = [(lb, sh, PressureFromShape(fvk, data.mean_z, B, sh.forces)) for lb, sh in _priors(model, s, p0)]
    steady_mode = "fit" if s.prestrain == "fit" else "prior"
    fits = [fit_prior(lb, sh, sy, y0, weight, pp, steady_mode) for lb, sh, sy in systems]
    dyn = None
    if s.prestrain == "dynamics" or (s.prestrain == "auto" and mode == "frames" and not pp.calibrated):
        best = max(fits, key=lambda f: f.log_evidence)
        dyn = dynamic_tension(data, best.shapes, best.system, y0, weight, pp)
        if dyn.used:
            fits = [fit_prior(lb, sh, sy, y0, weight, pp, "prior", (dyn.theta, dyn.cov)) for lb, sh, sy in systems]
        # (asked for the dynamics and not given them: _info's warnings say so, once, in the result)
    z = np.array([f.log_evidence for f in fits])
    w = np.exp(z - z.max())
    w /= w.sum()
    lifts = np.array([f.lift for f in fits])
    stds = np.array([f.lift_std for f in fits])
    mean = float(w @ lifts)
    std = float(np.sqrt(max(w @ (stds**2 + lifts**2) - mean**2, 0.0)))
    best = fits[int(np.argmax(w))]
    form = None
    if best.post.chi2_per_datum > ADEQUATE_CHI2:
        # a systematic misfit: the band takes in the lifts of the spaces the evidence does not exclude
        # (:mod:`.model_form`); the lift does not move
        form = model_form(model, s, p0, fvk, data, y0, weight, best, mean)
        std_before, std = std, float(np.hypot(std, form.spread))
    idx = np.flatnonzero(data.used)
    if mode == "frames":
        fl = frame_loads(data, best, s.inertia)
        extra = max(std**2 - best.lift_std**2, 0.0)  # the other priors' spread, scaled with the load
        t, load = fl.t, best.shapes.coefficients(fl.c)
        deflection, lift = fl.z, fl.lift
        lift_std = np.sqrt(fl.lift_std**2 + extra * (fl.lift / best.lift) ** 2)
    else:
        t = frames.t[idx]
        load = np.broadcast_to(best.load(), (idx.size, best.load().size))
        deflection = np.broadcast_to(best.deflection(), (idx.size, model.n))
        lift, lift_std = np.full(idx.size, mean), np.full(idx.size, std)
    modal = None
    if mode == "frames" and s.modes and fluctuation(data) >= MIN_FLUCTUATION:
        modal = modal_check(data, best.system, best.prestrain)
    info = _info(s, mode, data, fits, w, best, mean, std, pp, fvk, dyn, modal)
    info["model_form"] = None if form is None else form.as_dict(mean, std_before)
    if form is not None:
        info["warnings"].append(form.warning(mean, std_before))
    if mode == "frames":
        info["frames_chi2_per_datum_median"] = float(np.median(fl.chi2_per_datum))
    return IdentificationResult(
        method="fullfield",
        t=t,
        load=np.asarray(load),
        deflection=np.asarray(deflection),
        lift=lift,
        lift_std=lift_std,
        regularization=float(s.kappa),
        wall_s=time.perf_counter() - t0,
        info=info,
        load_space=None if best.shapes.space is None else best.shapes.space.space,
    )


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
    if np.any(np.abs(modal.misfit) > 3.0):
        p = modal.predicted
        out.append(
            f"the loaded frequencies measured ({f[0]:.1f}, {f[1]:.1f} Hz) are {np.max(np.abs(modal.misfit)):.2g} sd "
            f"off the model's ({p[0]:.1f}, {p[1]:.1f} Hz): its stiffness or mass is off (an air's added mass, a "
            "wrong density or thickness)"
        )
    return out


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
        },  # fmt: skip
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
        ],  # fmt: skip
        "chosen": best.label,
        "steady_lift_N": mean,  # the reported lift (IdentificationResult.reported_lift): the frames' steady part
        "steady_lift_std_N": std,
        "steady": {
            "lift_N": mean,
            "lift_std_N": std,
            "lift_std_load_N": best.lift_std_load,
            "lift_per_prior_std": best.lift_grad.tolist(),
        },  # fmt: skip
        "parameters": {"prestrain_x": ex, "prestrain_y": ey, "damping": float(fvk.params.viscous_scale)},
        "parameters_std": {"prestrain_x": float(sx), "prestrain_y": float(sy), "damping": 0.0},
        "prestrain_source": _source(pp, dyn),
        "prestrain_mode": s.prestrain,
        "tension_from_dynamics": None if dyn is None else dyn.as_dict(pp),
        "loaded_modes": None if modal is None else modal.as_dict(),
        "prestrain_field_pull": best.pull,
        "adequacy": {"chi2_per_datum": best.post.chi2_per_datum, "data": best.post.data},
        "model_adequate": bool(best.post.chi2_per_datum < ADEQUATE_CHI2),
        "inplane": inplane_check(data, fvk),
        "warnings": warnings,
        "dropped": [],
    }
