import pytest

from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem
from wingopt.workflows.protocols import simulate_case


@pytest.fixture(scope="session")
def membrane_problem():
    return load_problem("membrane")


@pytest.fixture(scope="session")
def membrane_models(membrane_problem):
    """The three seed meshes, built once per session."""
    return {nodes: MembraneModel.from_problem(membrane_problem, nodes) for nodes in [(13, 7), (25, 13), (49, 25)]}


@pytest.fixture(scope="module")
def fvk_short_record():
    """0.3 s of L1 on FvK truth (17x9), 1 % noise, and the 13x7 model (the transient route's budget and stops)."""
    problem = load_problem("membrane").with_mesh((13, 7))
    case = simulate_case(problem, "L1", 0.01, 0, (17, 9), 0.3, truth="fvk")
    return MembraneModel.from_problem(problem), case.measurements
