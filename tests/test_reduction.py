"""Reduced plate model for control: modes + static correction, tolerance-chosen size, exact ZOH."""

import numpy as np
import pytest
import scipy.linalg as sla

from wingopt.dynamics.reduction import frequency_response, reduce_system
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.problem import load_problem


@pytest.fixture(scope="module")
def plate():
    return PlateModel.from_problem(load_problem("plate"), (7, 31))


@pytest.fixture(scope="module")
def reduced(plate):
    return reduce_system(plate.system, output=plate.sensing, tol=1e-2, band_hz=50.0)


def _m_err(plate, a, b):
    return float(plate.m_norm(a - b) / plate.m_norm(b))


def test_size_is_chosen_by_the_tolerance(plate, reduced):
    # The smallest size meeting tol: the one before it does not.
    sizes = dict(reduced.history)
    assert reduced.error <= 1e-2 < sizes[reduced.n_modes - 1]
    assert 2 <= reduced.n_modes <= 8
    tighter = reduce_system(plate.system, tol=1e-3, band_hz=50.0)
    assert tighter.n_modes > reduced.n_modes and tighter.error <= 1e-3


def test_error_holds_at_frequencies_off_the_grid(plate, reduced):
    freqs = np.array([3.3, 17.1, 29.9, 44.4, 49.7])
    H = frequency_response(plate.system, freqs)
    Hr = reduced.response(freqs)
    for Hf, Hrf in zip(H, Hr):
        approx = reduced.basis @ Hrf + reduced.residual
        err = np.sqrt(np.trace((Hf - approx).conj().T @ (plate.mass @ (Hf - approx))).real)
        ref = np.sqrt(np.trace(Hf.conj().T @ (plate.mass @ Hf)).real)
        assert err / ref <= 1.05e-2


@pytest.mark.parametrize("correction", ["residual", "ritz"])
def test_steady_state_under_any_voltage_is_exact(plate, correction):
    red = reduce_system(plate.system, output=plate.sensing, tol=1e-2, band_hz=50.0, correction=correction)
    rng = np.random.default_rng(1)
    for _ in range(3):
        u = rng.uniform(-500, 1500, plate.n_inputs)
        z = plate.static_deflection(u)
        zr = red.expand(red.static_gain() @ u, u)
        assert _m_err(plate, zr, z) < 1e-10
        y = plate.sensing @ z
        yr = red.output_matrix @ (red.static_gain() @ u) + red.output_feedthrough @ u
        assert np.abs(yr - y).max() < 1e-10 * np.abs(y).max()


def test_without_static_correction_the_steady_state_is_off(plate):
    red = reduce_system(plate.system, n_modes=4, band_hz=50.0, correction="none")
    u = np.full(plate.n_inputs, 1000.0)
    assert _m_err(plate, red.expand(red.static_gain() @ u), plate.static_deflection(u)) > 1e-2


def test_basis_holds_the_true_modes_with_the_full_damping_block(plate, reduced):
    r = reduced.n_modes
    omega, Phi = plate.system.undamped_modes(r)
    np.testing.assert_allclose(reduced.omega, omega, rtol=1e-10)
    V = reduced.basis
    np.testing.assert_allclose(V.T @ (plate.mass @ V), np.eye(r), atol=1e-10)
    # Residual fields are M-orthogonal to the modes (the cost splits into modal + residual parts).
    assert np.abs(V.T @ (plate.mass @ reduced.residual)).max() < 1e-10 * np.abs(reduced.residual).max()
    # The plate's damping is not proportional: the projected block has off-diagonal terms, kept.
    off = reduced.damping - np.diag(np.diag(reduced.damping))
    assert np.abs(off).max() > 1e-6 * np.abs(np.diag(reduced.damping)).max()


def test_exact_zoh_matches_the_matrix_exponential(reduced):
    dt = 0.01
    disc = reduced.discretize(dt)
    ct = reduced.state_space()
    np.testing.assert_allclose(disc.A, sla.expm(ct.A * dt), rtol=1e-10, atol=1e-12)
    # G = int_0^dt e^{As} ds B by quadrature of the exponential.
    s = np.linspace(0.0, dt, 2001)
    integral = np.trapezoid([sla.expm(ct.A * si) for si in s], s, axis=0) @ ct.B
    np.testing.assert_allclose(disc.B, integral, rtol=1e-5, atol=1e-9 * np.abs(disc.B).max())


def test_bad_arguments_are_named(plate):
    with pytest.raises(InputError, match="correction"):
        reduce_system(plate.system, correction="guyan")
    with pytest.raises(InputError, match="tol = 1e-12: not met"):
        reduce_system(plate.system, tol=1e-12, max_modes=3)
