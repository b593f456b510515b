"""Joint extended Kalman filter (JEKF): the seed's recursive load estimator (chapter 6, eqs. 6.15–6.46).

The load ``P ≈ Σ f_i phi_i`` (deflection basis, ``p = M f``) is appended to the membrane state as
a random walk, ``f' = 0 + noise``, and the joint state ``[z, z', f]`` is estimated by an extended
Kalman filter on the quadratic stretch sensors ``s_i = z^T C_i z`` (Jacobian rows ``2 z^T C_i``):

* joint transition ``F_hat = expm([[A, B], [0, 0]] dt)``: ONE augmented matrix exponential
  (eq. 6.24), i.e. the exact zero-order hold of the plant with the load held over the step;
* process noise on the load block only, ``Qd`` per unit time: ``Qd = 0`` for static loads, Gelb's
  rule ``Qd_ii = Δf_i^2 / Δt`` (eq. 6.38) for a load expected to change by ``Δf`` over ``Δt``;
* Joseph-form covariance update (eq. 6.30);
* regularised initial covariance on the load block only (eqs. 6.44–6.46)::

      P0_d = (P0d_tilde^-1 + lambda Lam)^-1,     Lam = ∫ (phi_xx phi_xx^T + phi_yy phi_yy^T)

  With ``P0d_tilde = load_std^2 I`` and the default ``load_std = inf`` the prior on the load is the
  pure smoothness (Tikhonov) prior ``(lambda Lam)^-1``: ``lambda`` is then the only knob and the
  filter approximates ``min Σ |y_k - h(x_k)|^2_{R^-1} + lambda (f - f0)^T Lam (f - f0) + state prior``.

**Structure used for speed (exact).** The membrane's damping is Rayleigh, so with M-orthonormal
modes ``z = Phi q`` and the modal load ``g = Phi^T M f`` (``f = rho h Phi g``) the joint system
splits into one 3x3 block ``[q_k, q_k', g_k]`` per mode. The joint state is stored interleaved per
mode, so the transition is block diagonal and ``F P F^T`` costs ``O(n^2)`` (two batched 3x3
products) instead of the ``O(n^3)`` dense product; the measurement update is rank ``p`` (4
sensors) and is applied as one rank-``2p`` BLAS update of ``P``. Both are exact re-arrangements:
the Kalman filter is invariant under the linear change of coordinates, and keeping all modes
(``modes=None``, the default) is the full model. ``structure="dense"`` runs the same filter in
physical coordinates with the dense joint transition (the reference, ~``(3n)^3`` work per step).

**Sign.** Stretch sensors are sign-blind: the data are unchanged when the initial state and the
load both flip sign. The filter linearises about its current state, so the sign of the estimate
follows the prior initial deflection, the bubble ``initial_peak * 16 xi (1 - xi) eta (1 - eta)``
(the problem's ``initial_deflection``; when unknown, 1 cm with the sign of ``initial_load``).

Use :func:`jekf_identify` for a one-shot run, or the step-able :class:`JointEKF`
(``setup`` / ``step`` / ``run``). The two ways of choosing ``lambda`` are in
:mod:`wingopt.estimation.jekf_tuning`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla
from scipy.linalg.blas import dgemm

from wingopt.errors import InputError, SolverError
from wingopt.estimation.data import IdentificationResult, Measurements
from wingopt.membrane.loads import bubble
from wingopt.membrane.model import MembraneModel

__all__ = [
    "JEKFSettings",
    "JointEKF",
    "jekf_identify",
    "joint_transition",
    "SEED_MEASUREMENT_VARIANCE",
]

log = logging.getLogger(__name__)

SEED_MEASUREMENT_VARIANCE = 1.0e-4
"""The seed's measurement covariance ``R = 1e-4`` (section 6.4, "for simplicity's sake")."""

DEFAULT_PEAK = 0.01
"""Peak (m) of the seed's initial bubble, used when the problem does not state one."""

_STRUCTURES = ("modal", "dense")


def _as_positive(name: str, value: float, allow_inf: bool = False, allow_zero: bool = False) -> float:
    v = float(value)
    ok = (v > 0 or (allow_zero and v == 0)) and (math.isfinite(v) or (allow_inf and v == math.inf))
    if not ok:
        what = "non-negative" if allow_zero else "positive"
        raise InputError(f"{name} = {value!r}: expected a {what} number" + (" (inf allowed)" if allow_inf else ""))
    return v


