"""The horizon-``N`` QP of a :class:`~wingopt.control.mpc_problem.TrackingProblem`: sparse or condensed.

Written once with the states as variables (``"sparse"``, banded KKT) and condensed by eliminating
the states (``"condensed"``, dense ``N m`` Hessian); the parameter ``p = (x_0, w_prev)`` enters the
linear term and the bounds only (:class:`~wingopt.optim.qp.ParametricQP`), so a backend is built
once and re-solved each period, warm-started from the shifted previous plan (:func:`shift_plan`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from wingopt.control.mpc_problem import TrackingProblem
from wingopt.errors import InputError
from wingopt.optim.qp import ParametricQP

__all__ = ["assemble_qp", "condense", "shift_plan"]


class _Quadratic:
    """Accumulates ``z' A z + g' z + c`` over index subsets of a joint vector (COO triplets)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.vals: list[np.ndarray] = []
        self.g = np.zeros(n)
        self.c = 0.0

    def add(self, idx: np.ndarray, W: np.ndarray, offset: np.ndarray | None = None) -> None:
        """``(z[idx] - offset)' W (z[idx] - offset)``."""
        idx = np.asarray(idx)
        W = np.asarray(W, dtype=float)
        r, c = np.meshgrid(idx, idx, indexing="ij")
        self.rows.append(r.ravel())
        self.cols.append(c.ravel())
        self.vals.append(W.ravel())
        if offset is not None:
            Wa = W @ offset
            self.g[idx] -= Wa + W.T @ offset
            self.c += float(offset @ Wa)

    def linear(self, idx: np.ndarray, g: np.ndarray, c: float = 0.0) -> None:
        self.g[np.asarray(idx)] += g
        self.c += c

    def hessian(self) -> sp.csc_matrix:
        """``H`` of ``1/2 z' H z`` (symmetrised)."""
        A = sp.coo_matrix(
            (np.concatenate(self.vals), (np.concatenate(self.rows), np.concatenate(self.cols))), shape=(self.n, self.n)
        ).tocsc()
        return (A + A.T).tocsc()


def _difference_rows(N: int, m: int) -> sp.csc_matrix:
    """``w_k - w_{k-1}`` for k = 1..N-1 (rows), over ``w_0..w_{N-1}``."""
    D = sp.diags([np.ones(N), -np.ones(N - 1)], [0, -1], shape=(N, N))
    return sp.kron(D.tocsr()[1:], sp.identity(m), format="csc")


def dynamics_rows(F: np.ndarray, G: np.ndarray, N: int) -> sp.csc_matrix:
    """The rows ``x_{k+1} - F x_k - G w_k`` of an ``N``-step horizon in the unknowns ``(w, x)``
    (``x_0``'s term, from the parameters, is the caller's)."""
    nx = F.shape[0]
    I_N = sp.identity(N, format="csc")
    shift = sp.diags([np.ones(N - 1)], [-1], shape=(N, N), format="csc")
    return sp.hstack([-sp.kron(I_N, G), sp.kron(I_N, sp.identity(nx)) - sp.kron(shift, F)], format="csc")


