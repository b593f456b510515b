"""Streaming identification: one estimate per sample, bounded memory and work (real-time iteration).

:mod:`~.types` (settings, the per-sample estimate), :mod:`~.rows` (the window's linearised rows and
incremental normal equations), :mod:`~.estimator` (:class:`StreamingEstimator`, ``push(t, y)``, the
linear membrane); :mod:`~.nonlinear` (:class:`NonlinearStreamingEstimator`, the same shape on the
Berger membrane: an extended Kalman filter with :mod:`~.berger_step`, :mod:`~.nonlinear_start`,
:mod:`~.running_noise`).
"""

from wingopt.estimation.result import Estimate
from wingopt.estimation.streaming.estimator import StreamingEstimator
from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator, NonlinearStreamSettings
from wingopt.estimation.streaming.types import StreamSettings

__all__ = ["StreamingEstimator", "StreamSettings", "Estimate", "NonlinearStreamingEstimator", "NonlinearStreamSettings"]
