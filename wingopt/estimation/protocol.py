"""One estimator protocol: ``push`` samples, ``result()`` the estimate, or ``run`` a whole record.

Every estimator of the registry (:mod:`wingopt.estimation.registry`) is used the same way, the
FilterPy / PyLops habit::

    est = build(spec, model, options)         # wingopt.estimation.runners.build
    for t, y in samples:
        e = est.push(t, y)                    # an Estimate, or None for a record estimator
    res = est.result()                        # IdentificationResult, the one result type
    res = est.run(measurements)               # the same in one call

A record estimator (the MHE, the JEKF, the whole-record fit) buffers what it is pushed and fits it
in :meth:`~RecordEstimator.result`; a streaming one (the real-time MHE, the EKF) updates per sample
and its result is the history of its estimates (:class:`StreamEstimator`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.result import Estimate, IdentificationResult
from wingopt.measurements import Measurements

__all__ = ["Estimator", "RecordEstimator", "StreamEstimator"]


class Estimator(Protocol):
    """What every load estimator offers."""

    def push(self, t: float, y) -> Estimate | None: ...

    def result(self) -> IdentificationResult: ...

    def run(self, measurements: Measurements) -> IdentificationResult: ...


class RecordEstimator:
    """A whole-record estimator: samples are buffered; :meth:`result` fits the record.

    Parameters
    ----------
    fit : callable ``Measurements -> IdentificationResult``
    sensor_names : tuple of str
    """

    def __init__(self, fit: Callable[[Measurements], IdentificationResult], sensor_names) -> None:
        self._fit = fit
        self.names = tuple(sensor_names)
        self._t: list[float] = []
        self._y: list[np.ndarray] = []

    def push(self, t: float, y) -> None:
        self._t.append(float(t))
        self._y.append(np.asarray(y, dtype=float))
        return None

    def result(self) -> IdentificationResult:
        if not self._t:
            raise InputError("estimator: no samples were pushed")
        return self._fit(Measurements(np.array(self._t), np.array(self._y), self.names, None, "pushed samples"))

    def run(self, measurements: Measurements) -> IdentificationResult:
        return self._fit(measurements)


class StreamEstimator:
    """A streaming estimator (``push -> Estimate``) whose result is the history of its estimates.

    ``keep`` (default ``True``) keeps every estimate for :meth:`result`; a long stream that writes
    its estimates elsewhere (``wingopt identify --follow``) turns it off to keep memory bounded.
    """

    def __init__(self, stream, method: str, keep: bool = True) -> None:
        self.stream, self.method, self.keep = stream, method, keep
        self._history: list[Estimate] = []

    def __getattr__(self, name):  # the stream's own diagnostics (info(), last, count, dt)
        return getattr(self.stream, name)

    def push(self, t: float, y) -> Estimate:
        e = self.stream.push(t, y)
        if self.keep:
            self._history.append(e)
        return e

    def result(self) -> IdentificationResult:
        h = self._history
        if not h:
            raise InputError("estimator: no estimates (no samples pushed, or keep=False)")
        last = next((e.load for e in reversed(h) if e.load is not None), None)
        load = np.full((len(h), 0 if last is None else last.size), np.nan)
        for i, e in enumerate(h):
            if e.load is not None:
                load[i] = e.load
        info = dict(self.stream.info())
        info["phases"] = sorted({e.phase for e in h})
        info["model_adequate"] = bool(h[-1].adequate)
        steady = self.stream.finish() if hasattr(self.stream, "finish") else None
        if steady is not None:  # a steady record: the whole-record estimate is the answer (reported_lift)
            lift, std = steady.reported_lift
            info.update(record="steady", steady_lift_N=lift, steady_lift_std_N=std, steady=steady.info)
            info["model_adequate"] = bool(steady.info.get("model_adequate", True))
        return IdentificationResult(
            method=self.method,
            t=np.array([e.t for e in h]),
            load=load,
            deflection=np.zeros((len(h), 0)),
            lift=np.array([e.lift for e in h]),
            lift_std=np.array([e.lift_std for e in h]),
            info=info,
        )

    def run(self, measurements: Measurements) -> IdentificationResult:
        for t, y in zip(measurements.t, measurements.values):
            self.push(t, y)
        return self.result()
