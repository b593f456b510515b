"""The DAQ in the model (issue 32, item 2): the acquisition's transfer function, its problem-file
table, the spectral fit's use of it, and the test that finds an undeclared anti-aliasing filter.

The end-to-end checks use the shipped stand-in (FvK truth on a 49x25 mesh, 300 Hz, point-sampled)
passed through a zero-phase digital low-pass at its own rate: the spectrum above ~0.4 fs is gone, as
a DAQ's decimation filter leaves it (the records of ``benchmarks/daq_records.py`` filter before
decimating; they take minutes to make)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import scipy.signal as sig

from wingopt.errors import InputError, ProblemFileError
from wingopt.estimation.steady.buffeting import BuffetingProblem
from wingopt.estimation.steady.estimator import steady_identify
from wingopt.estimation.steady.spectra import spectral_data, with_acquisition
from wingopt.measurements import Measurements, read_measurements
from wingopt.measurements.acquisition import Acquisition
from wingopt.membrane import MembraneModel
from wingopt.problem import PROBLEMS_DIR, load_problem

ROOT = Path(__file__).resolve().parents[1]
FS = 300.0


# -- the transfer function ---------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["butterworth", "bessel"])
def test_an_analog_filter_passes_half_the_power_at_its_cutoff(kind):
    acq = Acquisition(kind, order=4, cutoff_hz=100.0)
    assert acq.power(np.array([0.0]), FS)[0] == pytest.approx(1.0, abs=1e-12)
    assert acq.power(np.array([100.0]), FS)[0] == pytest.approx(0.5, rel=1e-6)
    assert acq.power(np.array([-70.0]), FS)[0] == pytest.approx(acq.power(np.array([70.0]), FS)[0])


def test_butterworth_power_is_the_textbook_one_and_sets_the_fit_band():
    acq = Acquisition("butterworth", order=4, cutoff_hz=FS / 3)
    f = np.array([50.0, 120.0, 140.0])
    assert np.allclose(acq.power(f, FS), 1.0 / (1.0 + (f / (FS / 3)) ** 8), rtol=1e-9)
    # |H|^2 = 0.1 at fc 9^(1/8): the bins above are the filter's skirt
    assert acq.fit_band(FS) == pytest.approx(100.0 * 9 ** (1 / 8), abs=0.2)


def test_a_digital_filter_removes_the_aliases_and_stops_the_fit_at_its_passband():
    acq = Acquisition("delta-sigma")
    assert (acq.passband, acq.stopband) == (0.45, 0.55)
    f = np.array([10.0, 0.45 * FS, 0.5 * FS, 0.55 * FS, FS + 10.0, -FS + 10.0])
    assert np.allclose(acq.power(f, FS), [1, 1, 0.25, 0, 0, 0], atol=1e-12)  # -6 dB at Nyquist
    assert acq.fit_band(FS) == pytest.approx(0.45 * FS)
    assert Acquisition().fit_band(FS) == 0.5 * FS and Acquisition().power(np.array([1e4]), FS)[0] == 1.0


def test_a_fir_by_its_taps_is_flat_in_its_passband_and_empty_in_its_stopband():
    acq = Acquisition("fir", passband=0.4, stopband=0.6, taps=255)
    assert np.abs(acq.power(np.array([0.0, 0.2 * FS, 0.35 * FS]), FS) - 1).max() < 0.02
    assert acq.power(np.array([0.7 * FS, 1.3 * FS]), FS).max() < 1e-3


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"kind": "sinc3"}, "kind"),
        ({"kind": "fir", "passband": 0.6}, "passband"),
        ({"kind": "fir", "passband": 0.4, "stopband": 0.3}, "stopband"),
        ({"kind": "fir", "taps": 2}, "taps"),
        ({"kind": "butterworth"}, "cutoff_hz"),
        ({"kind": "butterworth", "cutoff_hz": -5.0}, "cutoff_hz"),
        ({"kind": "bessel", "cutoff_hz": 50.0, "order": 0}, "order"),
        ({"kind": "butterworth", "cutoff_hz": 50.0, "passband": 0.4}, "passband"),
        ({"kind": "point", "taps": 31}, "taps"),
    ],
)
def test_a_bad_acquisition_is_one_error_naming_the_field(kwargs, field):
    with pytest.raises(InputError) as exc:
        Acquisition(**kwargs)
    assert field in str(exc.value) and "\n" not in str(exc.value)


def _problem_file(tmp_path, line: str) -> Path:
    path = tmp_path / "p.toml"
    path.write_text((PROBLEMS_DIR / "membrane.toml").read_text() + "\n[measurements]\n" + line + "\n")
    return path


@pytest.mark.parametrize(
    "line, expected",
    [
        ('acquisition = "delta-sigma"', Acquisition("delta-sigma")),
        (
            'acquisition = { kind = "butterworth", order = 4, cutoff_hz = 100.0 }',
            Acquisition("butterworth", order=4, cutoff_hz=100.0),
        ),
        ('acquisition = { kind = "fir", passband = 0.4, stopband = 0.6, taps = 99 }', Acquisition("fir", 0.4, 0.6, 99)),
    ],
)  # fmt: skip
def test_the_measurements_table_declares_the_acquisition(tmp_path, line, expected):
    problem = load_problem(_problem_file(tmp_path, line))
    assert problem.acquisition == expected
    assert load_problem("membrane").acquisition is None


@pytest.mark.parametrize(
    "line, field",
    [
        ('acquisition = "sigma-delta"', "kind"),
        ('acquisition = { kind = "butterworth" }', "cutoff_hz"),
        ('acquisition = { kind = "fir", passband = 0.45, cut = 3 }', "acquisition.cut"),
        ("acquisition = 3", "acquisition"),
    ],
)
def test_a_bad_acquisition_in_the_problem_file_is_one_line(tmp_path, line, field):
    with pytest.raises(ProblemFileError) as exc:
        load_problem(_problem_file(tmp_path, line))
    text = str(exc.value)
    assert "[measurements]" in text and field in text and "\n" not in text, text


# -- the spectral model --------------------------------------------------------------------
@pytest.fixture(scope="module")
def standin():
    problem = load_problem("membrane")
    meas, _ = read_measurements(ROOT / "examples" / "data" / "tunnel_300Hz.csv", problem.sensor_names)
    return problem, meas


def _lowpassed(meas: Measurements) -> Measurements:
    """The record through a zero-phase 101-tap low-pass at 0.4 fs (the spectrum above ~0.42 fs gone)."""
    h = sig.firwin(101, 0.4 * FS, fs=FS)
    y = meas.values.copy()
    ok = np.all(np.isfinite(y), axis=1)
    m = np.nanmean(y, axis=0)
    filled = np.where(ok[:, None], y - m, 0.0)
    out = sig.filtfilt(h, [1.0], filled, axis=0) + m
    out[~ok] = np.nan
    return Measurements(meas.t, out, meas.sensor_names, None, "low-passed")


def test_the_model_spectrum_carries_the_filter_power(standin):
    """Without aliases, the Whittle model of a filtered record is the point-sampled one times
    ``|H(f)|^2``, signal and noise floor alike (the noise comes before the filter); a digital filter's
    aliases carry nothing in its passband; the bins stop at the fit band."""
    from wingopt.estimation.core.load_model import LoadShapes
    from wingopt.estimation.core.record_problem import ParameterPrior
    from wingopt.estimation.steady.problem import SteadyProblem, steady_data

    problem, meas = standin
    model = MembraneModel.from_problem(problem)
    prior = ParameterPrior.from_problem(problem, ("prestrain_x", "prestrain_y", "damping"))
    sp_ = SteadyProblem(model, LoadShapes.aerodynamic(model, 200.0, "x0"), steady_data(meas.values), prior)
    point = spectral_data(meas.t, meas.values, 2.0)
    acq = Acquisition("butterworth", order=4, cutoff_hz=100.0)
    filt = with_acquisition(point, acq)
    assert filt.freq.max() <= acq.fit_band(FS) + 1e-9 and filt.bins < point.bins
    b0, b1 = BuffetingProblem(sp_, point, aliases=0), BuffetingProblem(sp_, filt, aliases=0)
    b1.log_sigma_ref = b0.log_sigma_ref  # the same noise (its reference is set by each one's bins)
    th = np.zeros(b0.dim)
    th[0] = 0.5
    s0, s1 = b0.evaluate(th)["S"][: filt.bins], b1.evaluate(th)["S"]
    H = acq.power(filt.freq, FS)
    assert np.allclose(s1, H[:, None, None] * s0, rtol=1e-10, atol=0)
    ds = BuffetingProblem(sp_, spectral_data(meas.t, meas.values, 2.0, acquisition=Acquisition("delta-sigma")))
    assert np.all(ds.filter_power[:, [0, 2]] == 0) and np.all(ds.filter_power[:, 1] == 1)
    assert np.allclose(BuffetingProblem(sp_, point).filter_power, 1.0)


def test_an_undeclared_anti_aliasing_filter_is_found_and_said(standin):
    """The stand-in low-passed at 0.4 fs: the point-sampled fit's whitened power collapses above
    0.45 fs; the record is refitted as a digital filter's, the band holds both lifts, a warning says
    so. The stand-in itself gives no such warning (its top bands: 1.01-1.09 of the model's power)."""
    problem, meas = standin
    model = MembraneModel.from_problem(problem)
    plain = steady_identify(model, meas)
    assert not any("anti-aliasing" in w for w in plain.info["warnings"])
    res = steady_identify(model, _lowpassed(meas))
    said = [w for w in res.info["warnings"] if "anti-aliasing" in w]
    assert len(said) == 1 and "[measurements] acquisition" in said[0]
    lift, band = res.reported_lift
    assert abs(lift - 1.7640) <= 2 * band


def test_a_polyphase_resample_is_found_near_nyquist(standin):
    """The stand-in, its dropped frames left out, resampled to 250 Hz by ``scipy.signal.resample_poly``
    (a Kaiser FIR: -6 dB at Nyquist): its power is lost in the top half of the 0.45-0.5 fs band
    (0.61 of the model's; 0.77 over the whole band, which the test missed: -9.5 % at 3.2 bands, no
    warning). Found there, refitted and said: within 2 bands (measured -6.6 %, 1.2 bands)."""
    problem, meas = standin
    ok = np.all(np.isfinite(meas.values), axis=1)
    y = sig.resample_poly(meas.values[ok], 5, 6, axis=0)
    res = steady_identify(
        MembraneModel.from_problem(problem), Measurements(np.arange(len(y)) / 250.0, y, meas.sensor_names)
    )
    said = [w for w in res.info["warnings"] if "anti-aliasing" in w]
    assert len(said) == 1 and "0.475-0.5 fs" in said[0], res.info["warnings"]
    lift, band = res.reported_lift
    assert abs(lift - 1.7640) <= 2 * band


def test_a_declared_filter_is_fitted_without_the_test(standin):
    """Declared, the filter is in the model and no test is made: the low-passed stand-in within 2 bands
    (measured -5.4 %, 1.1 bands: the bins above 0.38 fs are gone, and with them some of the record's
    information; the point-sampled model on the same record reads -14 %)."""
    problem, meas = standin
    declared = dataclasses.replace(problem, acquisition=Acquisition("fir", passband=0.38, stopband=0.45))
    res = steady_identify(MembraneModel.from_problem(declared), _lowpassed(meas))
    assert not any("anti-aliasing" in w for w in res.info["warnings"])
    lift, band = res.reported_lift
    assert abs(lift - 1.7640) <= 2 * band and abs(lift / 1.7640 - 1) < 0.07


def test_the_api_takes_the_acquisition_and_refuses_a_bad_one():
    import wingopt as wo

    with pytest.raises(InputError) as exc:
        wo.identify("membrane", data=ROOT / "examples" / "data" / "tunnel_300Hz.csv", acquisition="sinc5")
    assert "acquisition kind = 'sinc5'" in str(exc.value)
    assert Acquisition.from_value({"kind": "bessel", "cutoff_hz": 90.0}) == Acquisition("bessel", cutoff_hz=90.0)
