"""A stream that never stops: the nonlinear filter's numerical failures, detected and recovered.

The extended Kalman filter linearises the quadratic sensors at its prediction. From a poor prior
(a load unlike the prior's smoothest shape: zero net lift, an edge-peaked load, an off-centre
bump) its first updates can throw the parameters where the membrane is unstable; the state then
grows without bound and the innovation covariance stops being positive definite (measured on
L2, FvK truth 49x25, no initial shape declared: the state at 1e8 prior stds after 19 samples,
"LinAlgError: innovation covariance not positive definite", and the stream stopped).

:class:`Recovery` watches every filter step: an innovation covariance that the covariance repair
cannot make positive definite, or a state that is not finite or beyond :data:`BLOWUP` prior
standard deviations, is a failure. It is recovered, with a warning, as follows:

* before the start-up (the provisional filter): the filter goes back to its prior and holds it
  (the samples are buffered as before) until the start-up's batch fit, which starts from the
  prior and the batch's amplitude scan;
* while tracking: the filter is reset from the batch fit of the latest samples (the kept ring,
  the start-up's length), as at the start-up; if that fails too, or the filter fails again before
  the ring has filled since its last reset (a record the model cannot follow: measured on an L2
  gust through an undeclared analog filter, a reset at every sample, 17 s each, and the last
  failure left the state diverged: no lift at the end), the filter goes back to its last healthy
  state and holds that answer, flagged, and retries when the ring has filled again.

Every failure is counted in ``info()["recoveries"]`` and said once in ``info()["warnings"]``; the
stream runs to the end of its input.
"""

from __future__ import annotations

import logging

import numpy as np

from wingopt.estimation.streaming.nonlinear_start import batch_start

__all__ = ["Recovery", "BLOWUP", "MAX_RESETS"]

log = logging.getLogger(__name__)

BLOWUP = 1e4
"""Scaled state (prior standard deviations) beyond which the filter has diverged."""

MAX_RESETS = 50
"""Batch resets at most in one stream; beyond, the filter holds its last answer, flagged."""


def healthy(est) -> bool:
    """The filter's state and sensitivities are finite and within :data:`BLOWUP` prior stds."""
    x, G = est.x, est.G
    return bool(np.isfinite(x).all() and np.abs(x).max() < BLOWUP and np.isfinite(G).all())


