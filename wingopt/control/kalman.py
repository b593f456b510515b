"""Steady-state Kalman filter on the nine patch strain sensors (the "G" of the seed's LQG).

Discrete model at the control period ``h`` (exact zero-order hold)::

    x_{k+1} = F x_k + G u_k + w_k,          w ~ N(0, W)
    y_k     = C x_k + D u_{k-1} + v_k,      v ~ N(0, V)     (D: feedthrough of the held input)

:class:`SteadyStateKalman` runs the stationary filter in predictor–corrector form: ``update(y_k)``
turns the prior ``x_{k|k-1}`` into the filtered estimate ``x_{k|k} = x_{k|k-1} + L (y_k - C x_{k|k-1})``
(``L = P C^T (C P C^T + V)^-1`` with ``P`` the stationary prior covariance of the discrete Riccati
equation), and ``predict(u_k)`` propagates it, ``x_{k+1|k} = F x_{k|k} + G u_k``. The seed's filter
(eqs. 5.24–5.26) is the continuous-time one with infinite confidence in the initial state
(``x_hat(0) = x(0)``); :meth:`reset` takes that initial state.

The filter is generic (any ``F, G, C, D``); :class:`EstimatorModel` builds the one the plate
controllers use: the modes the control period can sample, with full projected damping and exact
ZOH, plus the quasi-static residual of every patch (so the steady strain and deflection under any
voltage are exact) — a handful of states instead of the full model's 1830 (13x61) or 6534
(25x121), so the stationary gain costs milliseconds. Its ``expand`` maps the reduced estimate back
to full deflection coefficients.

Noise model (documented choice, :class:`KalmanSettings`): the process noise is voltage noise on
every patch (``W = G diag(sigma_u^2) G^T``, the disturbance that the controller can also see
through the actuators) plus a small white modal noise (``sigma_q^2 I`` on the modal
displacements and rates, which stands for the modes the reduced model leaves out and keeps the
filter from trusting its model blindly); the measurement noise is white with standard deviation
``sigma_y`` per sensor. The sensors' unit is m (strain x area over the substrate thickness,
eq. 4.19): one kilovolt on a patch gives 3–13e-6 on its own sensor, so the default
``sigma_y = 1e-8`` is about 0.1 % of that.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from wingopt.control.lqr import dlqe
from wingopt.dynamics.reduction import ReducedModel, modes_below, reduced_basis
from wingopt.errors import InputError

__all__ = ["SteadyStateKalman", "KalmanSettings", "EstimatorModel"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class KalmanSettings:
    """Noise model of the steady-state filter (see the module docstring).

    Parameters
    ----------
    sigma_u : float
        Standard deviation of the voltage noise on each patch, per control step (V).
    sigma_q : float
        Standard deviation of the white modal process noise (M-normalised modal units, m sqrt(kg)).
    sigma_y : float
        Standard deviation of the sensor noise (sensor units, m).
    """

    sigma_u: float = 1.0
    sigma_q: float = 1e-8
    sigma_y: float = 3e-7

    def __post_init__(self) -> None:
        for name in ("sigma_u", "sigma_q", "sigma_y"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"{name} = {v!r}: expected a standard deviation >= 0")
        if self.sigma_y <= 0:
            raise InputError(f"sigma_y = {self.sigma_y!r}: the measurement noise must be positive")


class SteadyStateKalman:
    """Stationary Kalman filter ``x_{k|k} = x_{k|k-1} + L (y_k - C x_{k|k-1})``.

    Parameters
    ----------
    F, G, C : ndarray
        Discrete model ``x+ = F x + G u``, ``y = C x``.
    W, V : ndarray
        Process and measurement noise covariances (``V`` positive definite).

    Examples
    --------
    >>> kf = SteadyStateKalman(F, G, C, W, V)          # doctest: +SKIP
    >>> kf.reset(np.zeros(F.shape[0]))
    >>> x_hat = kf.update(y0); kf.predict(u0)
    """

    def __init__(
        self, F: np.ndarray, G: np.ndarray, C: np.ndarray, W: np.ndarray, V: np.ndarray, D: np.ndarray | None = None
    ) -> None:
        F, G, C = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (F, G, C))
        W, V = np.atleast_2d(np.asarray(W, dtype=float)), np.atleast_2d(np.asarray(V, dtype=float))
        n = F.shape[0]
        if F.shape != (n, n) or G.shape[0] != n or C.shape[1] != n:
            raise InputError(f"Kalman filter: shapes F {F.shape}, G {G.shape}, C {C.shape} do not fit")
        if W.shape != (n, n) or V.shape != (C.shape[0], C.shape[0]):
            raise InputError(f"Kalman filter: noise covariances W {W.shape}, V {V.shape} do not fit")
        self.F, self.G, self.C, self.W, self.V = F, G, C, W, V
        self.D = np.zeros((C.shape[0], G.shape[1])) if D is None else np.atleast_2d(np.asarray(D, dtype=float))
        if self.D.shape != (C.shape[0], G.shape[1]):
            raise InputError(f"Kalman filter: D {self.D.shape}, expected {(C.shape[0], G.shape[1])}")
        # dlqe returns the predictor gain and the stationary *prior* covariance P.
        _, P, _ = dlqe(F, np.eye(n), C, 0.5 * (W + W.T), 0.5 * (V + V.T))
        self.P = 0.5 * (P + P.T)
        S = C @ self.P @ C.T + V
        self.L = np.linalg.solve(S, C @ self.P).T  # P C^T S^-1
        self._x = np.zeros(n)
        self._u = np.zeros(G.shape[1])
        self.innovation = np.zeros(C.shape[0])

    @property
    def n(self) -> int:
        return self.F.shape[0]

    @property
    def gain(self) -> np.ndarray:
        """Filter (corrector) gain ``L`` of ``x_{k|k} = x_{k|k-1} + L (y - C x_{k|k-1})``."""
        return self.L

    @cached_property
    def posterior_covariance(self) -> np.ndarray:
        """Stationary covariance of the filtered estimate, ``(I - L C) P``."""
        Pp = (np.eye(self.n) - self.L @ self.C) @ self.P
        return 0.5 * (Pp + Pp.T)

    @cached_property
    def error_dynamics(self) -> np.ndarray:
        """Eigenvalues of ``F (I - L C)`` (the prior error's transition); all inside the unit circle."""
        return np.linalg.eigvals(self.F @ (np.eye(self.n) - self.L @ self.C))

    @property
    def x_hat(self) -> np.ndarray:
        """The current estimate (the prior after :meth:`predict`, the filtered one after :meth:`update`)."""
        return self._x

    def reset(self, x0: np.ndarray | None = None, u0: np.ndarray | None = None) -> None:
        """Start from the prior ``x0`` (default zero: the plate at rest) with held input ``u0`` (default 0)."""
        self._x = np.zeros(self.n) if x0 is None else np.asarray(x0, dtype=float).copy()
        self._u = np.zeros(self.G.shape[1]) if u0 is None else np.asarray(u0, dtype=float).copy()
        self.innovation = np.zeros(self.C.shape[0])

    def update(self, y: np.ndarray) -> np.ndarray:
        """Measurement update with the sample ``y_k``; returns ``x_{k|k}``.

        The feedthrough ``D`` acts on the input of the last :meth:`predict` (the one still held).
        """
        self.innovation = np.asarray(y, dtype=float) - self.C @ self._x - self.D @ self._u
        self._x = self._x + self.L @ self.innovation
        return self._x

    def predict(self, u: np.ndarray) -> np.ndarray:
        """Time update with the input ``u_k`` applied over the step; returns ``x_{k+1|k}``."""
        self._u = np.asarray(u, dtype=float).copy()
        self._x = self.F @ self._x + self.G @ self._u
        return self._x


@dataclass(frozen=True, eq=False)
class EstimatorModel:
    """Reduced plate model for estimation and control design, with a quasi-static residual.

    ``z = Phi q + R_s u``: the lowest undamped modes ``Phi`` (M-orthonormal) carry the dynamics,
    ``q'' + Dq q' + diag(omega^2) q = Phi^T b u`` with the full ``Dq = Phi^T Kd Phi``, and the
    static-correction fields ``R_s = K^-1 b - Phi diag(omega^-2) Phi^T b`` (what the kept modes
    miss of each patch's static field, M-orthogonal to ``Phi``) follow the held voltage at once
    (mode-acceleration method). The steady deflection and strain under any voltage are therefore
    exact. ``F, G`` are the exact ZOH of the modal part at ``dt``; the sensors read
    ``y_k = C x_k + D u_{k-1}`` with ``C = [C_patch Phi, 0]``, ``D = C_patch R_s`` (at the sampling
    instant the voltage of the previous period is still applied).

    Why a quasi-static residual and few modes: a digital controller holding its voltages for a
    period cannot damp modes above the Nyquist frequency, and each voltage step rings them; with
    those modes in the design model the seed's velocity weight ``beta M`` makes the optimal
    discrete law creep (closed-loop time constants of 50–100 s, see ``docs/control_lqr.md``). The
    default band is therefore ``0.6 / dt`` (1.2 x Nyquist: the first three modes at 10 ms).
    """

    modes: np.ndarray
    residual: np.ndarray
    omega: np.ndarray
    A: np.ndarray
    B: np.ndarray
    F: np.ndarray
    G: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float

    @classmethod
    def from_model(cls, model, dt: float, n_modes: int | None = None, band_hz: float | None = None) -> EstimatorModel:
        """Modes of ``model`` below ``band_hz`` (default ``0.6 / dt``) or the lowest ``n_modes``."""
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt = {dt!r}: expected a positive sample period (s)")
        if n_modes is None:
            n_modes = modes_below(model.system, 0.6 / dt if band_hz is None else float(band_hz))
        elif int(n_modes) < 1:
            raise InputError(f"n_modes = {n_modes!r}: expected at least one mode")
        red = ReducedModel.from_basis(model.system, *reduced_basis(model.system, int(n_modes)), output=model.sensing)
        ct, disc = red.state_space(), red.discretize(dt)
        return cls(red.basis, red.residual, red.omega, ct.A, ct.B, disc.A, disc.B, disc.C, disc.D, float(dt))

    @property
    def r(self) -> int:
        """Number of modal coordinates ``q`` (the state has ``2 r``)."""
        return self.modes.shape[1]

    def coordinates(self, z: np.ndarray, mass) -> np.ndarray:
        """``q = Phi^T M z`` (M-orthogonal projection of a field onto the modes)."""
        return self.modes.T @ (mass @ np.asarray(z, dtype=float))

    def expand(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full deflection and rate coefficients ``(Phi q + R_s u, Phi q')`` of a reduced state."""
        return self.modes @ x[: self.r] + self.residual @ u, self.modes @ x[self.r :]

    def kalman(self, settings: KalmanSettings = KalmanSettings()) -> SteadyStateKalman:
        """The stationary filter of this model under the noise model ``settings``."""
        m = self.G.shape[1]
        W = settings.sigma_u**2 * (self.G @ self.G.T) + settings.sigma_q**2 * np.eye(2 * self.r)
        V = settings.sigma_y**2 * np.eye(m)
        return SteadyStateKalman(self.F, self.G, self.C, W, V, D=self.D)
