"""The MHE's IPOPT window solver on the optimisation layer: Hessian reuse gives the same optimum, cheaper."""

import numpy as np
import pytest

from wingopt.estimation.mhe import MHESettings, MovingHorizonEstimator
from wingopt.estimation.mhe.solvers import IpoptSolver, NumpySolver
from wingopt.membrane import MembraneModel
from wingopt.optim.status import SolveStatus
from wingopt.workflows.protocols import simulate_case


@pytest.fixture(scope="module")
def estimator(membrane_problem):
    small = membrane_problem.with_mesh((13, 7))
    case = simulate_case(small, "L1", 0.01, 0, (25, 13), t_end=0.3)
    s = MHESettings(window=100, stride=50, modes=20, regularization=1e-6)
    return MovingHorizonEstimator(MembraneModel.from_problem(small), s).setup(case.measurements)


def test_reuse_and_exact_hessian_reach_the_same_optimum_from_warm_and_cold_starts(estimator):
    problem = estimator._window_problem(0, estimator.lam)
    ref = NumpySolver(tolerance=1e-6).solve(problem, estimator._sol.theta)
    D = problem.scale
    warm = ref.theta * (1 + 0.02 * np.random.default_rng(1).standard_normal(ref.theta.size))
    cold = np.zeros_like(ref.theta)
    cold[2 * problem.reduced.m :] = ref.theta[2 * problem.reduced.m :] * 0.2  # a fifth of the load, no state
    for start in (warm, cold):
        sols = {
            "reuse": IpoptSolver(hessian="reuse").solve(problem, start),
            "reuse, no LM": IpoptSolver(hessian="reuse", cold_start_lm=False).solve(problem, start),
            "analytic": IpoptSolver(hessian="analytic").solve(problem, start),
        }
        # From the cold start every method (numpy LM too) lands in the same other local minimum.
        best = ref if start is warm else NumpySolver(tolerance=1e-6).solve(problem, start)
        assert (best.cost == pytest.approx(ref.cost, rel=1e-9)) == (start is warm)
        for name, sol in sols.items():
            assert sol.status in (SolveStatus.OPTIMAL, SolveStatus.OPTIMAL_INACCURATE), name
            assert sol.cost == pytest.approx(best.cost, rel=1e-7), name
            assert np.linalg.norm((sol.theta - best.theta) / D) <= 1e-3 * np.linalg.norm(best.theta / D), name
        assert sols["reuse"].iterations < sols["analytic"].iterations  # cheaper iterations, and fewer
    # From the warm start the held Hessian is enough: few IPOPT iterations, no exact-Hessian fallback.
    solver = IpoptSolver(hessian="reuse")
    sol = solver.solve(problem, warm)
    assert sol.iterations <= 10
    assert not any(key[-1] == "analytic" for key in solver._cache)
