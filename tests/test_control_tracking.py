"""The seed's LQR/LQG tracking controller: feedforward, steady state, and the issue-3 outcomes."""

import numpy as np
import pytest

from wingopt.control.closed_loop import simulate_closed_loop
from wingopt.control.lqr import dlqr, lqr
from wingopt.control.tracking import (
    LQRSettings,
    continuous_tracking,
    discrete_feedforward,
    make_lqr_controller,
    steady_state,
)
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.problem import load_problem


@pytest.fixture(scope="module")
def model13():
    return PlateModel.from_problem(load_problem("plate"), (13, 61))


@pytest.fixture(scope="module")
def runs13(model13):
    """LQG from rest, 2 s, the three shapes on the default mesh (unlimited, the seed's setting)."""
    out = {}
    for shape in ("twist", "camber", "bending"):
        zd = model13.target(shape)
        out[shape] = simulate_closed_loop(model13, make_lqr_controller(model13, zd), zd, t_end=2.0)
    return out


def _random_second_order(n=4, m=2, seed=0):
    rng = np.random.default_rng(seed)
    L = rng.standard_normal((n, n))
    K = L @ L.T + n * np.eye(n)
    D = 0.1 * np.eye(n)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-K, -D]])
    B = np.vstack([np.zeros((n, m)), rng.standard_normal((n, m))])
    return A, B, K, B[n:]


def test_continuous_feedforward_settles_on_the_regularised_static_fit():
    """Eq. 5.22: the closed loop of the seed's law settles where min ||z - z_d||^2 + u'Ru is."""
    n, m, r = 4, 2, 0.3
    A, B, K, b = _random_second_order(n, m)
    Q = np.diag(np.r_[np.ones(n), 0.5 * np.ones(n)])
    R = r * np.eye(m)
    z_d = np.array([1.0, -2.0, 0.5, 0.3])
    x_d = np.r_[z_d, np.zeros(n)]
    Kc, Pi, _ = lqr(A, B, Q, R)
    Kg, u_ff = continuous_tracking(A, B, Pi, R, x_d)
    np.testing.assert_allclose(Kg, Kc, rtol=1e-10)
    # equilibrium of x' = A x + B (u_ff - K (x - x_d))
    x_ss = np.linalg.solve(A - B @ Kg, -B @ (u_ff + Kg @ x_d))
    G = np.linalg.solve(K, b)
    u_fit = np.linalg.solve(G.T @ G + R, G.T @ z_d)
    np.testing.assert_allclose(x_ss[:n], G @ u_fit, rtol=1e-9)
    np.testing.assert_allclose(x_ss[n:], 0, atol=1e-10)
    # generalised form E x' = A_g x + B_g u gives the same law
    E = np.eye(2 * n)
    Kg2, u_ff2 = continuous_tracking(A, B, Pi, R, x_d, E=E)
    np.testing.assert_allclose(u_ff2, u_ff, rtol=1e-9)


