"""The DAQ's filter in the time-domain fits (issue 32): what an analog anti-aliasing filter does to a
record's samples (:class:`~wingopt.measurements.acquisition.SampleFilter`) and to a noise estimate
from differences (:meth:`~wingopt.measurements.acquisition.Acquisition.difference_gain`).

Reference: the filter run at 16x the record's rate (``scipy.signal``'s digital design of the same
filter there, close to the analog one) on the continuous signal, then sampled, as the hardware does."""

import math

import numpy as np
import pytest
import scipy.signal as sig

from wingopt.estimation.core.noise import estimate_noise_std
from wingopt.measurements.acquisition import Acquisition
from wingopt.measurements.decimation_filter import DecimationFilter

FS, OVER = 300.0, 16


def _oversampled(kind: str, cutoff: float) -> np.ndarray:
    design = sig.butter if kind == "butterworth" else sig.bessel
    extra = {} if kind == "butterworth" else {"norm": "mag"}
    return design(4, cutoff, fs=FS * OVER, output="sos", **extra)


@pytest.mark.parametrize("kind, cutoff", [("butterworth", 100.0), ("bessel", 100.0), ("butterworth", 40.0)])
@pytest.mark.parametrize("f0", [20.0, 50.0, 80.0])
def test_the_sample_filter_is_the_analog_filter_on_the_samples(kind, cutoff, f0):
    t = np.arange(0.0, 1.0, 1.0 / (FS * OVER))
    ringing = np.sin(2 * np.pi * f0 * t) * np.exp(-3.0 * t)  # a release's ringing, from rest
    recorded = sig.sosfilt(_oversampled(kind, cutoff), ringing)[::OVER]
    emulated = Acquisition(kind, order=4, cutoff_hz=cutoff).sample_filter(FS)(ringing[::OVER])
    point = ringing[::OVER]
    # past the start (the band limit's precursor on a ringing that starts with a kink): 0.3 % of the
    # amplitude at most (measured 0.02-0.24 %), where the point samples are 30-160 % off
    assert np.abs(emulated - recorded)[20:].max() < 3e-3
    assert np.abs(point - recorded)[20:].max() > 0.3


def test_the_sample_filter_is_linear_and_at_rest_on_a_constant():
    f = Acquisition("butterworth", order=4, cutoff_hz=100.0).sample_filter(FS)
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(2, 80, 3, 4))
    assert np.allclose(f(x + 2 * y), f(x) + 2 * f(y), atol=1e-13)
    assert np.allclose(f(np.full((40, 2), 3.5)), 3.5, atol=1e-12)  # a wing at rest before the record
    assert Acquisition("point").sample_filter(FS) is None and Acquisition("delta-sigma").sample_filter(FS) is None


def test_a_filtered_records_noise_is_read_with_the_filters_difference_gain():
    """Wideband sensor noise through a Butterworth at fs/3, then sampled: second differences see
    2.9x its variance, not the 6x of white noise, so the plain estimate is 1.43x low."""
    acq = Acquisition("butterworth", order=4, cutoff_hz=FS / 3)
    assert acq.difference_gain(2, FS) == pytest.approx(2.93, abs=0.02)
    assert Acquisition("point").difference_gain(2, FS) == math.comb(4, 2)
    rng = np.random.default_rng(1)
    noise = sig.sosfilt(_oversampled("butterworth", FS / 3), rng.normal(size=(200_000, 2)), axis=0)[::OVER]
    true = noise.std(axis=0)
    plain = estimate_noise_std(noise)
    declared = estimate_noise_std(noise, difference_gain=acq.difference_gain(2, FS))
    assert np.all(np.abs(declared / true - 1) < 0.03)
    assert np.all(plain / true < 0.75)


# -- a delay the time stamps do not take out ------------------------------------------------------------------
def test_a_declared_delay_shifts_the_time_domain_prediction():
    """A delta-sigma converter whose group delay the DAQ does not compensate: a sample stamped t holds
    the sensors at t - delay. The time-domain fits shift their prediction by it (a band-limited
    fractional delay, the record's start held before it); the spectra do not see it."""
    fs, f0, delay = 300.0, 23.0, 8.4 / 300.0
    acq = Acquisition("delta-sigma", delay_s=delay)
    t = np.arange(600) / fs

    def signal(t):  # smooth, at rest before t = 0
        return np.where(t > 0, np.sin(2 * np.pi * f0 * t) * (1 - np.exp(-np.maximum(t, 0) / 0.05)) ** 2, 0.0)

    # the fits' filter (:class:`DecimationFilter`), here on the samples' own grid (one sub-step)
    x = signal(t)[:, None]
    y = DecimationFilter.of(acq)(x, x, 1 / fs, 1)[:, 0]
    err = np.abs(y - signal(t - delay))
    assert err[:-40].max() < 5e-3 * np.abs(y).max()  # the start too: held at rest before the record
    # the spectra see none of it; without it the filter leaves the record's timing as it is
    f = np.linspace(-150, 150, 301)
    np.testing.assert_allclose(acq.power(f, fs), Acquisition("delta-sigma").power(f, fs), rtol=0, atol=1e-15)
    for plain in (Acquisition("delta-sigma"), Acquisition("delta-sigma", delay_s=0)):
        z = DecimationFilter.of(plain)(x, x, 1 / fs, 1)[:, 0]
        assert np.abs(z - signal(t))[:-40].max() < 5e-3 * np.abs(z).max()
    assert "8.4 ms delay not compensated" in Acquisition("fir", delay_s=8.4e-3).describe()
    assert Acquisition.from_value({"kind": "delta-sigma", "delay_s": delay}) == acq
    assert acq.as_dict()["delay_s"] == delay


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        (
            {"kind": "butterworth", "cutoff_hz": 100.0, "delay_s": 0.01},
            "delay_s = 0.01: not a setting of kind 'butterworth'",
        ),
        ({"kind": "delta-sigma", "delay_s": -0.01}, "delay_s = -0.01: expected a delay in seconds"),
        ({"kind": "point", "delay_s": 0.01}, "not a setting of kind 'point'"),
    ],
)
def test_a_delay_is_a_digital_filters_and_positive(kwargs, needle):
    from wingopt.errors import InputError

    with pytest.raises(InputError, match=needle.replace("(", r"\(").replace(".", r"\.")):
        Acquisition(**kwargs)
