"""The simulated identification protocol (spec §2, seed §6.4), free of the inverse crime.

The truth is simulated on a finer mesh than the estimator's (default 49x25 vs 25x13), from the
1 cm bubble at rest under a constant load for 1 s at 1 ms; Gaussian noise of standard deviation
``p * max_t |s_i(t)|`` is added per sensor. Errors are relative L2 norms over the membrane of
the analytic load and of the fine-mesh deflection, not coefficient norms.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wingopt.estimation.data import Measurements
from wingopt.fe import integrate
from wingopt.membrane import MembraneModel, PressureLoad, Trajectory, add_noise, bubble, load_case, simulate_response
from wingopt.problem.membrane import MembraneProblem

__all__ = ["TRUTH_NODES", "SimulatedCase", "simulate_case", "relative_l2"]

TRUTH_NODES = (49, 25)
"""Default mesh of the simulated truth (the estimator's default is the problem's 25x13)."""


def relative_l2(space, truth, estimate) -> float:
    """``||truth - estimate||_L2 / ||truth||_L2`` over the membrane, both callables ``(x, y)``."""
    num = integrate(space, lambda x, y: (truth(x, y) - estimate(x, y)) ** 2, order=8)
    den = integrate(space, lambda x, y: truth(x, y) ** 2, order=8)
    return float(np.sqrt(num / den))


@dataclass(frozen=True, eq=False)
class SimulatedCase:
    """A simulated record with its truth: the load, the fine-mesh model and trajectory."""

    load: PressureLoad
    truth_model: MembraneModel
    trajectory: Trajectory
    measurements: Measurements
    noise_fraction: float
    seed: int | None

    def true_deflection(self, k: int = -1):
        """Callable ``(x, y)``: the truth's deflection at sample ``k`` (fine mesh)."""
        return self.truth_model.field(self.trajectory.z[k])

    @property
    def true_lift(self) -> float:
        return integrate(self.truth_model.space, self.load, order=8)

    @property
    def true_absolute_load(self) -> float:
        """``∫ |P|`` (L2 has zero net lift, so lift errors are scaled by this)."""
        return integrate(self.truth_model.space, lambda x, y: np.abs(self.load(x, y)), order=8)

    def load_error(self, load_field) -> float:
        """Relative L2 error of an estimated pressure field (callable ``(x, y)``)."""
        return relative_l2(self.truth_model.space, self.load, load_field)

    def deflection_error(self, deflection_field, k: int = -1) -> float:
        """Relative L2 error of an estimated deflection field at sample ``k``."""
        return relative_l2(self.truth_model.space, self.true_deflection(k), deflection_field)


def simulate_case(
    problem: MembraneProblem,
    load: str | PressureLoad,
    noise: float,
    seed: int | None = 0,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    t_end: float = 1.0,
) -> SimulatedCase:
    """Simulate the identification protocol (spec §2) with its truth on a finer mesh.

    Parameters
    ----------
    problem : MembraneProblem
        The estimator's problem (material, sensors, ``dt``).
    load : str or PressureLoad
        ``"L1"``, ``"L2"``, ``"L3"``, ``"consistency"`` or any pressure field.
    noise : float
        Noise std as a fraction of each sensor's peak output (0.01 = 1 %).
    seed : int or None
        Noise seed.
    truth_nodes : (int, int) or None
        Mesh of the truth (``None``: the problem's own mesh, the seed's same-mesh protocol).
    t_end : float
        Duration (s) from the 1 cm bubble at rest.

    Returns
    -------
    SimulatedCase
        The truth trajectory, the noisy measurements and the error metrics against the truth.
    """
    if isinstance(load, str):
        load = load_case(load, problem.width, problem.height)
    truth_model = MembraneModel.from_problem(problem, truth_nodes)
    traj = simulate_response(
        truth_model, load, t_end=t_end, dt=problem.identification.dt, z0=bubble(problem.width, problem.height)
    )
    noisy, sigma = add_noise(traj.outputs, noise, seed)
    meas = Measurements(
        t=traj.t,
        values=noisy,
        sensor_names=problem.sensor_names,
        noise_std=sigma,
        source="simulated {} {:g}% seed {} truth {}x{}".format(
            load.name, 100 * noise, seed, *truth_model.problem.nodes
        ),
    )
    return SimulatedCase(load, truth_model, traj, meas, noise, seed)
