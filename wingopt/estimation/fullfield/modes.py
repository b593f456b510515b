"""The loaded membrane's first two frequencies from the frames: what they say about the prestrains.

A buffeting record's frames, projected on the loaded membrane's modes, give each mode's history;
its spectrum peaks at that mode's loaded frequency. The frequencies depend on the prestrains,
``f_mn^2 ∝ Tx (m/a)^2 + Ty (n/b)^2`` plus the load's stiffening, so the first mode (11) and the
x-antisymmetric one (21, which a leading-edge-peaked load excites) carry the prestrains' ratio,
which the frames' rank-one dynamics (:mod:`.tension`) leave to the prior. This module measures that
and says whether it is enough:

1. the loaded modes: the generalised eigenproblem of the reduced FvK tangent about the frames' mean
   deflection (:meth:`.system.PressureFromShape.tangent`, the load's stiffening included) and the
   mass, at the estimated prestrains;
2. the frames' fits projected on the first two (mass-orthonormal), each history's periodogram
   fitted by Whittle's likelihood with a damped oscillator driven by a low-pass forcing,
   ``S(f) = A |H(f)|^2 (1 + (f/fc)^2)^-n + N`` (frequency, damping, level, corner, order and noise
   free; the corner's and order's priors :mod:`wingopt.estimation.steady.buffeting`'s); the
   frequency's std from the Laplace approximation;
3. the model's sensitivity ``d f / d e0`` about the same mean shape, and the prestrains' covariance
   that the two measured frequencies alone would give (a model-form floor of
   :data:`FREQUENCY_MODEL_FORM_REL` added to each frequency's variance).

Measured (docs/dic.md): on 1.5 s records the two frequencies come out within 1.0 % and 1.3 %
(1 sd), and ``d log f / d log e0`` is 0.1-0.2 with the two modes' rows nearly parallel: each
prestrain within 3 % would need each frequency to about 0.1 %. The result is a check (measured
against predicted frequencies) and a statement of what the frames identify; the estimator does not
move the prestrains with it (``identifies`` is false on every record measured).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.optimize import minimize

from wingopt.estimation.fullfield.data import FieldData
from wingopt.estimation.fullfield.steady import _hessian
from wingopt.estimation.fullfield.system import PressureFromShape
from wingopt.estimation.steady.buffeting import FC_REF, NUISANCE, ORDER_REF

__all__ = ["ModalCheck", "modal_check", "FREQUENCY_MODEL_FORM_REL", "IDENTIFIED_REL", "MIN_SAMPLES"]

log = logging.getLogger(__name__)

FREQUENCY_MODEL_FORM_REL = 0.003
"""Model-form std of a loaded frequency, relative. Measured on the (0.06, 0.04) tunnel-LE buffeting
record (FvK 49x25 truth, exponential integrator, 8 substeps): the truth's own loaded tangent gives
107.87 and 127.20 Hz, the estimator's about the frames' mean shape at the true prestrains 107.72 and
127.06 (-0.14 %, -0.11 %), and a transfer fit between the two modal histories 126.77 (-0.34 %)."""

IDENTIFIED_REL = 0.015
"""The frequencies identify the prestrains when each one's std (relative) is at most this (3 % at 2 sd)."""

MIN_SAMPLES = 128
"""Fewer frames give no spectrum worth fitting."""

FLOOR_STD = 2.0
"""Prior std of the log noise floor of a modal spectrum, about its 5 % quantile (the floor may lie
below the signal everywhere: without a prior it is unbounded below)."""

DAMPING = (0.05, 1.0)
"""Prior of a mode's damping ratio: median and std of its log (a membrane in air: 2-15 %; the problem's
Kelvin-Voigt and viscous damping give 6 % at 110 Hz). It and :data:`BIN` keep the fit off most of a
periodogram's spikes; on 40 synthetic 1.5 s records of a 127 Hz mode one still locked onto a noise
hump 12 Hz off at 1 % damping (a Laplace band does not see a second optimum)."""

ENBW = 1.5
"""The Hann window's equivalent noise bandwidth, in bins: neighbouring periodogram ordinates are
correlated and Whittle's likelihood, which treats them as independent, overstates the information."""

BIN = 3
"""Periodogram ordinates averaged per bin before the fit (1.5 s at 300 Hz: bins of 2 Hz, a resonance
of 5 % damping is 11 Hz wide)."""

BAND = (0.15, 0.97)
"""The fitted band, as fractions of the Nyquist frequency (the forcing's low end and aliasing left out)."""