def assemble_qp(problem: TrackingProblem, horizon: int, formulation: str = "condensed") -> ParametricQP:
    """The horizon-``N`` QP of ``problem`` with parameter ``p = (x_0, w_prev)``.

    Variables: ``w_0..w_{N-1}`` (condensed), followed by ``x_1..x_N`` (sparse).
    """
    if formulation not in ("condensed", "sparse"):
        raise InputError(f"formulation = {formulation!r}: expected 'condensed' or 'sparse'")
    N, m, nx = int(horizon), problem.m, problem.nx
    nw, nX = N * m, N * nx
    nv, npar = nw + nX, nx + m
    iw = lambda k: np.arange(k * m, (k + 1) * m)  # noqa: E731
    ix = lambda k: nw + np.arange((k - 1) * nx, k * nx)  # x_k, k = 1..N  # noqa: E731
    ip_w = nv + nx + np.arange(m)

    # -- cost over z = (v, p) ---------------------------------------------------------------------
    J = _Quadratic(nv + npar)
    Q, x_d = problem.Q, problem.x_target
    Wu = problem.residual_gram + problem.rho * np.eye(m)
    rate = problem.sigma * np.block([[np.eye(m), -np.eye(m)], [-np.eye(m), np.eye(m)]])
    for k in range(N):
        J.add(ix(k + 1), Q, x_d)
        J.add(iw(k), Wu)
        J.linear(iw(k), -2.0 * problem.residual_target, problem.residual_constant)
        J.add(np.r_[iw(k), iw(k - 1) if k > 0 else ip_w], rate)
    if problem.settings.terminal == "lqr":
        J.add(np.r_[ix(N), iw(N - 1)], problem.P, np.r_[problem.x_s, problem.w_s])
        J.linear(ix(N), -problem.lam, float(problem.lam @ problem.x_s))
    Hz = J.hessian()
    H, Qp, Cpp = Hz[:nv, :nv], Hz[:nv, nv:], Hz[nv:, nv:]

    # -- constraints ------------------------------------------------------------------------------
    # Dynamics  x_{k+1} - F x_k - G w_k = 0  (x_0 from p).
    F, G = problem.F, problem.G
    A_dyn = dynamics_rows(F, G, N)
    B_dyn = sp.vstack([sp.hstack([sp.csc_matrix(F), sp.csc_matrix((nx, m))]), sp.csc_matrix((nX - nx, npar))])
    eq_A, eq_b0, eq_Bp = [A_dyn], [np.zeros(nX)], [B_dyn]
    if problem.settings.terminal == "static":
        sel = sp.csc_matrix((np.ones(nx), (np.arange(nx), ix(N))), shape=(nx, nv))
        eq_A.append(sel)
        eq_b0.append(problem.x_s)
        eq_Bp.append(sp.csc_matrix((nx, npar)))
    # Voltage limits on every w_k, then slew limits on w_0 - w_prev and w_k - w_{k-1}.
    sel_w = sp.hstack([sp.identity(nw), sp.csc_matrix((nw, nX))], format="csc")
    in_A = [sel_w]
    in_l = [np.tile(problem.w_min, N)]
    in_u = [np.tile(problem.w_max, N)]
    in_Lp = [sp.csc_matrix((nw, npar))]
    if problem.slew is not None:
        d = problem.slew
        in_A.append(sp.hstack([sp.identity(m), sp.csc_matrix((m, nv - m))], format="csc"))
        pick_wprev = sp.hstack([sp.csc_matrix((m, nx)), sp.identity(m)], format="csc")
        in_l.append(np.full(m, -d))
        in_u.append(np.full(m, d))
        in_Lp.append(pick_wprev)
        if N > 1:
            in_A.append(sp.hstack([_difference_rows(N, m), sp.csc_matrix((nw - m, nX))], format="csc"))
            in_l.append(np.full(nw - m, -d))
            in_u.append(np.full(nw - m, d))
            in_Lp.append(sp.csc_matrix((nw - m, npar)))
    A_in = sp.vstack(in_A, format="csc")
    Lp = sp.vstack(in_Lp, format="csc")
    qp = ParametricQP(
        H=H,
        q0=J.g[:nv],
        Qp=Qp,
        A_in=A_in,
        l0=np.concatenate(in_l),
        Lp=Lp,
        u0=np.concatenate(in_u),
        Up=Lp.copy(),
        A_eq=sp.vstack(eq_A, format="csc"),
        b0=np.concatenate(eq_b0),
        Bp=sp.vstack(eq_Bp, format="csc"),
        c0=J.c,
        cp=J.g[nv:],
        Cpp=Cpp.toarray(),
        names={"formulation": "sparse", "horizon": N, "n_inputs": m, "n_states": nx, "n_dynamics_rows": nX},
    )
    return qp if formulation == "sparse" else condense(qp, problem)


