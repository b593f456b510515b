"""A lab's pre-trigger: the still samples before a release or a pluck, found and left out of the
time-domain fits (:mod:`wingopt.estimation.core.onset`)."""

from __future__ import annotations

import numpy as np
import pytest

from wingopt.estimation.core.onset import quiet_lead
from wingopt.measurements import Measurements

RNG = np.random.default_rng(7)
T = np.arange(300) / 300.0


def _ringing(t: np.ndarray, amplitude: float = 200.0) -> np.ndarray:
    """A release: a decaying ringing from rest at ``t = 0`` (in noise std), on four sensors."""
    tt = np.maximum(t, 0.0)[:, None]
    return amplitude * (1.0 - np.cos(2 * np.pi * np.array([47.0, 51.0, 60.0, 73.0]) * tt)) * np.exp(-tt / 0.2)


def _noisy(y: np.ndarray) -> np.ndarray:
    return y + RNG.normal(size=y.shape)


@pytest.mark.parametrize("lead", [7, 30, 120])
def test_the_still_samples_before_a_release_are_found(lead):
    y = _noisy(_ringing(T - T[lead]) + 3.0)
    assert quiet_lead(y, np.ones(4), 1 / 300) == lead  # the fit starts at the last still sample


def test_a_record_that_moves_at_once_a_still_one_and_a_short_lead_have_none():
    assert quiet_lead(_noisy(_ringing(T)), np.ones(4), 1 / 300) == 0
    assert quiet_lead(_noisy(np.zeros((300, 4))), np.ones(4), 1 / 300) == 0
    assert quiet_lead(_noisy(_ringing(T - T[3])), np.ones(4), 1 / 300) == 0  # within a trigger's jitter
    assert quiet_lead(_noisy(_ringing(T - T[30])), np.ones(4), 1 / 3000) == 0  # 10 ms: a slow start, not a lead


def test_a_gradual_departure_is_the_fits_to_model():
    """A gust on a wing at rest in its equilibrium departs gradually: no lead is left out (the still
    part holds the load's information)."""
    gust = np.where((T > 0.3) & (T < 0.8), 40.0 * (1 - np.cos(2 * np.pi * (T - 0.3) / 0.5)), 0.0)
    assert quiet_lead(_noisy(np.repeat(gust[:, None], 4, axis=1) + 100.0), np.ones(4), 1 / 300) == 0


def test_a_glitch_in_the_pre_trigger_and_missing_samples_do_not_move_the_start():
    y = _noisy(_ringing(T - T[40]))
    y[10, 2] += 60.0  # one bad sample: not a start
    y[15:18] = np.nan  # missing rows
    assert quiet_lead(y, np.ones(4), 1 / 300) == 40


def test_a_pre_trigger_no_longer_breaks_the_transient_fit(fvk_short_record):
    """L1 released from the bubble with 0.1 s of pre-trigger: +98 % ± 73 N, chi-square 75 before
    (FvK truth 37x19 at 300 Hz); the fit now starts at the release and gives the answer of the
    record without the pre-trigger."""
    from wingopt.estimation.records import identify_record

    model, meas = fvk_short_record
    n = 40
    sigma = np.nanstd(np.diff(meas.values[-60:], axis=0), axis=0) / np.sqrt(2)
    lead = meas.values[0] + RNG.normal(size=(n, meas.values.shape[1])) * sigma
    dt = float(meas.t[1] - meas.t[0])
    t = np.concatenate([meas.t[0] - dt * np.arange(n, 0, -1), meas.t])
    padded = Measurements(t, np.vstack([lead, meas.values]), meas.sensor_names)
    plain = identify_record(model, meas)
    late = identify_record(model, padded)
    assert late.info["quiet_lead"]["samples"] == n
    assert any("a pre-trigger" in w for w in late.info["warnings"])
    lift, band = late.reported_lift
    ref, ref_band = plain.reported_lift
    assert abs(lift - ref) < 0.25 * ref_band  # what is right does not move beyond a quarter of its band
    assert late.info["adequacy"]["chi2_per_datum"] < 1.5


def test_the_still_samples_of_a_declared_delay_stay():
    """A DAQ that keeps its filter's delay in the time stamps shows the wing still for that delay
    after the release: the fit models those samples (its prediction is shifted by the delay), so
    they are not a pre-trigger."""
    from wingopt.measurements.acquisition import Acquisition

    y = _noisy(_ringing(T - T[30]))
    assert quiet_lead(y, np.ones(4), 1 / 300, Acquisition("delta-sigma", delay_s=10 / 300)) == 20
    assert quiet_lead(y, np.ones(4), 1 / 300, Acquisition("delta-sigma", delay_s=28 / 300)) == 0  # the delay's own
    assert quiet_lead(y, np.ones(4), 1 / 300, Acquisition("delta-sigma")) == 30
