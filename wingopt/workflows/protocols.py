"""The simulated identification protocols, free of the inverse crime: the studies' truth records.

:func:`simulate_case` maps a protocol's options (truth physics, mesh, prestrain and damping off the
problem file's, gust, start, duration) to one call of :func:`wingopt.membrane.simulate_truth` with
a full-order forward model on a finer mesh than the estimator's (default 49x25 vs 25x13). The seed's
protocol (spec §2, §6.4) is the default: the linear membrane from the 1 cm bubble at rest under a
constant load for 1 s at 1 ms, Gaussian noise of ``p * max_t |s_i|`` per sensor.
"""

from __future__ import annotations

from wingopt.membrane import (
    Gust,
    MembraneParameters,
    PressureLoad,
    RecordProtocol,
    TruthRecord,
    forward_model,
    simulate_truth,
)
from wingopt.problem.membrane import MembraneProblem

__all__ = ["TRUTH_NODES", "TRUTHS", "simulate_case"]

TRUTH_NODES = (49, 25)
"""Default mesh of the simulated truth (the estimator's default is the problem's 25x13)."""

TRUTHS = ("linear", "berger", "fvk")
"""Simulated truth physics: the seed's linear membrane, Berger, Föppl–von Kármán (full order)."""


def simulate_case(
    problem: MembraneProblem,
    load: str | PressureLoad,
    noise: float,
    seed: int | None = 0,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    t_end: float = 1.0,
    *,
    truth: str = "linear",
    prestrain: tuple[float, float] | None = None,
    damping: float = 1.0,
    gust: Gust | None = None,
    start: str = "bubble",
    dt: float | None = None,
    substeps: int = 2,
    tell_noise: bool = True,
) -> TruthRecord:
    """Simulate a protocol record with its truth on ``truth_nodes`` (``None``: the problem's mesh).

    Parameters
    ----------
    problem : MembraneProblem
        The estimator's problem (material, sensors, ``dt``).
    load : str or PressureLoad
        ``"L1"``, ``"L2"``, ``"L3"``, ``"consistency"``, ``"LE"`` or any pressure field.
    noise : float
        Noise std as a FRACTION of each sensor's peak output (0.01 = 1 %).
    truth : {"linear", "berger", "fvk"}
        The truth's physics (full order); ``prestrain = (ex, ey)`` and the ``damping`` factor put
        it off the problem file (the estimator still reads the file).
    gust : Gust, optional
        Load factor over time.
    start : {"bubble", "rest", "static"}
    tell_noise : bool
        The measurements carry the simulated noise std (``False``: estimators must estimate it).

    Returns
    -------
    TruthRecord
        The noisy measurements, the truth trajectory and load, and the error metrics against them.
    """
    params = MembraneParameters.nominal(problem, prestrain, damping)
    fwd = forward_model(problem, truth, nodes=truth_nodes or problem.nodes, params=params, substeps=substeps)
    protocol = RecordProtocol(
        t_end=t_end, dt=dt, start=start, noise=noise, seed=seed, load_factor=None if gust is None else gust.factor
    )
    rec = simulate_truth(fwd, load, protocol)
    return rec.told() if tell_noise else rec
