"""When a transient record's fit may stop before the solver's own test: a stall, a decided comparison,
an arrived lift.

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

* **an arrived lift** (the fuzz's records, ``benchmarks/fuzz_records.py``: a fit whose lift had
  arrived was capped at ``max_iter`` and called not converged): near its minimum a fit may crawl in
  the directions the lift does not depend on (the initial state, a prestrain's split) for tens of
  iterations (#112 of the fuzz: 52 iterations, the lift within 0.03 of its sigma after 5).
  :func:`arrived` calls the fit converged once every unknown is within half a posterior sigma of
  the local model's minimum (a decrement below ``ARRIVED_DECREMENT``: there the local model holds)
  and the undamped Gauss–Newton step would move the lift, the answer, by less than
  ``ARRIVED_LIFT`` of its posterior sigma: the 0.1 sigma the solver's own test (a decrement below
  0.01) asks of every direction, asked of the lift. The parameters are then within half a sigma of
  theirs, the chi-square within ``ARRIVED_DECREMENT`` (the evidence within 0.125 nats).

The rules read only iteration counts, chi-squares and the local model, so the same record stops at
the same point on any machine. They act as the solver's ``monitor`` (:class:`EarlyStop`), which the solver shows
every iterate before its step.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from wingopt.estimation.core.frame_check import EXCLUDES
from wingopt.estimation.core.least_squares import Stop
from wingopt.estimation.core.record_fit import Iterate
from wingopt.estimation.core.record_problem import RecordProblem
from wingopt.estimation.transient.lift_sensitivity import lift_jacobian

__all__ = ["STALL_WINDOW", "STALL_DROP", "STALL_DECREMENT", "STALL_MIN_DECREMENT", "DECIDED_NATS"]
__all__ += ["ARRIVED_DECREMENT", "ARRIVED_LIFT", "EarlyStop", "stalled", "behind", "arrived"]

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


ARRIVED_DECREMENT = STALL_MIN_DECREMENT
"""The decrement below which a fit may be called converged by its lift (:func:`arrived`): every
unknown within half a posterior sigma of the local model's minimum."""

ARRIVED_LIFT = 0.1
"""The lift's move under the undamped Gauss–Newton step, in its posterior sigma, below which
:func:`arrived` calls the fit converged (the solver's own test, ``sqrt(0.01)``, asked of the lift)."""


class EarlyStop:
    """The solver's monitor for one fit (:func:`~.solver.levenberg_marquardt`'s ``monitor``): it
    records the chi-square of every iterate and asks each of ``rules`` in turn whether to stop.

    ``costs``: the iterates' chi-squares (the start first); ``last``: the latest
    :class:`~.solver.Iterate`; ``reason``: the rule's description once one fired (else ``None``).
    A rule returns a reason in words (the fit stops, not converged) or a converged
    :class:`~wingopt.estimation.core.least_squares.Stop` (:func:`arrived`), and may leave what it
    measured on the monitor (``stall_decrement``, ``reach``, ``lift_move``).
    """

    def __init__(self, rules: tuple[Rule, ...]) -> None:
        self.rules = rules
        self.costs: list[float] = []
        self.last: Iterate | None = None
        self.reason: str | None = None

    def __call__(self, iterate: Iterate) -> str | Stop | None:
        self.costs.append(iterate.cost)
        self.last = iterate
        for rule in self.rules:
            verdict = rule(self)
            if verdict is not None:
                self.reason = verdict.reason if isinstance(verdict, Stop) else verdict
                log.debug("fit stopped after %d iterates: %s", len(self.costs), self.reason)
                return verdict
        return None

    def decrement(self) -> float:
        """Newton decrement at the latest iterate (the chi-square the undamped Gauss–Newton step would remove)."""
        return self.last.decrement

    def log_evidence(self) -> float:
        """Laplace log-evidence at the latest iterate (as :func:`.frame_check.log_evidence`)."""
        return self.last.log_evidence


Rule = Callable[["EarlyStop"], "str | Stop | None"]


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


def arrived(rp: RecordProblem) -> Rule:
    """The rule that calls a fit of ``rp`` converged once its lift has arrived (the module docstring)."""

    def rule(w: EarlyStop) -> Stop | None:
        it = w.last
        if not it.decrement < ARRIVED_DECREMENT or it.gradient is None:
            return None
        c, amp = rp.load_history(it.theta)
        lift_row = lift_jacobian(rp, c, amp)[-1]
        try:  # one solve: the Gauss-Newton step and the lift's posterior direction
            step, direction = np.linalg.solve(it.precision, np.column_stack([-it.gradient, lift_row])).T
        except np.linalg.LinAlgError:
            return None
        variance = float(lift_row @ direction)
        if not variance > 0:
            return None  # a record whose lift the unknowns do not move: the solver's own test decides
        move = abs(float(lift_row @ step)) / np.sqrt(variance)
        if not move < ARRIVED_LIFT:
            return None
        w.lift_move = move
        return Stop(
            True,
            f"converged: one more Gauss-Newton step would move the lift by {move:.2f} of its sigma "
            f"(decrement {it.decrement:.2f})",
        )

    return rule
