"""Run the registry's estimators: options to settings, one record or one stream.

:func:`run_record` runs a record estimator of :mod:`wingopt.estimation.registry` on
:class:`~wingopt.measurements.Measurements`; :func:`build_stream` builds a streaming one (``push``
one sample at a time). Settings are made from :class:`~wingopt.estimation.options.IdentifyOptions`
here, once (:func:`mhe_settings`, :func:`batch_settings`, :func:`ekf_settings`); an explicit
settings object replaces the defaults the options start from.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.fullfield import FullFieldSettings, fullfield_identify
from wingopt.estimation.lambda_rules import resolve as resolve_rule
from wingopt.estimation.mhe import STATE_PRIOR_EVIDENCE, MHESettings, mhe_identify
from wingopt.estimation.options import IdentifyOptions
from wingopt.estimation.protocol import Estimator, RecordEstimator, StreamEstimator
from wingopt.estimation.realistic import RealisticSettings, realistic_identify
from wingopt.estimation.realistic.mhe_check import check_mhe_result
from wingopt.estimation.registry import EstimatorSpec, check_options, resolve
from wingopt.estimation.result import IdentificationResult
from wingopt.measurements import Measurements
from wingopt.membrane import MembraneModel

__all__ = [
    "mhe_settings",
    "batch_settings",
    "ekf_settings",
    "fullfield_settings",
    "build",
    "run_record",
    "build_stream",
    "model_form_band",
]

log = logging.getLogger(__name__)


def mhe_settings(options: IdentifyOptions, base: MHESettings | None = None) -> MHESettings:
    """The moving-horizon settings of ``options`` (on ``base``, default :class:`MHESettings`)."""
    o, kw = options, {}
    for name in ("window", "stride"):  # whole samples, or seconds
        value = getattr(o, name)
        if value is not None:
            kw[name if isinstance(value, int) else f"{name}_s"] = value
    if o.solver is not None:
        kw["backend"] = o.solver
    if o.qp_solver is not None:
        kw["qp_solver"] = o.qp_solver
    if o.modes is not None:
        kw["modes"] = o.modes
    if o.load_model is not None:
        kw["load_model"] = "random_walk" if o.load_model == "varying" else "constant"
    if o.load_timescale is not None:
        kw["load_timescale"] = o.load_timescale
    if o.state_prior == "evidence":
        kw["state_prior_choices"] = STATE_PRIOR_EVIDENCE
    elif o.state_prior is not None:
        kw["state_prior"] = o.state_prior
    if o.pressure_bounds is not None:
        kw["pressure_bounds"] = o.pressure_bounds
    if o.load_space is not None:
        kw["load_space"] = o.load_space
    if o.consistency is not None:
        kw["consistency"] = o.consistency
    if o.lam is not None:
        if o.lam.is_fixed:
            kw["regularization"] = o.lam.value
        else:
            kw.update(regularization=None, lambda_rule=resolve_rule(o.lam.rule, "mhe").internal)
    return (base or MHESettings()).replace(**kw)


def batch_settings(spec: EstimatorSpec, options: IdentifyOptions, base: RealisticSettings | None = None):
    """The whole-record estimator's settings of ``options`` (membrane physics from ``spec``)."""
    kw = {"membrane_model": spec.model}
    if options.modes is not None:
        kw["modes"] = options.modes
    if options.load_model is not None:
        kw["load_model"] = {"varying": "gust"}.get(options.load_model, options.load_model)
    return (base or RealisticSettings()).replace(**kw)


def fullfield_settings(options: IdentifyOptions, base: FullFieldSettings | None = None) -> FullFieldSettings:
    """The full-field estimator's settings of ``options``: ``load_model`` constant is the steady mode,
    varying the time-resolved one; ``initial_load`` the load prior's pressure scale."""
    kw: dict = {}
    if options.load_model is not None:
        kw["mode"] = {"constant": "steady", "varying": "frames"}.get(options.load_model, "auto")
    if options.initial_load is not None:
        kw["pressure"] = abs(options.initial_load)
    return (base or FullFieldSettings()).replace(**kw)


def ekf_settings(spec: EstimatorSpec, options: IdentifyOptions):
    """The streaming extended Kalman filter's settings of ``options``."""
    from wingopt.estimation.streaming.types import NonlinearStreamSettings

    s = NonlinearStreamSettings(membrane_model=spec.model)
    return s if options.modes is None else dataclasses.replace(s, modes=options.modes)


