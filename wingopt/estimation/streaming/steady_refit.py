"""A stream that may be a steady record: the live filter, and the whole-record answer when it is steady.

A tunnel run has no release transient: the membrane is already loaded when the stream starts, and
a per-sample filter cannot tell the pressure from the tension on it (the four stretch sensors see
about ``(p/T)^2``; measured on the shipped stand-in, the FvK EKF ends at 1.27 ± 0.02 N where the
truth is 1.76 N). :class:`SteadyRefit` wraps the live filter: every sample goes through it, and the
record so far is kept (bounded); each time the record has grown by half since the last look (at
least ``every_s`` of data, at most ``max_interval_s``), it is tested for steadiness
(:func:`~wingopt.estimation.steady.estimator.is_steady`) and, if steady, refitted by the
whole-record estimator, whose steady lift the rows then carry (phase ``steady``). :meth:`finish`
refits the whole record once more, so the stream's final answer is the batch estimate of the same
samples. A record found not steady at a look (a release rings at its start) is a transient record
for good: the filter answers and the record is not looked at again (an hour-long protocol stream
whose ringing has left the kept record must not start refitting it); that first look fits the
record once by the batch route, whose frame check's lift spread then joins the filter's band
and whose lift checks the filter's (:mod:`.batch_check`).
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable

import numpy as np

from wingopt.estimation.core.result import Estimate, IdentificationResult
from wingopt.estimation.steady.estimator import is_steady
from wingopt.estimation.streaming.batch_check import MAX_CHECK_SAMPLES, BatchCheck
from wingopt.measurements import Measurements

__all__ = ["SteadyRefit"]

log = logging.getLogger(__name__)


class SteadyRefit:
    """The live filter ``inner`` plus whole-record refits of a steady record (module docstring).

    Parameters
    ----------
    inner
        A streaming estimator (``push(t, y) -> Estimate``, ``info()``, ``last``, ``count``, ``dt``).
    refit : callable
        ``refit(measurements) -> IdentificationResult``: the whole-record estimator.
    sensor_names : tuple of str
    noise_std : float, optional
        The sensors' noise 1-sigma, handed to the refits as the batch path does.
    every_s, max_interval_s : float
        Least and most data (s) between two looks at the record.
    max_samples : int
        The record kept (the latest samples): beyond it the refits see the last ``max_samples``.
    """

    def __init__(
        self,
        inner,
        refit: Callable[[Measurements], IdentificationResult],
        sensor_names: tuple[str, ...],
        *,
        noise_std: float | None = None,
        every_s: float = 1.0,
        max_interval_s: float = 10.0,
        max_samples: int = 500_000,
    ) -> None:
        self.inner, self._refit, self.names = inner, refit, tuple(sensor_names)
        self.noise_std = noise_std
        self.every_s, self.max_interval_s, self.max_samples = float(every_s), float(max_interval_s), int(max_samples)
        self._t: deque[float] = deque(maxlen=int(max_samples))
        self._y: deque[np.ndarray] = deque(maxlen=int(max_samples))
        self._looked_at = 0  # record length at the last look
        self.result: IdentificationResult | None = None  # the last refit of a steady record
        self.refits: list[dict] = []
        self.final = False
        self.transient = False  # a look found a transient: the filter's record for good
        self.check: BatchCheck | None = None  # the transient record's batch check (:mod:`.batch_check`)
        self._last: Estimate | None = None

    # the live filter's protocol, passed through
    @property
    def count(self) -> int:
        return self.inner.count

    @property
    def dt(self) -> float | None:
        return self.inner.dt

    @property
    def last(self) -> Estimate | None:
        return self._last if self._last is not None else self.inner.last

    def info(self) -> dict:
        out = self.inner.info()
        if self.check is not None:
            out = {**out, "batch_check": self.check.as_dict()}
            out["warnings"] = list(out.get("warnings", [])) + self.check.warnings()
        return out

    def push(self, t: float, y) -> Estimate:
        """Add one sample; the filter's estimate, or the last refit's steady lift once the record is steady."""
        e = self.inner.push(t, y)
        if self.transient:  # the filter's record: nothing kept
            return self._checked(e)
        if len(self._t) == self._t.maxlen:  # the oldest sample leaves the kept record
            self._looked_at = max(self._looked_at - 1, 0)
        self._t.append(float(e.t))
        self._y.append(np.asarray(y, dtype=float).copy())
        if self._due():
            self._look()
        if self.result is None:
            return self._checked(e)
        lift, std = self.result.reported_lift
        chi2 = self.result.info.get("adequacy", {}).get("chi2_per_datum", math.nan)
        adequate = bool(self.result.info.get("model_adequate", True))
        return Estimate(e.k, e.t, lift, math.inf if std is None else std, None, chi2, adequate, "steady")

    def finish(self) -> IdentificationResult | None:
        """Refit the whole record if it is steady (the stream's final answer); ``None`` if it is not."""
        if self.transient:
            return None
        if len(self._t) == self._looked_at:
            self.final = True
            if self.refits:
                self.refits[-1]["final"] = True
        else:
            self._look(final=True)
        return self.result

    def _checked(self, e: Estimate) -> Estimate:
        """The filter's estimate with the batch check's spread in its band (after a transient look)."""
        if self.check is not None:
            e = self.check.widened(e)
            self._last = e
        return e

    def _batch_check(self) -> None:
        """The whole-record batch fit of the first transient look's record, once (:mod:`.batch_check`)."""
        last, n = self.inner.last, len(self._t)
        c0 = time.thread_time()
        try:
            self.check = BatchCheck.of(self._refit(self._record()), last, n)
        except Exception as exc:  # noqa: BLE001 - a check that fails must not stop the stream
            self.check = BatchCheck.failed(last, n, exc)
        self._last = self.check.widened(last)
        for w in self.check.warnings():
            log.warning("[ekf stream] %s", w)
        log.info("transient stream: batch check on %d samples (%.2f s CPU)", n, time.thread_time() - c0)

    # -- the looks ---------------------------------------------------------------------------------
    def _due(self) -> bool:
        dt = self.inner.dt
        if not dt or self.transient:
            return False
        n, last = len(self._t), self._looked_at
        grown = (n - last) * dt
        return grown >= self.max_interval_s or (grown >= self.every_s and n >= 1.5 * last)

    def _record(self) -> Measurements:
        std = None if self.noise_std is None else np.full(len(self.names), float(self.noise_std))
        return Measurements(np.asarray(self._t), np.vstack(self._y), self.names, std, "stream")

    def _look(self, final: bool = False) -> None:
        self._looked_at, self.final = len(self._t), final
        if len(self._t) < 40:
            return
        values = np.vstack(self._y)
        if not is_steady(values):
            if self.result is not None:
                log.warning("the stream is no longer steady at t = %.6g s: back to the live filter", self._t[-1])
            elif self.check is None and len(self._t) <= MAX_CHECK_SAMPLES and self.inner.last is not None:
                self._batch_check()
            self.result, self.transient = None, True
            self._t.clear()
            self._y.clear()
            return
        c0 = time.thread_time()
        self.result = self._refit(self._record())
        lift, std = self.result.reported_lift
        cpu = time.thread_time() - c0
        self.refits.append({"t_s": self._t[-1], "samples": len(self._t), "lift_N": lift, "lift_std_N": std,
                            "cpu_s": cpu, "final": final})  # fmt: skip
        log.info("steady record: whole-record refit on %d samples: lift %.4g N (%.2f s CPU)", len(self._t), lift, cpu)
