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
