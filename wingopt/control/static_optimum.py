"""The best shape the patches can hold within their voltage limits (a 9-variable convex QP).

At equilibrium ``K z = b u``, so ``z(u) = Zs u`` with ``Zs = K^-1 b`` the static field of each patch
pair per volt (one sparse factorisation, nine solves). The static optimum is::

    min_u  ||Zs u - z_d||_M^2 / ||z_d||_M^2  +  rho ||u / v_ref||^2      s.t.  vmin <= u <= vmax

with a small input weight ``rho`` (1e-6 times the mean diagonal of the shape term's Hessian, see
:func:`input_weight_absolute`: it only breaks ties between patches with nearly parallel fields). It is solved in scaled
units ``w = u / v_ref`` (``v_ref = 1 kV``) so that the cost and the unknowns are O(1). Its solution
is also the steady state the finite-horizon QP converges to (:mod:`wingopt.control.mpc`), and its
shape error the floor that no controller can beat within the limits.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from wingopt.errors import InputError
from wingopt.optim.qp import ParametricQP
from wingopt.optim.registry import make_backend
from wingopt.optim.status import SolveStatus

__all__ = ["StaticOptimum", "static_fields", "static_optimum", "static_qp", "input_weight_absolute", "finite_limits"]

log = logging.getLogger(__name__)

VOLT_SCALE = 1000.0
"""The QPs' voltage unit (V): decision variables are in kV."""


def static_fields(model) -> np.ndarray:
    """``Zs = K^-1 b``: the static deflection per volt of each patch pair, shape ``(n, m)``.

    The model's cached static fields (:meth:`wingopt.dynamics.SecondOrderSystem.static_fields`).
    """
    return model.system.static_fields()


@dataclass(frozen=True)
class StaticOptimum:
    """Solution of the static problem.

    Attributes
    ----------
    voltages : ndarray (m,)
        Optimal patch voltages (V), exactly within the limits.
    deflection : ndarray (n,)
        Equilibrium field ``Zs u`` on the full FE model.
    shape_error : float
        ``||z - z_d||_M / ||z_d||_M`` (full FE model).
    objective : float
        The scaled cost (shape term plus input weight).
    active : ndarray of bool (m,)
        Patches at a voltage limit.
    status : SolveStatus
    backend : str
    """

    voltages: np.ndarray
    deflection: np.ndarray
    shape_error: float
    objective: float
    active: np.ndarray
    status: SolveStatus
    backend: str


def static_qp(
    fields: np.ndarray,
    mass,
    target: np.ndarray,
    *,
    vmin,
    vmax,
    input_weight: float = 1e-6,
    input_weight_si: float | None = None,
) -> tuple[ParametricQP, np.ndarray, float]:
    """The static problem as a :class:`ParametricQP` in ``w = u / 1 kV``.

    The parameter is the scaled projection ``g = Zs^T M z_d v_ref / ||z_d||^2`` (so that one built
    problem can be re-solved for another target of the same norm); returns ``(qp, g, scale)`` with
    ``scale = ||z_d||_M``.
    """
    m = fields.shape[1]
    MZ = np.asarray(mass @ fields)
    s2 = float(target @ (mass @ target))
    if not s2 > 0:
        raise InputError("target: the target shape is zero; nothing to morph to")
    G = (VOLT_SCALE**2 / s2) * (fields.T @ MZ)
    Hs = G + input_weight_absolute(G, input_weight, input_weight_si, np.sqrt(s2)) * np.eye(m)
    g = (VOLT_SCALE / s2) * (MZ.T @ target)
    lo, hi = finite_limits(vmin, vmax, m)
    qp = ParametricQP(
        H=sp.csc_matrix(2.0 * Hs),
        q0=np.zeros(m),
        Qp=sp.csc_matrix(-2.0 * np.eye(m)),
        A_in=sp.identity(m, format="csc"),
        l0=lo / VOLT_SCALE,
        Lp=sp.csc_matrix((m, m)),
        u0=hi / VOLT_SCALE,
        Up=sp.csc_matrix((m, m)),
        c0=1.0,
    )
    return qp, g, float(np.sqrt(s2))


def input_weight_absolute(
    gram: np.ndarray, relative: float, si: float | None = None, scale: float | None = None
) -> float:
    """``rho`` of the scaled problem (per kV^2, against ``||z - z_d||_M^2 / ||z_d||_M^2``).

    By default ``relative`` times the mean diagonal of the scaled shape Gram matrix ``gram``: the
    shape term's curvature per kV varies by orders of magnitude between targets (a 10 cm bend
    against a 1 cm twist), and ``relative = 1e-6`` changes the unconstrained optimum's shape error
    by ~1e-4 relative and a constrained one not visibly. With ``si`` given (V^-2, against
    ``||z - z_d||_M^2`` in kg m^2: the seed LQR's ``R = r I`` convention) it is ``si (1 kV)^2 / scale^2``
    with ``scale = ||z_d||_M``, so that the static problem is the LQR's regularised fit.
    """
    if si is not None:
        if scale is None:
            raise InputError("input_weight_si needs the target's M-norm (scale)")
        return float(si) * VOLT_SCALE**2 / float(scale) ** 2
    return float(relative) * float(np.trace(gram)) / gram.shape[0]