def condense(qp: ParametricQP, problem: TrackingProblem) -> ParametricQP:
    """Eliminate the states of a sparse :func:`assemble_qp` problem: ``v = T_w w + T_p p``."""
    N, m, nx = qp.names["horizon"], problem.m, problem.nx
    nw = N * m
    F, G = problem.F, problem.G
    # x_{k+1} = F^{k+1} x_0 + sum_j F^{k-j} G w_j.
    Fpow = [np.eye(nx)]
    for _ in range(N):
        Fpow.append(F @ Fpow[-1])
    FG = [Fk @ G for Fk in Fpow[:N]]
    Gamma = np.zeros((N * nx, nw))
    for k in range(N):
        for j in range(k + 1):
            Gamma[k * nx : (k + 1) * nx, j * m : (j + 1) * m] = FG[k - j]
    Tw = np.vstack([np.eye(nw), Gamma])
    npar = qp.n_parameters
    Tp = np.zeros((nw + N * nx, npar))
    if npar == nx + m:  # p = (x_0, w_prev): x_k = F^k x_0
        Tp[nw:, :nx] = np.vstack(Fpow[1 : N + 1])
    else:  # a parameter in every dynamics row (offset-free: the disturbance): x_{k+1} = F x_k + B_k p
        Bp = qp.Bp.toarray()[: N * nx]
        prev = np.zeros((nx, npar))
        for k in range(N):
            prev = F @ prev + Bp[k * nx : (k + 1) * nx]
            Tp[nw + k * nx : nw + (k + 1) * nx] = prev
    H = qp.H.toarray()
    HTw, HTp = H @ Tw, H @ Tp
    Qp = qp.Qp.toarray()
    Hc = Tw.T @ HTw
    Qpc = Tw.T @ (HTp + Qp)
    Cppc = Tp.T @ HTp + Tp.T @ Qp + Qp.T @ Tp + qp.Cpp
    nd = qp.names["n_dynamics_rows"]
    A_in = qp.A_in.toarray()
    shift_in = A_in @ Tp
    kw = {}
    if qp.n_eq > nd:  # equalities other than the dynamics (terminal constraint)
        A_eq = qp.A_eq.toarray()[nd:]
        kw = dict(
            A_eq=sp.csc_matrix(A_eq @ Tw),
            b0=qp.b0[nd:],
            Bp=sp.csc_matrix(qp.Bp.toarray()[nd:] - A_eq @ Tp),
        )
    return ParametricQP(
        H=sp.csc_matrix(0.5 * (Hc + Hc.T)),
        q0=Tw.T @ qp.q0,
        Qp=sp.csc_matrix(Qpc),
        A_in=sp.csc_matrix(A_in @ Tw),
        l0=qp.l0,
        Lp=sp.csc_matrix(qp.Lp.toarray() - shift_in),
        u0=qp.u0,
        Up=sp.csc_matrix(qp.Up.toarray() - shift_in),
        c0=qp.c0,
        cp=Tp.T @ qp.q0 + qp.cp,
        Cpp=0.5 * (Cppc + Cppc.T),
        names={**qp.names, "formulation": "condensed", "n_dynamics_rows": 0},
        **kw,
    )


def shift_plan(v: np.ndarray, qp: ParametricQP) -> np.ndarray:
    """Warm start: the previous plan advanced one period (last input and state repeated)."""
    names = qp.names
    N, m, nx = names["horizon"], names["n_inputs"], names["n_states"]
    w = v[: N * m].reshape(N, m)
    parts = [np.vstack([w[1:], w[-1:]]).ravel()]
    if names["formulation"] == "sparse":
        X = v[N * m :].reshape(N, nx)
        parts.append(np.vstack([X[1:], X[-1:]]).ravel())
    return np.concatenate(parts)


_shift = shift_plan  # the name the tests and older code use