@dataclass(frozen=True, eq=False)
class ModalCheck:
    """The loaded first two frequencies: measured from the frames and predicted; what they identify.

    Attributes
    ----------
    measured, measured_std : ndarray (2,)
        Frequencies (Hz) of the first two loaded modes fitted to the frames' modal histories, and
        their Laplace std.
    damping : ndarray (2,)
        The fitted damping ratios.
    predicted : ndarray (2,)
        The model's loaded frequencies (Hz) at ``prestrain`` about the frames' mean deflection.
    prestrain : ndarray (2,)
        The prestrains the modes were computed at (the estimator's).
    sensitivity : ndarray (2, 2)
        ``d f_i / d e0_j`` (Hz per unit prestrain).
    prestrain_std : ndarray (2,)
        Each prestrain's std from the two frequencies alone (model-form floor included).
    correlation : float
        Their correlation.
    """

    measured: np.ndarray
    measured_std: np.ndarray
    damping: np.ndarray
    predicted: np.ndarray
    prestrain: np.ndarray
    sensitivity: np.ndarray
    prestrain_std: np.ndarray
    correlation: float

    @property
    def prestrain_std_rel(self) -> np.ndarray:
        return self.prestrain_std / self.prestrain

    @property
    def identifies(self) -> bool:
        """Whether the frequencies pin each prestrain to :data:`IDENTIFIED_REL`."""
        return bool(np.all(self.prestrain_std_rel <= IDENTIFIED_REL))

    @property
    def misfit(self) -> np.ndarray:
        """Measured minus predicted, in units of the measured std (model-form floor included)."""
        return (self.measured - self.predicted) / self._std

    @property
    def _std(self) -> np.ndarray:
        return np.sqrt(self.measured_std**2 + (FREQUENCY_MODEL_FORM_REL * self.measured) ** 2)

    @property
    def needed_rel(self) -> float:
        """Relative std each frequency would need for each prestrain within :data:`IDENTIFIED_REL`."""
        G = np.linalg.inv(self.sensitivity * (self.prestrain[None, :] / self.measured[:, None]))  # d log e / d log f
        return float(IDENTIFIED_REL / np.sqrt(np.max(np.sum(G**2, axis=1))))

    def as_dict(self) -> dict:
        return {
            "frequencies_measured_hz": self.measured.tolist(),
            "frequencies_std_hz": self.measured_std.tolist(),
            "damping_ratio": self.damping.tolist(),
            "frequencies_predicted_hz": self.predicted.tolist(),
            "misfit_sd": self.misfit.tolist(),
            "prestrain_std_from_frequencies": self.prestrain_std.tolist(),
            "prestrain_std_rel_from_frequencies": self.prestrain_std_rel.tolist(),
            "correlation_from_frequencies": self.correlation,
            "frequency_std_rel_needed": self.needed_rel,
            "identifies_prestrains": self.identifies,
            "note": "f11, f21 from the frames' modal spectra: a check and a statement, not used for the prestrains",
        }


def loaded_modes(system: PressureFromShape, prestrain, count: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The first ``count`` loaded frequencies (Hz) and mass-orthonormal modes ``(n, count)`` about the
    system's deflection (the reduced FvK tangent, the load's stiffening included)."""
    lam, V = sla.eigh(system.tangent(prestrain), system.mass, subset_by_index=[0, count - 1])
    return np.sqrt(np.maximum(lam, 0.0)) / (2 * np.pi), V


def _uniform(t: np.ndarray, Q: np.ndarray) -> tuple[float, np.ndarray]:
    dt = float(np.median(np.diff(t)))
    n = int(round((t[-1] - t[0]) / dt)) + 1
    if n == t.size:
        return dt, Q
    grid = t[0] + dt * np.arange(n)
    return dt, np.stack([np.interp(grid, t, Q[:, j]) for j in range(Q.shape[1])], axis=1)


def _spectrum(q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided periodogram (Hann window) of a detrended history."""
    n = q.size
    x = q - np.polyval(np.polyfit(np.arange(n), q, 1), np.arange(n))
    win = np.hanning(n)
    F = np.fft.rfft(x * win)
    return np.fft.rfftfreq(n, dt), 2.0 * dt * np.abs(F) ** 2 / np.sum(win**2)


