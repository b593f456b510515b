"""Steady tunnel records for the tests: the static FvK state on a finer mesh than the estimator's.

A steady record's information on the load is the sensors' mean; its truth here is the full-order
FvK equilibrium on a 37x19 mesh (the estimator's is 25x13) under a tunnel pressure that acts up to
the frame, with prestrains off the problem file's, plus white sensor noise (2 % of the largest
output) and a few dropped frames.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from wingopt.measurements import Measurements
from wingopt.membrane import MembraneModel
from wingopt.membrane.full import FvKMembrane
from wingopt.membrane.loads import tunnel_load
from wingopt.membrane.parameters import MembraneParameters
from wingopt.problem import load_problem

TRUTH_NODES = (37, 19)
FRAMES, RATE = 450, 300.0


@cache
def static_truth(load: str, prestrain: tuple[float, float]) -> tuple[np.ndarray, float]:
    """Clean static sensor outputs and the true lift (N) of ``load`` at ``prestrain`` on the truth mesh."""
    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem, nodes=TRUTH_NODES)
    fvk = FvKMembrane.from_model(model).with_params(MembraneParameters(*prestrain))
    pressure = uniform_load(problem) if load == "uniform" else tunnel_load(load, problem.width, problem.height)
    sol = fvk.static(model.gram @ model.project(pressure))
    outputs = np.array([sol.z @ (C @ sol.z) for C in model.sensors.matrices])
    # The lift by quadrature of the pressure itself (the frame's strip included).
    n = 400
    xi = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(xi * problem.width, xi * problem.height, indexing="ij")
    lift = float(pressure(X, Y).mean() * problem.width * problem.height)
    return outputs, lift


def steady_record(load: str, prestrain: tuple[float, float], seed: int = 0, noise: float = 0.02) -> Measurements:
    """``FRAMES`` samples at ``RATE`` of the static state plus noise, 1 % of the rows dropped."""
    outputs, _ = static_truth(load, prestrain)
    rng = np.random.default_rng(seed)
    y = outputs[None, :] + noise * np.abs(outputs).max() * rng.standard_normal((FRAMES, outputs.size))
    y[rng.choice(FRAMES, FRAMES // 100, replace=False)] = np.nan
    return Measurements(np.arange(FRAMES) / RATE, y, load_problem("membrane").sensor_names)


def uniform_load(problem, mean: float = 180.0):
    """A uniform pressure: the simplest load that acts up to the frame, and none of the priors' shapes."""
    from wingopt.membrane.loads import PressureLoad

    return PressureLoad("uniform", lambda x, y: np.full(np.broadcast(x, y).shape, mean), f"uniform {mean:g} Pa")
