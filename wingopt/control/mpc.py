"""Morphing as a constrained finite-horizon QP (spec §4): open loop and receding horizon.

Model. The plate is reduced by :func:`wingopt.dynamics.reduction.reduce_system` (modal truncation,
full projected damping block, quasi-static residual correction so that every steady state is
exact; the number of modes from a frequency-response tolerance on the loop's Nyquist band) and
discretised exactly (ZOH) at the control period. Everything is solved in scaled units: fields
divided by ``s = ||z_d||_M`` and voltages in kV (``w = u / 1000``), so costs and unknowns are O(1).

Cost. Over ``N`` periods, with ``x_k = [q_k; q_k']`` and the field at the end of period ``k``
``z_{k+1} = Phi q_{k+1} + R u_k`` (the quasi-static part follows the held input)::

    sum_{k=0}^{N-1}  ||z_{k+1} - z_d||_M^2 + beta ||z'_{k+1}||_M^2 + rho ||w_k||^2 + sigma ||w_k - w_{k-1}||^2
                     + V_f(x_N, w_{N-1})

The shape term is the exact M-norm error of the reduced field (modal part plus residual part
plus the constant part of ``z_d`` outside the reduced space). Constraints: ``vmin <= u_k <= vmax``
per patch and ``|u_k - u_{k-1}| <= slew * period`` (``u_{-1}`` the voltage applied last).

Terminal cost. ``V_f(xi) = (xi - xi_s)^T P (xi - xi_s) - lambda^T (xi - xi_s)`` with ``xi = (x, w_prev)``:
``P`` is the Riccati solution of the reduced discrete LQR on the same stage cost (with the rate
term, hence the augmented state), ``(xi_s, w_s)`` the static optimum
(:mod:`wingopt.control.static_optimum`, within the limits), and ``lambda`` the steady-state
multiplier ``-(I - F)^-T grad_x l``. The linear term is what makes the target shape ``z_d``, which
no admissible voltage reaches, compatible with a quadratic tail: it *rotates* the stage cost
into a deviation cost about the best reachable steady state (the standard economic-MPC
construction), so the receding-horizon loop settles exactly at the static optimum and, without
active limits, the whole scheme is the infinite-horizon LQR. ``terminal="static"`` replaces
``V_f`` by the equality ``x_N = x_s``.

QP. Written once with the states as variables (``formulation="sparse"``, banded KKT: the default
for Clarabel, OSQP, IPOPT and the sparse CasADi plugins), and condensed by eliminating the states
(``"condensed"``, dense ``N m`` Hessian: the default for the dense active-set plugins); the
parameter ``p = (x_0, w_prev)`` enters the linear term and the bounds only
(:class:`~wingopt.control.mpc_backends.ParametricQP`), so each backend is built once and re-solved
each period, warm-started from the shifted previous plan.

Use. Closed loop: a steady-state Kalman filter on the nine patch sensors estimates ``x`` (the
sensor model carries the residual feedthrough ``C R u_{k-1}``), one QP per period, the first input
applied. Open loop: one QP over the manoeuvre from rest, replayed, the static optimum held after it.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from wingopt.control.lqr import dlqr
from wingopt.control.mpc_backends import BACKENDS, ParametricQP, QPBackend, make_backend
from wingopt.control.static_optimum import (
    VOLT_SCALE,
    StaticOptimum,
    finite_limits,
    input_weight_absolute,
    static_fields,
    static_optimum,
)
from wingopt.dynamics.reduction import CORRECTIONS, ReducedModel, reduce_system
from wingopt.errors import InputError

__all__ = [
    "QPSettings",
    "TrackingProblem",
    "QPController",
    "make_qp_controller",
    "assemble_qp",
    "MODES",
    "FORMULATIONS",
]

log = logging.getLogger(__name__)

MODES = ("closed-loop", "open-loop")
FORMULATIONS = ("auto", "condensed", "sparse")


@dataclass(frozen=True)
class QPSettings:
    """Settings of the morphing QP.

    Attributes
    ----------
    horizon : int or None
        Steps of the prediction horizon. Default: 10 in closed loop (0.1 s at 10 ms, one period of
        the first mode: the economic Riccati terminal cost carries the tail, and 20 or 40 steps
        change the 13x61 shape errors by < 0.4 % at twice and four times the cost, see
        ``docs/control_qp.md``), or the whole manoeuvre ``plan_time / period`` (open loop).
    plan_time : float
        Length of the open-loop manoeuvre (s) when ``horizon`` is not given.
    velocity_weight : float or None
        ``beta`` (s^2) of the velocity term ``beta ||z'||_M^2``; default 1e-2 s^2 (about
        ``40 / omega_1^2`` on the plate: residual vibration costs more than a static shape error,
        which makes the loop settle at the static optimum when every patch ends at a limit, e.g.
        bending; ``None`` for ``1 / omega_1^2``).
    input_weight, rate_weight : float
        ``rho`` and ``sigma``, relative to the mean curvature of the shape term per kV^2
        (:func:`~wingopt.control.static_optimum.input_weight_absolute`).
    input_weight_si : float or None
        ``rho`` as the seed LQR's ``r`` instead (V^-2 against ``||z - z_d||_M^2`` in kg m^2; e.g.
        :data:`wingopt.control.tracking.R_DEFAULT`), so that both settle at the same fit.
    slew_rate : float or None
        Largest voltage rate per patch (V/s); ``None`` for none.
    terminal : str
        ``"lqr"`` (Riccati terminal cost, default) or ``"static"`` (``x_N`` = static optimum).
    formulation : str
        ``"condensed"`` (states eliminated, dense Hessian), ``"sparse"`` (states kept, banded KKT)
        or ``"auto"``: condensed for the dense active-set CasADi plugins (qpoases, daqp) up to 600
        input unknowns, sparse otherwise (the faster choice measured for each backend).
    solver : str
        ``"clarabel"`` (default), ``"osqp"``, ``"ipopt"`` or ``"casadi-qp"``.
    plugin : str or None
        CasADi QP plugin for ``casadi-qp`` (default ``qpoases``).
    tolerance : float or None
        Backend tolerance (backend default if ``None``).
    mode : str
        ``"closed-loop"`` or ``"open-loop"``.
    reduction_tol : float
        Frequency-response tolerance of the reduced model (relative M-norm).
    band_hz : float or None
        Band of that tolerance; default the Nyquist frequency ``1 / (2 period)``.
    correction : str
        Static correction of the reduction (:data:`wingopt.dynamics.reduction.CORRECTIONS`).
    max_modes : int
        Most modes the reduction may keep.
    process_noise : float
        Kalman filter: standard deviation of an input-referred disturbance (kV).
    measurement_noise : float
        Kalman filter: sensor noise standard deviation relative to each sensor's response to 1 kV
        on its own patch (default 1.0: see :func:`make_filter`).
    """

    horizon: int | None = None
    plan_time: float = 2.0
    velocity_weight: float | None = 1e-2
    input_weight: float = 1e-6
    input_weight_si: float | None = None
    rate_weight: float = 1e-3
    slew_rate: float | None = 1.0e5
    terminal: str = "lqr"
    formulation: str = "auto"
    solver: str = "clarabel"
    plugin: str | None = None
    tolerance: float | None = None
    mode: str = "closed-loop"
    reduction_tol: float = 1e-2
    band_hz: float | None = None
    correction: str = "residual"
    max_modes: int = 60
    process_noise: float = 0.05
    measurement_noise: float = 1.0

    def __post_init__(self) -> None:
        checks = [
            ("mode", self.mode, MODES),
            ("solver", self.solver, BACKENDS),
            ("formulation", self.formulation, FORMULATIONS),
            ("terminal", self.terminal, ("lqr", "static")),
            ("correction", self.correction, CORRECTIONS),
        ]
        for name, value, allowed in checks:
            if value not in allowed:
                raise InputError(f"{name} = {value!r}: expected one of {', '.join(allowed)}")
        if self.horizon is not None and int(self.horizon) < 1:
            raise InputError(f"horizon = {self.horizon!r}: expected a positive number of steps")
        for name in ("input_weight", "rate_weight", "process_noise", "measurement_noise"):
            if not getattr(self, name) >= 0:
                raise InputError(f"{name} = {getattr(self, name)!r}: expected a non-negative number")
        if self.input_weight_si is not None and not self.input_weight_si > 0:
            raise InputError(f"input_weight_si = {self.input_weight_si!r}: expected a positive weight (V^-2)")
        if self.input_weight <= 0 and self.rate_weight <= 0 and self.input_weight_si is None:
            raise InputError("input_weight and rate_weight are both zero: the QP needs one to be positive")
        if self.slew_rate is not None and not self.slew_rate > 0:
            raise InputError(f"slew_rate = {self.slew_rate!r}: expected a positive rate (V/s) or None")

    def steps(self, period: float) -> int:
        """Horizon length in periods."""
        if self.horizon is not None:
            return int(self.horizon)
        return max(1, int(round(self.plan_time / period))) if self.mode == "open-loop" else 10


@dataclass(eq=False)
class TrackingProblem:
    """The reduced, scaled tracking problem of one target: model, weights, static optimum, tail.

    Build with :meth:`build`. Units: states ``x~ = x / s``, inputs ``w = u / 1 kV``.
    """

    reduced: ReducedModel
    period: float
    F: np.ndarray
    G: np.ndarray
    scale: float
    q_target: np.ndarray
    residual_gram: np.ndarray
    residual_target: np.ndarray
    residual_constant: float
    static_gain: np.ndarray
    beta: float
    rho: float
    sigma: float
    w_min: np.ndarray
    w_max: np.ndarray
    slew: float | None
    static: StaticOptimum
    w_s: np.ndarray
    x_s: np.ndarray
    P: np.ndarray
    lam: np.ndarray
    settings: QPSettings
    timings: dict = field(default_factory=dict)

    @property
    def nx(self) -> int:
        return self.F.shape[0]

    @property
    def m(self) -> int:
        return self.G.shape[1]

    @property
    def Q(self) -> np.ndarray:
        r = self.reduced.size
        return np.diag(np.r_[np.ones(r), np.full(r, self.beta)])

    @property
    def x_target(self) -> np.ndarray:
        return np.r_[self.q_target, np.zeros(self.reduced.size)]

    @classmethod
    def build(
        cls,
        model,
        target: np.ndarray,
        *,
        period: float,
        vmin=None,
        vmax=None,
        settings: QPSettings | None = None,
        reduced: ReducedModel | None = None,
        fields: np.ndarray | None = None,
    ) -> TrackingProblem:
        """Reduce, discretise, scale, solve the static optimum, and compute the terminal cost."""
        settings = settings or QPSettings()
        if not (np.isfinite(period) and period > 0):
            raise InputError(f"period = {period!r}: expected a positive control period (s)")
        timings = {}
        t0 = time.perf_counter()
        band = settings.band_hz or 0.5 / period
        if reduced is None:
            reduced = reduce_system(
                model.system,
                output=model.sensing,
                tol=settings.reduction_tol,
                band_hz=band,
                max_modes=settings.max_modes,
                correction=settings.correction,
            )
        timings["reduction_s"] = time.perf_counter() - t0
        t1 = time.perf_counter()
        target = np.asarray(target, dtype=float)
        M = model.mass
        s = float(np.sqrt(target @ (M @ target)))
        if not s > 0:
            raise InputError("target: the target shape is zero; nothing to morph to")
        disc = reduced.discretize(period)
        F, G = disc.A, disc.B * (VOLT_SCALE / s)
        Phi = reduced.basis
        q_d = Phi.T @ (M @ target)
        z_perp = target - Phi @ q_d
        Rt = reduced.residual * (VOLT_SCALE / s)
        MR = np.asarray(M @ Rt)
        gram_R = Rt.T @ MR
        h_R = MR.T @ z_perp / s
        c_R = float(z_perp @ (M @ z_perp)) / s**2
        Sg = reduced.static_gain() * (VOLT_SCALE / s)
        shape_gram = Sg.T @ Sg + gram_R  # == VOLT^2/s^2 Zs^T M Zs (the static problem's)
        m = G.shape[1]
        rho = input_weight_absolute(shape_gram, settings.input_weight, settings.input_weight_si, s)
        sigma = input_weight_absolute(shape_gram, settings.rate_weight)
        beta = settings.velocity_weight if settings.velocity_weight is not None else 1.0 / reduced.omega[0] ** 2
        lo, hi = finite_limits(vmin, vmax, m)
        slew = None if settings.slew_rate is None else settings.slew_rate * period / VOLT_SCALE

        # Static optimum on the full model (same weights): the steady state the QP must settle at.
        zs_fields = static_fields(model) if fields is None else fields
        static = static_optimum(
            model,
            target,
            vmin=vmin,
            vmax=vmax,
            input_weight=settings.input_weight,
            input_weight_si=settings.input_weight_si,
            backend=settings.solver,
            fields=zs_fields,
        )
        w_s = static.voltages / VOLT_SCALE
        r = reduced.size
        x_s = np.r_[Sg @ w_s, np.zeros(r)]
        timings["static_s"] = time.perf_counter() - t1

        # Terminal cost: LQR of the augmented model xi = (x, w_prev), input w, on the stage cost
        #   (F x + G w - x_s)' Q (...) + w' (gram_R + rho) w + sigma |w - w_prev|^2   (deviation form).
        t2 = time.perf_counter()
        nx = F.shape[0]
        Q = np.diag(np.r_[np.ones(r), np.full(r, beta)])
        Fa = np.block([[F, np.zeros((nx, m))], [np.zeros((m, nx)), np.zeros((m, m))]])
        Ga = np.vstack([G, np.eye(m)])
        Qa = sla.block_diag(F.T @ Q @ F, sigma * np.eye(m))
        Na = np.vstack([F.T @ Q @ G, -sigma * np.eye(m)])
        Ra = G.T @ Q @ G + gram_R + (rho + sigma) * np.eye(m)
        _, P, _ = dlqr(Fa, Ga, Qa, 0.5 * (Ra + Ra.T), Na)
        P = 0.5 * (P + P.T)
        # Steady-state multiplier: stationarity of the rotated cost in x at (x_s, w_s).
        x_d = np.r_[q_d / s, np.zeros(r)]
        grad_x = 2.0 * F.T @ Q @ (x_s - x_d)
        lam = -np.linalg.solve((np.eye(nx) - F).T, grad_x)
        timings["terminal_s"] = time.perf_counter() - t2
        return cls(
            reduced=reduced,
            period=float(period),
            F=F,
            G=G,
            scale=s,
            q_target=q_d / s,
            residual_gram=0.5 * (gram_R + gram_R.T),
            residual_target=h_R,
            residual_constant=c_R,
            static_gain=Sg,
            beta=float(beta),
            rho=rho,
            sigma=sigma,
            w_min=lo / VOLT_SCALE,
            w_max=hi / VOLT_SCALE,
            slew=slew,
            static=static,
            w_s=w_s,
            x_s=x_s,
            P=P,
            lam=lam,
            settings=settings,
            timings=timings,
        )

    # -- scaled <-> physical ----------------------------------------------------------------------
    def field(self, x: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Full field ``Phi q + R u`` (physical) of a scaled state and input."""
        r = self.reduced.size
        return self.reduced.expand(np.asarray(x)[..., :r] * self.scale, np.asarray(w) * VOLT_SCALE)

    def stage_shape_cost(self, x_next: np.ndarray, w: np.ndarray) -> float:
        """``||z - z_d||_M^2 / s^2`` of the reduced field at the end of a period."""
        r = self.reduced.size
        dq = x_next[:r] - self.q_target
        return float(dq @ dq + w @ self.residual_gram @ w - 2 * self.residual_target @ w + self.residual_constant)

    def simulate(self, x0: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Scaled states ``x_1..x_N`` of the reduced model under inputs ``w`` (N, m)."""
        X = np.empty((len(w), self.nx))
        x = np.asarray(x0, dtype=float)
        for k, wk in enumerate(w):
            x = self.F @ x + self.G @ wk
            X[k] = x
        return X


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
    I_N = sp.identity(N, format="csc")
    shift = sp.diags([np.ones(N - 1)], [-1], shape=(N, N), format="csc")
    A_dyn = sp.hstack([-sp.kron(I_N, G), sp.kron(I_N, sp.identity(nx)) - sp.kron(shift, F)], format="csc")
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
    Tp = np.zeros((nw + N * nx, nx + m))
    Tp[nw:, :nx] = np.vstack(Fpow[1 : N + 1])
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


def _shift(v: np.ndarray, qp: ParametricQP) -> np.ndarray:
    """Warm start: the previous plan advanced one period (last input and state repeated)."""
    names = qp.names
    N, m, nx = names["horizon"], names["n_inputs"], names["n_states"]
    w = v[: N * m].reshape(N, m)
    parts = [np.vstack([w[1:], w[-1:]]).ravel()]
    if names["formulation"] == "sparse":
        X = v[N * m :].reshape(N, nx)
        parts.append(np.vstack([X[1:], X[-1:]]).ravel())
    return np.concatenate(parts)


def make_filter(problem: TrackingProblem, process_noise: float, measurement_noise: float):
    """The steady-state Kalman filter of the reduced model on the patch sensors (scaled units).

    ``x_{k+1} = F x_k + G (w_k + d_k)``, ``y_k = C x_k + D w_{k-1} + v_k`` (the quasi-static residual
    reads the voltage still held): an input-referred disturbance ``d`` (std ``process_noise`` kV)
    and white sensor noise, each sensor scaled by its response to 1 kV on its own patch, with the
    relative std ``measurement_noise``. The sensors see, besides the modelled modes, every higher
    mode that each voltage step rings, aliased by the sampling: measured on 7x31, that mismatch is
    as large as the modal part of the signal, so the default (1.0) trusts the model and lets the
    sensors correct slowly (``docs/control_qp.md``, sweep). Returns ``(filter, y_scale)``.
    """
    from wingopt.control.kalman import SteadyStateKalman

    red = problem.reduced
    if red.output_matrix is None:
        raise InputError("closed-loop QP: the reduced model has no sensor output (reduce with output=model.sensing)")
    static_y = (red.output_matrix @ red.static_gain() + red.output_feedthrough) * VOLT_SCALE
    y_scale = np.maximum(np.abs(np.diag(static_y)), 1e-12 * np.abs(static_y).max())
    Cq = red.output_matrix * problem.scale / y_scale[:, None]
    C = np.hstack([Cq, np.zeros_like(Cq)])
    D = red.output_feedthrough * VOLT_SCALE / y_scale[:, None]
    G = problem.G
    W = max(process_noise, 1e-9) ** 2 * (G @ G.T) + 1e-12 * np.eye(problem.nx)
    V = max(measurement_noise, 1e-9) ** 2 * np.eye(C.shape[0])
    return SteadyStateKalman(problem.F, G, C, W, V, D=D), y_scale


class QPController:
    """Receding-horizon (or open-loop) morphing QP with the harness's ``Controller`` interface.

    ``reset(model, target)`` builds everything once (reduction, static optimum, terminal cost, QP,
    backend, filter); ``step(y)`` takes the patch-sensor sample at the start of a period and
    returns the voltages to hold over it. Diagnostics are collected in :attr:`extras`.
    """

    name = "qp"

    def __init__(self, settings: QPSettings, *, period: float, vmin=None, vmax=None) -> None:
        self.settings = settings
        self.period = float(period)
        self.vmin, self.vmax = vmin, vmax
        self.problem: TrackingProblem | None = None
        self.qp: ParametricQP | None = None
        self.backend: QPBackend | None = None
        self._key = None
        self.info: dict = {}
        self.solve_times: list[float] = []

    # -- setup ------------------------------------------------------------------------------------
    def setup(self, model, target: np.ndarray) -> None:
        """Build the problem, the QP and the backend (skipped when model and target are unchanged)."""
        target = np.asarray(target, dtype=float)
        key = (id(model), target.tobytes())
        if key == self._key:
            return
        t0 = time.perf_counter()
        st = self.settings
        self.problem = TrackingProblem.build(
            model, target, period=self.period, vmin=self.vmin, vmax=self.vmax, settings=st
        )
        N = st.steps(self.period)
        form = st.formulation
        if form == "auto":
            # Measured (docs/control_qp.md): interior-point and ADMM solvers are fastest on the sparse
            # form, the dense active-set plugins on the condensed one while it stays small.
            dense = st.solver == "casadi-qp" and (st.plugin or "qpoases") in ("qpoases", "daqp")
            form = "condensed" if dense and N * self.problem.m <= 600 else "sparse"
        t1 = time.perf_counter()
        self.qp = assemble_qp(self.problem, N, form)
        t2 = time.perf_counter()
        self.backend = make_backend(st.solver, self.qp, tolerance=st.tolerance, plugin=st.plugin)
        self.filter, self._y_scale = None, None
        if st.mode == "closed-loop":
            self.filter, self._y_scale = make_filter(self.problem, st.process_noise, st.measurement_noise)
        self._key = key
        pb = self.problem
        self.info = {
            "static_optimum_error": pb.static.shape_error,
            "static_optimum_voltages_V": pb.static.voltages.tolist(),
            "qp_mode": st.mode,
            "qp_solver": self.backend.name + (f"/{st.plugin or 'qpoases'}" if st.solver == "casadi-qp" else ""),
            "qp_horizon": N,
            "qp_formulation": form,
            "qp_variables": self.qp.n_variables,
            "reduced_modes": pb.reduced.n_modes,
            "reduced_states": pb.nx,
            "reduction_error": pb.reduced.error,
            "reduction_band_hz": pb.reduced.band_hz,
            "build_s": {
                **{k: round(v, 4) for k, v in pb.timings.items()},
                "assemble_s": round(t2 - t1, 4),
                "backend_s": round(self.backend.build_seconds, 4),
                "total_s": round(time.perf_counter() - t0, 4),
            },
            "settings": asdict(st),
        }

    def reset(self, model, target: np.ndarray) -> None:
        """Prepare a run from rest (``Controller`` protocol)."""
        self.setup(model, target)
        m = self.problem.m
        self._w_prev = np.zeros(m)
        self._warm = None
        self._k = 0
        self.solve_times: list[float] = []
        self.iterations: list[int] = []
        self.objectives: list[float] = []
        self.max_violation_V = 0.0
        if self.filter is not None:
            self.filter.reset()
        self._plan = None
        if self.settings.mode == "open-loop":
            sol = self._solve(np.zeros(self.problem.nx), self._w_prev)
            self._plan = sol.v[: self.qp.names["horizon"] * m].reshape(-1, m)
            self.info["open_loop_objective"] = sol.objective
            self.info["open_loop_solve_s"] = sol.seconds

    # -- stepping ---------------------------------------------------------------------------------
    def _solve(self, x0, w_prev):
        sol = self.backend.solve(np.r_[x0, w_prev], warm=self._warm)
        self._warm = _shift(sol.v, self.qp)
        self.solve_times.append(sol.seconds)
        self.iterations.append(sol.iterations)
        self.objectives.append(sol.objective)
        return sol

    def _admissible(self, w: np.ndarray) -> np.ndarray:
        """Project a solver's answer onto the limits (it may sit ~tolerance outside them)."""
        pb = self.problem
        lo, hi = pb.w_min, pb.w_max
        if pb.slew is not None:
            lo = np.maximum(lo, self._w_prev - pb.slew)
            hi = np.minimum(hi, self._w_prev + pb.slew)
        self.max_violation_V = max(self.max_violation_V, float(np.max(np.r_[lo - w, w - hi, 0.0])) * VOLT_SCALE)
        return np.clip(w, lo, hi)

    def step(self, y: np.ndarray) -> np.ndarray:
        """Voltages (V) to hold over the next period, given the patch-sensor sample ``y``."""
        if self.problem is None:
            raise InputError("QPController.step: call reset(model, target) first")
        m = self.problem.m
        if self._plan is not None:
            w = self._plan[self._k] if self._k < len(self._plan) else self.problem.w_s
            w = self._admissible(np.asarray(w, dtype=float))
        else:
            x_hat = self.filter.update(np.asarray(y, dtype=float) / self._y_scale)
            sol = self._solve(x_hat, self._w_prev)
            w = self._admissible(sol.v[:m])
            self.filter.predict(w)
        self._w_prev = w
        self._k += 1
        return w * VOLT_SCALE

    def run(self, model, target: np.ndarray, measurements) -> np.ndarray:
        """Convenience: ``reset`` then ``step`` over a sequence of sensor samples; voltages (nt, m)."""
        self.reset(model, target)
        return np.array([self.step(y) for y in measurements])

    @property
    def extras(self) -> dict:
        """Method-specific numbers for :class:`~wingopt.workflows.morph.MorphResult` (= :meth:`summary`)."""
        return self.summary()

    def summary(self) -> dict:
        """Build information (static optimum, sizes, timings) plus the step statistics of the last run."""
        out = dict(self.info)
        if getattr(self, "solve_times", None):
            t = np.asarray(self.solve_times)
            out.update(
                qp_solves=len(t),
                qp_step_median_s=float(np.median(t)),
                qp_step_max_s=float(t.max()),
                qp_step_median_over_period=float(np.median(t) / self.period),
                qp_iterations_median=float(np.median(self.iterations)),
                qp_max_bound_violation_V=self.max_violation_V,
            )
        return out


def make_qp_controller(model, target, *, vmin, vmax, period: float, **options) -> QPController:
    """The morphing QP as a harness ``Controller`` (``wingopt.workflows.morph.METHODS["qp"]``).

    Parameters
    ----------
    model : PlateModel
    target : ndarray (n,)
        Target coefficients ``z_d``.
    vmin, vmax : float, array or None
        Voltage limits (V).
    period : float
        Control period (s).
    **options
        Fields of :class:`QPSettings` (``horizon``, ``solver``, ``mode``, ...); ``None`` values
        are ignored so that a command line can pass its unset options through.
    """
    known = QPSettings.__dataclass_fields__
    unknown = sorted(k for k in options if k not in known)
    if unknown:
        raise InputError(f"qp option(s) {', '.join(unknown)}: expected some of {', '.join(known)}")
    settings = replace(QPSettings(), **{k: v for k, v in options.items() if v is not None})
    ctrl = QPController(settings, period=period, vmin=vmin, vmax=vmax)
    ctrl.setup(model, target)
    return ctrl
