"""Nonlinear truth records of the identification protocol, as :class:`NonlinearCase` objects.

:func:`fvk_case`: the Föppl–von Kármán membrane (the high-fidelity truth,
:func:`wingopt.workflows.records.simulate_record`). :func:`berger_case`: a Berger membrane on a
finer mesh (default 49x25), with more modes (120) and a finer time step (8 sub-steps per sample)
than the estimator's model. Both: prestrains and damping off the problem file's, the protocol's
1 cm bubble start, optional 1-cos gust, Gaussian noise of ``p * max |s_i|`` (spec §2). The Berger
truth is a *richer* model than the Berger estimator's (mesh, modes, integration), not an
independent one: the Berger physics is shared. Numbers measured on it say so."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.data import Measurements
from wingopt.estimation.realistic.berger_modal import BergerModal
from wingopt.membrane import MembraneModel, PressureLoad, Trajectory, add_noise, bubble
from wingopt.problem.membrane import MembraneProblem
from wingopt.workflows.protocols import SimulatedCase
from wingopt.workflows.records import Gust, leading_edge_load, simulate_record, truth_load

__all__ = ["Gust", "ISSUE_GUST", "NonlinearCase", "leading_edge_load", "truth_load", "berger_case", "fvk_case"]


@dataclass(frozen=True, eq=False)
class NonlinearCase(SimulatedCase):
    """A :class:`SimulatedCase` with the true lift history and the truth's model parameters."""

    lift_history: np.ndarray | None = None
    parameters: dict | None = None


ISSUE_GUST = Gust(start=0.4, duration=0.2, amplitude=0.3)
"""The gust of the mismatch study: 1-cos, +60 % over 0.2 s, starting at 0.4 s (after the bubble's transient)."""


def berger_case(
    problem: MembraneProblem,
    load: str,
    noise: float,
    seed: int = 0,
    prestrain: tuple[float, float] | None = None,
    damping: float = 1.0,
    gust: Gust | None = None,
    nodes: tuple[int, int] = (49, 25),
    modes: int = 120,
    substeps: int = 8,
    nonlinear: bool = True,
    t_end: float = 1.0,
) -> NonlinearCase:
    """Simulate a Berger (``nonlinear``) or linear truth record of the identification protocol.

    ``prestrain = (ex, ey)`` (default: the file's, isotropic) and the ``damping`` factor are the
    truth's; the estimator still reads the problem file.
    """
    if not (np.isfinite(noise) and 0 <= noise <= 1):
        raise InputError(f"noise = {noise!r}: expected a fraction in [0, 1]")
    e0 = problem.material.prestrain
    ex, ey = (e0, e0) if prestrain is None else (float(prestrain[0]), float(prestrain[1]))
    truth_model = MembraneModel.from_problem(problem, nodes)
    bm = BergerModal.build(truth_model, modes, substeps=substeps)
    dt = problem.identification.dt
    steps = int(round(t_end / dt))
    t = np.arange(steps + 1) * dt
    pl = truth_load(load, problem.width, problem.height)
    f = truth_model.project(pl)
    factor = np.ones(steps + 1) if gust is None else gust.factor(t)
    forces = factor[:-1, None] * (bm.input_matrix @ f)[None]
    z0 = truth_model.project(bubble(problem.width, problem.height))
    Q = bm.simulate(bm.to_modal(z0), np.zeros(bm.m), forces, ex, ey, damping, nonlinear=nonlinear)
    Z = bm.deflection(Q)
    clean = truth_model.sensors.outputs(Z)
    noisy, _ = add_noise(clean, noise, seed)
    kind = "Berger" if nonlinear else "linear"
    return _case(
        problem, kind, load, pl, f, truth_model, t, Z, factor, clean, noisy, noise, seed, nodes, (ex, ey), damping
    )


def fvk_case(
    problem: MembraneProblem,
    load: str,
    noise: float,
    seed: int = 0,
    prestrain: tuple[float, float] | None = None,
    damping: float = 1.0,
    gust: Gust | None = None,
    nodes: tuple[int, int] = (49, 25),
    substeps: int = 2,
    t_end: float = 1.0,
) -> NonlinearCase:
    """Simulate a Föppl–von Kármán truth record of the identification protocol.

    The same protocol and meaning of the arguments as :func:`berger_case` (``damping`` scales both
    damping terms); the truth is the full FvK membrane (in-plane displacements solved, nonlinear
    strains) on ``nodes``, integrated with ``substeps`` steps per sample.
    """
    rec = simulate_record(
        problem,
        load,
        t_end=t_end,
        nodes=tuple(nodes),
        prestrain=prestrain,
        damping_scale=damping,
        gust=gust,
        noise=noise,
        seed=seed,
        truth="fvk",
        substeps=substeps,
    )
    ex, ey = rec.params.eps0_x, rec.params.eps0_y
    f = rec.model.project(rec.load)
    return _case(
        problem, "FvK", load, rec.load, f, rec.model, rec.t, rec.z, rec.load_factor, rec.outputs, rec.values,
        noise, seed, nodes, (ex, ey), damping,
    )  # fmt: skip


def _case(problem, kind, load, pl, f, model, t, Z, factor, clean, noisy, noise, seed, nodes, prestrain, damping):
    """The :class:`NonlinearCase` of a simulated record: trajectory, measurements, scaled load, lift history."""
    ex, ey = prestrain
    traj = Trajectory(t, Z, np.gradient(Z, problem.identification.dt, axis=0), factor[:-1, None] * f[None], clean)
    nx, ny = nodes
    meas = Measurements(
        t=t,
        values=noisy,
        sensor_names=problem.sensor_names,
        noise_std=None,
        source=f"{kind} truth {load} {100 * noise:g}% seed {seed} {nx}x{ny} e0=({ex:g},{ey:g}) d={damping:g}",
    )
    final = float(factor[-1])
    scaled = PressureLoad(pl.name, lambda x, y: final * pl(x, y), pl.description, pl.breaks_x, pl.breaks_y)
    params = {"prestrain_x": ex, "prestrain_y": ey, "damping": damping}
    case = NonlinearCase(scaled, model, traj, meas, noise, seed, None, params)
    return dataclasses.replace(case, lift_history=factor * case.true_lift / final)
