"""The loaded membrane's first two frequencies from DIC frames (``fullfield.modes``): measured, and
what they say about the prestrains' ratio.

On the stand-in (FvK 49x25 truth, prestrain (0.056, 0.046) where the problem file says 0.05, 3 %
buffeting, 450 frames at 300 Hz) the frames' modal spectra show f11 and f21 within their bands of
the loaded tangent at the true prestrains; the two frequencies would need about 0.08 % each for
every prestrain within 3 %, they are measured to 1.0 % and 1.3 %: the ratio is not identified, the
result says so and its prestrain band (the prior's along the ratio) covers the truth.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from wingopt.estimation.fullfield import FullFieldSettings, fullfield_identify
from wingopt.estimation.fullfield.data import field_data
from wingopt.estimation.fullfield.modes import (
    FREQUENCY_MODEL_FORM_REL,
    _fit_frequency,
    _from_frequencies,
    _spectrum,
    loaded_modes,
    modal_check,
)
from wingopt.estimation.fullfield.system import PressureFromShape
from wingopt.measurements import read_dic
from wingopt.membrane import MembraneModel, MembraneParameters
from wingopt.membrane.full import FvKMembrane

TRUE_E0 = (0.056, 0.046)


@pytest.fixture(scope="module")
def standin(membrane_problem):
    path = Path(__file__).resolve().parents[1] / "examples" / "data" / "tunnel_dic_300Hz.npz"
    frames = read_dic(path, (membrane_problem.width, membrane_problem.height))
    with np.load(path) as z:
        assert tuple(z["truth_prestrain"]) == TRUE_E0
    return frames


def _oscillator_record(f0, zeta, n, dt, seed):
    """A stationary damped oscillator driven by low-pass noise (exact spectrum, circular)."""
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, dt)
    r = f / f0
    H = 1.0 / (1 - r**2 + 2j * zeta * r)
    drive = (1 + (f / 30.0) ** 2) ** -1.0
    X = H * drive * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    return np.fft.irfft(X, n) + 1e-4 * rng.standard_normal(n)


def test_the_spectral_fit_finds_a_resonance_with_an_honest_band():
    """450 samples at 300 Hz of a 110 Hz mode (damping 5 %): the frequency to about 1 %, the band covering
    (measured on 40 records: 75 % within 1 sd, 95 % within 2; at 127 Hz, 6 %: 68 %, 92 %, one record
    locked onto a noise hump 12 Hz off: a lone record's Laplace band does not see a second optimum)."""
    dt, n, f0 = 1 / 300, 450, 110.0
    z = []
    for seed in range(12):
        f, I = _spectrum(_oscillator_record(f0, 0.05, n, dt, seed), dt)
        sel = (f > 22.5) & (f < 145.5)
        est, std, zeta = _fit_frequency(f[sel], I[sel], 100.0)  # started 9 % off
        assert 0.004 * f0 < std < 0.03 * f0 and 0.02 < zeta < 0.1
        z.append((est - f0) / std)
    z = np.abs(z)
    assert np.all(z < 3.5) and np.mean(z < 2) >= 0.8 and np.median(z) < 1.2, z


def test_no_information_gives_no_band():
    """A frequency with no peak (infinite std) leaves the prestrains unconstrained, never a tight band."""
    J = np.array([[900.0, 1500.0], [2000.0, 1400.0]])
    s, _ = _from_frequencies(J, np.array([1.0, np.inf]))
    assert np.all(np.isinf(s))
    s, corr = _from_frequencies(J, np.array([1.0, 1.0]))
    assert np.all(np.isfinite(s)) and -1 < corr < 1


def test_loaded_frequencies_of_the_standin_and_what_they_identify(standin, membrane_problem):
    model = MembraneModel.from_problem(membrane_problem)
    res = fullfield_identify(model, standin)
    m = res.info["loaded_modes"]
    f, sf = np.array(m["frequencies_measured_hz"]), np.array(m["frequencies_std_hz"])
    # the loaded tangent about the frames' mean shape at the TRUE prestrains: 107.9, 126.9 Hz
    # (unloaded: 81.8, 104.9); measured 108.8 ± 1.05, 127.3 ± 1.62
    data = field_data(standin, model, 1e-8, 0.5)
    fvk = FvKMembrane.from_model(model, MembraneParameters(0.05, 0.05, 1.0, 1.0))
    system = PressureFromShape(fvk, data.mean_z, data.basis, np.zeros((model.n, 1)))
    true_f = loaded_modes(system, TRUE_E0)[0]
    assert np.allclose(true_f, [107.9, 126.9], atol=0.3)
    band = np.sqrt(sf**2 + (FREQUENCY_MODEL_FORM_REL * f) ** 2)
    assert np.all(np.abs(f - true_f) < 2 * band) and np.all(sf < 0.015 * f) and np.all(sf > 0.003 * f)
    assert np.all(np.abs(m["misfit_sd"]) < 2)
    # the ratio's signature is 0.08 % of a frequency per 3 % of a prestrain: not identified, and said so
    assert m["frequency_std_rel_needed"] < 0.002 and not m["identifies_prestrains"]
    assert min(m["prestrain_std_rel_from_frequencies"]) > 0.1
    assert any("do not identify the prestrains' ratio" in w for w in res.info["warnings"])
    # measured: -11.3 %, +7.9 % with bands of 13.8 %, 14.6 % (the frequencies alone: ±23 %, ±17 %): off by
    # more than 3 %, the band covers
    p, s = res.info["parameters"], res.info["parameters_std"]
    for k, e in zip(("prestrain_x", "prestrain_y"), TRUE_E0):
        assert abs(p[k] - e) < s[k] < 0.2 * e


def test_the_check_is_off_for_steady_and_short_records(standin, membrane_problem):
    model = MembraneModel.from_problem(membrane_problem)
    k = slice(0, 100)
    cut = {n: getattr(standin, n)[k] for n in ("t", "u", "v", "w", "exx", "eyy", "exy", "valid")}
    data = field_data(dataclasses.replace(standin, **cut), model, 1e-8, 0.5)
    fvk = FvKMembrane.from_model(model, MembraneParameters(0.05, 0.05, 1.0, 1.0))
    system = PressureFromShape(fvk, data.mean_z, data.basis, np.zeros((model.n, 1)))
    assert modal_check(data, system, (0.05, 0.05)) is None  # 100 frames: no spectrum worth fitting
    assert fullfield_identify(model, standin, FullFieldSettings(modes=False)).info["loaded_modes"] is None
    assert fullfield_identify(model, standin, FullFieldSettings(mode="steady")).info["loaded_modes"] is None
