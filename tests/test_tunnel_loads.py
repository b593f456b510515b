"""The tunnel stand-in's loads: steady pressures that act up to the frame, and buffeting."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from wingopt.errors import InputError
from wingopt.membrane.loads import TUNNEL_LOADS, Buffeting, tunnel_load

W, L = 0.14, 0.07


def _mean(p, n=600):
    xi = (np.arange(n) + 0.5) / n
    X, Y = np.meshgrid(xi * W, xi * L, indexing="ij")
    return float(p(X, Y).mean())


@pytest.mark.parametrize("name", ["tunnel-LE", "tunnel-TE", "tunnel-bump"])
def test_a_tunnel_load_has_the_requested_mean_pressure(name):
    assert _mean(tunnel_load(name, W, L, mean=180.0)) == pytest.approx(180.0, rel=2e-3)


def test_the_leading_edge_load_peaks_at_the_leading_edge_and_acts_on_the_frame():
    p = tunnel_load("tunnel-LE", W, L)
    x = np.linspace(0, W, 141)
    on_mid = p(x, np.full_like(x, L / 2))
    assert np.argmax(on_mid) <= 2  # the peak within 2 mm of x = 0 (the camber term adds just behind it)
    assert (
        on_mid[0] > 1.3 * on_mid[70] and on_mid[0] > 5 * on_mid[-1]
    )  # highest at the leading edge, least at the trailing
    assert p(np.array([W / 2]), np.array([0.0]))[0] > 0.5 * on_mid[70]  # 0.6 of the centre on the side frames


def test_the_trailing_edge_load_mirrors_the_leading_edge_one():
    le, te = tunnel_load("tunnel-LE", W, L), tunnel_load("tunnel-TE", W, L)
    x, y = np.random.default_rng(0).uniform(0, 1, (2, 50))
    np.testing.assert_allclose(te(x * W, y * L), le(W - x * W, y * L), rtol=1e-12)


def test_the_antisymmetric_load_has_no_lift():
    p = tunnel_load("tunnel-anti", W, L)
    assert abs(_mean(p)) < 1e-9 * _mean(lambda x, y: np.abs(p(x, y)))


def test_an_unknown_tunnel_load_is_refused_by_name():
    with pytest.raises(InputError, match="tunnel load = 'tunnel-X'"):
        tunnel_load("tunnel-X", W, L)
    assert set(TUNNEL_LOADS) >= {"tunnel-LE", "tunnel-TE", "tunnel-bump", "tunnel-anti"}


def test_buffeting_has_its_rms_and_its_spectrum():
    """Stationary: the RMS of a long series is the requested one; order 2 rolls off as f^-4 above the
    corner (one-sided PSD at 4 fc is 1/17^2 of the low-frequency level)."""
    b = Buffeting(rms=0.03, corner_hz=30.0, order=2, seed=3, duration=60.0)
    t = np.arange(0, 60.0, 1 / 1200.0)
    eps = b.factor(t) - 1.0
    assert np.sqrt(np.mean(eps**2)) == pytest.approx(0.03, rel=0.1)
    f, S = signal.welch(eps, fs=1200.0, nperseg=4096)
    low = S[(f > 1) & (f < 5)].mean()
    at = S[np.argmin(np.abs(f - 120.0))]
    assert at / low == pytest.approx(1 / 17**2, rel=0.35)


def test_buffeting_is_reproducible_and_refuses_what_it_cannot_give():
    t = np.linspace(0, 1, 301)
    np.testing.assert_array_equal(Buffeting(seed=1).factor(t), Buffeting(seed=1).factor(t))
    assert not np.allclose(Buffeting(seed=1).factor(t), Buffeting(seed=2).factor(t))
    with pytest.raises(InputError, match="generated for 5 s"):
        Buffeting().factor(np.array([6.0]))
    with pytest.raises(InputError, match="buffeting rms"):
        Buffeting(rms=1.5)
