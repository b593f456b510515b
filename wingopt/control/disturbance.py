"""Offset-free tracking for the morphing QP: an input-disturbance model and a target calculation.

The QP of :mod:`wingopt.control.mpc` settles at its model's static optimum. On a plate that is not
its model (stiffer skin, weaker patches, hysteresis) that equilibrium is not the plant's best,
and the QP has no integral action to find out: it settles where its *model* would be best (issue
34: camber 11 % above what the plant could hold). Offset-free MPC (Muske & Badgwell 2002, Pannocchia
& Rawlings 2003) adds a constant disturbance to the estimator's model and moves the steady-state
target with its estimate. Here the disturbance is input-referred, ``d`` in kV on each patch:

    x_{k+1} = F x_k + G (w_k + d_k),   d_{k+1} = d_k,   y_k = C x_k + D (w_{k-1} + d_k)

so the patches act "as if" with ``w + d`` (a wrong d33 is exactly such a gain, a hysteresis
offset or creep nearly so; stiffness errors are close to one per patch). With nine sensors and
nine disturbance states the augmented pair is detectable iff ``[[I - F, -G], [C, D]]`` has full
column rank, i.e. the model's static sensor gain ``C (I - F)^-1 G + D`` is invertible
(:func:`check_detectable`; the plate's is, condition ~1e2).

Target calculation (per step, :class:`TargetCalculator`): the commanded steady voltage that is
best for the model *with* the disturbance, within the limits,

    w_s(d) = argmin_{w_min <= w <= w_max}  ||Zs (w + d) - z_d||_M^2 / s^2 + rho ||w||^2

a 9-unknown box QP (the static optimum's, with its linear term moved by ``d``), and
``x_s = Sg (w_s + d)``. The horizon QP (:func:`assemble_offset_free_qp`) is today's with the
parameter extended to ``p = (x_0, w_prev, d, x_s, w_s)``: ``d`` enters the dynamics and the
residual field, ``(x_s, w_s)`` the terminal cost and its steady-state multiplier (affine in
``x_s``). The voltage limits stay on the commanded ``w``. At ``d = 0`` it is today's QP exactly.
At a fixed point of the loop the estimate ``d`` reproduces the measured strains, so the target
is the best equilibrium of the model corrected by the plant's measured static response.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from wingopt.control.kalman import SteadyStateKalman
from wingopt.control.mpc_assembly import _difference_rows, _Quadratic, condense, dynamics_rows
from wingopt.control.mpc_problem import TrackingProblem
from wingopt.errors import InputError
from wingopt.optim.qp import ParametricQP
from wingopt.optim.registry import make_backend

__all__ = [
    "check_detectable",
    "make_disturbance_filter",
    "TargetCalculator",
    "assemble_offset_free_qp",
    "terminal_multiplier_map",
]


def check_detectable(F: np.ndarray, G: np.ndarray, C: np.ndarray, D: np.ndarray, tol: float = 1e-10) -> float:
    """Refuse an input-disturbance model that the sensors cannot tell from the state.

    ``(x, d)`` with ``d`` constant is detectable from ``y`` (given a detectable ``(F, C)``) iff
    ``[[I - F, -G], [C, D]]`` has full column rank. Returns its reciprocal condition number; an
    :class:`InputError` when it is numerically rank-deficient (fewer independent sensors than
    disturbances, or a patch that no sensor sees at DC).
    """
    nx, nd = F.shape[0], G.shape[1]
    if C.shape[0] < nd:
        raise InputError(f"offset_free: {C.shape[0]} sensors for {nd} input disturbances: expected at least as many")
    M = np.block([[np.eye(nx) - F, -G], [C, D]])
    s = np.linalg.svd(M, compute_uv=False)
    rcond = float(s[-1] / s[0])
    if rcond < tol:
        raise InputError(
            f"offset_free: the input-disturbance model is not detectable from the patch sensors "
            f"(reciprocal condition {rcond:.2g} < {tol:g}); turn offset_free off"
        )
    return rcond


def make_disturbance_filter(problem: TrackingProblem, base, disturbance_noise: float):
    """The steady-state Kalman filter of ``(x, d)`` from the plain filter ``base`` (scaled units).

    ``base`` is :func:`wingopt.control.mpc.make_filter`'s filter (its ``C``, ``D``, ``W``, ``V``);
    the disturbance is a random walk of std ``disturbance_noise`` kV per period.
    """
    F, G, C, D = problem.F, problem.G, base.C, base.D
    nx, m = problem.nx, problem.m
    check_detectable(F, G, C, D)
    Fa = np.block([[F, G], [np.zeros((m, nx)), np.eye(m)]])
    Ga = np.vstack([G, np.zeros((m, m))])
    Ca = np.hstack([C, D])
    Wa = sla.block_diag(base.W, max(disturbance_noise, 1e-9) ** 2 * np.eye(m))
    return SteadyStateKalman(Fa, Ga, Ca, Wa, base.V, D=D)


class TargetCalculator:
    """``w_s(d)``: the commanded steady voltage best for the model shifted by the disturbance ``d``.

    A box QP in the nine scaled voltages with parameter ``d`` (built once; any backend of the
    ``qp`` capability, DAQP by default), so that a step costs tens of microseconds.
    """

    def __init__(self, problem: TrackingProblem, solver: str | None = None) -> None:
        pb = problem
        Hs = pb.static_gain.T @ pb.static_gain + pb.residual_gram  # shape term's curvature (scaled)
        hs = pb.static_gain.T @ pb.q_target + pb.residual_target
        m = pb.m
        self.Sg = pb.static_gain
        self.nx = pb.nx
        self.qp = ParametricQP(
            H=sp.csc_matrix(2.0 * (Hs + pb.rho * np.eye(m))),
            q0=-2.0 * hs,
            Qp=sp.csc_matrix(2.0 * Hs),
            A_in=sp.identity(m, format="csc"),
            l0=pb.w_min.copy(),
            Lp=sp.csc_matrix((m, m)),
            u0=pb.w_max.copy(),
            Up=sp.csc_matrix((m, m)),
            names={"what": "offset-free target"},
        )
        self.backend = make_backend(solver or "daqp", self.qp)
        self.w_min, self.w_max = pb.w_min, pb.w_max
        self.last_status = None

    def solve(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x_s, w_s)`` for the disturbance estimate ``d`` (scaled units)."""
        sol = self.backend.solve(np.asarray(d, dtype=float))
        self.last_status = sol.status
        w_s = np.clip(sol.v, self.w_min, self.w_max)
        x_s = np.r_[self.Sg @ (w_s + d), np.zeros(self.nx - self.Sg.shape[0])]
        return x_s, w_s