@dataclass(frozen=True)
class JEKFSettings:
    """Configuration of the joint EKF.

    Parameters
    ----------
    regularization : float
        ``lambda`` in ``P0_d = (P0d_tilde^-1 + lambda Lam)^-1`` (units ``1/(Pa^2 m^-2)``: it depends
        on the units of ``R`` and ``Lam``, so the seed's ``8.58e14`` does not carry over).
    measurement_variance : float, sequence of float, or None
        ``R`` (diagonal): one variance for all sensors or one per sensor. ``None``: take
        ``Measurements.noise_std**2``, or estimate it from the data when the measurements carry
        none (:func:`wingopt.estimation.jekf_tuning.estimate_noise_std`). Seed: ``1e-4``.
    initial_load : float or None
        Uniform prior mean of the pressure (Pa), projected onto the load space. ``None``: the
        problem's ``identification.initial_load`` (the seed's 200 Pa); ``0.0``: zero initial load.
    initial_peak : float or None
        Signed peak (m) of the initial bubble ``16 xi (1 - xi) eta (1 - eta)``, the prior mean of
        the initial deflection. It fixes the sign of the estimate (the data are unchanged when the
        initial state and the load both flip). ``None``: the problem's
        ``identification.initial_deflection`` when non-zero (the protocol's 1 cm), else 1 cm with
        the sign of :attr:`sign_prior`.
    sign_prior : float or None
        Sign prior of the load (Pa; only its sign is used) when ``initial_peak`` is not known;
        ``None``: ``initial_load`` if non-zero, else the problem's ``initial_load``.
    load_std : float
        ``sqrt`` of the diagonal of ``P0d_tilde`` (Pa per coefficient); ``inf`` (default): no
        prior beyond ``lambda Lam``.
    deflection_std, velocity_std : float
        1-sigma of the initial deflection (m) and velocity (m/s) per coefficient: the initial
        state is known up to this (the seed starts the filter at the simulated plant's initial
        condition).
    load_change, load_change_time : float
        Gelb's rule ``Qd = load_change^2 / load_change_time`` (Pa^2/s per coefficient); the
        default ``0`` is the static-load filter (``Qd = 0``).
    modes : int or None
        Keep only the lowest ``modes`` membrane modes (approximate, faster); ``None``: all (exact).
    structure : {"modal", "dense"}
        ``"modal"``: the exact block-diagonal form (fast); ``"dense"``: physical coordinates with
        the dense joint transition (reference; slow on 25x13).
    symmetrize_every : int
        Re-symmetrise ``P`` every this many steps (round-off only: the updates are symmetric in exact
        arithmetic; ``1`` = every step).
    """

    regularization: float = 1.0
    measurement_variance: float | tuple[float, ...] | None = SEED_MEASUREMENT_VARIANCE
    initial_load: float | None = None
    initial_peak: float | None = None
    sign_prior: float | None = None
    load_std: float = math.inf
    deflection_std: float = 1.0e-5
    velocity_std: float = 1.0e-3
    load_change: float = 0.0
    load_change_time: float = 1.0
    modes: int | None = None
    structure: str = "modal"
    symmetrize_every: int = 25

    def __post_init__(self) -> None:
        _as_positive("regularization", self.regularization)
        if self.measurement_variance is not None:
            r = np.atleast_1d(np.asarray(self.measurement_variance, dtype=float))
            if r.ndim != 1 or r.size == 0 or not np.all(np.isfinite(r) & (r > 0)):
                raise InputError(
                    f"measurement_variance = {self.measurement_variance!r}: expected a positive variance "
                    "(one, or one per sensor) or None (from the data)"
                )
        if self.initial_load is not None and not math.isfinite(float(self.initial_load)):
            raise InputError(f"initial_load = {self.initial_load!r}: expected a finite pressure (Pa) or None")
        if self.initial_peak is not None and not (math.isfinite(self.initial_peak) and self.initial_peak != 0):
            raise InputError(f"initial_peak = {self.initial_peak!r}: expected a non-zero peak (m) or None")
        if self.sign_prior is not None and not (math.isfinite(self.sign_prior) and self.sign_prior != 0):
            raise InputError(f"sign_prior = {self.sign_prior!r}: expected a non-zero pressure (Pa) or None")
        _as_positive("load_std", self.load_std, allow_inf=True)
        _as_positive("deflection_std", self.deflection_std, allow_zero=True)
        _as_positive("velocity_std", self.velocity_std, allow_zero=True)
        _as_positive("load_change", self.load_change, allow_zero=True)
        _as_positive("load_change_time", self.load_change_time)
        if self.modes is not None and (int(self.modes) != self.modes or self.modes < 1):
            raise InputError(f"modes = {self.modes!r}: expected a positive integer or None (all modes)")
        if self.structure not in _STRUCTURES:
            raise InputError(f"structure = {self.structure!r}: expected one of {', '.join(_STRUCTURES)}")
        if int(self.symmetrize_every) != self.symmetrize_every or self.symmetrize_every < 1:
            raise InputError(f"symmetrize_every = {self.symmetrize_every!r}: expected a positive integer")

    @classmethod
    def seed(cls, regularization: float = 1.0, **changes: Any) -> JEKFSettings:
        """The seed-faithful filter: ``R = 1e-4``, uniform ``initial_load`` prior (200 Pa), the bubble."""
        return cls(regularization=regularization, **changes)

    @classmethod
    def tuned(cls, regularization: float = 1.0, **changes: Any) -> JEKFSettings:
        """The "tuned" filter: zero initial load, ``R`` from the data's noise level."""
        base = {"initial_load": 0.0, "measurement_variance": None}
        base.update(changes)
        return cls(regularization=regularization, **base)

    def replace(self, **changes: Any) -> JEKFSettings:
        return dataclasses.replace(self, **changes)

    @property
    def process_intensity(self) -> float:
        """Gelb's ``Qd_ii = Δf^2 / Δt`` (Pa^2/s)."""
        return self.load_change**2 / self.load_change_time


