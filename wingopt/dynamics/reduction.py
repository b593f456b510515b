"""Reduced-order models for control: modal truncation with static correction.

The plate's damping ``Kd`` is not proportional, so its undamped modes do not decouple it. The
reduced model keeps the lowest ``r`` undamped modes ``Phi`` (M-orthonormal) with the *full*
projected damping block, and adds a static correction so that the steady state under any input
is the full model's, exactly::

    z ≈ Phi q + R u,     q'' + Dq q' + diag(omega^2) q = Bq u,     y = C Phi q + C R u
    Dq = Phi^T Kd Phi (full),   Bq = Phi^T b,   R = Zs - Phi Phi^T M Zs,   Zs = K^-1 b

``R`` is the residual flexibility (the part of each input's static field the kept modes miss,
M-orthogonal to them): the truncated modes respond quasi-statically, the classical mode
acceleration correction. At equilibrium ``Phi q = Phi diag(omega^-2) Bq u = Phi Phi^T M Zs u``,
so ``Phi q + R u = Zs u`` exactly. In a sampled loop the quasi-static part follows the input
held over the period: ``z`` at the end of period ``k`` is ``Phi q_{k+1} + R u_k``.

The alternative ``static_correction="ritz"`` (Dickens' modal truncation augmentation) appends the
residual fields to the basis instead and takes Ritz vectors of ``(K, M)`` on the enlarged space;
their stiff pseudo-modes (hundreds of Hz to kHz, nearly undamped) then ring in the prediction at
aliased frequencies that do not match the plant's, so the feedthrough form is the default.

The number of kept modes is chosen from an error tolerance: the smallest ``r`` for which the
frequency response ``u -> z`` of the reduced model, expanded to the full field, is within ``tol``
of the full model's in the M-norm, relative, at every frequency of a grid on ``[0, band_hz]``.
Full-field quantities are evaluated by the caller on the full FE model.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.dynamics.statespace import SecondOrderSystem, StateSpace, zoh
from wingopt.errors import InputError

__all__ = [
    "ReducedModel",
    "reduce_system",
    "reduced_basis",
    "static_residual",
    "modes_below",
    "frequency_response",
    "CORRECTIONS",
]

log = logging.getLogger(__name__)

CORRECTIONS = ("residual", "ritz", "none")
"""Static corrections: quasi-static residual feedthrough (default), Ritz augmentation, none."""


@dataclass(frozen=True, eq=False)
class ReducedModel:
    """``q'' + Dq q' + diag(omega^2) q = Bq u`` with ``z ≈ Phi q + R u`` and ``y ≈ C Phi q + C R u``.

    Attributes
    ----------
    basis : ndarray (n, r)
        ``Phi``, M-orthonormal and K-orthogonal: ``Phi^T M Phi = I``, ``Phi^T K Phi = diag(omega^2)``.
        With the ``"ritz"`` correction the last columns are the static-correction Ritz vectors.
    omega : ndarray (r,)
        Circular frequencies (rad/s) of the columns of ``basis``.
    damping : ndarray (r, r)
        ``Phi^T Kd Phi`` (full: the damping is not proportional).
    input_matrix : ndarray (r, m)
        ``Phi^T b``.
    residual : ndarray (n, m)
        ``R``: quasi-static residual field per unit input, M-orthogonal to ``basis`` (zeros when the
        correction is ``"ritz"`` or ``"none"``).
    output_matrix : ndarray (p, r) or None
        ``C Phi`` for an output ``y = C z`` (the patch sensors).
    output_feedthrough : ndarray (p, m) or None
        ``C R``.
    n_modes : int
        Number of true modes kept.
    correction : str
        One of :data:`CORRECTIONS`.
    error : float
        Largest relative M-norm error of the frequency response ``u -> z`` on the band grid.
    band_hz : float
        Upper end of the band the error was measured on.
    history : tuple of (int, float)
        ``(modes, error)`` for every size tried.
    """

    basis: np.ndarray
    omega: np.ndarray
    damping: np.ndarray
    input_matrix: np.ndarray
    residual: np.ndarray
    output_matrix: np.ndarray | None = None
    output_feedthrough: np.ndarray | None = None
    n_modes: int = 0
    correction: str = "residual"
    error: float = float("nan")
    band_hz: float = float("nan")
    history: tuple[tuple[int, float], ...] = field(default=(), repr=False)

    @classmethod
    def from_basis(
        cls,
        system: SecondOrderSystem,
        basis: np.ndarray,
        omega: np.ndarray,
        residual: np.ndarray,
        output: np.ndarray | None = None,
        **info,
    ) -> ReducedModel:
        """The reduced model of ``system`` on an M-orthonormal, K-orthogonal ``basis`` (see :func:`reduced_basis`).

        The damping is projected in full (``Phi^T Kd Phi``, symmetrised); ``output`` ``C`` is
        carried as ``C Phi`` and ``C R``. ``info`` sets the bookkeeping fields (``n_modes``, ...).
        """
        Dq = basis.T @ (system.damping @ basis)
        Bq = np.asarray(sp.csr_matrix(system.input_matrix).T @ basis).T
        C = None if output is None else np.asarray(output, dtype=float)
        return cls(
            basis=basis,
            omega=omega,
            damping=0.5 * (Dq + Dq.T),
            input_matrix=Bq,
            residual=residual,
            output_matrix=None if C is None else C @ basis,
            output_feedthrough=None if C is None else C @ residual,
            **info,
        )

    @property
    def size(self) -> int:
        """Number of reduced coordinates ``q`` (the state ``[q; q']`` has twice as many)."""
        return self.omega.size

    @property
    def n_states(self) -> int:
        return 2 * self.size

    @property
    def n_inputs(self) -> int:
        return self.input_matrix.shape[1]

    def state_space(self) -> StateSpace:
        """Continuous first-order form, state ``x = [q; q']``, output ``C Phi q + C R u`` (if known)."""
        r = self.size
        A = np.block([[np.zeros((r, r)), np.eye(r)], [-np.diag(self.omega**2), -self.damping]])
        B = np.vstack([np.zeros_like(self.input_matrix), self.input_matrix])
        if self.output_matrix is None:
            return StateSpace(A, B)
        C = np.hstack([self.output_matrix, np.zeros_like(self.output_matrix)])
        return StateSpace(A, B, C, self.output_feedthrough)

    def discretize(self, dt: float) -> StateSpace:
        """Exact zero-order hold (one augmented exponential) at period ``dt``; ``C, D`` carried over."""
        ct = self.state_space()
        F, G = zoh(ct.A, ct.B, dt)
        return StateSpace(F, G, ct.C, ct.D, dt=dt)

    def static_gain(self) -> np.ndarray:
        """``dq/du`` at equilibrium, ``diag(omega^-2) Bq``."""
        return self.input_matrix / self.omega[:, None] ** 2

    def coordinates(self, z: np.ndarray, mass) -> np.ndarray:
        """``q = Phi^T M z``: M-orthogonal projection of a field (or of each row of ``(nt, n)``)."""
        z = np.asarray(z, dtype=float)
        return np.asarray(mass @ z.T).T @ self.basis

    def expand(self, q: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Full field ``Phi q + R u`` (rows for histories ``(nt, r)``, ``(nt, m)``)."""
        z = np.asarray(q) @ self.basis.T
        if u is not None:
            z = z + np.asarray(u) @ self.residual.T
        return z

    def response(self, freqs_hz: np.ndarray) -> np.ndarray:
        """Reduced frequency response ``(Omega^2 - w^2 + i w Dq)^-1 Bq`` per frequency, ``(nf, r, m)``."""
        out = np.empty((len(freqs_hz), self.size, self.n_inputs), dtype=complex)
        K = np.diag(self.omega**2)
        for i, f in enumerate(freqs_hz):
            w = 2 * np.pi * f
            out[i] = np.linalg.solve(K - w**2 * np.eye(self.size) + 1j * w * self.damping, self.input_matrix)
        return out


def frequency_response(system: SecondOrderSystem, freqs_hz: np.ndarray) -> np.ndarray:
    """Full-order ``H(w) = (K - w^2 M + i w Kd)^-1 b`` at each frequency, shape ``(nf, n, m)``."""
    M, D, K = (sp.csc_matrix(a) for a in (system.mass, system.damping, system.stiffness))
    B = _dense(system.input_matrix).astype(complex)
    out = np.empty((len(freqs_hz), system.n, B.shape[1]), dtype=complex)
    for i, f in enumerate(freqs_hz):
        w = 2 * np.pi * f
        out[i] = spla.splu((K - w**2 * M + 1j * w * D).tocsc()).solve(B)
    return out


def _dense(a) -> np.ndarray:
    return a.toarray() if sp.issparse(a) else np.asarray(a, dtype=float)


def _relative_error(H: np.ndarray, MH: np.ndarray, W: np.ndarray, MW: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``||H - W X||_M / ||H||_M`` per frequency (Frobenius over inputs), without n-sized products per X.

    ``||H - W X||_M^2 = ||H||_M^2 - 2 Re tr(X^H W^T M H) + tr(X^H W^T M W X)``.
    """
    full2 = np.einsum("fij,fij->f", H.conj(), MH).real
    WMH = np.einsum("ir,fim->frm", W, MH)
    G = W.T @ MW
    cross = np.einsum("frm,frm->f", X.conj(), WMH).real
    quad = np.einsum("frm,rs,fsm->f", X.conj(), G, X).real
    return np.sqrt(np.maximum(full2 - 2 * cross + quad, 0.0) / full2)


def static_residual(system: SecondOrderSystem, shapes: np.ndarray, omega: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """What the kept modes miss of the static response to ``rhs``: ``K^-1 rhs - Phi diag(omega^-2) Phi^T rhs``.

    The mode-acceleration correction: M-orthogonal to ``shapes`` (M-orthonormal modes of
    ``system``), so ``Phi q + residual`` is the exact static field when ``q`` is the modal static
    response. ``rhs`` is ``(n,)`` or ``(n, m)``.
    """
    rhs = _dense(rhs)
    return system.static_solve(rhs) - shapes @ ((shapes.T @ rhs) / (omega[:, None] if rhs.ndim == 2 else omega) ** 2)


def reduced_basis(
    system: SecondOrderSystem, n_modes: int, correction: str = "residual"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Phi, omega, R)`` for one truncation of ``system`` to its lowest ``n_modes`` modes.

    Parameters
    ----------
    system : SecondOrderSystem
        The full model; its cached modes and static fields are used.
    n_modes : int
        Number of true modes kept.
    correction : {"residual", "ritz", "none"}
        ``"residual"``: the true modes and the quasi-static residual fields ``R`` of the inputs
        (:func:`static_residual` of ``B``); ``"ritz"``: the residual fields appended to the modes
        and Ritz vectors of ``(K, M)`` on the enlarged space (``R = 0``); ``"none"``: the modes
        alone (``R = 0``).

    Returns
    -------
    Phi : ndarray (n, r)
        M-orthonormal, K-orthogonal: ``Phi^T K Phi = diag(omega^2)``.
    omega : ndarray (r,)
        Circular frequencies, rad/s, ascending.
    R : ndarray (n, m)
        Residual fields per unit input (zeros unless ``"residual"``).
    """
    if correction not in CORRECTIONS:
        raise InputError(f"correction = {correction!r}: expected one of {', '.join(CORRECTIONS)}")
    omega, Phi = system.undamped_modes(n_modes)
    M = system.mass
    n, m = system.n, system.input_matrix.shape[1]
    if correction == "none":
        return Phi, omega, np.zeros((n, m))
    R = static_residual(system, Phi, omega, system.input_matrix)
    if correction == "residual":
        return Phi, omega, R
    # Ritz: M-orthonormalise the residual fields (dropping dependent directions), then diagonalise K.
    G = R.T @ (M @ R)
    g, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = g > 1e-12 * max(g.max(), 1e-300)
    T = Phi
    if keep.any():
        Rn = R @ (U[:, keep] / np.sqrt(g[keep]))
        Rn = Rn - Phi @ (Phi.T @ (M @ Rn))  # Gram–Schmidt twice against the modes
        T = np.hstack([Phi, Rn])
    Mt, Kt = T.T @ (M @ T), T.T @ (system.stiffness @ T)
    lam, X = sla.eigh(0.5 * (Kt + Kt.T), 0.5 * (Mt + Mt.T))
    return T @ X, np.sqrt(np.clip(lam, 0.0, None)), np.zeros((n, m))


def modes_below(system: SecondOrderSystem, band_hz: float, start: int = 8) -> int:
    """Number of undamped modes of ``system`` at or below ``band_hz`` (at least one).

    Asks the model's mode cache for more modes (doubling from ``start``) until one lies above
    the band or all are known.
    """
    top = system.n - 1
    count = min(start, top)
    while True:
        omega, _ = system.undamped_modes(count)
        if omega[-1] > 2 * np.pi * band_hz or count >= top:
            return max(int(np.count_nonzero(omega <= 2 * np.pi * band_hz)), 1)
        count = min(2 * count, top)


def _band_error(system: SecondOrderSystem, red: ReducedModel, freqs: np.ndarray, H, MH) -> float:
    """The largest relative M-norm error of ``red``'s response ``u -> z`` against the full one ``H`` on ``freqs``."""
    # The reduced field is W X with W = [Phi, R] and X = [H_r; I].
    W = np.hstack([red.basis, red.residual])
    m = red.residual.shape[1]
    X = np.concatenate([red.response(freqs), np.broadcast_to(np.eye(m), (len(freqs), m, m))], axis=1)
    return float(_relative_error(H, MH, W, np.asarray(system.mass @ W), X).max())


def reduce_system(
    system: SecondOrderSystem,
    *,
    output: np.ndarray | None = None,
    tol: float = 1e-2,
    band_hz: float = 50.0,
    n_freqs: int = 60,
    max_modes: int = 60,
    correction: str = "residual",
    n_modes: int | None = None,
) -> ReducedModel:
    """Reduce ``system`` by modal truncation with static correction, to the smallest size meeting ``tol``.

    Parameters
    ----------
    system : SecondOrderSystem
        Full FE model ``M z'' + Kd z' + K z = b u``.
    output : ndarray (p, n), optional
        Output map ``y = C z``, carried into the reduced model as ``C Phi`` and ``C R``.
    tol : float
        Largest allowed relative M-norm error of the frequency response ``u -> z`` on the band.
    band_hz : float
        Upper end of the band (e.g. the Nyquist frequency of the control loop). The grid holds
        ``n_freqs`` points from 0 Hz to ``band_hz`` plus every natural frequency inside the band.
    max_modes : int
        Largest number of modes tried; an :class:`InputError` is raised if ``tol`` is not met.
    correction : str
        ``"residual"`` (quasi-static feedthrough, default), ``"ritz"`` or ``"none"`` (plain
        truncation: the steady state is then not exact).
    n_modes : int, optional
        Keep exactly this many modes instead of searching (the error is still measured).

    Returns
    -------
    ReducedModel
        The reduced model with its measured error, the band and the sizes tried.
    """
    if correction not in CORRECTIONS:
        raise InputError(f"correction = {correction!r}: expected one of {', '.join(CORRECTIONS)}")
    if not (tol > 0 and band_hz > 0):
        raise InputError(f"tol = {tol!r}, band_hz = {band_hz!r}: expected positive numbers")
    n = system.n
    b = _dense(system.input_matrix)
    top = int(max_modes if n_modes is None else n_modes)
    if not 1 <= top <= n - b.shape[1] - 1:
        raise InputError(f"modes = {top}: expected 1..{n - b.shape[1] - 1}")
    omega_all, _ = system.undamped_modes(top)

    f_modes = omega_all / (2 * np.pi)
    freqs = np.unique(np.concatenate([np.linspace(0.0, band_hz, n_freqs), f_modes[f_modes <= band_hz]]))
    H = frequency_response(system, freqs)
    MH = np.stack([system.mass @ Hf for Hf in H])

    history = []
    for r in [top] if n_modes is not None else range(1, top + 1):
        red = ReducedModel.from_basis(system, *reduced_basis(system, r, correction))
        err = _band_error(system, red, freqs, H, MH)
        history.append((r, err))
        if err <= tol:
            break
    else:
        if n_modes is None:
            raise InputError(
                f"tol = {tol:g}: not met with {top} modes on 0..{band_hz:g} Hz (error {err:.3g}); "
                "raise max_modes or loosen tol"
            )
    log.info("reduced %d dofs to %d modes (%s correction), error %.2e on 0..%g Hz", n, r, correction, err, band_hz)
    return ReducedModel.from_basis(
        system,
        red.basis,
        red.omega,
        red.residual,
        output,
        n_modes=r,
        correction=correction,
        error=err,
        band_hz=float(band_hz),
        history=tuple(history),
    )
