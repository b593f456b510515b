import pytest

from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem


@pytest.fixture(scope="session")
def membrane_problem():
    return load_problem("membrane")


@pytest.fixture(scope="session")
def membrane_models(membrane_problem):
    """The three seed meshes, built once per session."""
    return {nodes: MembraneModel.from_problem(membrane_problem, nodes) for nodes in [(13, 7), (25, 13), (49, 25)]}