def test_discrete_feedforward_matches_the_bellman_fixed_point():
    """Discrete analogue: the steady state is the KKT point of the stage cost on the fixed points."""
    n, m = 4, 2
    A, B, K, b = _random_second_order(n, m, seed=1)
    from wingopt.dynamics import zoh

    h = 0.05
    F, G = zoh(A, B, h)
    Q, R = np.eye(2 * n) * h, 0.2 * np.eye(m) * h
    g = np.array([0.3, -0.1])
    Kd, P, _ = dlqr(F, G, Q, R)
    S = R + G.T @ P @ G
    x_d = np.r_[np.array([0.5, 1.0, -1.0, 0.2]), np.zeros(n)]
    u_ff = discrete_feedforward(F, G, Kd, P, S, x_d, g)
    # closed-loop fixed point
    x_ss = np.linalg.solve(np.eye(2 * n) - F + G @ Kd, G @ (u_ff + Kd @ x_d))
    u_ss = u_ff - Kd @ (x_ss - x_d)
    # KKT of min (x-x_d)'Q(x-x_d) + u'Ru - 2 g'u s.t. x = F x + G u
    Hm = np.block([[2 * Q, np.zeros((2 * n, m)), (np.eye(2 * n) - F).T], [np.zeros((m, 2 * n)), 2 * R, -G.T],
                   [np.eye(2 * n) - F, -G, np.zeros((2 * n, 2 * n))]])  # fmt: skip
    rhs = np.r_[2 * Q @ x_d, 2 * g, np.zeros(2 * n)]
    sol = np.linalg.solve(Hm, rhs)
    np.testing.assert_allclose(x_ss, sol[: 2 * n], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(u_ss, sol[2 * n : 2 * n + m], rtol=1e-8)


def test_lqg_settles_on_the_regularised_static_fit():
    """Full plant, Kalman filter and all: after 25 s the voltages are the static fit's to 1e-4."""
    model = PlateModel.from_problem(load_problem("plate"), (7, 31))
    zd = model.target("bending")
    res = simulate_closed_loop(model, make_lqr_controller(model, zd), zd, t_end=25.0)
    u_fit, z_fit = steady_state(model, zd)
    np.testing.assert_allclose(res.u[-1], u_fit, rtol=1e-4, atol=1e-3 * np.abs(u_fit).max())
    assert res.final_shape_error == pytest.approx(model.m_norm(z_fit - zd) / model.m_norm(zd), rel=1e-4)


def test_twist_pz8_pz9_opposite_and_largest(runs13):
    u = runs13["twist"].u[-1]
    assert u[7] * u[8] < 0
    assert set(np.argsort(-np.abs(u))[:2]) == {7, 8}
    assert 2000 < abs(u[7]) < 4500  # seed: about 4 kV


def test_twist_tip_corners_opposite_and_near_one_centimetre(runs13):
    tip = runs13["twist"].final_tip
    assert tip[0] > 0 > tip[1]
    assert abs(tip[0] + tip[1]) < 1e-6
    assert tip[0] == pytest.approx(0.01, rel=0.25)


@pytest.mark.xfail(
    strict=True,
    reason="not met by any reading of the seed's law: its equilibrium is the weighted static best fit of the "
    "Table 5.1 twist, whose tips stay at or below 0.80 cm (M or L2 weight, any r; see the test below)",
)
def test_twist_tip_corners_within_20_percent(runs13):
    assert runs13["twist"].final_tip[0] == pytest.approx(0.01, rel=0.2)


def test_twist_tips_of_every_reading_of_the_seed_law(model13):
    """Issue 16: why the seed's twist outcome (±4 kV on PZ8/PZ9, tips ±1 cm) is not reproduced.

    The plate has the authority: ±4 kV on PZ8/PZ9 alone puts the tips at ±1.01 cm. But the closed
    loop of the seed's law (any Q = blockdiag(alpha W, beta W), R, and the exact feedforward of eq.
    5.22) settles on the R-regularised W-weighted static best fit (tested above and in
    ``test_continuous_feedforward_settles_on_the_regularised_static_fit``), and that fit of the
    Table 5.1 twist uses PZ2/PZ3 against PZ8/PZ9 to lift the mid-span, which keeps the tips low.
    Measured on 13x61 for the mass weight (the spec's reading) and the L2 Gram matrix (the seed's
    literal ``∫ phi_i phi_j``) over r = 1e-18..1e-12: tips at most 0.801 cm (the 20 % bound is
    0.800 cm, touched only at r = 1e-15, where PZ8/PZ9 carry 2.6 kV and the camber needs 6.5 kV on PZ1)
    and PZ8/PZ9 at most 2.9 kV.
    """
    from wingopt.control.tracking import static_fields

    G = static_fields(model13)
    u = np.zeros(9)
    u[7], u[8] = 4000.0, -4000.0
    assert abs(model13.tip_corners(G @ u)[0]) == pytest.approx(0.0101, abs=2e-4)
    zd = model13.target("twist")
    tips, pz89 = [], []
    for W in (model13.mass, model13.gram):
        H, g = G.T @ (W @ G), G.T @ (W @ zd)
        for r in 10.0 ** np.arange(-18, -11):
            uf = np.linalg.solve(H + r * np.eye(9), g)
            tips.append(model13.tip_corners(G @ uf)[0])
            pz89.append(abs(uf[7]))
    assert max(tips) == pytest.approx(0.00801, abs=5e-5)  # below the 0.8 cm the 20 % check needs
    assert max(pz89) < 2950  # the seed: about 4 kV


def test_bending_tip_within_20_percent(runs13):
    tip = runs13["bending"].final_tip
    assert tip == pytest.approx([-0.1, -0.1], rel=0.2)
    u = runs13["bending"].u[-1]
    assert u[7] == pytest.approx(u[8]) and u[7] > 0  # PZ8/PZ9 same sign


def test_camber_pz1_pz4_pz7_largest(runs13):
    u = runs13["camber"].u[-1]
    assert set(np.argsort(-np.abs(u))[:3]) == {0, 3, 6}
    assert np.abs(u).max() < 4000
    assert runs13["camber"].final_tip.min() > 0  # the seed's unwanted positive tip bending


def test_design_time_constant_is_the_weights_ratio(model13):
    """With alpha = beta = 1 the slowest closed-loop time constant is sqrt(beta/alpha) = 1 s."""
    c = make_lqr_controller(model13, model13.target("twist"))
    assert c.design.time_constants[0] == pytest.approx(1.0, rel=0.05)


def test_unknown_options_are_named():
    with pytest.raises(InputError, match="unknown option"):
        LQRSettings.from_options(horizon=10)
    with pytest.raises(InputError, match="r = "):
        LQRSettings(r=-1.0)
