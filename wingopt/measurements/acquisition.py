"""How a DAQ samples a record: :class:`Acquisition`, its anti-aliasing filter and transfer function.

A record is not the membrane's outputs at the sample times unless the DAQ point-samples them. Most
strain-bridge modules are delta-sigma converters: they sample fast and hand over a decimated,
linear-phase FIR-filtered record, flat to ~0.45 fs and empty above ~0.55 fs, so the aliases a point
sampler folds back are gone and the spectrum near the Nyquist frequency is the filter's. Others put
an analog low-pass (Butterworth, Bessel) before a point sampler: the aliases are attenuated, not
removed, and the spectrum bends well below Nyquist. A spectral fit that assumes point sampling then
reads a bent spectrum as a different membrane (measured: a tunnel record through a delta-sigma
filter read -21 % at 2.6 bands, "converged").

:class:`Acquisition` declares the sampling (``[measurements] acquisition``, :mod:`wingopt.problem.
measurements`; or ``dataclasses.replace(problem, acquisition=Acquisition(...))``):

=============== =====================================================================================
kind            response ``H(f)`` (``fs`` the output rate)
=============== =====================================================================================
``point``       1 at every frequency (aliases folded back unattenuated)
``fir``         a linear-phase digital decimation filter: 1 to ``passband fs``, 0 from ``stopband fs``
                (cosine transition), or, with ``taps``, a Kaiser-window design of that many taps at
                :data:`OVERSAMPLE` ``fs`` (cut-off midway)
``delta-sigma`` ``fir`` with the usual converter's edges: ``passband`` 0.45, ``stopband`` 0.55
``butterworth`` analog, ``order`` (default 4), -3 dB at ``cutoff_hz``
``bessel``      analog, ``order`` (default 4), -3 dB at ``cutoff_hz``
=============== =====================================================================================

What the estimators do with it: the spectral (buffeting) fit multiplies each alias of the model
spectrum and the noise floor (the sensors' noise comes before the filter) by ``|H(f + k fs)|^2`` and
keeps only the bins in :meth:`Acquisition.fit_band` (a digital filter's passband; where an analog
filter passes at least a tenth of the power). The transient (time-domain) fits run a declared
analog filter causally over their predicted outputs at the integrator's sub-steps
(:class:`~wingopt.measurements.analog_filter.CausalFilter`, :meth:`Acquisition.state_space`): its
phase lag and gain at the membrane's frequencies are in the model (a 4th-order Butterworth at fs/3
passes a 50 Hz ringing at 300 Hz at 0.91 of its amplitude, 1.9 ms late), and so is its attenuation
of the modes above the Nyquist frequency that ring at a release (read off the samples,
:class:`SampleFilter`, they fold back: L1 from the bubble +19.9 % ± 3.9 N, run causally +0.1 % ±
0.25 N). A digital decimation filter is flat to its passband edge and its group delay compensated
by the converter (as its :meth:`Acquisition.response` says), unless ``delay_s`` says the time
stamps keep it; the time-domain fits run it at the sub-steps too
(:class:`~wingopt.measurements.decimation_filter.DecimationFilter`, :meth:`Acquisition.grid_filter`):
it removes the modes above the Nyquist frequency that ring at a release, which point samples fold
back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal as sig

from wingopt.errors import InputError

__all__ = ["Acquisition", "SampleFilter", "KINDS", "OVERSAMPLE", "POWER_FLOOR"]

KINDS = ("point", "fir", "delta-sigma", "butterworth", "bessel")
"""The sampling kinds :class:`Acquisition` knows."""

OVERSAMPLE = 8
"""Rate (in output samples) at which a ``fir`` declared by its ``taps`` is designed."""

POWER_FLOOR = 0.1
"""An analog filter's bins are fitted where it passes at least this fraction of the power (-10 dB):
beyond, the record's spectrum is the filter's skirt and the noise, and a small error in the declared
response would be read as the membrane."""

_GRID = 8192
"""Frequency grid of a :class:`SampleFilter`'s taps (the record's rate over it is the resolution)."""
_TAIL, _PRECURSOR, _LEAD = 1e-4, 1e-3, 16
"""A :class:`SampleFilter` keeps the taps after the sample down to ``_TAIL`` of the largest, before
it down to ``_PRECURSOR`` (at most ``_LEAD`` of them)."""

_ALIASES = 16
"""Aliases of the sensors' wideband noise folded into a filtered record (:meth:`Acquisition.difference_gain`)."""

_DIGITAL = ("fir", "delta-sigma")
_ANALOG = ("butterworth", "bessel")


