"""Model-adequacy check of a linear-MHE result: the flag, the left-out samples, the widened band.

The linear moving-horizon estimator (:mod:`wingopt.estimation.mhe`) is kept unchanged (its numbers
are the seed protocol's). This check runs after it and only *adds*: the chi-square per datum of
its deflection history against the data, per segment (:func:`.adequacy.assess`), the samples it
left out (a skipped load onset, with the chi-square the MHE measured there) reported with their
reason and a warning line, and, when the data the estimate used contradict the linear model,
``model_adequate = False``, a warning and the lift band widened by the square root of their worst
segment chi-square per datum: a confident wrong answer becomes a flagged answer.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from wingopt.estimation.data import IdentificationResult, Measurements
from wingopt.estimation.realistic.adequacy import assess
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
    # The band answers for the samples the estimate used: their misfit widens it. Samples the MHE
    # left out (an onset it could not explain) did not enter the estimate; they are reported, with
    # their misfit, as a warning of their own rather than blown into the band.
    adequate = ad.adequate
    inflation = ad.inflation if not adequate else 1.0
    warnings = []
    if not adequate:
        warnings.append(
            f"linear model inadequate: chi-square per datum {ad.chi2_per_datum:.2f} on the samples used; "
            f"band widened x{inflation:.2f}; try --model nonlinear"
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
