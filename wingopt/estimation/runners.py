"""Run the registry's estimators: settings from options, one record or one stream.

:func:`run_record` runs a record estimator of :mod:`wingopt.estimation.registry` on
:class:`~wingopt.measurements.Measurements`; :func:`build_stream` builds a streaming one (``push``
one sample at a time); :func:`build` puts either behind the one protocol. An estimator's settings
are made here, once, by :func:`settings_for`: its settings dataclass (the registry row's) with the
options its fields declare applied and the problem's declaration filled in; an explicit settings
object replaces the defaults the options start from. Each method has one runner
(:data:`RECORD_RUNNERS`, :data:`STREAM_BUILDERS`): no method name is compared anywhere else.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation import jekf
from wingopt.estimation.core.lambda_rules import resolve as resolve_rule
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.fullfield import fullfield_identify
from wingopt.estimation.mhe import mhe_identify
from wingopt.estimation.mhe.model_check import check_mhe_result
from wingopt.estimation.options import IdentifyOptions, apply_options
from wingopt.estimation.protocol import Estimator, RecordEstimator, StreamEstimator
from wingopt.estimation.records import RecordSettings, identify_record
from wingopt.estimation.registry import EstimatorSpec, check_options, resolve
from wingopt.estimation.streaming import StreamingEstimator
from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator
from wingopt.estimation.streaming.steady_refit import SteadyRefit
from wingopt.measurements import Measurements
from wingopt.membrane import MembraneModel

__all__ = [
    "settings_for",
    "check_settings",
    "build",
    "run_record",
    "build_stream",
    "model_form_band",
    "RECORD_RUNNERS",
    "STREAM_BUILDERS",
]

log = logging.getLogger(__name__)


def settings_for(spec: EstimatorSpec, options: IdentifyOptions | None = None, base=None, *, problem=None):
    """The settings ``spec`` runs with: ``base`` (default: its settings dataclass's defaults) on the
    row's membrane, with the options its settings declare applied and, given the ``problem`` and
    where the settings have a ``declaration``, the problem's ``[identification]`` in it
    (:func:`~wingopt.estimation.declaration.with_declaration`: a ``base`` that carries one keeps it)."""
    settings = base if base is not None else spec.settings()
    names = {f.name for f in dataclasses.fields(settings)}
    if "membrane_model" in names:
        settings = dataclasses.replace(settings, membrane_model=spec.model)
    if problem is not None and "declaration" in names:
        settings = with_declaration(settings, problem)
    return apply_options(settings, options if options is not None else IdentifyOptions())


def check_settings(spec: EstimatorSpec, settings) -> None:
    """Refuse a settings object that is not the estimator's own settings dataclass (``None`` passes)."""
    if settings is None:
        return
    if spec.stream or spec.method not in _TAKES_SETTINGS:
        raise InputError(f"settings: the {spec.label} takes no settings object")
    if not isinstance(settings, spec.settings):
        kind = spec.settings.__name__
        raise InputError(f"settings = {type(settings).__name__}: the {spec.label} takes a {kind} (or None)")


def _mhe(spec, model, meas, options, settings, truth, frames) -> IdentificationResult:
    p0 = options.initial_load
    result = mhe_identify(model, meas, settings_for(spec, options, settings, problem=model.problem), initial_load=p0)
    result = check_mhe_result(model, meas, result)
    if result.diagnostics.model_adequate is False and options.model_form is not False:
        result = model_form_band(model, meas, result, p0)
    return result


def _batch(spec, model, meas, options, settings, truth, frames) -> IdentificationResult:
    s = settings_for(spec, options, settings, problem=model.problem)
    return identify_record(model, meas, s, initial_load=options.initial_load)


def _fullfield(spec, model, meas, options, settings, truth, frames) -> IdentificationResult:
    if frames is None:
        raise InputError(f"{spec.label}: no DIC frames given (wingopt identify --dic FRAMES)")
    return fullfield_identify(model, frames, settings_for(spec, options, settings, problem=model.problem))


def _jekf(spec, model, meas, options, settings, truth, frames) -> IdentificationResult:
    """The joint EKF: ``jekf-seed`` tunes its lambda on the noise-free truth as the seed did."""
    variant = spec.method.removeprefix("jekf-")
    kw: dict = {}
    if options.modes is not None:
        kw["modes"] = options.modes
    lam = options.lam
    if lam is not None and lam.is_fixed:
        kw["regularization"] = lam.value
    elif lam is not None and variant == "tuned":
        kw["rule"] = resolve_rule(lam.rule, "jekf").internal
    elif lam is not None:
        resolve_rule(lam.rule, "jekf-seed")  # the seed's filter has its one rule: refuse any other name
    return jekf.identify(model, meas, variant=variant, truth=truth, initial_load=options.initial_load, **kw)


RECORD_RUNNERS = {"mhe": _mhe, "batch": _batch, "fullfield": _fullfield, "jekf-seed": _jekf, "jekf-tuned": _jekf}
"""Each record estimator's runner: ``(spec, model, measurements, options, settings, truth, frames)``."""

_TAKES_SETTINGS = ("mhe", "batch", "fullfield")
"""The record estimators that take a settings object (the JEKF's presets are set by options)."""


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
    from (the row's settings dataclass: an :class:`MHESettings`, a :class:`RecordSettings` or a
    :class:`FullFieldSettings`); ``frames`` (:class:`~wingopt.measurements.dic.DICFrames`) are the
    full-field estimator's data.
    """
    if spec.stream:
        raise InputError(f"{spec.label}: a streaming estimator, use build_stream")
    check_settings(spec, settings)
    options = IdentifyOptions() if options is None else options
    return RECORD_RUNNERS[spec.method](spec, model, measurements, options, settings, truth, frames)


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


def _ekf_stream(spec: EstimatorSpec, model: MembraneModel, options: IdentifyOptions):
    s = settings_for(spec, options, problem=model.problem)
    ekf = NonlinearStreamingEstimator(model, s, noise_std=options.noise_std, initial_load=options.initial_load)
    if spec.model != "fvk":
        return ekf
    batch = resolve("batch", "fvk")  # a steady stream's answer is the batch estimate of its record
    names, std = model.problem.sensor_names, options.noise_std
    return SteadyRefit(ekf, lambda meas: run_record(batch, model, meas, options), names, noise_std=std)


def _mhe_stream(spec: EstimatorSpec, model: MembraneModel, options: IdentifyOptions):
    s = settings_for(spec, options, problem=model.problem)
    return StreamingEstimator(model, s, options.noise_std, options.initial_load)


STREAM_BUILDERS = {"mhe": _mhe_stream, "ekf": _ekf_stream}
"""Each streaming estimator's builder: ``(spec, model, options) -> push(t, y)`` estimator."""


def build_stream(spec: EstimatorSpec, model: MembraneModel, options: IdentifyOptions | None = None):
    """The streaming estimator ``spec`` (``push(t, y) -> Estimate``, ``info()``, ``last``)."""
    if not spec.stream:
        raise InputError(f"{spec.label}: not a streaming estimator, use run_record")
    return STREAM_BUILDERS[spec.method](spec, model, IdentifyOptions() if options is None else options)


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
    alt = identify_record(model, meas, RecordSettings(membrane_model="fvk"), initial_load=initial_load)
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
