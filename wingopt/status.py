"""One status vocabulary for every result: :class:`RunStatus`.

Each result (an identification, a morphing run, a calibration) says in one word whether its
numbers can be used, derived from what it already records (solver statuses, a converged flag, the
model's adequacy, finite numbers). The solver-level vocabulary of :mod:`wingopt.optim.status`
(``optimal``, ``infeasible``, ...) names what one solve returned; this one names what a whole run
delivered, so a notebook can filter results with ``result.status is RunStatus.CONVERGED`` and
``summary.json`` carries the same word as ``"status"``.
"""

from __future__ import annotations

import enum
import math

__all__ = ["RunStatus", "worst", "from_solver_statuses", "from_info"]


class RunStatus(enum.StrEnum):
    """What a run delivered, from best to worst.

    ``converged``: the solvers converged and the model explains the data (where that is checked).
    ``misfit``: converged, but the model does not explain the data (the estimate and its band are
    not trustworthy, see the warnings). ``not_converged``: an answer came back, but a solver stopped
    at its iteration cap or reported an inaccurate solution, or a simulated run had not settled by
    its end. ``failed``: no usable number (NaN).
    """

    CONVERGED = "converged"
    MISFIT = "misfit"
    NOT_CONVERGED = "not_converged"
    FAILED = "failed"

    @property
    def ok(self) -> bool:
        """Whether the numbers can be used as they are."""
        return self is RunStatus.CONVERGED


_ORDER = list(RunStatus)


def worst(*statuses: RunStatus) -> RunStatus:
    """The worst of ``statuses`` (``converged`` when none is given)."""
    return max(statuses, key=_ORDER.index, default=RunStatus.CONVERGED)


def from_solver_statuses(raw) -> RunStatus:
    """The run status of a list of :class:`~wingopt.optim.status.SolveStatus` values (or their names).

    Any solve that was not ``optimal`` makes the run ``not_converged``: a failed solve raises a
    :class:`~wingopt.errors.SolverError` before a result exists, so the ones left are answers
    that came back inaccurate or at the iteration cap.
    """
    names = {str(getattr(s, "value", s)) for s in (raw or ())}
    return RunStatus.CONVERGED if names <= {"optimal"} else RunStatus.NOT_CONVERGED


def from_info(info: dict, *numbers: float) -> RunStatus:
    """The status of a result from its ``info`` diagnostics and its headline ``numbers``.

    Parameters
    ----------
    info : dict
        A result's diagnostics: ``statuses`` (solver statuses), ``converged`` (bool) and
        ``model_adequate`` (bool) count where present.
    *numbers : float
        The result's headline numbers (a lift, the parameters): one NaN, inf or ``None`` fails it.

    Returns
    -------
    RunStatus
        ``failed`` when a number is not finite; else the worst of what ``info`` records.
    """
    if any(n is None or not math.isfinite(float(n)) for n in numbers):
        return RunStatus.FAILED
    out = [from_solver_statuses(info.get("statuses"))]
    if info.get("converged") is False:
        out.append(RunStatus.NOT_CONVERGED)
    if info.get("model_adequate") is False:
        out.append(RunStatus.MISFIT)
    return worst(*out)
