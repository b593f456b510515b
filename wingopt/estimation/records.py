"""Which fit models a whole record: the steady tunnel fit or the transient fit.

The one place where a record's route is chosen. A steady record (a loaded wing in steady flow)
goes to :func:`~wingopt.estimation.steady.estimator.steady_identify`; its own check refuses a
mean that moves (a gust, a drift) and hands the record to the transient fit
(:func:`~wingopt.estimation.transient.estimator.transient_identify`), so that a routing error
costs the steady fit's time, never the answer.
"""

from __future__ import annotations

import logging

from wingopt.estimation.core.record_settings import LOAD_MODELS, MEMBRANE_MODELS, RecordSettings
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.steady.estimator import is_steady, steady_identify
from wingopt.estimation.transient.estimator import transient_identify
from wingopt.measurements.series import Measurements
from wingopt.membrane import MembraneModel

__all__ = ["RecordSettings", "identify_record", "answered_by_steady_fit", "LOAD_MODELS", "MEMBRANE_MODELS"]

log = logging.getLogger(__name__)


def identify_record(
    model: MembraneModel,
    measurements: Measurements,
    settings: RecordSettings | None = None,
    initial_load: float | None = None,
) -> IdentificationResult:
    """Identify the load of one record (batch over all its samples) by the fit that models it.

    Parameters
    ----------
    model : MembraneModel
        The estimator's membrane (its problem, mesh and sensors).
    measurements : Measurements
        The record.
    settings : RecordSettings, optional
        ``settings.record`` forces ``"steady"`` or ``"transient"``; ``"auto"`` (default) tests
        the record (:func:`~wingopt.estimation.steady.estimator.is_steady`) with the FvK model.
        ``settings.declaration`` is filled here from ``model.problem`` when not given, once for
        the steady and the transient fit.
    initial_load : float, optional
        The load the record starts under, when known.

    Returns
    -------
    IdentificationResult
        ``info["routing"]`` says which fit answered and why.
    """
    s = with_declaration(settings or RecordSettings(), model.problem)
    if s.record == "transient" or not (
        s.record == "steady" or (s.record == "auto" and s.membrane_model == "fvk" and is_steady(measurements.values))
    ):
        return transient_identify(model, measurements, s, initial_load)
    res = steady_identify(model, measurements, s, initial_load)
    if s.record == "steady" or not res.info["mean_moves"]["moved"]:
        return res
    routing = (
        f"routed to the transient fit: the steady route found the load's mean moving (a window "
        f"{res.info['mean_moves']['largest_window_move']:.0%} off the record's median)"
    )
    log.info(routing)
    return transient_identify(model, measurements, s, initial_load, routing=routing)


def answered_by_steady_fit(result: IdentificationResult) -> bool:
    """Whether the steady fit answered (a batch result, or a stream's steady refit)."""
    return result.diagnostics.record == "steady"
