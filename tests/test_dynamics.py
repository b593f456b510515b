import numpy as np
import pytest
from scipy.integrate import solve_ivp

from wingopt.dynamics import SecondOrderSystem, discretize, simulate, zoh
from wingopt.membrane import bubble, forward_model, load_case


@pytest.fixture(scope="module")
def coarse(membrane_models):
    return membrane_models[(13, 7)]


def test_zoh_step_equals_the_ode_solution(coarse, membrane_problem):
    W, L = membrane_problem.width, membrane_problem.height
    ss = coarse.system.state_space()
    f = coarse.project(load_case("L2", W, L))
    x0 = np.concatenate([coarse.project(bubble(W, L)), np.zeros(coarse.n)])
    dt = 2e-3
    F, G = zoh(ss.A, ss.B, dt)
    x1 = F @ x0 + G @ f
    sol = solve_ivp(lambda t, x: ss.A @ x + ss.B @ f, (0, dt), x0, method="DOP853", rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(x1, sol.y[:, -1], rtol=0, atol=1e-9 * np.abs(x1).max())


def test_modal_zoh_equals_the_augmented_exponential(coarse, membrane_problem):
    W, L = membrane_problem.width, membrane_problem.height
    f = coarse.project(load_case("L1", W, L))
    z0 = coarse.project(bubble(W, L))
    dsys = discretize(coarse.system.state_space(), 1e-3)
    X = simulate(dsys, np.concatenate([z0, np.zeros(coarse.n)]), np.tile(f, (200, 1)))
    tr = forward_model(coarse, "linear").run(f, 0.2, dt=1e-3, z0=z0)
    scale = np.abs(X[:, : coarse.n]).max()
    np.testing.assert_allclose(tr.z, X[:, : coarse.n], atol=1e-10 * scale)
    np.testing.assert_allclose(tr.zdot, X[:, coarse.n :], atol=1e-10 * np.abs(X[:, coarse.n :]).max())


def test_static_limit_of_a_constant_load(membrane_models, membrane_problem):
    model = membrane_models[(25, 13)]
    f = model.project(load_case("L3", membrane_problem.width, membrane_problem.height))
    tr = forward_model(model, "linear").run(f, 1.0)
    z_static = model.static_deflection(f)
    assert np.abs(tr.z[-1] - z_static).max() < 1e-6 * np.abs(z_static).max()


def test_undamped_energy_is_conserved_by_the_discrete_map(coarse, membrane_problem):
    sys = SecondOrderSystem(coarse.mass, 0 * coarse.mass, coarse.stiffness, coarse.gram)
    ss = sys.state_space()
    F, _ = zoh(ss.A, ss.B, 1e-3)
    n = coarse.n
    M, K = coarse.mass.toarray(), coarse.stiffness.toarray()

    def energy(x):
        return 0.5 * x[n:] @ M @ x[n:] + 0.5 * x[:n] @ K @ x[:n]

    x = np.concatenate([coarse.project(bubble(membrane_problem.width, membrane_problem.height)), np.zeros(n)])
    e0 = energy(x)
    for _ in range(2000):
        x = F @ x
    assert abs(energy(x) - e0) / e0 < 1e-10


def test_time_varying_load_and_sensor_outputs(coarse, membrane_problem):
    W, L = membrane_problem.width, membrane_problem.height
    f1 = coarse.project(load_case("L1", W, L))
    ramp = forward_model(coarse, "linear").run(lambda t: f1 * min(1.0, t / 0.1), t_end=0.3)
    tr = forward_model(coarse, "linear").run(f1, t_end=0.3)
    # the ramp's response reaches the constant load's once the ramp is over and the transient decays
    assert np.abs(ramp.outputs[-1] - tr.outputs[-1]).max() < 0.05 * np.abs(tr.outputs[-1]).max()
    np.testing.assert_allclose(tr.outputs, coarse.sensors.outputs(tr.z))
    assert tr.outputs.shape == (301, 4) and np.all(tr.outputs >= 0)