def _number(name: str, value, lo: float, hi: float, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InputError(f"acquisition {name} = {value!r}: expected {what}")
    v = float(value)
    if not (math.isfinite(v) and lo < v < hi):
        raise InputError(f"acquisition {name} = {value!r}: expected {what}")
    return v


@dataclass(frozen=True)
class Acquisition:
    """How the DAQ sampled the record (module docstring).

    Parameters
    ----------
    kind : {"point", "fir", "delta-sigma", "butterworth", "bessel"}
    passband, stopband : float, optional
        A digital filter's edges, fractions of the output sample rate (``fir`` default 0.45 and
        ``1 - passband``; ``delta-sigma``: 0.45 and 0.55).
    taps : int, optional
        A ``fir``'s length at :data:`OVERSAMPLE` times the output rate (a Kaiser-window design);
        without it the response is ideal in the passband and the stopband.
    order : int, optional
        An analog filter's order (default 4).
    cutoff_hz : float, optional
        An analog filter's -3 dB frequency (Hz); required for ``butterworth`` and ``bessel``.
    delay_s : float, optional
        A digital filter's delay (s) that the DAQ's time stamps do not take out: a sample stamped
        ``t`` holds the sensors at ``t - delay_s``. A delta-sigma converter's linear-phase FIR delays
        by its group delay (in its data sheet, e.g. 38/fs); most DAQ drivers compensate it (the default,
        0). The spectra do not see it; the time-domain fits (transient, calibration) shift their
        prediction by it (:meth:`sample_filter`).
    """

    kind: str = "point"
    passband: float | None = None
    stopband: float | None = None
    taps: int | None = None
    order: int | None = None
    cutoff_hz: float | None = None
    delay_s: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InputError(f"acquisition kind = {self.kind!r}: expected one of {', '.join(KINDS)}")
        digital = self.kind in _DIGITAL
        analog = self.kind in _ANALOG
        for name, ok in (("passband", digital), ("stopband", digital), ("taps", self.kind == "fir"),
                         ("order", analog), ("cutoff_hz", analog), ("delay_s", digital)):  # fmt: skip
            if getattr(self, name) is not None and not ok:
                raise InputError(f"acquisition {name} = {getattr(self, name)!r}: not a setting of kind {self.kind!r}")
        if digital:
            default = 0.45
            pb = (
                default
                if self.passband is None
                else _number("passband", self.passband, 0, 0.5, "a fraction of fs in (0, 0.5)")
            )
            sb = (
                1.0 - pb
                if self.stopband is None
                else _number("stopband", self.stopband, pb, 1.0, f"a fraction of fs in ({pb:g}, 1)")
            )
            object.__setattr__(self, "passband", pb)
            object.__setattr__(self, "stopband", sb)
            if self.taps is not None:
                if (
                    isinstance(self.taps, bool)
                    or not isinstance(self.taps, (int, np.integer))
                    or not 3 <= self.taps <= 100_000
                ):
                    raise InputError(f"acquisition taps = {self.taps!r}: expected a whole number of taps, 3 to 100000")
                object.__setattr__(self, "taps", int(self.taps))
        if self.delay_s is not None:
            delay = 0.0 if self.delay_s == 0 else _number("delay_s", self.delay_s, 0, 1.0, "a delay in seconds, 0 to 1")
            object.__setattr__(self, "delay_s", delay)
        if analog:
            order = 4 if self.order is None else self.order
            if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 1 <= order <= 12:
                raise InputError(f"acquisition order = {self.order!r}: expected a filter order, 1 to 12")
            object.__setattr__(self, "order", int(order))
            if self.cutoff_hz is None:
                raise InputError(f"acquisition kind = {self.kind!r}: give its cutoff_hz (the -3 dB frequency, Hz)")
            object.__setattr__(
                self, "cutoff_hz", _number("cutoff_hz", self.cutoff_hz, 0, math.inf, "a positive frequency (Hz)")
            )

    @property
    def point(self) -> bool:
        """Point sampling: no filter, every alias folded back."""
        return self.kind == "point"

    @property
    def digital(self) -> bool:
        return self.kind in _DIGITAL

    def response(self, f: np.ndarray, fs: float) -> np.ndarray:
        """The complex response ``H(f)`` at frequencies ``f`` (Hz, any sign) for output rate ``fs`` (Hz)."""
        f = np.asarray(f, dtype=float)
        if self.point:
            return np.ones(f.shape, dtype=complex)
        if self.digital:
            if self.taps is not None:
                rate = OVERSAMPLE * fs
                h = sig.firwin(self.taps, 0.5 * (self.passband + self.stopband) * fs, fs=rate)
                _, H = sig.freqz(h, worN=np.abs(f).ravel(), fs=rate)
                H = H * np.exp(2j * np.pi * np.abs(f).ravel() * (self.taps - 1) / (2 * rate))  # delay compensated
                return np.where(f.ravel() < 0, np.conj(H), H).reshape(f.shape) * self._delay(f)
            a = np.abs(f) / fs
            x = np.clip((a - self.passband) / (self.stopband - self.passband), 0.0, 1.0)
            return (0.5 * (1.0 + np.cos(np.pi * x))) * self._delay(f)
        b, a = self._analog()
        _, H = sig.freqs(b, a, worN=2 * np.pi * np.abs(f).ravel())
        return np.where(f.ravel() < 0, np.conj(H), H).reshape(f.shape)

    def _delay(self, f: np.ndarray) -> np.ndarray:
        """The uncompensated delay's phase ``exp(-2 pi i f delay_s)`` (1 without one)."""
        if not self.delay_s:
            return np.ones(np.shape(f), dtype=complex)
        return np.exp(-2j * np.pi * np.asarray(f, float) * self.delay_s)

    def _analog(self) -> tuple[np.ndarray, np.ndarray]:
        """An analog filter's transfer function ``b(s) / a(s)``."""
        wc = 2 * np.pi * self.cutoff_hz
        if self.kind == "butterworth":
            return sig.butter(self.order, wc, analog=True)
        return sig.bessel(self.order, wc, analog=True, norm="mag")

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """An analog filter's state space ``(A, B, C, D)`` (``B``, ``C`` as vectors), normalised as
        :meth:`response`: what a filter that goes one sample at a time carries
        (:mod:`wingopt.estimation.streaming.output_filter`)."""
        if self.kind not in _ANALOG:
            raise InputError(f"acquisition kind = {self.kind!r}: expected an analog filter (butterworth, bessel)")
        # designed at a unit cutoff and scaled in time (H(s / wc): A, B times wc): the companion form of
        # the polynomial in s itself would hold wc^order
        if self.kind == "butterworth":
            b, a = sig.butter(self.order, 1.0, analog=True)
        else:
            b, a = sig.bessel(self.order, 1.0, analog=True, norm="mag")
        A, B, C, D = sig.tf2ss(b, a)
        wc = 2 * np.pi * self.cutoff_hz
        return wc * A, wc * B[:, 0], C[0], float(D[0, 0])

    def sample_filter(self, fs: float) -> SampleFilter | None:
        """What an analog filter does to a record sampled at ``fs`` (Hz), read off the samples
        (:class:`SampleFilter`); ``None`` for point sampling and a digital filter. The time-domain
        fits run the filters at the integrator's sub-steps instead (:meth:`grid_filter`,
        :mod:`.analog_filter`): read off the samples, the modes above the Nyquist frequency that
        ring at a release fold back (kept as that reference, ``tests/test_transient_daq_causal.py``)."""
        if self.point or self.digital:
            return None
        h = self._impulse(fs, fs)
        peak = np.abs(h).max()
        lag = int(np.flatnonzero(np.abs(h[: _GRID // 2]) > _TAIL * peak)[-1]) + 1
        lead = int(min(_LEAD, np.count_nonzero(np.abs(h[_GRID // 2 :]) > _PRECURSOR * peak)))
        return SampleFilter.of_impulse(h, lead, lag)

    def grid_filter(self, fs: float, rate: float) -> SampleFilter:
        """The filter of a record sampled at ``fs`` (Hz) as it acts on a finer grid of ``rate`` (Hz),
        e.g. an integrator's sub-steps (:mod:`.decimation_filter`): the inverse transform of ``H(f)``
        over ``|f| < rate / 2``, every tap down to ``_TAIL`` of the largest on both sides (a
        linear-phase filter's precursor is as long as its tail)."""
        h = self._impulse(fs, rate)
        big = np.abs(h) > _TAIL * np.abs(h).max()
        lag = int(np.flatnonzero(big[: _GRID // 2])[-1]) + 1
        lead = int(_GRID // 2 - np.flatnonzero(big[_GRID // 2 :])[0]) if big[_GRID // 2 :].any() else 0
        return SampleFilter.of_impulse(h, lead, lag)

    def _impulse(self, fs: float, rate: float) -> np.ndarray:
        """The filter's impulse response ``(_GRID,)`` on a grid of ``rate`` (Hz), of a record sampled
        at ``fs``: the inverse transform of ``H(f)`` over ``|f| < rate / 2`` (negative times wrapped)."""
        f = np.fft.fftfreq(_GRID, 1.0 / rate)
        return np.real(np.fft.ifft(self.response(f, fs)))

    def difference_gain(self, order: int, fs: float) -> float:
        """The variance of the record's noise's ``order``-th differences over its own variance: the
        constant of a noise estimate from differences (:mod:`wingopt.estimation.core.noise`). White noise,
        point-sampled: ``C(2 order, order)`` (6 for second differences). Through the filter (the
        sensors' wideband noise comes before it, folded by the sampling: ``sum_j |H(f + j fs)|^2``)
        the differences see less of it (a 4th-order Butterworth at fs/3: 2.9 for 6): without this
        the noise is underestimated 1.4x and a fit that explains the record reads chi-square 2."""
        if self.point:
            return float(math.comb(2 * order, order))
        f = np.linspace(-0.5 * fs, 0.5 * fs, 2001)
        folded = sum(self.power(f + j * fs, fs) for j in range(-_ALIASES, _ALIASES + 1))
        weight = (2.0 * np.sin(np.pi * f / fs)) ** (2 * order)
        return float(np.trapezoid(weight * folded, f) / np.trapezoid(folded, f))

    def power(self, f: np.ndarray, fs: float) -> np.ndarray:
        """``|H(f)|^2`` (what a spectrum sees: every channel is filtered alike, the phase cancels)."""
        return np.abs(self.response(f, fs)) ** 2

    def fit_band(self, fs: float) -> float:
        """Top of the band a spectral fit keeps (Hz): Nyquist for point sampling, a digital filter's
        passband edge, an analog filter's :data:`POWER_FLOOR` frequency (at most Nyquist)."""
        if self.point:
            return 0.5 * fs
        if self.digital:
            return self.passband * fs
        f = np.linspace(0.0, 0.5 * fs, 2001)
        below = np.flatnonzero(self.power(f, fs) < POWER_FLOOR)
        return float(f[below[0]]) if below.size else 0.5 * fs

    def describe(self) -> str:
        """One line: what the DAQ did."""
        if self.point:
            return "point sampling"
        if self.digital:
            taps = f", {self.taps} taps" if self.taps is not None else ""
            name = "delta-sigma FIR" if self.kind == "delta-sigma" else "digital FIR"
            delay = f", {1e3 * self.delay_s:.4g} ms delay not compensated" if self.delay_s else ""
            return f"{name} (passband {self.passband:.3g} fs, stopband {self.stopband:.3g} fs{taps}{delay})"
        return f"analog {self.kind} filter, order {self.order}, -3 dB at {self.cutoff_hz:.4g} Hz"

    def as_dict(self) -> dict:
        """What a run records."""
        keys = ()
        if self.digital:
            keys = ("passband", "stopband", "taps", "delay_s")
        elif not self.point:
            keys = ("order", "cutoff_hz")
        return {"kind": self.kind, **{k: getattr(self, k) for k in keys if getattr(self, k) is not None}}

    @classmethod
    def from_value(cls, value, where: str = "acquisition") -> Acquisition:
        """From a problem file's value: a kind (``"delta-sigma"``) or a table ``{kind = ..., ...}``."""
        if isinstance(value, Acquisition):
            return value
        if isinstance(value, str):
            return cls(value)
        if isinstance(value, dict):
            unknown = sorted(set(value) - {"kind", "passband", "stopband", "taps", "order", "cutoff_hz", "delay_s"})
            if unknown:
                raise InputError(
                    f"{where}.{unknown[0]}: not an acquisition setting (expected kind, passband, stopband, taps, "
                    "order, cutoff_hz, delay_s)"
                )
            if "kind" not in value:
                raise InputError(f"{where}: give its kind ({', '.join(KINDS)})")
            return cls(**value)
        raise InputError(f"{where} = {value!r}: expected a kind ({', '.join(KINDS)}) or a table {{kind = ..., ...}}")


@dataclass(frozen=True, eq=False)
class SampleFilter:
    """A filter as it acts on samples at the record's rate (the time-domain fits use it for a digital
    filter's declared delay; an analog filter they run causally, :mod:`.analog_filter`): the samples' band-limited
    signal through the filter, sampled again. Its taps are the inverse transform of ``H(f)`` over
    ``|f| < fs/2`` (a smooth record's signal between samples is the band-limited one; a hold's
    interpolation would attenuate a 50 Hz ringing at 300 Hz by 9 %), ``lead`` of them before the
    sample (the band limit's precursor), scaled to the filter's unit gain at rest. The signal before
    the record is held at its first sample (a wing at rest or in equilibrium), after it at its last.
    Linear: the same call filters a prediction ``(N, ...)`` and its Jacobian."""

    taps: np.ndarray
    lead: int

    @classmethod
    def of_impulse(cls, h: np.ndarray, lead: int, lag: int) -> SampleFilter:
        """The taps of an impulse response ``h`` (negative times wrapped to its end) from ``lead``
        before to ``lag`` after zero, normalised to a unit DC gain."""
        taps = np.concatenate([h[h.size - lead :], h[: lag + 1]])
        return cls(taps / taps.sum(), lead)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x)
        lag = self.taps.size - 1 - self.lead
        padded = np.concatenate([np.repeat(x[:1], lag, axis=0), x, np.repeat(x[-1:], self.lead, axis=0)])
        return sig.oaconvolve(padded, self.taps.reshape(-1, *(1,) * (x.ndim - 1)), mode="valid", axes=0)
