"""The spectral data of a steady record: binned cross-periodograms of the fluctuation about the mean.

A wing in steady flow fluctuates about its static shape (buffeting). The fluctuation's cross-spectral
matrices carry the loaded membrane's resonances, hence its tension (:mod:`.buffeting`); the mean
carries the static load (:mod:`.steady`). This module makes the former: the record's mean is removed,
its discrete Fourier transform taken (no taper: the membrane's resonances are broad, ~6 % damping,
and the spectrum spans ~30 dB, well inside a rectangular window's leakage floor), and the cross-
periodograms ``I_k = dt/N X_k X_k^H`` (two-sided PSD, units²/Hz) averaged over bins of ``L``
neighbouring Fourier frequencies (``L = round(bin_hz T)``, ~1 Hz). Whittle's likelihood of a bin is
then that of ``L`` independent complex Wishart draws of its matrix.

Dropped frames (rows with a NaN) are dropped as whole rows and zero-filled after the mean of the
present rows is removed. For frames lost at random with probability ``1 - q`` the zero-filled
periodogram has expectation ``q^2 S(f) + q(1 - q) dt var``: divided by ``q^2`` it is the spectrum
plus a white floor of ``(1 - q)/q`` times the variance (1 % of it at 1 % loss), which the fitted
noise floor takes up. The ``N q`` present frames carry ``q`` times the information of ``N``: the
averaging counts are scaled by ``q``. Nothing is interpolated. Long gaps (a non-random mask) break
the white-floor argument; more than :data:`MAX_DROPPED` of the frames missing is refused.

Invariants (tests): every bin matrix is Hermitian and positive semi-definite, and Parseval holds,
``2 df sum_k I_k (0 < k < N/2) + df I_{N/2} = var / q`` (``df = 1/(N dt)``, ``var`` the present
frames' variance).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.core.distributions import gamma_ppf
from wingopt.measurements.acquisition import Acquisition

__all__ = ["SpectralData", "spectral_data", "with_acquisition", "Screen", "screen", "MAX_DROPPED"]

log = logging.getLogger(__name__)

MAX_DROPPED = 0.2
"""Largest fraction of dropped frames the spectral data accept (the white-floor argument assumes
isolated, random losses)."""


@dataclass(frozen=True, eq=False)
class SpectralData:
    """Binned cross-periodograms of a record's fluctuation.

    Attributes
    ----------
    freq : ndarray ``(B,)``
        Bin centres (Hz): the mean of the bin's Fourier frequencies.
    periodogram : ndarray ``(B, p, p)`` complex
        Averaged cross-periodograms (two-sided PSD, units²/Hz), Hermitian and PSD.
    counts : ndarray ``(B,)``
        Fourier frequencies averaged in each bin.
    weights : ndarray ``(B,)``
        Whittle weights: ``counts`` times the fraction of frames present.
    dt : float
        Sample period (s).
    frames : int
        Frames in the record (present or not).
    present : float
        Fraction of frames present.
    mean, variance : ndarray ``(p,)``
        Mean and variance of the present frames.
    acquisition : Acquisition
        How the DAQ sampled the record (point sampling unless declared): the model spectrum's
        ``|H(f)|^2`` (:mod:`wingopt.measurements.acquisition`); the bins stop at its fit band.
    """

    freq: np.ndarray
    periodogram: np.ndarray
    counts: np.ndarray
    weights: np.ndarray
    dt: float
    frames: int
    present: float
    mean: np.ndarray
    variance: np.ndarray
    acquisition: Acquisition = Acquisition()

    @property
    def bins(self) -> int:
        return self.freq.size

    @property
    def p(self) -> int:
        return self.periodogram.shape[1]

    @property
    def nyquist(self) -> float:
        return 0.5 / self.dt

    @property
    def duration(self) -> float:
        return self.frames * self.dt


def _sample_period(t: np.ndarray) -> float:
    dt = np.diff(np.asarray(t, dtype=float))
    if dt.size < 1:
        raise InputError("spectral data: need at least 2 frames")
    step = float(np.median(dt))
    if np.max(np.abs(dt - step)) > 1e-3 * step:
        raise InputError(
            f"spectral data: the frames are not evenly spaced (steps {dt.min():.4g} to {dt.max():.4g} s); "
            "a dropped frame is a row of NaN at its time, not a missing row"
        )
    return step


def spectral_data(
    t: np.ndarray,
    values: np.ndarray,
    bin_hz: float = 1.0,
    fmin: float = 1.0,
    fmax: float | None = None,
    acquisition: Acquisition | None = None,
) -> SpectralData:
    """Binned cross-periodograms of the fluctuation of ``values`` ``(N, p)`` sampled at times ``t``.

    Parameters
    ----------
    t : ndarray ``(N,)``
        Evenly spaced sample times (s).
    values : ndarray ``(N, p)``
        Sensor outputs; a row with any NaN is a dropped frame.
    bin_hz : float
        Bin width (Hz), rounded to a whole number of Fourier frequencies (at least one).
    fmin, fmax : float
        Band kept (Hz); ``fmax`` default: just below the Nyquist frequency (which is left out, as is 0),
        and never above the acquisition's fit band (:meth:`Acquisition.fit_band`).
    acquisition : Acquisition, optional
        How the DAQ sampled the record (default: point sampling).

    Returns
    -------
    SpectralData
    """
    y = np.asarray(values, dtype=float)
    if y.ndim != 2 or y.shape[0] != np.size(t):
        raise InputError(f"spectral data: values of shape {y.shape} for {np.size(t)} times")
    if not (np.isfinite(bin_hz) and bin_hz > 0):
        raise InputError(f"bin_hz = {bin_hz!r}: expected a positive width (Hz)")
    dt = _sample_period(t)
    N = y.shape[0]
    ok = np.all(np.isfinite(y), axis=1)
    q = float(ok.mean())
    if q < 1.0 - MAX_DROPPED or ok.sum() < 16:
        raise InputError(
            f"spectral data: {1 - q:.0%} of the {N} frames dropped (at most {MAX_DROPPED:.0%} and 16 frames present)"
        )
    mean = y[ok].mean(axis=0)
    x = np.where(ok[:, None], y - mean, 0.0)  # zero-filled fluctuation (dropped rows contribute nothing)
    X = np.fft.rfft(x, axis=0)
    f = np.fft.rfftfreq(N, dt)
    acq = acquisition or Acquisition()
    top = 0.5 / dt if fmax is None else min(float(fmax), 0.5 / dt)
    top = min(top, acq.fit_band(1.0 / dt) + 1e-9)  # above it the spectrum is the filter's, not the membrane's
    keep = (f > 0) & (f >= fmin) & (f < top) & (np.arange(f.size) < (N + 1) // 2)  # no DC, no Nyquist
    if keep.sum() < 1:
        raise InputError(f"spectral data: no Fourier frequency in [{fmin:g}, {top:g}) Hz for {N} frames")
    X, f = X[keep], f[keep]
    L = max(1, int(np.floor(bin_hz * N * dt + 0.5 + 1e-9)))  # round half up (450 frames at 300 Hz: 2)
    nb = max(1, f.size // L)
    edges = np.linspace(0, f.size, nb + 1).round().astype(int)  # bins of L or L + 1 frequencies: all are used
    counts = np.diff(edges)
    scale = dt / (N * q * q)  # dt/N |X|^2, divided by q^2 (module docstring)
    I = np.einsum("fp,fq->fpq", X, X.conj()) * scale
    csum = np.concatenate([np.zeros((1,) + I.shape[1:], complex), np.cumsum(I, axis=0)])
    fsum = np.concatenate([[0.0], np.cumsum(f)])
    Ib = (csum[edges[1:]] - csum[edges[:-1]]) / counts[:, None, None]
    Ib = 0.5 * (Ib + np.conj(np.swapaxes(Ib, 1, 2)))  # Hermitian to rounding
    fb = (fsum[edges[1:]] - fsum[edges[:-1]]) / counts
    var = y[ok].var(axis=0)
    log.debug("spectral data: %d frames (%.1f %% present), %d bins of %d frequencies", N, 100 * q, nb, L)
    return SpectralData(fb, Ib, counts, counts * q, dt, N, q, mean, var, acq)


@dataclass(frozen=True)
class Screen:
    """Is there a resonance above the noise floor near the first loaded mode?

    ``ratio``: peak in the band of the sensors' mean smoothed auto-spectrum over its noise floor;
    ``peak_hz`` where it is; ``threshold`` what ``informative`` compared it with.
    """

    ratio: float
    peak_hz: float
    band: tuple[float, float]
    threshold: float
    informative: bool


FLOOR_QUANTILE = 0.2
"""Quantile of a sensor's bins that sets its noise floor in :func:`screen`."""