def terminal_multiplier_map(problem: TrackingProblem) -> np.ndarray:
    """``Lambda`` of the steady-state multiplier ``lambda = Lambda (x_s - x_d)`` (see ``mpc_problem``)."""
    F, Q = problem.F, problem.Q
    return -np.linalg.solve((np.eye(problem.nx) - F).T, 2.0 * F.T @ Q)


def assemble_offset_free_qp(problem: TrackingProblem, horizon: int, formulation: str = "condensed") -> ParametricQP:
    """The horizon-``N`` QP with parameter ``p = (x_0, w_prev, d, x_s, w_s)`` (terminal ``"lqr"`` only).

    Today's cost (:func:`wingopt.control.mpc_assembly.assemble_qp`) with the disturbance in the
    dynamics and the residual field, and the terminal anchor ``(x_s, w_s)`` a parameter.
    """
    if formulation not in ("condensed", "sparse"):
        raise InputError(f"formulation = {formulation!r}: expected 'condensed' or 'sparse'")
    if problem.settings.terminal != "lqr":
        raise InputError("offset_free: needs terminal = 'lqr' (a static terminal constraint cannot move)")
    N, m, nx = int(horizon), problem.m, problem.nx
    nw, nX = N * m, N * nx
    nv, npar = nw + nX, 2 * nx + 3 * m
    J = _offset_free_cost(problem, N)
    Hz = J.hessian()
    H, Qp, Cpp = Hz[:nv, :nv], Hz[:nv, nv:], Hz[nv:, nv:]
    F, G = problem.F, problem.G
    B_dyn = np.zeros((nX, npar))
    B_dyn[:nx, :nx] = F
    B_dyn[:, nx + m : nx + 2 * m] = np.tile(G, (N, 1))
    A_in, l0, u0, Lp = _input_rows(problem, N, nv, npar)
    qp = ParametricQP(
        H=H,
        q0=J.g[:nv],
        Qp=Qp,
        A_in=A_in,
        l0=l0,
        Lp=Lp,
        u0=u0,
        Up=Lp.copy(),
        A_eq=dynamics_rows(F, G, N),
        b0=np.zeros(nX),
        Bp=sp.csc_matrix(B_dyn),
        c0=J.c,
        cp=J.g[nv:],
        Cpp=Cpp.toarray(),
        names={
            "formulation": "sparse",
            "horizon": N,
            "n_inputs": m,
            "n_states": nx,
            "n_dynamics_rows": nX,
            "offset_free": True,
        },
    )
    return qp if formulation == "sparse" else condense(qp, problem)


