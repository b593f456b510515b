"""Levenberg–Marquardt: the one nonlinear least-squares solver of the estimators.

A step-able solver in the manner of PyLops' solvers: :meth:`LevenbergMarquardt.setup` takes the
start, :meth:`~LevenbergMarquardt.step` takes one iteration (an accepted step, or the verdict that
none is left) and :meth:`~LevenbergMarquardt.run` iterates to the end; :func:`least_squares_fit`
does all three. What its users do differently is passed in, never written as a second loop:

* the **problem** (:class:`LeastSquaresProblem`): the local quadratic model at a point
  (``linearize``), the minimiser of the damped model (``damped_step``: a Cholesky solve, a
  least-distance QP, ...), the model's predicted decrease along a step, and a trial point's cost;
* the **stopping rule** (:class:`StoppingPolicy`): before an iteration (iteration limit, Newton
  decrement, work budget, monitor), after an accepted step, and when no damping lowers the cost;
* the **damping** (:class:`Damping`): the start and floor of Nielsen's update.

The solver owns the iteration: the damping ``mu`` and its growth ``nu`` (Nielsen's update: a gain
``rho > 0`` accepts the step and multiplies ``mu`` by ``max(floor, 1 - (2 rho - 1)^3)``; otherwise
``mu *= nu, nu *= 2``), the gain ratio ``rho = (cost - trial cost) / predicted decrease``, and
the count of iterations. Costs are chi-squares (sums of squared whitened residuals).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from wingopt.errors import InputError

__all__ = [
    "Damping",
    "LeastSquaresProblem",
    "LevenbergMarquardt",
    "SolverState",
    "Stop",
    "StoppingPolicy",
    "least_squares_fit",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Damping:
    """Nielsen's damping update.

    Attributes
    ----------
    initial : float
        ``mu`` at the start (``1e-8``: start as Gauss–Newton, next to the optimum).
    floor : float
        Smallest factor on ``mu`` after an accepted step (Nielsen: 1/3).
    singular : float or None
        Factor on ``mu`` when the damped model has no minimiser (``damped_step`` returns ``None``);
        ``None``: the rejection update (``mu *= nu, nu *= 2``) with the ``cap``.
    cap : float
        Past this ``mu`` no damped step lowers the cost: the iteration has stalled.
    """

    initial: float = 1e-3
    floor: float = 1.0 / 3.0
    singular: float | None = None
    cap: float = 1e12

    def __post_init__(self) -> None:
        if not self.initial > 0:
            raise InputError(f"Damping.initial = {self.initial!r}: expected a positive number")
        if not 0 < self.floor < 1:
            raise InputError(f"Damping.floor = {self.floor!r}: expected a number in (0, 1)")
        if self.singular is not None and not self.singular > 1:
            raise InputError(f"Damping.singular = {self.singular!r}: expected None or a number > 1")
        if not self.cap > self.initial:
            raise InputError(f"Damping.cap = {self.cap!r}: expected a number above initial = {self.initial!r}")


@dataclass(frozen=True)
class Stop:
    """Why the solver stopped: ``converged`` or not, and the ``reason`` in words."""

    converged: bool
    reason: str


class LeastSquaresProblem(Protocol):
    """What the solver needs of a problem; ``x`` are the unknowns as the problem scales them.

    ``linearize(x, trial)`` returns the local model at ``x`` (any object with a ``cost``
    attribute); ``trial`` is the accepted trial that moved the iterate to ``x`` (``None`` at the
    start), whose work (a Jacobian computed with the residuals) the model may reuse.
    ``damped_step(local, mu)`` returns the step minimising the model damped by ``mu``, or ``None``
    where it has none. ``predicted_decrease(local, step)`` is the model's decrease along ``step``
    (it may raise where the step is unusable). ``trial(x, step, first)`` evaluates ``x + step``
    (any object with a ``cost``; ``first``: no step of this iteration was rejected yet).
    """

    def linearize(self, x: np.ndarray, trial: Any | None) -> Any: ...

    def damped_step(self, local: Any, mu: float) -> np.ndarray | None: ...

    def predicted_decrease(self, local: Any, step: np.ndarray) -> float: ...

    def trial(self, x: np.ndarray, step: np.ndarray, first: bool) -> Any: ...


class StoppingPolicy:
    """When to stop; the default never stops before an iteration nor after a step, and calls an
    iteration with no decrease along any damped step not converged. Subclasses override."""

    def before_iteration(self, state: SolverState) -> Stop | None:
        """Checked before each iteration; a :class:`Stop` ends the solve, ``None`` takes the iteration."""
        return None

    def after_step(self, state: SolverState) -> Stop | None:
        """Checked after each accepted step (``state.predicted``, ``state.decrease`` are the step's)."""
        return None

    def hopeless(self, state: SolverState) -> bool:
        """After a rejected step: ``True`` gives up raising the damping (``state.predicted``)."""
        return False

    def stalled(self, state: SolverState) -> Stop:
        """The verdict when no damped step lowered the cost."""
        return Stop(False, "no decrease along any damped step")


@dataclass(eq=False)
class SolverState:
    """The solver's iterate: unknowns ``x``, damping ``mu`` and its growth ``nu``, iterations
    taken, the last step's ``predicted`` and accepted ``decrease``, and the ``stop`` once stopped.
    The local model (:attr:`local`) is built when first asked for at each new point."""

    problem: LeastSquaresProblem
    x: np.ndarray
    mu: float
    nu: float = 2.0
    iterations: int = 0
    predicted: float = float("nan")
    decrease: float = float("nan")
    stop: Stop | None = None
    _local: Any = None
    _trial: Any = None

    @property
    def local(self) -> Any:
        """The problem's local model at ``x`` (built once per point, reusing the accepted trial)."""
        if self._local is None:
            self._local = self.problem.linearize(self.x, self._trial)
            self._trial = None
        return self._local

    @property
    def cost(self) -> float:
        return self.local.cost

    def move(self, step: np.ndarray, trial: Any) -> None:
        """Accept ``x + step``, evaluated as ``trial``."""
        self.x = self.x + step
        self._local, self._trial = None, trial


class LevenbergMarquardt:
    """Levenberg–Marquardt iteration on a :class:`LeastSquaresProblem`.

    Parameters
    ----------
    problem : LeastSquaresProblem
    policy : StoppingPolicy, optional
        When to stop (default: never before the damping reaches its cap).
    damping : Damping, optional

    Examples
    --------
    >>> solver = LevenbergMarquardt(problem, policy, Damping(initial=1e-3))  # doctest: +SKIP
    >>> state = solver.setup(x0)  # doctest: +SKIP
    >>> while solver.step():  # doctest: +SKIP
    ...     print(state.iterations, state.cost)
    """

    def __init__(
        self, problem: LeastSquaresProblem, policy: StoppingPolicy | None = None, damping: Damping | None = None
    ) -> None:
        self.problem = problem
        self.policy = policy or StoppingPolicy()
        self.damping = damping or Damping()
        self.state: SolverState | None = None

    def setup(self, x0: np.ndarray) -> SolverState:
        """Start from ``x0`` (used as given: the caller copies it where it must)."""
        self.state = SolverState(self.problem, np.asarray(x0, dtype=float), self.damping.initial)
        return self.state

    def step(self) -> bool:
        """Take one iteration; ``False`` once stopped (``state.stop`` says why)."""
        st = self.state
        if st is None:
            raise InputError("LevenbergMarquardt.step before setup: call setup(x0) first")
        if st.stop is not None:
            return False
        st.stop = self.policy.before_iteration(st)
        if st.stop is not None:
            return False
        st.iterations += 1
        local, dmp = st.local, self.damping
        first = True
        while True:
            d = self.problem.damped_step(local, st.mu)
            if d is None:  # no minimiser of the damped model: damp more
                if dmp.singular is not None:
                    st.mu *= dmp.singular
                    continue
                st.mu *= st.nu
                st.nu *= 2
                if st.mu > dmp.cap:
                    break
                continue
            st.predicted = pred = self.problem.predicted_decrease(local, d)
            trial = self.problem.trial(st.x, d, first)
            gain = (local.cost - trial.cost) / pred if np.isfinite(trial.cost) and pred > 0 else -1.0
            if gain > 0:
                log.debug(
                    "LM %d: cost %.6g -> %.6g (predicted %.3g, mu %.2g)",
                    st.iterations,
                    local.cost,
                    trial.cost,
                    pred,
                    st.mu,
                )
                st.decrease = local.cost - trial.cost
                st.move(d, trial)
                st.mu *= max(dmp.floor, 1.0 - (2.0 * gain - 1.0) ** 3)
                st.nu = 2.0
                st.stop = self.policy.after_step(st)
                return st.stop is None
            first = False
            st.mu *= st.nu
            st.nu *= 2
            if st.mu > dmp.cap or self.policy.hopeless(st):
                break
        st.stop = self.policy.stalled(st)
        log.debug("LM: no decrease along any damped step after %d iterations: %s", st.iterations, st.stop.reason)
        return False

    def run(self, x0: np.ndarray | None = None) -> SolverState:
        """Iterate to the end (from ``x0`` when given, else from :meth:`setup`'s start)."""
        if x0 is not None:
            self.setup(x0)
        while self.step():
            pass
        return self.state


def least_squares_fit(
    problem: LeastSquaresProblem,
    x0: np.ndarray,
    policy: StoppingPolicy | None = None,
    damping: Damping | None = None,
) -> SolverState:
    """One-shot :class:`LevenbergMarquardt`: ``setup(x0)`` and ``run()``; the final state."""
    return LevenbergMarquardt(problem, policy, damping).run(x0)
