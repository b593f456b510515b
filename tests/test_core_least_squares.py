"""The one nonlinear least-squares solver (``wingopt.estimation.core.least_squares``): a step-able
Levenberg–Marquardt whose problem, damping and stopping rule are passed in. The MHE windows and the
record fits run it through their adapters (their answers: test_estimation_mhe.py,
test_transient_*.py)."""

from dataclasses import dataclass

import numpy as np
import pytest

from wingopt.errors import InputError
from wingopt.estimation.core import (
    Damping,
    LevenbergMarquardt,
    Stop,
    StoppingPolicy,
    least_squares_fit,
)

T = np.linspace(0.0, 1.0, 21)
TRUE = np.array([2.0, -1.5])


@dataclass(frozen=True)
class _Local:
    cost: float
    r: np.ndarray
    J: np.ndarray


@dataclass(frozen=True)
class _Trial:
    cost: float


class _ExpFit:
    """Residuals ``a exp(b t) - y`` of noise-free data from ``TRUE``: the minimum is ``TRUE``, cost 0."""

    def __init__(self, singular_below: float = 0.0) -> None:
        self.y = TRUE[0] * np.exp(TRUE[1] * T)
        self.singular_below = singular_below
        self.linearizations = 0
        self.steps = 0

    def residuals(self, x):
        return x[0] * np.exp(x[1] * T) - self.y

    def linearize(self, x, trial):
        self.linearizations += 1
        r = self.residuals(x)
        e = np.exp(x[1] * T)
        return _Local(float(r @ r), r, np.column_stack([e, x[0] * T * e]))

    def damped_step(self, local, mu):
        self.steps += 1
        if mu < self.singular_below:
            return None
        H = local.J.T @ local.J
        return -np.linalg.solve(H + mu * np.diag(np.diag(H)), local.J.T @ local.r)

    def predicted_decrease(self, local, step):
        g, H = local.J.T @ local.r, local.J.T @ local.J
        return float(-(2 * g @ step + step @ H @ step))

    def trial(self, x, step, first):
        r = self.residuals(x + step)
        return _Trial(float(r @ r))


class _Tolerance(StoppingPolicy):
    def __init__(self, tol=1e-24, max_iterations=100):
        self.tol, self.max_iterations = tol, max_iterations

    def before_iteration(self, state):
        if state.iterations >= self.max_iterations:
            return Stop(False, "maximum iterations reached")
        return Stop(True, "converged") if state.cost < self.tol else None


def test_converges_to_the_exact_minimum():
    st = least_squares_fit(_ExpFit(), np.array([1.0, 0.0]), _Tolerance(), Damping(initial=1e-3))
    assert st.stop == Stop(True, "converged")
    assert np.allclose(st.x, TRUE, rtol=1e-10, atol=0)
    assert st.cost < 1e-24 and 3 <= st.iterations < 100


def test_stepping_is_running():
    """``setup`` + ``step`` until it returns False is ``run``: the same iterate, bit for bit."""
    one = least_squares_fit(_ExpFit(), np.array([1.0, 0.0]), _Tolerance(), Damping(initial=1e-3))
    solver = LevenbergMarquardt(_ExpFit(), _Tolerance(), Damping(initial=1e-3))
    st = solver.setup(np.array([1.0, 0.0]))
    costs = [st.cost]
    while solver.step():
        costs.append(st.cost)
    assert np.array_equal(st.x, one.x) and st.iterations == one.iterations == len(costs) - 1
    assert all(b < a for a, b in zip(costs, costs[1:], strict=False))  # every accepted step lowers the cost
    assert not solver.step() and st.iterations == one.iterations  # a stopped solver stays stopped


def test_the_policy_limits_the_iterations_and_the_model_is_built_when_asked_once_per_point():
    problem = _ExpFit()
    st = least_squares_fit(problem, np.array([1.0, 0.0]), _Tolerance(max_iterations=2), Damping(initial=1e-3))
    assert st.stop == Stop(False, "maximum iterations reached") and st.iterations == 2
    # the start and the first accepted point: the limit stops before the second point's model is needed
    assert problem.linearizations == 2
    cost = st.cost
    assert problem.linearizations == 3 and st.cost == cost and problem.linearizations == 3


def test_a_singular_damped_model_raises_the_damping_by_its_factor():
    """``singular = 10``: from ``mu = 1e-3`` the first step exists at ``mu = 1`` (three raises)."""
    problem = _ExpFit(singular_below=0.5)
    solver = LevenbergMarquardt(problem, _Tolerance(max_iterations=1), Damping(1e-3, singular=10.0))
    st = solver.setup(np.array([1.0, 0.0]))
    assert solver.step() and problem.steps == 4  # three refusals, then the accepted step
    # then Nielsen's factor on an accepted step, within [floor, 1]
    assert 1.0 / 3.0 - 1e-15 <= st.mu / (1e-3 * 10.0 * 10.0 * 10.0) <= 1.0


def test_no_decrease_is_stalled_past_the_cap():
    """A problem whose damped step never exists: the damping grows past its cap and the solve stalls."""
    st = least_squares_fit(_ExpFit(singular_below=np.inf), np.array([1.0, 0.0]), _Tolerance(), Damping(1e-3, cap=1e3))
    assert st.stop == StoppingPolicy().stalled(st) and not st.stop.converged
    assert st.iterations == 1 and st.mu > 1e3 and np.array_equal(st.x, [1.0, 0.0])


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"initial": 0.0}, "initial = 0.0"),
        ({"floor": 1.0}, "floor = 1.0"),
        ({"singular": 1.0}, "singular = 1.0"),
        ({"cap": 1e-9}, "cap = 1e-09"),
    ],
)
def test_damping_is_checked(kwargs, field):
    with pytest.raises(InputError, match=field):
        Damping(**kwargs)


def test_step_before_setup_is_refused():
    with pytest.raises(InputError, match="setup"):
        LevenbergMarquardt(_ExpFit()).step()