def run_record(
    spec: EstimatorSpec,
    model: MembraneModel,
    measurements: Measurements,
    options: IdentifyOptions | None = None,
    *,
    truth=None,
    settings=None,
    frames=None,
) -> IdentificationResult:
    """Run the record estimator ``spec`` on ``measurements``.

    ``truth`` (a simulated record) is handed only to ``jekf-seed``, which tunes its lambda on the
    noise-free truth as the seed did; ``settings`` replaces the default settings the options start
    from (an :class:`MHESettings`, a :class:`RealisticSettings` or a :class:`FullFieldSettings`);
    ``frames`` (:class:`~wingopt.measurements.dic.DICFrames`) are the full-field estimator's data.
    """
    if spec.stream:
        raise InputError(f"{spec.label}: a streaming estimator, use build_stream")
    options = IdentifyOptions() if options is None else options
    p0 = options.initial_load
    if spec.method == "fullfield":
        if frames is None:
            raise InputError(f"{spec.label}: no DIC frames given (wingopt identify --dic FRAMES)")
        return fullfield_identify(model, frames, fullfield_settings(options, settings))
    if spec.method == "mhe":
        result = mhe_identify(model, measurements, mhe_settings(options, settings), initial_load=p0)
        result = check_mhe_result(model, measurements, result)
        if result.info.get("model_adequate") is False and options.model_form is not False:
            result = model_form_band(model, measurements, result, p0)
        return result
    if spec.method == "batch":
        return realistic_identify(model, measurements, batch_settings(spec, options, settings), initial_load=p0)
    from wingopt.estimation import jekf

    kw: dict = {}
    if options.modes is not None:
        kw["modes"] = options.modes
    lam = options.lam
    if lam is not None and lam.is_fixed:
        kw["regularization"] = lam.value
    elif lam is not None and spec.method == "jekf-tuned":
        kw["rule"] = resolve_rule(lam.rule, "jekf").internal
    elif lam is not None:
        resolve_rule(lam.rule, "jekf-seed")  # the seed's filter has its one rule: refuse any other name
    variant = "tuned" if spec.method == "jekf-tuned" else "seed"
    return jekf.identify(model, measurements, variant=variant, truth=truth, initial_load=p0, **kw)


def build(
    spec: EstimatorSpec,
    model: MembraneModel,
    options: IdentifyOptions | None = None,
    *,
    truth=None,
    settings=None,
    keep: bool = True,
    frames=None,
) -> Estimator:
    """Any estimator of the registry behind the one protocol (:mod:`wingopt.estimation.protocol`).

    ``truth``, ``settings`` and ``frames`` as :func:`run_record` (record estimators); ``keep``: a
    stream keeps its estimates for ``result()``.
    """
    options = IdentifyOptions() if options is None else options
    check_options(spec, options)
    if spec.stream:
        return StreamEstimator(build_stream(spec, model, options), f"{spec.method}-stream", keep)
    return RecordEstimator(
        lambda meas: run_record(spec, model, meas, options, truth=truth, settings=settings, frames=frames),
        model.problem.sensor_names,
    )


def build_stream(spec: EstimatorSpec, model: MembraneModel, options: IdentifyOptions | None = None):
    """The streaming estimator ``spec`` (``push(t, y) -> Estimate``, ``info()``, ``last``)."""
    if not spec.stream:
        raise InputError(f"{spec.label}: not a streaming estimator, use run_record")
    options = IdentifyOptions() if options is None else options
    if spec.method == "ekf":
        from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator
        from wingopt.estimation.streaming.steady_refit import SteadyRefit

        ekf = NonlinearStreamingEstimator(
            model, ekf_settings(spec, options), noise_std=options.noise_std, initial_load=options.initial_load
        )
        if spec.model != "fvk":
            return ekf
        batch = resolve("batch", "fvk")  # a steady stream's answer is the batch estimate of its record
        names, std = model.problem.sensor_names, options.noise_std
        return SteadyRefit(ekf, lambda meas: run_record(batch, model, meas, options), names, noise_std=std)
    from wingopt.estimation.streaming import StreamingEstimator, StreamSettings

    return StreamingEstimator(model, StreamSettings(mhe=mhe_settings(options)), options.noise_std, options.initial_load)


CROSS_CHECK = "[fvk cross-check]"
"""The source prefix of the warnings of the FvK fit that :func:`model_form_band` runs."""


def model_form_band(model: MembraneModel, meas: Measurements, result: IdentificationResult, initial_load):
    """Widen a flagged linear-MHE band by its distance to the FvK whole-record estimate of the same data.

    The misfit inflation of :func:`check_mhe_result` cannot cover a bias it does not see: on a
    stiffening membrane the steady data after the left-out start fit a wrong load well. The
    distance to the estimate of a model that explains the whole record, plus that estimate's own
    1-sigma band, is a model-form uncertainty: added in quadrature, the band reaches the far side of
    the alternative's band (``info["model_form"]``). The estimate is unchanged.
    """
    alt = realistic_identify(model, meas, RealisticSettings(membrane_model="fvk"), initial_load=initial_load)
    alt_lift, alt_sd = alt.reported_lift
    diff = float(result.lift[-1] - alt_lift)
    alt_std = 0.0 if alt_sd is None else alt_sd
    own = np.zeros_like(result.lift) if result.lift_std is None else np.asarray(result.lift_std, dtype=float)
    std = np.sqrt(own**2 + (abs(diff) + alt_std) ** 2)
    info = dict(result.info)
    info["model_form"] = {
        "alternative": alt.info.get("model", "realistic (FvK)"),
        "alternative_lift_N": alt_lift,
        "alternative_lift_std_N": alt_sd,
        "alternative_adequate": alt.info.get("model_adequate"),
        "difference_N": diff,
    }
    # The cross-check's own warnings (its fit's adequacy, its iteration cap) are about the FvK fit,
    # not this estimate: they say so, and come once, after this estimate's own.
    info["warnings"] = list(info.get("warnings", [])) + [
        f"{CROSS_CHECK} model-form uncertainty: the FvK whole-record estimator gives {alt_lift:.4g} N on the "
        f"same data (± {alt_std:.3g} N), {diff:+.3g} N from this estimate; the band reaches across that "
        "estimate's band",
        *(f"{CROSS_CHECK} {w}" for w in alt.info.get("warnings", [])),
    ]
    return dataclasses.replace(result, lift_std=std, info=info)