def _oscillator(f: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``A |H|^2 (1 + (f/fc)^2)^-n + N``, ``p = log(f0, zeta, A, fc, n, N)``; ``H`` per unit ``omega0^2``
    (the forcing's low-pass spectrum as :mod:`wingopt.estimation.steady.buffeting`'s)."""
    f0, z, A, fc, order, N = np.exp(p)
    r = f / f0
    return A / ((1 - r**2) ** 2 + (2 * z * r) ** 2) * (1 + (f / fc) ** 2) ** -order + N


def _fit_frequency(f: np.ndarray, I: np.ndarray, guess: float) -> tuple[float, float, float]:
    """Whittle fit of one modal periodogram: ``(frequency, its std, damping ratio)`` (Hz); the std is
    infinite where the likelihood has no proper maximum (no peak in the band)."""
    floor = np.log(max(float(np.quantile(I, 0.05)), 1e-300))

    m = (f.size // BIN) * BIN  # bins of BIN ordinates: one ordinate's spike does not pass for a resonance
    f, I = f[:m].reshape(-1, BIN).mean(axis=1), I[:m].reshape(-1, BIN).mean(axis=1)

    def nll(p) -> float:  # Whittle's on the binned periodogram, with the priors of the floor and the damping
        S = _oscillator(f, p)
        prior = (
            ((p[5] - floor) / FLOOR_STD) ** 2
            + ((p[1] - np.log(DAMPING[0])) / DAMPING[1]) ** 2
            + ((p[3] - np.log(FC_REF)) / NUISANCE["log_fc"]) ** 2
            + ((p[4] - np.log(ORDER_REF)) / NUISANCE["order"]) ** 2
        )
        return BIN * float(np.sum(np.log(S) + I / S)) + 0.5 * prior

    level = float(np.median(I[f < guess * 0.6])) if np.any(f < guess * 0.6) else float(np.median(I))
    best = None
    for f0 in guess * np.array([0.85, 0.95, 1.05, 1.15]):
        p0 = np.array([np.log(f0), np.log(DAMPING[0]), np.log(level), np.log(FC_REF), np.log(ORDER_REF), floor])
        res = minimize(nll, p0, method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-6, "fatol": 1e-6})
        if best is None or res.fun < best.fun:
            best = res
    best = minimize(nll, best.x, method="BFGS", options={"gtol": 1e-6})
    f0, zeta = float(np.exp(best.x[0])), float(np.exp(best.x[1]))
    H = _hessian(nll, best.x, 1e-3)
    lam = np.linalg.eigvalsh(H) if np.all(np.isfinite(H)) else np.zeros(1)
    if lam.min() <= 0 or not f[0] < f0 < f[-1]:
        return f0, float("inf"), zeta
    return f0, f0 * float(np.sqrt(ENBW * np.linalg.inv(H)[0, 0])), zeta


def _from_frequencies(J: np.ndarray, var_f: np.ndarray) -> tuple[np.ndarray, float]:
    """The prestrains' std and correlation from frequencies of variance ``var_f`` (infinite: none)."""
    info = J.T @ (J / var_f[:, None])  # an infinite variance contributes nothing
    lam = np.linalg.eigvalsh(info)
    if not np.all(np.isfinite(info)) or lam.min() <= 1e-12 * max(lam.max(), 1e-300):
        return np.full(2, np.inf), 0.0
    cov = np.linalg.inv(info)
    s = np.sqrt(np.diag(cov))
    return s, float(cov[0, 1] / (s[0] * s[1]))


def modal_check(data: FieldData, system: PressureFromShape, prestrain) -> ModalCheck | None:
    """The first two loaded frequencies from the frames, against the model at ``prestrain`` (module docstring).

    Returns ``None`` when the record has fewer than :data:`MIN_SAMPLES` frames.
    """
    idx = np.flatnonzero(data.used)
    if idx.size < MIN_SAMPLES:
        return None
    e0 = np.asarray(prestrain, float)
    fm, V = loaded_modes(system, e0)
    Z = data.fit.coef[idx]
    dt, Q = _uniform(data.frames.t[idx], (Z - Z.mean(axis=0)) @ (system.mass @ V))
    nyq = 0.5 / dt
    meas, std, zeta = np.empty(2), np.empty(2), np.empty(2)
    for j in range(2):
        f, I = _spectrum(Q[:, j], dt)
        sel = (f > BAND[0] * nyq) & (f < BAND[1] * nyq)
        meas[j], std[j], zeta[j] = _fit_frequency(f[sel], I[sel], fm[j])
    J = np.empty((2, 2))
    for k in range(2):
        h = 1e-3 * e0[k]
        d = np.zeros(2)
        d[k] = h
        J[:, k] = (loaded_modes(system, e0 + d)[0] - loaded_modes(system, e0 - d)[0]) / (2 * h)
    s, corr = _from_frequencies(J, std**2 + (FREQUENCY_MODEL_FORM_REL * meas) ** 2)
    out = ModalCheck(meas, std, zeta, fm, e0, J, s, corr)
    log.info(
        "loaded frequencies: measured %.2f ± %.2f, %.2f ± %.2f Hz; predicted %.2f, %.2f; "
        "prestrains from them ± %.1f %%, ± %.1f %%",
        meas[0],
        std[0],
        meas[1],
        std[1],
        fm[0],
        fm[1],
        *(100 * out.prestrain_std_rel),
    )
    return out
