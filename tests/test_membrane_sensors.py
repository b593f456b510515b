import numpy as np
import pytest

from wingopt.fe import gauss_legendre
from wingopt.membrane import MembraneModel, add_noise, noise_std_for
from wingopt.problem.membrane import StretchSensorSpec


def bubble_poly(W, L):
    """A bi-quadratic/cubic field vanishing on the edges: exactly in the spline space."""

    def w(x, y):
        return x * (W - x) * (1 + x / W) * y * (L - y)

    def wx(x, y):
        return (W - 2 * x + (2 * W * x - 3 * x**2) / W) * y * (L - y)

    def wy(x, y):
        return x * (W - x) * (1 + x / W) * (L - 2 * y)

    return w, wx, wy


def gauss_2d(f, rect, n=40):
    """Independent high-order quadrature (no splitting: the integrand is a polynomial)."""
    t, wt = gauss_legendre(n)
    x0, x1, y0, y1 = rect
    X, Y = np.meshgrid(x0 + (x1 - x0) * t, y0 + (y1 - y0) * t, indexing="ij")
    return float(np.sum(f(X, Y) * np.outer(wt, wt)) * (x1 - x0) * (y1 - y0))


def test_sensor_matrices_symmetric_psd(membrane_models):
    model = membrane_models[(25, 13)]
    for C in model.sensors.matrices:
        assert abs(C - C.T).max() <= 1e-15 * abs(C).max()
        assert np.linalg.eigvalsh(C.toarray()).min() > -1e-12 * abs(C).max()


@pytest.mark.parametrize("rect", [(0.010, 0.045, 0.010, 0.022), (0.0123, 0.0871, 0.00731, 0.0613)])
def test_sensor_output_equals_independent_quadrature(membrane_problem, rect):
    """Includes a rectangle whose edges lie on no element edge: the split quadrature is exact."""
    W, L = membrane_problem.width, membrane_problem.height
    w, wx, wy = bubble_poly(W, L)
    problem = membrane_problem.with_sensors([StretchSensorSpec("S", rect, gain=1.7)])
    model = MembraneModel.from_problem(problem, (13, 7))
    z = model.project(w)
    # the field is in the space: projection is exact
    np.testing.assert_allclose(
        model.space.evaluate(z, [0.03, 0.1], [0.02, 0.05]), w(np.array([0.03, 0.1]), np.array([0.02, 0.05])), rtol=1e-11
    )
    area = (rect[1] - rect[0]) * (rect[3] - rect[2])
    expected = 1.7 / (2 * area) * gauss_2d(lambda x, y: wx(x, y) ** 2 + wy(x, y) ** 2, rect)
    assert model.sensors.outputs(z)[0] == pytest.approx(expected, rel=1e-11)


def test_whole_domain_sensor_is_the_scaled_tension_matrix(membrane_problem):
    W, L = membrane_problem.width, membrane_problem.height
    model = MembraneModel.from_problem(membrane_problem.with_sensors([StretchSensorSpec("all", (0, W, 0, L))]), (13, 7))
    C = model.sensors.matrices[0]
    K_over_T = model.stiffness / membrane_problem.material.tension
    assert abs(C - K_over_T / (2 * W * L)).max() < 1e-12 * abs(C).max()


def test_jacobian_is_two_z_C(membrane_models):
    model = membrane_models[(13, 7)]
    z = np.random.default_rng(3).standard_normal(model.n) * 1e-3
    J = model.sensors.jacobian(z)
    eps = 1e-7
    fd = np.stack(
        [
            (model.sensors.outputs(z + eps * e) - model.sensors.outputs(z - eps * e)) / (2 * eps)
            for e in np.eye(model.n)
        ],
        axis=1,
    )
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-9 * np.abs(J).max())
    # sign-blind
    np.testing.assert_allclose(model.sensors.outputs(-z), model.sensors.outputs(z), rtol=1e-15)


def test_seeded_noise_levels():
    clean = np.abs(np.random.default_rng(0).standard_normal((1001, 4)))
    a, sa = add_noise(clean, 0.05, seed=7)
    b, _ = add_noise(clean, 0.05, seed=7)
    c, _ = add_noise(clean, 0.05, seed=8)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    np.testing.assert_allclose(sa, 0.05 * clean.max(axis=0))
    np.testing.assert_allclose((a - clean).std(axis=0) / sa, 1.0, atol=0.1)
    np.testing.assert_allclose(noise_std_for(clean, 0.0), 0.0)
