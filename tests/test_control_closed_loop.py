"""Closed-loop harness: exact-ZOH plants, saturation, input checks."""

import numpy as np
import pytest

from wingopt.control.closed_loop import Controller, simulate_closed_loop
from wingopt.control.plant import make_plant
from wingopt.control.tracking import make_lqr_controller
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.problem import load_problem


@pytest.fixture(scope="module")
def model7():
    return PlateModel.from_problem(load_problem("plate"), (7, 31))


class Constant:
    """A controller holding fixed voltages (open loop)."""

    name = "constant"

    def __init__(self, u, period=0.01):
        self.u = np.asarray(u, float)
        self.period = period

    def reset(self, model, target):
        self.calls = 0

    def step(self, y):
        self.calls += 1
        return self.u


def test_controllers_satisfy_the_protocol(model7):
    c = make_lqr_controller(model7, model7.target("twist"))
    assert isinstance(c, Controller)
    assert isinstance(Constant(np.zeros(9)), Controller)


@pytest.mark.parametrize("kind", ["dense", "modal"])
def test_plants_hold_the_exact_static_deflection(model7, kind):
    """The DC gain of either plant is the full model's ``K^-1 b`` (static correction in the modal one)."""
    plant = make_plant(model7, 0.01, kind)
    u = np.linspace(-1000, 1500, 9)
    x_ss = np.linalg.solve(np.eye(plant.F.shape[0]) - plant.F, plant.G @ u)
    z, zd = plant.fields(x_ss)
    z_static = model7.static_deflection(u)
    # (I - F) is nearly singular (|eig F| up to 0.997): round-off of the exponential is amplified ~300x.
    assert np.abs(z - z_static).max() < 1e-7 * np.abs(z_static).max()
    assert np.abs(zd).max() < 1e-6 * np.abs(z_static).max()  # m/s against m: about 1e-6 s


def test_finer_plant_step_is_exact_at_the_control_instants(model7):
    zd = model7.target("bending")
    c = make_lqr_controller(model7, zd)
    a = simulate_closed_loop(model7, c, zd, t_end=0.3, plant="dense")
    b = simulate_closed_loop(model7, c, zd, t_end=0.3, plant="dense", plant_dt=0.002)
    assert b.t.size == 5 * (a.t.size - 1) + 1
    assert np.abs(a.z - b.z[::5]).max() < 1e-8 * np.abs(a.z).max()
    np.testing.assert_allclose(a.u, b.u, rtol=1e-7, atol=1e-6)


def test_modal_plant_agrees_with_the_dense_one(model7):
    """Default 10 kHz band + static correction against the dense exact ZOH, LQG bending on 7x31."""
    zd = model7.target("bending")
    c = make_lqr_controller(model7, zd)
    a = simulate_closed_loop(model7, c, zd, t_end=2.0, plant="dense")
    b = simulate_closed_loop(model7, c, zd, t_end=2.0, plant="modal")
    assert np.abs(a.shape_error - b.shape_error).max() < 2e-3
    assert np.abs(a.tip - b.tip).max() < 2e-3 * np.abs(a.tip).max()


def test_saturation_is_exact_and_recorded(model7):
    zd = model7.target("bending")
    c = make_lqr_controller(model7, zd, vmin=-500.0, vmax=1500.0)
    res = simulate_closed_loop(model7, c, zd, t_end=1.0, vmin=-500.0, vmax=1500.0)
    assert res.u.max() <= 1500.0 and res.u.min() >= -500.0
    assert res.u.max() == 1500.0  # the limit is reached (bending asks for kilovolts)
    assert res.peak_voltage == (res.u.min(), res.u.max())


def test_harness_clips_a_controller_that_ignores_the_limits(model7):
    c = Constant(np.full(9, 3000.0))
    res = simulate_closed_loop(model7, c, model7.target("bending"), t_end=0.1, vmin=-500, vmax=1500)
    assert np.all(res.u == 1500.0) and np.all(res.u_requested == 3000.0)
    assert c.calls == 10 and res.t_u.size == 10 and res.t.size == 11


def test_sensor_noise_is_seeded(model7):
    zd = model7.target("twist")
    runs = [
        simulate_closed_loop(model7, Constant(np.zeros(9)), zd, t_end=0.05, sensor_noise=1e-7, seed=s)
        for s in (1, 1, 2)
    ]
    np.testing.assert_array_equal(runs[0].y, runs[1].y)
    assert not np.array_equal(runs[0].y, runs[2].y)
    assert np.std(runs[0].y) == pytest.approx(1e-7, rel=0.5)


@pytest.mark.parametrize(
    "kwargs,needle",
    [
        ({"t_end": 0.001}, "t_end"),
        ({"plant_dt": 0.003}, "not an integer multiple"),
        ({"vmin": 10.0, "vmax": 5.0}, "vmin < vmax"),
        ({"sensor_noise": -1.0}, "sensor_noise"),
        ({"plant": "exact"}, "plant"),
    ],
)
def test_bad_harness_input_is_named(model7, kwargs, needle):
    with pytest.raises(InputError, match=needle):
        simulate_closed_loop(model7, Constant(np.zeros(9)), model7.target("twist"), **kwargs)


def test_bad_target_shape(model7):
    with pytest.raises(InputError, match="target: shape"):
        simulate_closed_loop(model7, Constant(np.zeros(9)), np.zeros(5))
