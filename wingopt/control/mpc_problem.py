"""The reduced, scaled tracking problem of one target (:class:`TrackingProblem`).

Reduction and exact discretisation of the plate, scaling (fields by ``s = ||z_d||_M``, voltages in
kV), the weights, the static optimum within the limits and the economic Riccati terminal cost
(see :mod:`wingopt.control.mpc` for the cost it serves).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from wingopt.control.lqr import dlqr
from wingopt.control.mpc_settings import QPSettings
from wingopt.control.static_optimum import (
    VOLT_SCALE,
    StaticOptimum,
    finite_limits,
    input_weight_absolute,
    static_fields,
    static_optimum,
)
from wingopt.dynamics.reduction import ReducedModel, reduce_system
from wingopt.errors import InputError

__all__ = ["TrackingProblem"]


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
            reduced = _reduce(model, settings, band)
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
        gram_R, h_R, c_R = _residual_terms(reduced, M, z_perp, s)
        Sg = reduced.static_gain() * (VOLT_SCALE / s)
        shape_gram = Sg.T @ Sg + gram_R  # == VOLT^2/s^2 Zs^T M Zs (the static problem's)
        m = G.shape[1]
        rho = input_weight_absolute(shape_gram, settings.input_weight, settings.input_weight_si, s)
        sigma = input_weight_absolute(shape_gram, settings.rate_weight)
        beta = settings.velocity_weight if settings.velocity_weight is not None else 1.0 / reduced.omega[0] ** 2
        lo, hi = finite_limits(vmin, vmax, m)
        slew = None if settings.slew_rate is None else settings.slew_rate * period / VOLT_SCALE

        # Static optimum on the full model (same weights): the steady state the QP must settle at.
        static = _static(model, target, vmin, vmax, settings, fields)
        w_s = static.voltages / VOLT_SCALE
        r = reduced.size
        x_s = np.r_[Sg @ w_s, np.zeros(r)]
        timings["static_s"] = time.perf_counter() - t1

        t2 = time.perf_counter()
        Q = np.diag(np.r_[np.ones(r), np.full(r, beta)])
        P, lam = _terminal_cost(F, G, Q, gram_R, rho, sigma, x_s, np.r_[q_d / s, np.zeros(r)])
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


def _reduce(model, settings: QPSettings, band: float) -> ReducedModel:
    """The QP's reduced model of the plate: modes in ``band`` (Hz) seen by the sensors, with the static correction."""
    return reduce_system(
        model.system,
        output=model.sensing,
        tol=settings.reduction_tol,
        band_hz=band,
        max_modes=settings.max_modes,
        correction=settings.correction,
    )


def _static(model, target: np.ndarray, vmin, vmax, settings: QPSettings, fields: np.ndarray | None):
    """The static optimum on the full model with the QP's weights (``fields``: the patches' static fields)."""
    return static_optimum(
        model,
        target,
        vmin=vmin,
        vmax=vmax,
        input_weight=settings.input_weight,
        input_weight_si=settings.input_weight_si,
        backend=settings.solver,
        fields=static_fields(model) if fields is None else fields,
    )


def _terminal_cost(F, G, Q, gram_R, rho, sigma, x_s, x_d) -> tuple[np.ndarray, np.ndarray]:
    """The terminal cost ``P`` and the steady-state multiplier ``lam`` of the scaled QP.

    ``P``: the LQR of the augmented model ``xi = (x, w_prev)``, input ``w``, on the stage cost
    ``(F x + G w - x_s)' Q (...) + w' (gram_R + rho) w + sigma |w - w_prev|^2`` (deviation form);
    ``lam``: stationarity of the rotated cost in ``x`` at the static optimum ``x_s`` (target ``x_d``).
    """
    nx, m = F.shape[0], G.shape[1]
    Fa = np.block([[F, np.zeros((nx, m))], [np.zeros((m, nx)), np.zeros((m, m))]])
    Ga = np.vstack([G, np.eye(m)])
    Qa = sla.block_diag(F.T @ Q @ F, sigma * np.eye(m))
    Na = np.vstack([F.T @ Q @ G, -sigma * np.eye(m)])
    Ra = G.T @ Q @ G + gram_R + (rho + sigma) * np.eye(m)
    _, P, _ = dlqr(Fa, Ga, Qa, 0.5 * (Ra + Ra.T), Na)
    P = 0.5 * (P + P.T)
    grad_x = 2.0 * F.T @ Q @ (x_s - x_d)
    lam = -np.linalg.solve((np.eye(nx) - F).T, grad_x)
    return P, lam


def _residual_terms(reduced: ReducedModel, M, z_perp: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The scaled cost of the field the reduced basis misses: the residual's Gram matrix, its cross
    term with the target's unreduced part ``z_perp`` and that part's own (constant) cost."""
    Rt = reduced.residual * (VOLT_SCALE / s)
    MR = np.asarray(M @ Rt)
    gram_R = Rt.T @ MR
    h_R = MR.T @ z_perp / s
    c_R = float(z_perp @ (M @ z_perp)) / s**2
    return gram_R, h_R, c_R
