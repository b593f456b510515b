import pytest

from wingopt.errors import SolverError
from wingopt.optim.status import SolveStatus, require_success, status_from


@pytest.mark.parametrize(
    "backend,raw,expected",
    [
        ("clarabel", "optimal", SolveStatus.OPTIMAL),
        ("clarabel", "optimal_inaccurate", SolveStatus.OPTIMAL_INACCURATE),
        ("clarabel", "infeasible", SolveStatus.INFEASIBLE),
        ("osqp", "solved", SolveStatus.OPTIMAL),
        ("osqp", "primal infeasible", SolveStatus.INFEASIBLE),
        ("osqp", "dual infeasible", SolveStatus.UNBOUNDED),
        ("osqp", "maximum iterations reached", SolveStatus.MAX_ITERATIONS),
        ("ipopt", "Solve_Succeeded", SolveStatus.OPTIMAL),
        ("ipopt", "Solved_To_Acceptable_Level", SolveStatus.OPTIMAL_INACCURATE),
        ("ipopt", "Infeasible_Problem_Detected", SolveStatus.INFEASIBLE),
        ("ipopt", "Maximum_Iterations_Exceeded", SolveStatus.MAX_ITERATIONS),
        ("ipopt", "Invalid_Number_Detected", SolveStatus.NUMERICAL_ERROR),
        ("casadi", "something new", SolveStatus.UNKNOWN),
        ("clarabel", "unbounded", SolveStatus.UNBOUNDED),
        ("ipopt", "Error_In_Step_Computation", SolveStatus.NUMERICAL_ERROR),
    ],
)
def test_status_mapping(backend, raw, expected):
    assert status_from(backend, raw) is expected


def test_failure_names_backend_status_and_hint():
    with pytest.raises(SolverError) as exc:
        require_success("osqp", "primal infeasible")
    assert exc.value.backend == "osqp" and exc.value.status == "primal infeasible"
    assert "osqp failed with status 'primal infeasible'" in str(exc.value) and "voltage" in str(exc.value)
    assert require_success("ipopt", "Solve_Succeeded") is SolveStatus.OPTIMAL
