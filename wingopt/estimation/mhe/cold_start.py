"""A window solved from scratch (a cold start): amplitude scan, coarse-to-fine solve, sign choice.

Facts this module is built on (spec §4, "What is known about this inverse problem"):

* A start from ``f = 0`` stalls: the output Jacobian ``2 x^T C_i`` carries no load information
  once the transient has decayed, and the cost is a long curved valley in which Gauss–Newton
  crawls. The start is therefore an **amplitude scan**, both signs, along the smoothest load
  shape of ``Lam``, evaluated cheaply on the window's data.
* From the best scan points a **coarse** problem (initial state in the lowest few modes, load in
  the few smoothest shapes; ~10 unknowns) is solved to convergence, and only then the **full**
  window problem, starting next to its minimum (a few Newton/LM iterations instead of hundreds).
* The data are unchanged when both the initial state and the load flip sign, so every minimum
  comes with a mirror image of exactly the same data misfit; a wrong-*relative*-sign minimum
  (state and load of opposite orientation) lies close in cost. Each candidate is oriented by the
  prior (:func:`sign_score`): the load must correlate positively with the prior load
  ``initial_load`` (uniform), and, when a prior initial deflection is known (the protocol's bubble),
  the initial deflection must correlate positively with it. Of the oriented candidates the one
  with the least cost is kept.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from wingopt.errors import SolverError
from wingopt.estimation.core.load_space import LoadSpace
from wingopt.estimation.mhe.model import MHEModel
from wingopt.estimation.mhe.solvers import WindowSolution, WindowSolver
from wingopt.estimation.mhe.window import WindowProblem
from wingopt.membrane import MembraneModel, bubble

__all__ = ["SignPrior", "initial_priors", "sign_score", "smooth_load_shapes", "start_window", "StartReport"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class SignPrior:
    """What fixes the sign: the prior load coefficients and, optionally, the prior initial deflection.

    Attributes
    ----------
    load : ndarray ``(n_f,)``
        Prior mean load (the uniform ``initial_load`` projected on the load space).
    deflection_modal : ndarray ``(m,)`` or None
        Modal coordinates of the prior initial deflection, or ``None`` when unknown.
    """

    load: np.ndarray
    deflection_modal: np.ndarray | None = None


def initial_priors(
    model: MembraneModel, load_space: LoadSpace, reduced: MHEModel, initial_load: float, initial_deflection: float
) -> tuple[SignPrior, np.ndarray]:
    """Sign prior and prior initial modal state of a record's start.

    Parameters
    ----------
    model : MembraneModel
    load_space : LoadSpace
    reduced : MHEModel
    initial_load : float
        Prior load (Pa), uniform; its sign fixes the estimate's sign.
    initial_deflection : float
        Peak (m) of the prior initial bubble; ``0``: unknown (the prior state is rest).

    Returns
    -------
    tuple
        ``(SignPrior, x_prior)``: the prior modal state holds the bubble's modal displacements.
    """
    m = reduced.m
    f_prior = load_space.project(lambda x, yy: np.full_like(x, initial_load))
    x_prior = np.zeros(2 * m)
    q_prior = None
    if initial_deflection != 0:
        problem = model.problem
        z0 = model.project(bubble(problem.width, problem.height, initial_deflection))
        q_prior = reduced.to_modal(z0)
        x_prior[:m] = q_prior
    return SignPrior(f_prior, q_prior), x_prior


def sign_score(reduced: MHEModel, theta: np.ndarray, prior: SignPrior) -> float:
    """Agreement of ``theta`` with the sign prior, in ``[-2, 2]`` (``[-1, 1]`` without deflection prior).

    Sum of the cosine between the estimated and the prior load (``L2`` inner product of the load
    space) and, when known, the cosine between the estimated and the prior initial deflection
    (mass inner product, i.e. the Euclidean one of modal coordinates). Mirror images have opposite
    scores.
    """
    m = reduced.m
    ls = reduced.load_space
    f = reduced.load(theta[2 * m : 3 * m])
    fp = prior.load
    score = float(f @ (ls.gram @ fp)) / max(ls.l2_norm(f) * ls.l2_norm(fp), 1e-300)
    if prior.deflection_modal is not None:
        q, qp = theta[:m], prior.deflection_modal
        score += float(q @ qp) / max(np.linalg.norm(q) * np.linalg.norm(qp), 1e-300)
    return score


def smooth_load_shapes(reduced: MHEModel, count: int) -> np.ndarray:
    """Modal forces ``(count, m)`` of the ``count`` smoothest load shapes (least ``Lam`` per ``L2``).

    Generalised eigenvectors of ``(Lam, Gram)`` in the load space with the smallest eigenvalues,
    mapped to modal forces and normalised to unit lift magnitude (or unit norm when the lift
    vanishes, e.g. for shapes antisymmetric in x).
    """
    ls = reduced.load_space
    scale = (np.pi / min(ls.space.width, ls.space.height)) ** 4
    Lam = (ls.regularizer + reduced.ridge * scale * ls.gram).toarray()
    _, V = sla.eigh(Lam, ls.gram.toarray(), subset_by_index=(0, count - 1))
    U = (reduced.input_matrix @ V).T
    out = []
    for u, v in zip(U, V.T):
        lift = abs(ls.lift(v))
        norm = ls.l2_norm(v) * ls.space.width * ls.space.height
        out.append(u / max(lift, 1e-3 * norm))
    return np.array(out)


class _Subspace:
    """The window problem restricted to ``theta = P z`` (same interface as :class:`WindowProblem`)."""

    bounds = None

    def __init__(self, problem: WindowProblem, P: np.ndarray) -> None:
        self.problem, self.P = problem, P
        self.scale = np.ones(P.shape[1])
        self.H0 = P.T @ problem.H0 @ P
        self.g0 = P.T @ problem.g0

    @property
    def dim(self) -> int:
        return self.P.shape[1]

    def cost(self, z):
        return self.problem.cost(self.P @ z)

    def normal_equations(self, z):
        r, J = self.problem.linearize(self.P @ z)
        J = J @ self.P
        H = J.T @ J + self.H0
        return 0.5 * (H + H.T), J.T @ r - self.H0 @ z + self.g0

    def second_order(self, z):
        return self.P.T @ self.problem.second_order(self.P @ z) @ self.P


@dataclass
class StartReport:
    """Diagnostics of the start-up: scan, candidates and the sign decision."""

    scan_best: float
    candidates: list
    chosen: int
    sign_score: float
    coarse_iterations: int
    fine_iterations: int


def _orient(reduced, theta, prior):
    s = sign_score(reduced, theta, prior)
    return (theta, s) if s >= 0 else (-theta, -s)


def start_window(
    problem: WindowProblem,
    solver: WindowSolver,
    coarse_solver: WindowSolver,
    prior: SignPrior,
    x_prior: np.ndarray,
    lift_scale: float,
    state_modes: int = 4,
    shapes: int = 3,
    amplitudes: int = 16,
    keep: int = 2,
    extra_starts: tuple = (),
) -> tuple[WindowSolution, StartReport]:
    """Solve the first window from scratch: scan, coarse solve, fine solve, orient by the prior.

    Parameters
    ----------
    problem : WindowProblem
    solver, coarse_solver : WindowSolver
        For the full problem and for the coarse subspace problem.
    prior : SignPrior
    x_prior : ndarray ``(2m,)``
        Prior mean of the initial modal state (start of the scan).
    lift_scale : float
        Typical lift magnitude (N); the scan covers ``1e-2 .. 1e1`` times it, both signs.
    state_modes, shapes : int
        Size of the coarse problem: initial state in the lowest ``state_modes`` modes, load in the
        ``shapes`` smoothest shapes.
    amplitudes : int
        Scan points per sign.
    keep : int
        Distinct coarse minima refined on the full problem.
    extra_starts : tuple of ndarray
        Further full-problem starting points (e.g. a continuation from another lambda), refined
        and compared with the scan's candidates.
    """
    red = problem.reduced
    ms = min(state_modes, red.m)
    sub, z_base = _coarse_problem(problem, x_prior, smooth_load_shapes(red, shapes) * lift_scale, ms)
    scan = _amplitude_scan(sub, z_base, 2 * ms, amplitudes)
    # Best points of each sign (the two signs are distinct starts once the state prior is non-zero).
    starts = [s for s in scan if s[1] > 0][:keep] + [s for s in scan if s[1] < 0][:keep]
    coarse, coarse_it = _coarse_minima(sub, coarse_solver, [z for _, _, z in starts], prior)
    fine = [th for _, th in coarse[:keep]] + [np.asarray(x, dtype=float) for x in extra_starts]
    (sol, score, idx), candidates, fine_it = _refined(problem, solver, fine, prior)
    sol.hessian, _ = problem.normal_equations(sol.theta)
    sol.iterations = coarse_it + fine_it
    report = StartReport(scan[0][0], candidates, idx, score, coarse_it, fine_it)
    return sol, report


def _coarse_problem(
    problem: WindowProblem, x_prior: np.ndarray, U: np.ndarray, ms: int
) -> tuple[_Subspace, np.ndarray]:
    """The coarse problem: ``q0, q0'`` of the lowest ``ms`` modes (scaled) and the load a sum of the
    smooth shapes ``U`` (modal forces, all blocks alike); and the prior state in its unknowns."""
    m, D, dim = problem.reduced.m, problem.scale, problem.dim
    shapes = U.shape[0]
    nz = 2 * ms + shapes
    P = np.zeros((dim, nz))
    for j in range(ms):
        P[j, j] = D[j]
        P[m + j, ms + j] = D[m + j]
    blocks = (dim - 2 * m) // m
    for b in range(blocks):
        P[(2 + b) * m : (3 + b) * m, 2 * ms :] = U.T
    z_base = np.zeros(nz)
    z_base[:ms] = x_prior[:ms] / D[:ms]
    z_base[ms : 2 * ms] = x_prior[m : m + ms] / D[m : m + ms]
    return _Subspace(problem, P), z_base


def _amplitude_scan(sub: _Subspace, z_base: np.ndarray, index: int, amplitudes: int) -> list[tuple]:
    """``(cost, amplitude, z)`` along the smoothest shape (unknown ``index``), both signs, cheapest first."""
    grid = np.logspace(-2, 1, amplitudes)
    scan = []
    for a in np.concatenate([-grid, grid]):
        z = z_base.copy()
        z[index] = a
        scan.append((sub.cost(z), a, z))
    scan.sort(key=lambda s: s[0])
    return scan


def _coarse_minima(
    sub: _Subspace, coarse_solver: WindowSolver, starts: list[np.ndarray], prior: SignPrior
) -> tuple[list[tuple[float, np.ndarray]], int]:
    """The distinct minima of the coarse problem from ``starts``, oriented by the prior and cheapest
    first, as full unknowns ``(cost, theta)``; and the iterations they took."""
    red, P, D = sub.problem.reduced, sub.P, sub.problem.scale
    coarse = []
    iterations = 0
    for z in starts:
        try:
            sol = coarse_solver.solve(sub, z)
        except Exception as exc:  # a failed start is just a discarded candidate
            log.debug("coarse start failed: %s", exc)
            continue
        iterations += sol.iterations
        theta, _ = _orient(red, P @ sol.theta, prior)
        coarse.append((sol.cost, theta))
    coarse.sort(key=lambda c: c[0])
    distinct = []
    for cst, th in coarse:
        if all(np.linalg.norm((th - o) / D) > 1e-3 * (1 + np.linalg.norm(o / D)) for _, o in distinct):
            distinct.append((cst, th))
    return distinct, iterations


def _refined(
    problem: WindowProblem, solver: WindowSolver, starts: list[np.ndarray], prior: SignPrior
) -> tuple[tuple[WindowSolution, float, int], list[dict], int]:
    """Solve the full problem from each start, orient each answer by the prior: ``(the cheapest
    solution, its sign score, its index)``, every candidate's summary, and the iterations taken."""
    red = problem.reduced
    m = red.m
    candidates = []
    iterations = 0
    best = None
    for th in starts:
        sol = solver.solve(problem, th)
        iterations += sol.iterations
        theta, score = _orient(red, sol.theta, prior)
        sol.theta = theta
        sol.cost = problem.cost(theta)
        candidates.append({"cost": sol.cost, "sign_score": score, "lift": float(red.lift_row @ theta[2 * m : 3 * m])})
        if best is None or sol.cost < best[0].cost:
            best = (sol, score, len(candidates) - 1)
    if best is None:
        raise SolverError(solver.name, "no start-up candidate converged", "check the data and the noise level")
    return best, candidates, iterations