SCREEN_RATIO = 1.5
"""A resonance is informative when the smoothed spectrum peaks above its floor by this plus 4 standard
deviations of white noise's smoothed ratio, ``4 / sqrt(p w L)`` (``p w L`` periodogram ordinates
averaged): 2.1 for 1.5 s at 300 Hz (white noise's peak ratio: 1.4-1.7), 1.8 for 4.6 s (1.2-1.4)."""


def screen(
    data: SpectralData, band: tuple[float, float], window_hz: float = 8.0, threshold: float | None = None
) -> Screen:
    """Cheap test of the buffeting's information on the tension (before any fit).

    Each sensor's auto-spectrum is smoothed over ``window_hz`` (a moving average of whole bins) and
    divided by its white-noise floor: the ``FLOOR_QUANTILE`` quantile of its bins over the whole band
    divided by that of white noise's bin average (a Gamma variate): the buffeting raises part of the
    band, the low quantile stays on the rest; where it raises all of it, the floor is too high and
    the ratio errs low. The sensors' mean of these
    ratios, peaked within ``band`` (the first loaded mode's plausible frequencies, Hz), is the
    statistic (white noise: ~1.3; the tunnel's 3 % buffeting at 2 % noise: ~5). ``threshold``
    default: :data:`SCREEN_RATIO` plus four of white noise's standard deviations.
    """
    auto = np.real(np.einsum("bii->bi", data.periodogram))
    df = float(np.median(np.diff(data.freq))) if data.bins > 1 else 1.0
    w = max(1, int(round(window_hz / df)))
    if data.bins < 2 * w:
        return Screen(float("nan"), float("nan"), band, float("nan"), False)
    L = int(np.median(data.counts))
    floor = np.maximum(np.quantile(auto, FLOOR_QUANTILE, axis=0) * L / gamma_ppf(FLOOR_QUANTILE, L), 1e-300)
    kernel = np.ones(w) / w
    smooth = np.stack([np.convolve(auto[:, i] * data.counts, kernel, "valid") for i in range(data.p)], axis=1)
    smooth /= np.convolve(data.counts.astype(float), kernel, "valid")[:, None]
    fc = np.convolve(data.freq, kernel, "valid")
    ratio = (smooth / floor).mean(axis=1)
    inband = (fc >= band[0]) & (fc <= band[1])
    if not inband.any():
        return Screen(float("nan"), float("nan"), band, float("nan"), False)
    k = int(np.argmax(np.where(inband, ratio, -np.inf)))
    if threshold is None:
        threshold = SCREEN_RATIO + 4.0 / np.sqrt(data.p * w * L)
    out = Screen(float(ratio[k]), float(fc[k]), tuple(map(float, band)), float(threshold), bool(ratio[k] >= threshold))
    log.debug("buffeting screen: ratio %.2f at %.1f Hz in [%.0f, %.0f] Hz", out.ratio, out.peak_hz, *band)
    return out


def with_acquisition(data: SpectralData, acquisition: Acquisition) -> SpectralData:
    """``data`` as sampled by ``acquisition``: its bins up to the acquisition's fit band (a refit's
    spectra when the record turns out to be anti-aliased; the periodograms themselves are unchanged)."""
    keep = data.freq <= acquisition.fit_band(1.0 / data.dt) + 1e-9
    if keep.sum() < 2:
        raise InputError(f"spectral data: no bin below the fit band of {acquisition.describe()}")
    return SpectralData(
        data.freq[keep], data.periodogram[keep], data.counts[keep], data.weights[keep], data.dt, data.frames,
        data.present, data.mean, data.variance, acquisition,
    )  # fmt: skip
