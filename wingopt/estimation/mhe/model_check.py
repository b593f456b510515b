"""Model-adequacy check of a linear-MHE result: the flag, the left-out samples, the widened band.

The linear moving-horizon estimator (:mod:`wingopt.estimation.mhe`) is kept unchanged (its numbers
are the seed protocol's). This check runs after it and only *adds*: the chi-square per datum of
its deflection history against the data, per segment (:func:`.adequacy.assess`), the samples it
left out (a skipped load onset, with the chi-square the MHE measured there) reported with their
reason and a warning line, and, when data contradict the linear model (a misfit of the samples
used, or samples left out because the model could not explain them), ``model_adequate = False``,
a warning and the lift band widened by the square root of the worst chi-square per datum: a
confident wrong answer becomes a flagged answer.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from wingopt.estimation.core.adequacy import assess
from wingopt.estimation.core.result import IdentificationResult
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel

__all__ = ["check_mhe_result"]


def check_mhe_result(
    model: MembraneModel, measurements: Measurements, result: IdentificationResult, segment_s: float = 0.05
) -> IdentificationResult:
    """A copy of the MHE ``result`` with ``info['adequacy']``, ``model_adequate``, ``warnings``,
    ``dropped`` and, when inadequate, a widened ``lift_std``. Estimates are not changed."""
    meas = measurements
    sigma = np.asarray(result.info.get("noise_std"), dtype=float)
    idx = np.searchsorted(meas.t, result.t)
    r = np.full(meas.values.shape, np.nan)
    pred = model.sensors.outputs(result.deflection)
    r[idx] = (meas.values[idx] - pred) / sigma
    ad = assess(meas.t, r, 0.0, segment_s)
    dropped, worst = [], ad.chi2_per_datum
    onset = result.info.get("onset") or {}
    if onset.get("samples_skipped", 0):
        per = [max(a["chi2_per_datum"]) for a in onset.get("attempts", []) if a.get("chi2_per_datum")]
        worst_onset = max(per) if per else float("nan")
        dropped.append(
            {
                "t_from_s": float(meas.t[0]),
                "t_to_s": float(onset["t_start"]),
                "samples": int(onset["samples_skipped"]),
                "reason": "load onset: the linear model does not fit these samples (MHE consistency test)",
                "chi2_per_datum": worst_onset,
            }
        )
        if np.isfinite(worst_onset):
            worst = max(worst, worst_onset)
    for rs in result.info.get("restarts") or []:
        dropped.append({"restart": rs, "reason": "estimate restarted on data inconsistent with it"})
    # Samples the MHE left out because the linear model could not explain them are data the model
    # contradicts: on a real (stiffening) membrane they are the bubble's ringing, and the steady
    # remainder then fits a wrong load with a tight band. So a left-out start flags the result and its
    # misfit widens the band, like a misfit of the samples used (the workflow may add a model-form
    # term on top: :func:`wingopt.workflows.identify.identify`).
    onset_misfit = bool(dropped and "samples" in dropped[0])
    adequate = ad.adequate and not onset_misfit
    inflation = 1.0 if adequate else float(np.sqrt(max(worst, ad.inflation**2, 1.0)))
    warnings = []
    if not adequate:
        warnings.append(
            f"linear model inadequate: chi-square per datum {ad.chi2_per_datum:.2f} on the samples used"
            + (f", {worst:.3g} on the {dropped[0]['samples']} samples left out" if onset_misfit else "")
            + f"; band widened x{inflation:.2f}; try --model fvk"
        )
    if dropped and "samples" in dropped[0]:
        d = dropped[0]
        warnings.append(
            f"{d['samples']} samples at the start (to t = {d['t_to_s']:.4g} s) left out: the linear model does not "
            f"fit them (chi-square per datum {worst:.3g}); the estimate uses the rest"
        )
    info = dict(result.info)
    info.update(
        adequacy={**ad.as_dict(), "model_adequate": adequate, "band_inflation": inflation},
        model_adequate=adequate,
        warnings=list(info.get("warnings", [])) + warnings,
        dropped=dropped,
        model="linear",
    )
    std = None if result.lift_std is None else result.lift_std * inflation
    return dataclasses.replace(result, lift_std=std, info=info)
