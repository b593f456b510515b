"""Streaming identification: one estimate per sample, bounded memory and work (real-time iteration).

:mod:`~.types` (settings, the per-sample estimate), :mod:`~.rows` (the window's linearised rows and
incremental normal equations), :mod:`~.estimator` (:class:`StreamingEstimator`, ``push(t, y)``, the
linear membrane); :mod:`~.nonlinear` (:class:`NonlinearStreamingEstimator`, the same shape on the
Berger or FvK membrane: an extended Kalman filter on the forward-model layer's one-sample map, with
:mod:`~.nonlinear_start`, :mod:`~.running_noise`, :mod:`~.recovery` (numerical failures recovered)
and :mod:`~.batch_check` (the batch fit's frame check in the band)).
"""

from wingopt.estimation.core.result import Estimate
from wingopt.estimation.streaming.estimator import StreamingEstimator
from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator, NonlinearStreamSettings
from wingopt.estimation.streaming.types import StreamSettings

__all__ = ["StreamingEstimator", "StreamSettings", "Estimate", "NonlinearStreamingEstimator", "NonlinearStreamSettings"]
