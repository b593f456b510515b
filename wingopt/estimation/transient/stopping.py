"""When a transient record's fit may stop before the solver's own test: a stall, a decided comparison.

The solver (:func:`~.solver.levenberg_marquardt`) stops when the Gauss–Newton step would lower the
chi-square by less than ``tol`` (0.01) or after ``max_iter`` iterations. Two cases spent most of a
record's work without changing its answer (issue 26, ``benchmarks/bench_records.py``):

* **a stall**: on a record the model explains poorly (a release with a load near zero, white
  noise) the chi-square falls by hundredths per iteration while the Gauss–Newton model still
  predicts a few tenths; forty iterations later the fit is where it was, and flagged as not
  converged. :func:`stalled` stops it when the last ``STALL_WINDOW`` iterations together lowered
  the chi-square by less than ``STALL_DROP`` and by less than the Newton decrement (what one
  undamped Gauss–Newton step predicts: the squared posterior-metric distance to the local model's
  minimum), and that decrement is below ``STALL_DECREMENT``: the fit is then within
  ``sqrt(decrement)`` posterior sigma of that minimum (at least ``STALL_MIN_DECREMENT``: nearer,
  the solver finishes), and the local model no longer leads it
  there. A fit converging as its model predicts (the decrement falling faster than the chi-square,
  the protocol records) is never called stalled. The fit stays *not converged*
  (its flag and warning), and the estimator widens the lift band by ``sqrt(1 + decrement)``;
* **a decided comparison**: the frame prior's fit (:mod:`.frame_check`) only has to tell whether
  its evidence can reach the interior prior's. :func:`behind` stops it once even the decrease the
  local model still predicts (the Newton decrement, and only near the minimum, where that model
  holds: a decrement of at most ``DECIDED_NATS``) leaves it more than ``DECIDED_NATS`` below (its weight in the mixture
  below ``exp(-DECIDED_NATS)``, far under :data:`.frame_check.DECISIVE`): the interior prior is
  the answer, as the finished fit would have made it (measured: L1, LE, L2 on FvK truth are
  17–21 nats apart; white noise 31).

Both rules read only iteration counts and chi-squares, so the same record stops at the same point
on any machine. They act as the solver's ``monitor`` (:class:`EarlyStop`), which the solver shows
every iterate before its step.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from wingopt.estimation.core.frame_check import EXCLUDES
from wingopt.estimation.core.record_fit import Iterate

__all__ = ["STALL_WINDOW", "STALL_DROP", "STALL_DECREMENT", "STALL_MIN_DECREMENT", "DECIDED_NATS"]
__all__ += ["EarlyStop", "stalled", "behind"]

log = logging.getLogger(__name__)

STALL_WINDOW = 5
"""Iterations over which a stall is measured."""

STALL_DROP = 0.5
"""Chi-square units the last ``STALL_WINDOW`` iterations lowered the cost by, below which the fit stalls."""

STALL_DECREMENT = 4.0
"""A stall stops the fit only within ``sqrt(STALL_DECREMENT)`` = 2 posterior sigma of the local
model's minimum (a fit far from it is left to the solver and the budget)."""

STALL_MIN_DECREMENT = 0.25
"""Below this decrement (half a posterior sigma) a slow fit is left to the solver: it is about to
converge (L1 on FvK truth crawls at 0.03 before its decrement falls below the solver's 0.01)."""

DECIDED_NATS = EXCLUDES
"""Log-evidence gap (with the cost decrease still predicted credited) beyond which the frame prior's
fit stops: the evidence excludes it (:data:`.frame_check.EXCLUDES`, a weight below ``exp(-12)`` = 6e-6)."""


class EarlyStop:
    """The solver's monitor for one fit (:func:`~.solver.levenberg_marquardt`'s ``monitor``): it
    records the chi-square of every iterate and asks each of ``rules`` in turn whether to stop.

    ``costs``: the iterates' chi-squares (the start first); ``last``: the latest
    :class:`~.solver.Iterate`; ``reason``: the rule's description once one fired (else ``None``).
    A rule may leave what it measured on the monitor (``stall_decrement``, ``reach``).
    """

    def __init__(self, rules: tuple[Rule, ...]) -> None:
        self.rules = rules
        self.costs: list[float] = []
        self.last: Iterate | None = None
        self.reason: str | None = None

    def __call__(self, iterate: Iterate) -> str | None:
        self.costs.append(iterate.cost)
        self.last = iterate
        for rule in self.rules:
            self.reason = rule(self)
            if self.reason is not None:
                log.debug("fit stopped after %d iterates: %s", len(self.costs), self.reason)
                break
        return self.reason

    def decrement(self) -> float:
        """Newton decrement at the latest iterate (the chi-square the undamped Gauss–Newton step would remove)."""
        return self.last.decrement

    def log_evidence(self) -> float:
        """Laplace log-evidence at the latest iterate (as :func:`.frame_check.log_evidence`)."""
        return self.last.log_evidence


Rule = Callable[["EarlyStop"], "str | None"]


def stalled(w: EarlyStop) -> str | None:
    """A stall (see the module docstring): its description, or ``None``."""
    c = w.costs
    if len(c) <= STALL_WINDOW or c[-1 - STALL_WINDOW] - c[-1] >= STALL_DROP:
        return None
    drop = c[-1 - STALL_WINDOW] - c[-1]
    dec = w.decrement()
    if not (drop < dec and STALL_MIN_DECREMENT <= dec < STALL_DECREMENT):
        return None  # converging as the local model says (or too far from its minimum to call it a stall)
    w.stall_decrement = dec
    return (
        f"stalled: the chi-square fell by {drop:.2f} over the last {STALL_WINDOW} iterations, less than one "
        f"Gauss-Newton step predicts ({dec:.2f})"
    )


def behind(z_other: float) -> Rule:
    """The rule that stops a fit whose evidence cannot come within :data:`DECIDED_NATS` of ``z_other``."""

    def rule(w: EarlyStop) -> str | None:
        if len(w.costs) < 2:
            return None
        dec = w.decrement()
        if not dec <= DECIDED_NATS:
            return None  # far from the local model's minimum: its predicted decrease is no bound
        reach = w.log_evidence() + 0.5 * dec
        z, k = reach - 0.5 * dec, len(w.costs) - 1
        log.debug("iterate %d: evidence %.2f + %.2f predicted, other prior's %.2f", k, z, 0.5 * dec, z_other)
        if z_other - reach <= DECIDED_NATS:
            return None
        w.reach = reach
        return f"decided: its evidence, {reach:.1f} at most, is {z_other - reach:.1f} nats below the other prior's"

    return rule