def _offset_free_cost(problem: TrackingProblem, N: int) -> _Quadratic:
    """The horizon's cost over ``(w, x, p)``: tracking, input and rate weights, the residual field of
    the acting voltage ``w_k + d``, and the terminal cost anchored at the parameters ``(x_s, w_s)``."""
    m, nx = problem.m, problem.nx
    nw, nX = N * m, N * nx
    nv, npar = nw + nX, 2 * nx + 3 * m
    iw = lambda k: np.arange(k * m, (k + 1) * m)  # noqa: E731
    ix = lambda k: nw + np.arange((k - 1) * nx, k * nx)  # noqa: E731
    ip_w = nv + nx + np.arange(m)
    ip_d = ip_w + m
    ip_xs = nv + nx + 2 * m + np.arange(nx)
    ip_ws = nv + 2 * nx + 2 * m + np.arange(m)
    J = _Quadratic(nv + npar)
    Q, x_d = problem.Q, problem.x_target
    gR, hR = problem.residual_gram, problem.residual_target
    rate = problem.sigma * np.block([[np.eye(m), -np.eye(m)], [-np.eye(m), np.eye(m)]])
    for k in range(N):
        J.add(ix(k + 1), Q, x_d)
        J.add(iw(k), problem.rho * np.eye(m))
        # The residual field follows the acting voltage w_k + d.
        J.add(np.r_[iw(k), ip_d], np.block([[gR, gR], [gR, gR]]))
        J.linear(np.r_[iw(k), ip_d], np.r_[-2.0 * hR, -2.0 * hR], problem.residual_constant)
        J.add(np.r_[iw(k), iw(k - 1) if k > 0 else ip_w], rate)
    # (xi_N - xi_s)' P (xi_N - xi_s) with xi = (x, w_prev), xi_s a parameter.
    P = problem.P
    J.add(np.r_[ix(N), iw(N - 1), ip_xs, ip_ws], np.block([[P, -P], [-P, P]]))
    # -lambda' (x_N - x_s), lambda = Lam (x_s - x_d): bilinear in (x_N, x_s).
    Lam = terminal_multiplier_map(problem)
    Z = np.zeros((nx, nx))
    J.add(np.r_[ix(N), ip_xs], np.block([[Z, Z], [-Lam.T, Lam.T]]))
    J.linear(ix(N), Lam @ x_d)
    J.linear(ip_xs, -Lam @ x_d)
    return J


def _input_rows(problem: TrackingProblem, N: int, nv: int, npar: int):
    """The horizon's inequality rows ``(A_in, l0, u0, Lp)``: the voltage limits and, with a slew
    rate, the first step from ``w_prev`` (a parameter) and every later step."""
    m, nx = problem.m, problem.nx
    nw, nX = N * m, N * nx
    sel_w = sp.hstack([sp.identity(nw), sp.csc_matrix((nw, nX))], format="csc")
    in_A, in_l, in_u = [sel_w], [np.tile(problem.w_min, N)], [np.tile(problem.w_max, N)]
    in_Lp = [sp.csc_matrix((nw, npar))]
    if problem.slew is not None:
        s = problem.slew
        in_A.append(sp.hstack([sp.identity(m), sp.csc_matrix((m, nv - m))], format="csc"))
        pick = np.zeros((m, npar))
        pick[:, nx : nx + m] = np.eye(m)
        in_l.append(np.full(m, -s))
        in_u.append(np.full(m, s))
        in_Lp.append(sp.csc_matrix(pick))
        if N > 1:
            in_A.append(sp.hstack([_difference_rows(N, m), sp.csc_matrix((nw - m, nX))], format="csc"))
            in_l.append(np.full(nw - m, -s))
            in_u.append(np.full(nw - m, s))
            in_Lp.append(sp.csc_matrix((nw - m, npar)))
    A_in, Lp = sp.vstack(in_A, format="csc"), sp.vstack(in_Lp, format="csc")
    return A_in, np.concatenate(in_l), np.concatenate(in_u), Lp