def joint_generator(model: MembraneModel) -> np.ndarray:
    """Continuous joint matrix ``[[A, B], [0, 0]]`` of the state ``[z, z', f]`` (eq. 6.22), dense."""
    ss = model.system.state_space()
    n = model.n
    gen = np.zeros((3 * n, 3 * n))
    gen[: 2 * n, : 2 * n] = ss.A
    gen[: 2 * n, 2 * n :] = ss.B
    return gen


def joint_transition(model: MembraneModel, dt: float) -> np.ndarray:
    """Joint transition ``F_hat = expm([[A, B], [0, 0]] dt)`` (eq. 6.24): ONE augmented exponential.

    Its blocks are ``[[F, G], [0, I]]`` with ``F, G`` the exact zero-order hold of the plant: the
    load is held over the step. Dense ``(3n, 3n)``; for the fast filter see :class:`JointEKF`.
    """
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"dt = {dt!r}: expected a positive sample period (s)")
    return sla.expm(joint_generator(model) * dt)


def _modal_blocks(omega: np.ndarray, damping: np.ndarray, dt: float) -> np.ndarray:
    """Per-mode joint transition ``expm([[0, 1, 0], [-w^2, -c, 1], [0, 0, 0]] dt)``, shape (r, 3, 3).

    The same augmented exponential as :func:`joint_transition`, block-diagonalised by the modes.
    """
    gen = np.zeros((omega.size, 3, 3))
    gen[:, 0, 1] = 1.0
    gen[:, 1, 0] = -(omega**2)
    gen[:, 1, 1] = -damping
    gen[:, 1, 2] = 1.0
    return sla.expm(gen * dt)


