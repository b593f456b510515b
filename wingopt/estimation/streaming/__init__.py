"""Streaming identification: one estimate per sample, bounded memory and work (real-time iteration).

:mod:`~.types` (settings, the per-sample estimate), :mod:`~.rows` (the window's linearised rows and
incremental normal equations), :mod:`~.estimator` (:class:`StreamingEstimator`, ``push(t, y)``).
"""

from wingopt.estimation.streaming.estimator import StreamingEstimator
from wingopt.estimation.streaming.types import Estimate, StreamSettings

__all__ = ["StreamingEstimator", "StreamSettings", "Estimate"]
