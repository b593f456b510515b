"""The MHE's IPOPT window solver: the whole nonlinear window problem through CasADi.

IPOPT options and status mapping come from :mod:`wingopt.optim`; the Hessian pieces are the
closed forms of :class:`~wingopt.estimation.mhe.window.WindowProblem`.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.mhe.lm import NumpySolver, WindowSolution, WindowSolver, _cholesky
from wingopt.estimation.mhe.window import WindowProblem
from wingopt.optim.casadi_backend import ipopt_options
from wingopt.optim.status import fail, status_from

__all__ = ["IpoptSolver", "IPOPT_HESSIANS", "REUSE_ITERATIONS", "REUSE_RESTARTS"]

log = logging.getLogger(__name__)

IPOPT_HESSIANS = ("analytic", "ad", "reuse")
"""Hessians the IPOPT window solver can hand IPOPT (see :class:`IpoptSolver`)."""

REUSE_ITERATIONS = 10
"""Most IPOPT iterations with one reused Hessian; then it is refreshed at the last iterate."""

REUSE_RESTARTS = 2
"""Refreshes of the reused Hessian before the exact Hessian at every iterate takes over."""


class _ColdStart(Exception):
    """The exact Hessian at the start is indefinite: do not hold it constant."""


class IpoptSolver(WindowSolver):
    """The full nonlinear window problem with IPOPT (CasADi, exact Hessian), built once per shape.

    Parameters (data, weights, quadratic part, bounds) are CasADi parameters, so consecutive
    windows of the same length re-use one compiled NLP and warm-start from the previous answer.
    The unknowns are preconditioned: ``xi = xi0 + P z`` with ``P = L^-T`` and ``L L^T`` the
    Gauss–Newton matrix at the start, so IPOPT sees an O(1)-conditioned problem (the arrival cost
    alone spans ten or more decades; without this IPOPT stalls at its iteration limit).

    ``hessian="analytic"`` hands IPOPT the exact Hessian of the Lagrangian assembled from
    the same closed-form pieces as the numpy backend (``2 J^T W J`` minus the residual-weighted
    sensor terms), built as a CasADi function: 6x less time than CasADi's automatic second
    derivatives (``hessian="ad"``), with identical iterates (measured on the protocol's L1 run).
    ``hessian="reuse"`` evaluates that exact Hessian once per window, at the start (in numpy, the
    numpy backend's closed forms), and, where it is positive definite (a warm start), declares it
    constant to IPOPT: every iteration then costs one objective and one gradient
    evaluation only; after :data:`REUSE_ITERATIONS` it is refreshed at the last iterate (at most
    :data:`REUSE_RESTARTS` times, then the exact Hessian at every iterate finishes). From a cold
    start (the exact Hessian indefinite: the first window, started from coarse-subspace minima)
    without bounds, ``cold_start_lm=True`` first takes the numpy backend's damped Levenberg–Marquardt
    steps to the convex region (0.03 s against 0.5 s of IPOPT's 36 regularised iterations on the
    protocol's L1 run), and IPOPT finishes from there; with bounds, or ``cold_start_lm=False``,
    IPOPT with the exact Hessian at every iterate does the whole solve. ``hessian="reuse"`` is the
    default (1 s of 1 kHz data: 0.56 s process CPU time against 1.34 s with ``"analytic"``, see
    ``benchmarks/bench_mhe.py``). The NLP and its optimum are the same; warm-started
    windows start next to their optimum, where the Hessian barely changes (measured in
    ``benchmarks/bench_mhe.py``).
    """

    name = "ipopt"

    def __init__(
        self,
        max_iterations: int = 200,
        tolerance: float = 1e-3,
        print_level: int = 0,
        hessian: str = "reuse",
        cold_start_lm: bool = True,
    ) -> None:
        super().__init__(max_iterations, tolerance)
        if hessian not in IPOPT_HESSIANS:
            raise InputError(f"ipopt hessian = {hessian!r}: expected one of {', '.join(IPOPT_HESSIANS)}")
        self.print_level = print_level
        self.hessian = hessian
        self.cold_start_lm = bool(cold_start_lm)
        self._cache: dict = {}

    def _build(self, problem: WindowProblem, hessian: str):
        """The compiled IPOPT solver of windows shaped like ``problem``, built once per shape."""
        import casadi as ca

        red, basis = problem.reduced, problem.basis
        nb = 0 if problem.bounds is None else problem.bounds.A.shape[0]
        key = (id(red), basis.length, basis.blocks, problem.dim, nb, hessian)
        if key in self._cache:
            return self._cache[key]
        nlp, hess = _window_nlp(ca, problem, nb, hessian)
        opts = {"print_time": False, "ipopt": self._ipopt_options(nb, hessian)}
        if hess is not None:
            opts["hess_lag"] = hess
        solver = ca.nlpsol("mhe_window", "ipopt", nlp, opts)
        self._cache[key] = solver
        return solver

    def _ipopt_options(self, nb: int, hessian: str) -> dict:
        """IPOPT's options for a window with ``nb`` linear bounds and the ``hessian`` kind."""
        iterations = min(self.max_iterations, REUSE_ITERATIONS) if hessian == "reuse" else self.max_iterations
        ipopt = ipopt_options(1e-8, iterations, self.print_level, acceptable_tol=1e-6)
        if not nb:
            ipopt["mu_init"] = 1e-8
        else:  # the bounds are linear in z
            ipopt.update(jac_c_constant="yes", jac_d_constant="yes")
        if hessian == "reuse":
            ipopt["hessian_constant"] = "yes"
        return ipopt

    def solve(self, problem: WindowProblem, theta0: np.ndarray) -> WindowSolution:
        t0 = time.perf_counter()
        if self.hessian != "reuse":
            theta, raw, iterations = self._solve_nlp(problem, theta0, self.hessian)
            return self._finish(problem, theta, raw, iterations, t0)
        theta, iterations, raw = theta0, 0, "cold start"
        for attempt in range(REUSE_RESTARTS):
            try:
                theta, raw, more = self._solve_nlp(problem, theta, "reuse")
            except _ColdStart:
                if attempt or not self.cold_start_lm or problem.bounds is not None:
                    break
                # Cold start without bounds: damped Gauss–Newton/Newton steps (the numpy backend's
                # Levenberg–Marquardt) into the region where the cost is convex, then IPOPT.
                lm = NumpySolver(self.max_iterations, self.tolerance).solve(problem, theta)
                theta, raw, more = self._solve_nlp(problem, lm.theta, "reuse")
                more += lm.iterations
            iterations += more
            if status_from(self.name, raw).ok:
                break
        else:
            raw = "reused Hessians did not converge"
        if not status_from(self.name, raw).ok:
            # Far from the optimum (a cold start: the exact Hessian is indefinite there) a constant
            # Hessian is no model of the cost: the exact Hessian at every iterate, from where we are.
            log.debug("ipopt: %s after %d iterations; exact Hessian at every iterate now", raw, iterations)
            theta, raw, more = self._solve_nlp(problem, theta, "analytic")
            iterations += more
        return self._finish(problem, theta, raw, iterations, t0)

    def _solve_nlp(self, problem: WindowProblem, theta0: np.ndarray, hessian: str) -> tuple[np.ndarray, str, int]:
        """One IPOPT solve from ``theta0``: ``(theta, raw status, iterations)``."""
        import scipy.linalg as sla

        solver = self._build(problem, hessian)
        D = problem.scale
        xi0 = np.asarray(theta0, dtype=float) / D
        Hs = D[:, None] * problem.H0 * D[None, :]
        Hgn, _ = problem.normal_equations(D * xi0)
        Hgn = D[:, None] * Hgn * D[None, :]
        L = _cholesky(Hgn + 1e-12 * np.trace(Hgn) / Hgn.shape[0] * np.eye(Hgn.shape[0]))
        P = np.eye(problem.dim) if L is None else sla.solve_triangular(L.T, np.eye(problem.dim), lower=False)
        Hz = P.T @ Hs @ P
        gz = P.T @ (Hs @ xi0 - D * problem.g0)
        params = [
            problem.y.ravel(order="F"),
            problem.w.ravel(order="F"),
            (0.5 * (Hz + Hz.T)).ravel(order="F"),
            gz,
            D,
            P.ravel(order="F"),
            xi0,
        ]
        args = {"x0": np.zeros(problem.dim)}
        if problem.bounds is not None:
            params.append((problem.bounds.A * D[None, :]).ravel(order="F"))
            args["lbg"] = problem.bounds.lo
            args["ubg"] = problem.bounds.hi
        if hessian == "reuse":
            # Exact Hessian of f in z at the start: 2 P^T D (H_GN + second order) D P (f is V in z).
            # Not positive definite: far from the optimum, where neither it nor the Gauss–Newton
            # matrix held constant is a model of the cost (measured: 54 iterations on the cold
            # window against 36 with the exact Hessian at every iterate).
            S = D[:, None] * problem.second_order(D * xi0) * D[None, :]
            K = 2.0 * P.T @ (Hgn + S) @ P
            K = 0.5 * (K + K.T)
            if _cholesky(K) is None:
                raise _ColdStart
            params.append((0.5 * (K + K.T)).ravel(order="F"))
        args["p"] = np.concatenate(params)
        try:
            res = solver(**args)
        except RuntimeError as exc:  # pragma: no cover - casadi raises on internal errors
            raise fail(self.name, f"casadi error: {exc}", "mhe") from None
        stats = solver.stats()
        raw = stats.get("return_status", "unknown")
        theta = D * (xi0 + P @ np.asarray(res["x"]).ravel())
        return theta, raw, int(stats.get("iter_count", 0))


def _window_nlp(ca, problem: WindowProblem, nb: int, hessian: str):
    """The window's NLP in the preconditioned unknowns ``z`` with its data as parameters, and the
    Hessian of its Lagrangian handed to IPOPT (``None``: CasADi's automatic one, ``hessian="ad"``)."""
    N, p = problem.basis.length, problem.reduced.p
    n = problem.dim
    z = ca.MX.sym("z", n)
    P_y = ca.MX.sym("y", N, p)
    P_w = ca.MX.sym("w", N, p)
    P_H = ca.MX.sym("H", n, n)
    P_g = ca.MX.sym("g", n)
    P_D = ca.MX.sym("D", n)
    P_P = ca.MX.sym("P", n, n)
    P_x0 = ca.MX.sym("xi0", n)
    xi = P_x0 + ca.mtimes(P_P, z)
    data, JWJ, second, seqs = _data_misfit(ca, problem, xi * P_D, P_y, P_w, hessian == "analytic")
    # The quadratic part, re-centred at the start and in the preconditioned unknowns
    # (H_z = P^T H_s P, g_z = P^T (H_s xi0 - g_s)), so no large constants cancel in it.
    f = data + ca.mtimes([z.T, P_H, z]) + 2 * ca.dot(P_g, z)
    params = ca.vertcat(ca.vec(P_y), ca.vec(P_w), ca.vec(P_H), P_g, P_D, ca.vec(P_P), P_x0)
    g = []
    if nb:
        P_A = ca.MX.sym("A", nb, n)
        params = ca.vertcat(params, ca.vec(P_A))
        g = ca.mtimes(P_A, xi)
    if hessian == "reuse":
        # The exact Hessian in z at the window's start, a parameter: constant during the solve.
        P_K = ca.MX.sym("K", n, n)
        params = ca.vertcat(params, ca.vec(P_K))
    nlp = {"x": z, "p": params, "f": f}
    if nb:
        nlp["g"] = g
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", nb if nb else 0)
    if hessian == "reuse":
        H_z = P_K
    elif hessian == "analytic":
        blocks = [[second[i][j] if j >= i else second[j][i].T for j in range(len(seqs))] for i in range(len(seqs))]
        H_theta = 2 * JWJ - 4 * ca.blockcat(blocks)
        DP = ca.repmat(P_D, 1, n) * P_P  # d theta / d z = diag(D) P
        H_z = ca.mtimes([DP.T, H_theta, DP]) + 2 * P_H
    else:
        return nlp, None
    hess = ca.Function(
        "hess_lag", [z, params, lam_f, lam_g], [ca.triu(lam_f * H_z)], ["x", "p", "lam_f", "lam_g"], ["hess"]
    )
    return nlp, hess


def _data_misfit(ca, problem: WindowProblem, theta, P_y, P_w, analytic: bool):
    """The window's weighted data misfit in ``theta``; with ``analytic``, the pieces of its exact
    Hessian too: ``J^T W J``, the residual-weighted sensor blocks, and the response sequences."""
    red, basis = problem.reduced, problem.basis
    N, p, m, B = basis.length, red.p, red.m, basis.blocks
    n = problem.dim
    q0, v0 = theta[:m], theta[m : 2 * m]
    Q = ca.DM(basis.a) * ca.repmat(q0.T, N, 1) + ca.DM(basis.b) * ca.repmat(v0.T, N, 1)
    for blk in range(B):
        ub = theta[(2 + blk) * m : (3 + blk) * m]
        Q = Q + ca.DM(basis.c[blk]) * ca.repmat(ub.T, N, 1)
    data = 0
    seqs = [ca.DM(basis.a), ca.DM(basis.b)] + [ca.DM(basis.c[blk]) for blk in range(B)]
    JWJ = ca.MX.zeros(n, n)
    second = [[ca.MX.zeros(m, m) for _ in seqs] for _ in seqs]
    for s in range(p):
        C = ca.DM(red.sensor_matrices[s])
        CQ = ca.mtimes(Q, C)
        h = ca.sum2(CQ * Q)
        r = P_y[:, s] - h
        data = data + ca.sumsqr(ca.sqrt(P_w[:, s]) * r)
        if analytic:
            # Analytic exact Hessian pieces (far cheaper than automatic differentiation):
            # dh/dtheta = 2 [CQ*a, CQ*b, CQ*c_b], d2h = 2 P_k^T C P_k per sample.
            J = ca.horzcat(*[2 * CQ * S for S in seqs])
            JWJ = JWJ + ca.mtimes(J.T, J * ca.repmat(P_w[:, s], 1, n))
            rho = P_w[:, s] * r
            for i, Si in enumerate(seqs):
                left = (Si * ca.repmat(rho, 1, m)).T
                for j in range(i, len(seqs)):
                    second[i][j] = second[i][j] + C * ca.mtimes(left, seqs[j])
    return data, JWJ, second, seqs