class JointEKF:
    """Step-able joint EKF on the membrane (``setup`` / ``step`` / ``run``).

    Parameters
    ----------
    model : MembraneModel
        The estimator's model (its mesh is the estimator's mesh).
    settings : JEKFSettings, optional
        Default: the seed-faithful :meth:`JEKFSettings.seed` with ``lambda = 1``.
    dt : float, optional
        Default sample period (s) for :meth:`step` without a time; default the problem's ``dt``.

    Examples
    --------
    >>> ekf = JointEKF(model, JEKFSettings.tuned(regularization=1e-9))   # doctest: +SKIP
    >>> result = ekf.run(measurements)                                  # doctest: +SKIP
    >>> ekf.setup(measurement_variance=sigma**2); ekf.step(y0, t=0.0); ekf.step(y1)  # doctest: +SKIP
    """

    def __init__(self, model: MembraneModel, settings: JEKFSettings | None = None, dt: float | None = None) -> None:
        if not isinstance(model, MembraneModel):
            raise InputError(f"model: expected a MembraneModel, got {type(model).__name__}")
        self.model = model
        self.settings = JEKFSettings.seed() if settings is None else settings
        if not isinstance(self.settings, JEKFSettings):
            raise InputError(f"settings: expected JEKFSettings, got {type(self.settings).__name__}")
        self.dt = float(model.problem.identification.dt if dt is None else dt)
        _as_positive("dt", self.dt)
        self.n = model.n
        self.sensors = model.sensors
        self.p = len(self.sensors)
        s = self.settings
        t0 = time.perf_counter()
        if s.structure == "modal":
            modal = model.modal(None if s.modes is None else min(int(s.modes), self.n))
            self.r = modal.count
            self._phi = modal.shapes  # (n, r), mass-orthonormal
            self._omega = modal.omega
            self._cdamp = modal.damping
            self._areal = model.problem.material.areal_density
            # q = Phi^T (rho h M) z ;  g = Phi^T M f ;  f = rho h Phi g
            self._to_q = np.asarray((model.mass @ self._phi).T)
            self._to_g = np.asarray((model.gram @ self._phi).T)
            self.size = 3 * self.r
            self._qidx = slice(0, self.size, 3)
            self._vidx = slice(1, self.size, 3)
            self._gidx = slice(2, self.size, 3)
        else:
            self.r = self.n
            self.size = 3 * self.n
            self._generator = joint_generator(model)
            self._qidx = slice(0, self.n)
            self._vidx = slice(self.n, 2 * self.n)
            self._gidx = slice(2 * self.n, 3 * self.n)
        self._transitions: dict[float, np.ndarray] = {}
        self._lift_weights = self._load_weights(model.basis_integrals)
        self.build_seconds = time.perf_counter() - t0
        self._ready = False

    # -- coordinates -----------------------------------------------------------------------
    def _load_weights(self, a: np.ndarray) -> np.ndarray:
        """Vector ``w`` on the load entries of the state with ``a^T f = w^T s_load``."""
        if self.settings.structure == "modal":
            return self._areal * (self._phi.T @ a)
        return np.asarray(a, dtype=float)

    def _state_from_physical(self, z: np.ndarray, v: np.ndarray, f: np.ndarray) -> np.ndarray:
        x = np.empty(self.size)
        if self.settings.structure == "modal":
            x[self._qidx], x[self._vidx], x[self._gidx] = self._to_q @ z, self._to_q @ v, self._to_g @ f
        else:
            x[self._qidx], x[self._vidx], x[self._gidx] = z, v, f
        return x

    def _deflection(self, x: np.ndarray) -> np.ndarray:
        return self._phi @ x[self._qidx] if self.settings.structure == "modal" else x[self._qidx].copy()

    def _velocity(self, x: np.ndarray) -> np.ndarray:
        return self._phi @ x[self._vidx] if self.settings.structure == "modal" else x[self._vidx].copy()

    def _load(self, x: np.ndarray) -> np.ndarray:
        if self.settings.structure == "modal":
            return self._areal * (self._phi @ x[self._gidx])
        return x[self._gidx].copy()

    def _block_covariance(self, cov_z: np.ndarray, cov_v: np.ndarray, cov_f: np.ndarray) -> np.ndarray:
        """Block-diagonal prior in filter coordinates from physical blocks."""
        P = np.zeros((self.size, self.size))
        if self.settings.structure == "modal":
            tq, tg = self._to_q, self._to_g
            blocks = ((self._qidx, tq @ cov_z @ tq.T), (self._vidx, tq @ cov_v @ tq.T), (self._gidx, tg @ cov_f @ tg.T))
        else:
            blocks = ((self._qidx, cov_z), (self._vidx, cov_v), (self._gidx, cov_f))
        for idx, block in blocks:
            P[idx, idx] = 0.5 * (block + block.T)
        return P

    def transition(self, dt: float) -> np.ndarray:
        """Joint transition for a step of ``dt``: ``(r, 3, 3)`` per-mode blocks, or dense ``(3n, 3n)``."""
        key = round(float(dt), 12)
        tr = self._transitions.get(key)
        if tr is None:
            if self.settings.structure == "modal":
                tr = _modal_blocks(self._omega, self._cdamp, dt)
            else:
                tr = sla.expm(self._generator * dt)
            if len(self._transitions) > 64:  # irregular sampling: do not grow without bound
                self._transitions.clear()
            self._transitions[key] = tr
        return tr

    def _process_noise(self, dt: float) -> np.ndarray | None:
        """Load-block process noise over ``dt`` (Gelb: ``Qd dt`` per coefficient), filter coordinates."""
        q = self.settings.process_intensity
        if q == 0.0:
            return None
        if self.settings.structure == "modal":
            return q * dt * (self._to_g @ self._to_g.T)
        return q * dt * np.eye(self.n)

    # -- prior -------------------------------------------------------------------------------
    def prior_load_covariance(self) -> np.ndarray:
        """``P0_d = (P0d_tilde^-1 + lambda Lam)^-1`` in load coefficients (eq. 6.46), dense ``(n, n)``."""
        s = self.settings
        prec = s.regularization * self.model.regularizer.toarray()
        if math.isfinite(s.load_std):
            prec[np.diag_indices_from(prec)] += 1.0 / s.load_std**2
        try:
            c = sla.cho_factor(prec, lower=True)
        except np.linalg.LinAlgError as exc:
            raise SolverError("cholesky", "not positive definite", "P0d_tilde^-1 + lambda Lam must be SPD") from exc
        return sla.cho_solve(c, np.eye(self.n))

    @property
    def initial_load_value(self) -> float:
        """Uniform prior mean of the pressure, Pa."""
        s = self.settings
        return self.model.problem.identification.initial_load if s.initial_load is None else float(s.initial_load)

    @property
    def initial_peak(self) -> float:
        """Signed peak of the initial bubble, m (see :class:`JEKFSettings`)."""
        s, ident = self.settings, self.model.problem.identification
        if s.initial_peak is not None:
            return float(s.initial_peak)
        known = float(getattr(ident, "initial_deflection", 0.0) or 0.0)
        if known != 0.0:
            return known
        sign = s.sign_prior
        if sign is None:
            sign = self.initial_load_value if self.initial_load_value != 0 else ident.initial_load
        return math.copysign(DEFAULT_PEAK, sign)

    def initial_guess(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Prior mean ``(z0, v0, f0)``: the signed bubble, zero velocity, the uniform load (projected)."""
        prob = self.model.problem
        load = self.initial_load_value
        z0 = self.model.project(bubble(prob.width, prob.height, self.initial_peak))
        f0 = self.model.project(lambda x, y: np.full_like(x, load)) if load != 0.0 else np.zeros(self.n)
        return z0, np.zeros(self.n), f0

    def setup(
        self,
        initial_deflection: np.ndarray | None = None,
        initial_velocity: np.ndarray | None = None,
        initial_load: np.ndarray | None = None,
        measurement_variance: float | np.ndarray | None = None,
        t0: float = 0.0,
    ) -> JointEKF:
        """Initialise mean and covariance at time ``t0`` (defaults from :meth:`initial_guess`).

        ``measurement_variance`` overrides the settings' ``R`` (needed when the settings say
        ``None``, i.e. "from the data": :meth:`run` fills it from the measurements).
        """
        z0, v0, f0 = self.initial_guess()
        z0 = z0 if initial_deflection is None else self._vector("initial_deflection", initial_deflection)
        v0 = v0 if initial_velocity is None else self._vector("initial_velocity", initial_velocity)
        f0 = f0 if initial_load is None else self._vector("initial_load", initial_load)
        R = self.settings.measurement_variance if measurement_variance is None else measurement_variance
        if R is None:
            raise InputError(
                "measurement_variance = None: the settings take R from the data; pass measurement_variance "
                "to setup() or use run(measurements)"
            )
        R = np.broadcast_to(np.asarray(R, dtype=float), (self.p,)).copy() if np.ndim(R) <= 1 else None
        if R is None or not np.all(np.isfinite(R) & (R > 0)):
            raise InputError(f"measurement_variance: expected {self.p} positive variances (or one)")
        self.R = R
        s = self.settings
        eye = np.eye(self.n)
        self.x = self._state_from_physical(z0, v0, f0)
        self.P = np.ascontiguousarray(
            self._block_covariance(s.deflection_std**2 * eye, s.velocity_std**2 * eye, self.prior_load_covariance())
        )
        self._work = (np.empty_like(self.P), np.empty_like(self.P))
        self.t = float(t0)
        self._started = False
        self._steps = 0
        self._updates = 0
        self._skipped = 0
        self.loglik = 0.0
        self.nis_sum = 0.0
        self.innovation_count = 0
        self.last_nis = float("nan")
        self.last_innovation = np.full(self.p, np.nan)
        self._ready = True
        return self

    def _vector(self, name: str, v) -> np.ndarray:
        arr = np.asarray(v, dtype=float)
        if arr.shape != (self.n,) or not np.all(np.isfinite(arr)):
            raise InputError(f"{name}: shape {arr.shape}, expected ({self.n},) finite coefficients")
        return arr

    # -- the filter ----------------------------------------------------------------------------
    def predict(self, dt: float) -> None:
        """Time update over ``dt``: ``x <- F x``, ``P <- F P F^T + Q`` (exact block-diagonal form)."""
        if dt <= 0:
            return
        tr = self.transition(dt)
        x, P = self.x, self.P
        if self.settings.structure == "modal":
            r = self.r
            self.x = np.matmul(tr, x.reshape(r, 3, 1)).reshape(-1)
            # F P F^T with F block-diagonal (3x3 per mode) = F (F P)^T for symmetric P: two batched
            # row operations. Only the q, q' rows change (the load rows of F are [0, 0, 1]).
            rows = np.ascontiguousarray(tr[:, :2, :])
            P3, A, B = P.reshape(r, 3, -1), self._work[0], self._work[1]
            A3 = A.reshape(r, 3, -1)
            A3[:, 2, :] = P3[:, 2, :]
            np.matmul(rows, P3, out=A3[:, :2, :])
            np.copyto(B, A.T)
            B3 = B.reshape(r, 3, -1)
            P3[:, 2, :] = B3[:, 2, :]
            np.matmul(rows, B3, out=P3[:, :2, :])
        else:
            self.x = tr @ x
            self.P = tr @ P @ tr.T
        Q = self._process_noise(dt)
        if Q is not None:
            self.P[self._gidx, self._gidx] += Q
        self.t += dt

    def update(self, y: np.ndarray) -> bool:
        """Measurement update with the finite entries of ``y`` (Joseph form); ``False`` if none."""
        y = np.asarray(y, dtype=float)
        if y.shape != (self.p,):
            raise InputError(f"y: shape {y.shape}, expected ({self.p},) sensor values")
        ok = np.isfinite(y)
        if not ok.any():
            self._skipped += 1
            self.last_nis = float("nan")
            self.last_innovation = np.full(self.p, np.nan)
            return False
        z = self._deflection(self.x)
        mats = [C for C, use in zip(self.sensors.matrices, ok) if use]
        Cz = np.stack([C @ z for C in mats])  # (m, n)
        h = Cz @ z
        jac = 2.0 * Cz
        Hq = jac @ self._phi if self.settings.structure == "modal" else jac  # (m, r)
        P = self.P
        # U = P H^T with H non-zero on the deflection entries only; P symmetric -> U^T = Hq P[q, :]
        U = np.ascontiguousarray((Hq @ P[self._qidx, :]).T)  # (N, m)
        S = Hq @ U[self._qidx, :]
        S = 0.5 * (S + S.T) + np.diag(self.R[ok])
        try:
            cS = sla.cho_factor(S, lower=True)
        except np.linalg.LinAlgError as exc:
            raise SolverError("jekf", "innovation covariance not positive definite", "check R > 0") from exc
        # S is only m x m (m <= p sensors): invert it and multiply, rather than a triangular solve
        # with N right-hand sides (a threaded BLAS call that stalls on a busy machine).
        Sinv = sla.cho_solve(cS, np.eye(S.shape[0]))
        Sinv = 0.5 * (Sinv + Sinv.T)
        K = U @ Sinv  # (N, m)
        e = y[ok] - h
        self.last_innovation = np.full(self.p, np.nan)
        self.last_innovation[ok] = e
        # Innovation statistics (prediction-error decomposition of the likelihood): lambda rules.
        nis = float(e @ Sinv @ e)
        logdet = 2.0 * float(np.sum(np.log(np.diag(cS[0]))))
        self.last_nis = nis
        self.nis_sum += nis
        self.innovation_count += int(ok.sum())
        self.loglik += -0.5 * (nis + logdet + ok.sum() * math.log(2 * math.pi))
        self.x = self.x + K @ e
        # Joseph form (I - K H) P (I - K H)^T + K R K^T, expanded exactly as
        # P - K U^T - U K^T + K S K^T  =  P - [K, U] [U - K S, K]^T : one rank-2m BLAS update in place.
        W = np.asfortranarray(np.hstack([K, U]))
        V = np.asfortranarray(np.hstack([U - K @ S, K]))
        # P is C-ordered and symmetric: update its transpose (Fortran view) in place, P^T -= V W^T.
        PT = dgemm(-1.0, V, W, beta=1.0, c=P.T, trans_b=True, overwrite_c=True)
        if not np.shares_memory(PT, P):  # pragma: no cover - BLAS wrapper copied; keep correctness
            self.P = np.ascontiguousarray(PT.T)
        self._updates += 1
        return True

    def _symmetrize(self) -> None:
        # Round-off only: the updates are symmetric in exact arithmetic.
        work = self._work[0]
        np.add(self.P, self.P.T, out=work)
        np.multiply(work, 0.5, out=self.P)

    def step(self, y: np.ndarray, t: float | None = None) -> np.ndarray:
        """Advance to the sample time ``t`` (default: one ``dt`` later; the first call uses ``t0``),
        then update with ``y`` (NaN entries are skipped; an all-NaN sample is prediction only).

        Returns the posterior load coefficients (deflection basis).
        """
        if not self._ready:
            self.setup()
        if t is None:
            dt = self.dt if self._started else 0.0
        else:
            dt = float(t) - self.t
            if dt < -1e-12 * max(1.0, abs(self.t)):
                raise InputError(f"t = {t!r}: earlier than the filter's time {self.t!r}")
        self.predict(dt)
        self._started = True
        self.update(y)
        self._steps += 1
        if self._steps % self.settings.symmetrize_every == 0:
            self._symmetrize()
        return self.load

    # -- current estimate ----------------------------------------------------------------------
    @property
    def load(self) -> np.ndarray:
        """Posterior load coefficients ``f`` (deflection basis, ``P ≈ Σ f_i phi_i``)."""
        return self._load(self.x)

    @property
    def deflection(self) -> np.ndarray:
        return self._deflection(self.x)

    @property
    def velocity(self) -> np.ndarray:
        return self._velocity(self.x)

    @property
    def lift(self) -> float:
        """``∫ P_hat`` (N)."""
        return float(self._lift_weights @ self.x[self._gidx])

    @property
    def lift_std(self) -> float:
        """1-sigma of the lift from the load block of ``P``: ``sqrt(a^T P_ff a)``."""
        w = self._lift_weights
        return float(np.sqrt(max(w @ (self.P[self._gidx, self._gidx] @ w), 0.0)))

    def load_covariance(self) -> np.ndarray:
        """Posterior covariance of the load coefficients ``f`` (dense ``(n, n)``)."""
        Pg = self.P[self._gidx, self._gidx]
        if self.settings.structure == "modal":
            T = self._areal * self._phi
            return T @ Pg @ T.T
        return Pg.copy()

    # -- batch ---------------------------------------------------------------------------------
    def run(self, measurements: Measurements, setup: bool = True, progress: bool = False) -> IdentificationResult:
        """Filter a whole record; returns the posterior histories at every sample time.

        ``info`` holds: ``settings`` (dict), ``structure``, ``modes``, ``R`` (variances used),
        ``R_source``, ``initial_load_Pa``, ``initial_peak_m``, ``updates``, ``skipped`` (all-NaN
        samples: prediction only), ``innovations`` ``(N, p)`` (``y_k - h(x_k^-)``, NaN where
        missing), ``nis`` (per sample, NaN when skipped), ``mean_nis`` (per scalar measurement; ~1
        when the filter's statistics match the data), ``loglik`` (Gaussian prediction-error
        log-likelihood of the data), ``seconds_per_sample`` (wall) and ``cpu_seconds_per_sample``
        (process CPU time: less sensitive to a busy machine), ``sample_period``, ``build_s``.
        """
        if not isinstance(measurements, Measurements):
            raise InputError(f"measurements: expected Measurements, got {type(measurements).__name__}")
        names = tuple(measurements.sensor_names)
        if names != tuple(self.sensors.names):
            raise InputError(f"measurements.sensor_names = {names!r}: expected {tuple(self.sensors.names)!r}")
        if measurements.count == 0:
            raise InputError("measurements: no samples")
        R_source = "settings"
        if setup:
            R = self.settings.measurement_variance
            if R is None:
                from wingopt.estimation.jekf_tuning import noise_variance

                R, R_source = noise_variance(measurements, self.model)
            self.setup(measurement_variance=R, t0=float(measurements.t[0]))
        elif not self._ready:
            raise InputError("run(setup=False): call setup() first")
        else:
            R_source = "setup()"
        N = measurements.count
        loads = np.empty((N, self.n))
        defl = np.empty((N, self.n))
        lift = np.empty(N)
        lift_std = np.empty(N)
        nis = np.empty(N)
        innov = np.empty((N, self.p))
        iterator = range(N)
        if progress:
            from tqdm import tqdm

            iterator = tqdm(iterator, desc="jekf", unit="sample", leave=False)
        t0, c0 = time.perf_counter(), time.process_time()
        for k in iterator:
            self.step(measurements.values[k], t=float(measurements.t[k]))
            loads[k] = self.load
            defl[k] = self.deflection
            lift[k] = self.lift
            lift_std[k] = self.lift_std
            nis[k] = self.last_nis
            innov[k] = self.last_innovation
        self._symmetrize()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        s = self.settings
        info = {
            "settings": dataclasses.asdict(s),
            "structure": s.structure,
            "modes": self.r,
            "R": self.R.tolist(),
            "R_source": R_source,
            "initial_load_Pa": self.initial_load_value,
            "initial_peak_m": self.initial_peak,
            "updates": self._updates,
            "skipped": self._skipped,
            "nis": nis,
            "innovations": innov,
            "mean_nis": self.nis_sum / max(self.innovation_count, 1),
            "loglik": self.loglik,
            "seconds_per_sample": wall / N,
            "cpu_seconds_per_sample": cpu / N,
            "sample_period": float(np.median(np.diff(measurements.t))) if N > 1 else self.dt,
            "build_s": self.build_seconds,
        }
        log.debug("jekf: %d samples in %.2f s (%.2f ms/sample), lambda %.3g", N, wall, 1e3 * wall / N, s.regularization)
        return IdentificationResult(
            method="jekf",
            t=measurements.t.copy(),
            load=loads,
            deflection=defl,
            lift=lift,
            lift_std=lift_std,
            regularization=float(s.regularization),
            wall_s=wall,
            info=info,
        )


def jekf_identify(
    model: MembraneModel,
    measurements: Measurements,
    settings: JEKFSettings | None = None,
    **changes: Any,
) -> IdentificationResult:
    """One-shot JEKF: ``JointEKF(model, settings.replace(**changes)).run(measurements)``.

    Parameters
    ----------
    model : MembraneModel
        Estimator model.
    measurements : Measurements
        The record (NaN = missing).
    settings : JEKFSettings, optional
        Default :meth:`JEKFSettings.seed`; keyword ``changes`` override its fields, e.g.
        ``jekf_identify(model, meas, regularization=1e-8)``.
    """
    settings = JEKFSettings.seed() if settings is None else settings
    if changes:
        try:
            settings = settings.replace(**changes)
        except TypeError as exc:
            raise InputError(f"jekf_identify: {exc}") from exc
    return JointEKF(model, settings).run(measurements)
