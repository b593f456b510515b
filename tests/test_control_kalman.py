"""Stationary Kalman filter on the patch sensors."""

import numpy as np
import pytest

from wingopt.control.closed_loop import simulate_closed_loop
from wingopt.control.kalman import EstimatorModel, KalmanSettings, SteadyStateKalman
from wingopt.control.lqr import dlqe
from wingopt.control.tracking import make_lqr_controller
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.problem import load_problem


@pytest.fixture(scope="module")
def model7():
    return PlateModel.from_problem(load_problem("plate"), (7, 31))


def test_filter_gain_is_the_stationary_one():
    F = np.array([[0.99, 0.05], [-0.2, 0.98]])
    G = np.array([[0.0], [0.1]])
    C = np.array([[1.0, 0.0]])
    W, V = 0.01 * np.eye(2), np.array([[1e-3]])
    kf = SteadyStateKalman(F, G, C, W, V)
    _, P, _ = dlqe(F, np.eye(2), C, W, V)
    np.testing.assert_allclose(kf.gain, P @ C.T @ np.linalg.inv(C @ P @ C.T + V), rtol=1e-10)
    # P is the fixed point of the Riccati recursion (prior covariance).
    Pp = kf.posterior_covariance
    np.testing.assert_allclose(F @ Pp @ F.T + W, kf.P, rtol=1e-9)
    assert np.abs(kf.error_dynamics).max() < 1
    kf.reset(np.ones(2))
    x = kf.update(np.array([2.0]))
    np.testing.assert_allclose(x, np.ones(2) + kf.gain @ (np.array([2.0]) - C @ np.ones(2)))
    np.testing.assert_allclose(kf.predict(np.array([1.0])), F @ x + G[:, 0])


def test_shapes_are_checked():
    with pytest.raises(InputError, match="do not fit"):
        SteadyStateKalman(np.eye(2), np.ones((3, 1)), np.ones((1, 2)), np.eye(2), np.eye(1))
    with pytest.raises(InputError, match="sigma_y"):
        KalmanSettings(sigma_y=0.0)


def test_estimator_model_is_exact_at_steady_state(model7):
    em = EstimatorModel.from_model(model7, 0.01)
    assert em.r == 3  # modes below 0.6 / dt = 60 Hz: 10, 39, 52 Hz
    u = np.linspace(-500, 1500, 9)
    x = np.linalg.solve(np.eye(2 * em.r) - em.F, em.G @ u)
    z, _ = em.expand(x, u)
    zs = model7.static_deflection(u)
    assert np.abs(z - zs).max() < 1e-9 * np.abs(zs).max()
    np.testing.assert_allclose(em.C @ x + em.D @ u, model7.sensing @ zs, rtol=1e-8)


def test_filter_converges_on_noisy_sensors(model7):
    """Plate driven by the LQG towards bending; sensors with noise; the estimate error shrinks."""
    zd = model7.target("bending")
    c = make_lqr_controller(model7, zd)
    errs = []

    class Watch:
        name, period = "watch", c.period

        def reset(self, model, target):
            c.reset(model, target)

        def step(self, y):
            u = c.step(y)
            errs.append(c.estimate()[0])
            return u

    res = simulate_closed_loop(model7, Watch(), zd, t_end=2.0, sensor_noise=2e-7, seed=3)
    est = np.array(errs)
    true = res.z[:-1]
    e = model7.m_norm(est - true) / model7.m_norm(zd)
    # The plate starts at rest and the filter knows it; the transient excites it and the filter
    # catches up: the error at the end is well below its peak and small.
    assert e[-20:].mean() < 0.3 * e.max()
    assert e[-1] < 0.05