def finite_limits(vmin, vmax, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-patch voltage limits (V) as finite arrays: scalars broadcast, ``None``/inf become +-1e9 V."""
    lo = np.broadcast_to(np.asarray(-np.inf if vmin is None else vmin, dtype=float), (m,)).copy()
    hi = np.broadcast_to(np.asarray(np.inf if vmax is None else vmax, dtype=float), (m,)).copy()
    if np.any(lo >= hi):  # the same rule as VoltageLimits: a range, not a point
        raise InputError(f"vmin = {vmin!r}, vmax = {vmax!r}: expected vmin < vmax")
    # Unbounded sides become a bound far outside any voltage the problem could use (QP backends
    # want finite numbers; 1e9 V is never active).
    return np.where(np.isfinite(lo), lo, -1e9), np.where(np.isfinite(hi), hi, 1e9)


def _polish(qp: ParametricQP, g: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Snap a backend's answer to its active set and solve the rest exactly (9 unknowns).

    Interior-point and ADMM answers sit ~1e-7 kV inside an active limit; fixing the patches found
    at a limit and solving the stationarity conditions of the free ones gives the exact optimum,
    accepted only if it is feasible and the multipliers of the fixed patches have the right sign
    (otherwise the backend's clipped answer is kept).
    """
    H = qp.H.toarray()
    lo, hi = qp.l0, qp.u0
    tol = 1e-5 * (hi - lo)
    at_lo, at_hi = w <= lo + tol, w >= hi - tol
    fixed = at_lo | at_hi
    x = np.where(at_lo, lo, np.where(at_hi, hi, w))
    free = ~fixed
    grad = -2.0 * g  # q(p) of the static QP
    if free.any():
        rhs = -(grad[free] + H[np.ix_(free, fixed)] @ x[fixed])
        x[free] = np.linalg.solve(H[np.ix_(free, free)], rhs)
    gradient = H @ x + grad
    ok = (
        np.all(x[free] >= lo[free])
        and np.all(x[free] <= hi[free])
        and np.all(gradient[at_lo] >= -1e-9 * max(np.abs(grad).max(), 1e-300))
        and np.all(gradient[at_hi] <= 1e-9 * max(np.abs(grad).max(), 1e-300))
    )
    return x if ok else w


def static_optimum(
    model,
    target: np.ndarray,
    *,
    vmin=None,
    vmax=None,
    input_weight: float = 1e-6,
    input_weight_si: float | None = None,
    backend: str = "clarabel",
    fields: np.ndarray | None = None,
) -> StaticOptimum:
    """Best equilibrium shape within ``vmin <= u <= vmax`` (per patch, scalars broadcast).

    Parameters
    ----------
    model : PlateModel
        Full FE model (``mass``, ``stiffness``, ``actuation``).
    target : ndarray (n,)
        Target coefficients ``z_d``.
    vmin, vmax : float or array, optional
        Voltage limits (V); ``None`` for unbounded.
    input_weight : float
        ``rho`` relative to the mean curvature of the shape term per kV^2 (:func:`input_weight_absolute`).
    input_weight_si : float, optional
        ``r`` in V^-2 against ``||z - z_d||_M^2`` (kg m^2) instead, the seed LQR's convention.
    backend : str
        QP backend (:data:`wingopt.optim.registry.BACKENDS`), or ``"direct"`` for the
        unconstrained closed form (only when both limits are ``None``).
    fields : ndarray (n, m), optional
        Precomputed :func:`static_fields`.
    """
    Zs = static_fields(model) if fields is None else fields
    target = np.asarray(target, dtype=float)
    qp, g, scale = static_qp(
        Zs, model.mass, target, vmin=vmin, vmax=vmax, input_weight=input_weight, input_weight_si=input_weight_si
    )
    if backend == "direct":
        if vmin is not None or vmax is not None:
            raise InputError("backend = 'direct' solves the unconstrained problem only: pass vmin = vmax = None")
        w = np.linalg.solve(qp.H.toarray(), 2.0 * g)
        status, name = SolveStatus.OPTIMAL, "direct"
    else:
        sol = make_backend(backend, qp).solve(g)
        w, status, name = sol.v, sol.status, sol.backend
    w = _polish(qp, g, np.clip(w, qp.l0, qp.u0))
    u = VOLT_SCALE * w
    z = Zs @ u
    err = float(np.sqrt(max((z - target) @ (model.mass @ (z - target)), 0.0))) / scale
    tol = 1e-6 * (qp.u0 - qp.l0)
    active = (w <= qp.l0 + tol) | (w >= qp.u0 - tol)
    log.debug("static optimum: error %.4g, voltages %s", err, np.round(u, 1))
    return StaticOptimum(u, z, err, qp.objective(w, g), active, status, name)
