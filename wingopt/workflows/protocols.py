"""The simulated identification protocols, free of the inverse crime: the studies' truth records.

:func:`simulate_case` maps a protocol's options (truth physics, mesh, prestrain and damping off the
problem file's, gust, start, duration) to one call of :func:`wingopt.membrane.simulate_truth` with
a full-order forward model on a finer mesh than the estimator's (default 49x25 vs 25x13). The seed's
protocol (spec §2, §6.4) is the default: the linear membrane from the 1 cm bubble at rest under a
constant load for 1 s at 1 ms, Gaussian noise of ``p * max_t |s_i|`` per sensor.
"""

from __future__ import annotations

import math

from wingopt.errors import InputError
from wingopt.membrane import (
    Gust,
    MembraneModel,
    MembraneParameters,
    PressureLoad,
    RecordProtocol,
    TruthRecord,
    forward_model,
    simulate_truth,
)
from wingopt.problem.membrane import MembraneProblem
from wingopt.validate import check_nodes, check_number

__all__ = ["TRUTH_NODES", "TRUTHS", "simulate_case", "check_truth_settings", "estimator_model"]

TRUTH_NODES = (49, 25)
"""Default mesh of the simulated truth (the estimator's default is the problem's 25x13)."""

TRUTHS = ("linear", "berger", "fvk")
"""Simulated truth physics: the seed's linear membrane, Berger, Föppl–von Kármán (full order)."""


def check_truth_settings(truth: str, prestrain, damping) -> None:
    """The simulated truth's physics, prestrains ``(ex, ey)`` (1e-9..0.5, as a problem file's) and
    damping factor (above 0, at most 1000): an :class:`~wingopt.errors.InputError` naming the option."""
    if truth not in TRUTHS:
        raise InputError(f"truth = {truth!r}: expected one of {', '.join(TRUTHS)}")
    if prestrain is not None:
        try:
            pair = [float(v) for v in prestrain]
        except (TypeError, ValueError):
            pair = []
        if len(pair) != 2 or not all(math.isfinite(v) and 1e-9 <= v <= 0.5 for v in pair):
            raise InputError(
                f"truth-prestrain = {prestrain!r}: expected two prestrains (ex, ey) from 1e-9 to 0.5 (e.g. 0.06 0.04)"
            )
    if (
        isinstance(damping, bool)
        or not isinstance(damping, (int, float))
        or not (math.isfinite(damping) and 0 < damping <= 1000)
    ):
        raise InputError(
            f"truth-damping = {damping!r}: expected a damping factor above 0 and at most 1000 (1: the file's)"
        )


def simulate_case(
    problem: MembraneProblem,
    load: str | PressureLoad,
    noise_fraction: float | None = None,
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
    noise: float | None = None,
) -> TruthRecord:
    """Simulate a protocol record with its truth on ``truth_nodes`` (``None``: the problem's mesh).

    Parameters
    ----------
    problem : MembraneProblem
        The estimator's problem (material, sensors, ``dt``).
    load : str or PressureLoad
        ``"L1"``, ``"L2"``, ``"L3"``, ``"consistency"``, ``"LE"`` or any pressure field.
    noise_fraction : float
        Noise std as a FRACTION of each sensor's peak output (0.01 = 1 %; ``identify`` and the
        command line take ``noise_percent`` / ``--noise`` in percent).
    truth : {"linear", "berger", "fvk"}
        The truth's physics (full order); ``prestrain = (ex, ey)`` and the ``damping`` factor put
        it off the problem file (the estimator still reads the file).
    gust : Gust, optional
        Load factor over time.
    start : {"bubble", "rest", "static"}
    tell_noise : bool
        The measurements carry the simulated noise std (``False``: estimators must estimate it).
    noise :
        No longer accepted (its unit was not in its name): an :class:`InputError` names ``noise_fraction``.

    Returns
    -------
    TruthRecord
        The noisy measurements, the truth trajectory and load, and the error metrics against them.
    """
    if noise is not None or noise_fraction is None:
        raise InputError(
            f"noise = {noise!r}: give noise_fraction (0.01 = 1 % of each sensor's peak output); "
            "wingopt.identify takes noise_percent (1 = 1 %)"
            if noise is not None
            else "simulate_case: give noise_fraction (0.01 = 1 % of each sensor's peak output; 0 for a clean record)"
        )
    check_truth_settings(truth, prestrain, damping)
    if truth_nodes is not None:
        truth_nodes = check_nodes(truth_nodes, "truth_nodes")
    check_number("t_end", t_end, positive=True)
    check_number("noise_fraction", noise_fraction, lo=0.0, hi=1.0)
    case = (problem, load, noise_fraction, seed, truth_nodes, t_end)
    case += (truth, prestrain, damping, gust, start, dt, substeps)  # in _simulate's order
    key = case
    try:
        hash(key)
    except TypeError:  # a load or gust that is not hashable: simulated afresh
        key = None
    if seed is None:  # fresh noise every time
        key = None
    rec = _RECENT.get(key) if key is not None else None
    if rec is None:
        rec = _simulate(*case)
        if key is not None:
            _RECENT.clear()  # one record kept: the runs of one case follow each other (demo, studies)
            _RECENT[key] = rec
    return rec.told() if tell_noise else rec


_RECENT: dict = {}
"""The last simulated record (a :class:`TruthRecord` is immutable; its noise is seeded): the demo's
three estimators on one load, or a linear and a realistic estimator on one FvK truth, share it."""


def _simulate(
    problem, load, noise_fraction, seed, truth_nodes, t_end, truth, prestrain, damping, gust, start, dt, substeps
):
    params = MembraneParameters.nominal(problem, prestrain, damping)
    fwd = forward_model(problem, truth, nodes=truth_nodes or problem.nodes, params=params, substeps=substeps)
    protocol = RecordProtocol(
        t_end=t_end,
        dt=dt,
        start=start,
        noise_fraction=noise_fraction,
        seed=seed,
        load_factor=None if gust is None else gust.factor,
    )
    return simulate_truth(fwd, load, protocol)


_MODELS: dict = {}
"""The last estimator model built by :func:`~wingopt.workflows.identify.identify` (a
:class:`MembraneModel` is immutable): runs on one problem one after the other (the demo's nine, a
comparison's estimators) share it and what it caches (its modes for the JEKF, the MHE's reduced
bases) instead of assembling it for each."""


def estimator_model(problem: MembraneProblem) -> MembraneModel:
    """The estimator's model of ``problem``: the last one built when it is the same problem (:data:`_MODELS`)."""
    try:
        cached = _MODELS.get(problem)
    except TypeError:  # a problem that is not hashable: assembled afresh
        return MembraneModel.from_problem(problem)
    if cached is None:
        _MODELS.clear()  # one model kept
        cached = _MODELS[problem] = MembraneModel.from_problem(problem)
    return cached
