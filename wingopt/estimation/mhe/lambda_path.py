"""The lambda path of the moving-horizon estimator's first window.

Lambda (the weight of the load's roughness) is chosen on the first window from the data only: a
path of solves over a grid relative to the problem's natural scale (:func:`natural_scale`),
continued outwards from a probe and refined once inside the chosen bracket; the rule
(:func:`~wingopt.estimation.core.regularization.choose_lambda`) picks a point of it. Used by
:class:`~wingopt.estimation.mhe.startup.StartUp`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import scipy.linalg as sla

from wingopt.estimation.core.regularization import LambdaPoint, choose_lambda
from wingopt.estimation.mhe.solvers import WindowSolution, WindowSolver
from wingopt.estimation.mhe.window import WindowProblem

__all__ = ["natural_scale", "path_point", "lambda_path"]


def natural_scale(problem: WindowProblem, theta: np.ndarray, v: np.ndarray) -> float:
    """Scale of lambda at which roughness and data information balance along the load shape ``v``.

    Parameters
    ----------
    problem : WindowProblem
        The window (its data Jacobian is used; its lambda does not matter).
    theta : ndarray
        Unknowns at which the data are linearised.
    v : ndarray
        Modal forces of a load shape (the smoothest one).

    Returns
    -------
    float
        ``lambda_nat = (v^T H_data v) / (v^T S^-1 v)``, ``H_data`` the data's Gauss–Newton matrix.
    """
    m = problem.reduced.m
    _, J = problem.linearize(theta)
    Ju = J[:, 2 * m : 3 * m] @ v
    return float(Ju @ Ju) / float(v @ problem.reduced.roughness @ v)


def path_point(problem: WindowProblem, sol: WindowSolution, lam: float) -> LambdaPoint:
    """One point of the lambda path: data misfit, degrees of freedom and evidence at ``lam``."""
    _, J = problem.linearize(sol.theta)
    D = problem.scale
    Hs = D[:, None] * sol.hessian * D[None, :]
    Js = J * D[None, :]
    c = sla.cho_factor(Hs)
    dof = float(np.trace(sla.cho_solve(c, Js.T @ Js)))
    try:
        evidence = problem.log_evidence(sol.theta)
    except np.linalg.LinAlgError:  # a singular prior (free space without edge term): no evidence
        evidence = None
    return LambdaPoint(float(lam), problem.data_cost(sol.theta), dof, problem.n_data, evidence)


def lambda_path(
    problem_at: Callable[[float], WindowProblem],
    solver: WindowSolver,
    theta0: np.ndarray,
    lam_nat: float,
    lam_probe: float,
    grid: list[float],
    rule: str,
) -> tuple[float, dict, dict[float, np.ndarray]]:
    """Lambda path on a window (continuation from a start-up) and the data-only rule.

    Parameters
    ----------
    problem_at : callable
        ``lambda -> WindowProblem``: the window at that weight.
    solver : WindowSolver
    theta0 : ndarray
        The start-up's answer at ``lam_probe`` (where the continuation starts).
    lam_nat : float
        The natural scale (:func:`natural_scale`) the relative ``grid`` is built on.
    lam_probe : float
        The start-up's weight.
    grid : list of float
        Sorted relative lambdas.
    rule : str
        The rule of :func:`~wingopt.estimation.core.regularization.choose_lambda`.

    Returns
    -------
    tuple
        ``(lambda, info, solutions)``: the chosen lambda, the rule's info with ``natural_scale``
        and the ``path`` added, and the unknowns solved at every lambda of the path.
    """
    path: list[LambdaPoint] = []
    sols: dict[float, np.ndarray] = {}
    lams = [lam_nat * g for g in grid]

    def solve_at(lam, theta):
        problem = problem_at(lam)
        sol = solver.solve(problem, theta)
        sols[lam] = sol.theta
        path.append(path_point(problem, sol, lam))
        return sol

    # Continuation outwards from the probe, each solve warm-started from its neighbour.
    i0 = int(np.argmin([abs(np.log(lam / lam_probe)) for lam in lams]))
    theta = theta0
    for i in range(i0, len(lams)):
        theta = solve_at(lams[i], theta).theta
    theta = sols[lams[i0]]
    for i in range(i0 - 1, -1, -1):
        theta = solve_at(lams[i], theta).theta
    # Refine once inside the bracket of the chosen lambda (the grid is coarse, the knee sharp).
    lam, info = choose_lambda(path, rule)
    known = sorted(sols)
    lo = max((x for x in known if x <= lam), default=known[0])
    hi = min((x for x in known if x >= lam), default=known[-1])
    if hi > lo * 1.5:
        mid_lam = float(np.sqrt(lo * hi))
        solve_at(mid_lam, sols[lo])
        lam, info = choose_lambda(path, rule)
    info["natural_scale"] = lam_nat
    info["path"] = [dataclasses.asdict(p) for p in sorted(path, key=lambda p: p.lam)]
    return lam, info, sols