class Recovery:
    """The failure watch of one :class:`~.nonlinear.NonlinearStreamingEstimator` (module docstring).

    ``ring``: the latest samples (the start-up's length), the data of a reset; ``hold``: the filter
    is not updated (after a failure, until the start-up or the next reset)."""

    def __init__(self, samples: int, sensors: int = 1) -> None:
        self._ring = np.full((max(int(samples), 1), sensors), np.nan)  # allocated once: nothing grows
        self._kept = 0
        self.hold = False
        self.events: list[dict] = []
        self._since_hold = 0
        self._since_reset: int | None = None  # samples since the last reset (None: none yet)
        self._good: tuple | None = None  # the last healthy (x, G, Sigma, DAQ filter): what a hold keeps

    @property
    def ring(self) -> np.ndarray:
        """The kept samples, oldest first."""
        n, size = self._kept, self._ring.shape[0]
        if n < size:
            return self._ring[:n].copy()
        i = n % size
        return np.concatenate([self._ring[i:], self._ring[:i]])

    def keep(self, y: np.ndarray) -> None:
        if self._ring.shape[1] != np.size(y):
            self._ring = np.full((self._ring.shape[0], np.size(y)), np.nan)
            self._kept = 0
        self._ring[self._kept % self._ring.shape[0]] = y
        self._kept += 1
        if self.hold:
            self._since_hold += 1
        if self._since_reset is not None:
            self._since_reset += 1

    def due(self) -> bool:
        """A held tracking filter's next reset: the ring has filled again since the hold."""
        return self.hold and self._since_hold >= self._ring.shape[0] and len(self.events) <= MAX_RESETS

    def step(self, est, y: np.ndarray, predict: bool = True) -> None:
        """One filter step (``predict`` then update) with the watch around it."""
        if self.hold:
            if est.phase == "tracking" and self.due():
                self.reset(est, "retry after a failed reset")
            return
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                if predict:
                    est._predict()
                est._update(y)
            ok, why = healthy(est), "the filter's state diverged (beyond 1e4 prior stds or not finite)"
        except np.linalg.LinAlgError as exc:
            ok, why = False, str(exc)
        if not ok:
            self.fail(est, why)
        elif est.phase == "tracking":
            self._keep(est)

    def fail(self, est, why: str) -> None:
        """A failure: back to the prior before the start-up, a reset from the batch fit while tracking."""
        first = not self.events
        self.events.append({"sample": est.count - 1, "phase": est.phase, "reason": why})
        if first:
            log.warning("[ekf stream] %s at sample %d: recovered (%s)", why, est.count - 1, self._how(est))
        if est.phase in ("waiting", "provisional"):
            est.x, est.G = est._prior_state(np.array(est._buf))
            est.Sigma = np.eye(est.d)
            self.hold = True  # until the start-up's batch fit
            return
        self.reset(est, why)

    def reset(self, est, why: str) -> None:
        """The filter from the batch fit of the ring (as the start-up), or held when that fails too."""
        Y = self.ring
        self.hold, self._since_hold = True, 0
        again = self._since_reset is not None and self._since_reset < self._ring.shape[0]
        if again or len(self.events) > MAX_RESETS or Y.shape[0] < est.settings.min_samples:
            if again:
                self.events[-1]["reset"] = f"held: failed again {self._since_reset} samples after the last reset"
            self._restore(est)
            return
        self._since_reset = 0
        est.x, est.G = est._prior_state(Y)
        est.Sigma = np.eye(est.d)
        try:
            with np.errstate(over="ignore", invalid="ignore"):
                out = batch_start(est, Y, est.sigma)
        except Exception as exc:  # noqa: BLE001 - a failed reset holds the filter; the stream goes on
            self.events[-1]["reset"] = f"failed: {type(exc).__name__}: {exc}"
            self._restore(est)
            return
        if not healthy(est):
            self.events[-1]["reset"] = "failed: the batch fit's state is not finite"
            self._restore(est)
            return
        self.hold = False
        self._keep(est)
        self.events[-1]["reset"] = {"samples": int(Y.shape[0]), "chi2_per_datum": out["startup_chi2_per_datum"]}
        est.verdict.fitted(out["startup_chi2_per_datum"], Y.shape[0], "reset")
        log.info("[ekf stream] reset from the batch fit of the last %d samples (%s)", Y.shape[0], why)

    def _keep(self, est) -> None:
        """The state as the last healthy one, with the DAQ filter's states that belong to it."""
        self._good = (est.x.copy(), est.G.copy(), est.Sigma.copy(), None if est.daq is None else est.daq.snapshot())

    def _restore(self, est) -> None:
        """Back to the last healthy state (held, flagged): a diverged state has no answer to report."""
        if self._good is not None:
            est.x, est.G, est.Sigma = (a.copy() for a in self._good[:3])
            if est.daq is not None:
                est.daq.restore(self._good[3])
        elif not healthy(est):  # no healthy tracking state yet: the prior
            est.x, est.G = est._prior_state(self.ring)
            est.Sigma = np.eye(est.d)
            if est.daq is not None:  # the DAQ's filter settled on it, as at the start
                est.daq.settle(est._input())

    def released(self) -> None:
        """The start-up's batch fit replaced the held provisional filter."""
        self.hold = False

    @staticmethod
    def _how(est) -> str:
        if est.phase in ("waiting", "provisional"):
            return "the filter holds its prior until the start-up's batch fit"
        return "the filter is reset from the batch fit of its latest samples"

    def info(self) -> dict:
        if not self.events:
            return {}
        first = self.events[0]
        msg = (
            f"the filter failed numerically {len(self.events)} time(s) (first at sample {first['sample']}, "
            f"{first['phase']}: {first['reason']}) and was recovered (prior held until the start-up's batch fit, "
            "or reset from the batch fit of its latest samples); its band is the recovered filter's"
        )
        if self.hold:
            msg += "; it ended held at its last answer (flagged)"
        return {"recoveries": self.events[-20:], "recovery_count": len(self.events), "warnings": [msg]}
