"""An anti-aliasing filter the problem does not declare: found near Nyquist, refitted, and said.

A record handed over by a DAQ with an anti-aliasing filter has less power near the Nyquist frequency
than a point-sampled one: a digital (delta-sigma) filter empties the band above its passband (0.45
fs), an analog one bends the spectrum from well below Nyquist (a 4th-order Butterworth at fs/3 passes
a fifth of the power at 0.45 fs). The buffeting fit of a point-sampled model then reads the bent
spectrum as another membrane (measured on an independent FvK record through a Butterworth at fs/3:
-11.8 % at 3.5 bands, "converged").

The test (:func:`collapse`): at the point-sampled fit, the whitened periodogram's trace ``t_b =
tr(S_b^-1 I_b) / p`` has mean 1 and variance ``1 / (p n_b)`` in every bin (a complex Wishart's
trace); over the bins of :data:`BANDS` its weighted mean is compared with 1. A band whose mean is
below :data:`COLLAPSE` and :data:`Z` standard deviations below 1 has lost power the model says is
there: an anti-aliasing filter. The record is then refitted as if the filter were declared
(:func:`assumed`: a digital filter's passband 0.45 fs when only the top band collapsed, else a
digital filter cut, and an analog 4th-order Butterworth with its cutoff, where the bins' power ratio
falls to one half; the refit whose spectrum fits better is kept), and every answer's band takes in
the distance between the two fits' lifts: the filter's shape is a guess, the lift's dependence on it
is in the band. Declared (``[measurements] acquisition``), no test is made.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from wingopt.estimation.steady.buffeting_fit import BuffetingFit
from wingopt.estimation.steady.spectra import with_acquisition
from wingopt.measurements.acquisition import Acquisition

__all__ = ["collapse", "assumed", "refit_anti_aliased", "BANDS", "COLLAPSE", "Z"]

log = logging.getLogger(__name__)

BANDS = ((0.40, 0.45), (0.45, 0.50), (0.475, 0.50))
"""The bands near Nyquist (fractions of the sample rate) where a filter's loss is looked for. The last
is the top half of the second: a resampler's filter (``scipy.signal.resample_poly``: -6 dB at
Nyquist) loses its power there, and averaged over 0.45-0.5 fs the loss was diluted below the test
(the 4.7 s tunnel record resampled to 250 Hz: 0.77 ± 0.07 over 0.45-0.5 fs, 0.61 ± 0.10 over
0.475-0.5 fs; -9.5 % at 3.2 bands, unsaid)."""

COLLAPSE = 0.8
"""A band's mean whitened power below this (and :data:`Z` sigma below 1) is a collapse. Measured on
FvK records (benchmarks/daq_records.py, 4.7 s at 300 Hz): point-sampled 0.92-1.10 in both bands, the
stand-in 1.01-1.09; a delta-sigma filter (stopband from 0.5 fs) 0.45-0.55 above 0.45 fs; a Butterworth
at fs/3 0.36 at 0.40-0.45 fs and 0.15-0.18 above; a polyphase resample to 250 Hz 0.72-0.78 above
0.45 fs and 0.61-0.67 above 0.475 fs (point-sampled there: 0.94-1.17); a half-band filter
(stopband from 0.55 fs) ~0.9, not caught, and harmless (within 1 band)."""

Z = 3.0
"""Standard deviations below 1 a band's mean must lie to be a collapse (a 1.5 s record's top band has
a standard deviation of ~0.11, a 4.7 s record's ~0.06, its top half's ~0.10). A band's mean is a
gamma variate of mean 1 (``p n_b`` degrees of freedom), whose lower tail is lighter than a normal's:
3 sigma is a false alarm in under 0.15 % of point-sampled records per band, and a false alarm costs
a refit and a wider band, never the answer (3.5 missed the resample above at 0.64 ± 0.10)."""


def _whitened(bf: BuffetingFit) -> tuple[np.ndarray, np.ndarray]:
    """Bin frequencies and the whitened periodogram traces ``tr(S^-1 I) / p`` at the fit."""
    bp = bf.problem
    S = bp.evaluate(bf.theta)["S"]
    I = bp.spectra.periodogram
    t = np.real(np.einsum("bii->b", np.linalg.solve(S, I))) / bp.spectra.p
    return bp.spectra.freq, t


def collapse(bf: BuffetingFit) -> list[dict]:
    """The bands of :data:`BANDS` whose power collapsed against the point-sampled fit ``bf`` (empty:
    none, or the acquisition is declared)."""
    spec = bf.problem.spectra
    if not spec.acquisition.point:
        return []
    f, t = _whitened(bf)
    fs = 1.0 / spec.dt
    out = []
    for lo, hi in BANDS:
        m = (f >= lo * fs) & (f < hi * fs)
        w = spec.weights[m]
        if m.sum() < 2:
            continue
        mean = float(w @ t[m] / w.sum())
        sd = float(1.0 / np.sqrt(spec.p * w.sum()))
        log.debug("Nyquist test: %.2f-%.2f fs, whitened power %.2f +- %.2f", lo, hi, mean, sd)
        if mean < COLLAPSE and mean < 1.0 - Z * sd:
            out.append({"band_fs": [lo, hi], "power_ratio": mean, "std": sd})
    return out


def assumed(bf: BuffetingFit, bands: list[dict]) -> list[Acquisition]:
    """The filters a refit may assume (module docstring): a digital one's passband 0.45 fs when only
    the top band collapsed; else, with the edge where the bins' smoothed power ratio first falls
    below one half, a digital filter cut there and an analog 4th-order Butterworth with its -3 dB
    point there (the refit that fits its spectrum better is kept)."""
    if all(b["band_fs"][0] >= 0.45 for b in bands):
        return [Acquisition("delta-sigma")]
    f, t = _whitened(bf)
    fs = 1.0 / bf.problem.spectra.dt
    k = max(1, int(round(5.0 / max(float(np.median(np.diff(f))), 1e-9))))  # ~5 Hz smoothing
    smooth = np.convolve(t, np.ones(k) / k, "same")
    below = (f > 0.2 * fs) & (smooth < 0.5)
    edge = float(f[np.argmax(below)]) / fs if below.any() else 0.45
    edge = min(max(edge, 0.2), 0.45)
    return [
        Acquisition("fir", passband=0.95 * edge, stopband=1.0 - 0.95 * edge),
        Acquisition("butterworth", order=4, cutoff_hz=edge * fs),
    ]


def refit_anti_aliased(solutions, refits, spectra, fit_all, notes: list[str]):
    """After the point-sampled spectral fits ``refits`` (``[(Solution, why)]`` of ``fit_all``), test
    the best for a collapse near Nyquist; on one, refit every solution as if the filter were declared,
    widen each band by the distance between its two lifts, and say so in ``notes``. Returns the
    refits to use and the test's record (``None``: no test)."""
    done = [(x, why) for x, why in refits if why is None and x.buffeting is not None]
    if not done or not spectra.acquisition.point:
        return refits, None
    best = max(done, key=lambda r: r[0].log_evidence)[0]
    bands = collapse(best.buffeting)
    record = {"collapsed": bands, "assumed": None}
    if not bands:
        return refits, record
    tries = []
    for acq in assumed(best.buffeting, bands):
        again = fit_all(solutions, with_acquisition(spectra, acq))
        ok = [x for x, why in again if why is None]
        chi2 = max(ok, key=lambda x: x.log_evidence).spectral_chi2 if ok else np.inf
        log.debug("anti-aliasing refit assuming %s: spectral residual %.2f", acq.describe(), chi2)
        tries.append((chi2, acq, again))
    _, acq, again = min(tries, key=lambda x: x[0])
    record["assumed"] = acq.as_dict()
    out = []
    for (old, why_old), (new, why) in zip(refits, again):
        if why is not None or why_old is not None:
            out.append((old, why_old))
            continue
        band = float(np.hypot(new.lift_std, new.lift - old.lift))
        out.append((dataclasses.replace(new, lift_std=band), None))
    worst = min(bands, key=lambda b: b["power_ratio"])
    lo, hi = worst["band_fs"]
    notes.append(
        f"the record's spectrum collapses near the Nyquist frequency ({worst['power_ratio']:.0%} of the model's "
        f"power at {lo:g}-{hi:g} fs): an anti-aliasing filter the problem does not declare? Refitted assuming "
        f"{acq.describe()}; the band holds the point-sampled fit's lift too ({best.lift:.4g} N). Declare it: "
        "[measurements] acquisition"
    )
    return out, record
