"""Tables 6.2 / 6.3 of the dissertation, convergence to the exact frequencies, static deflection."""

import numpy as np
import pytest

from wingopt.fe import load_vector

TABLE_6_2 = {
    (13, 7): [82.140658289, 103.90063548, 132.44827162, 151.46455282],
    (25, 13): [82.14063341, 103.90059613, 132.44779727, 151.45989864],
    (49, 25): [82.14063306, 103.90059557, 132.44779115, 151.45984442],
}
TABLE_6_3 = {
    (13, 7): [
        (-31.919407, 515.116976),
        (-39.910341, 651.605852),
        (-53.228785, 830.492986),
        (-63.885917, 949.533112),
        (-71.876851, 1029.731486),
    ],
    (25, 13): [
        (-31.919399, 515.116819),
        (-39.910325, 651.605605),
        (-53.228537, 830.490015),
        (-63.883134, 949.503990),
        (-71.874060, 1029.704576),
    ],
    (49, 25): [
        (-31.919399, 515.116817),
        (-39.910325, 651.605601),
        (-53.228534, 830.489977),
        (-63.883102, 949.503651),
        (-71.874027, 1029.704263),
    ],
}


def exact_frequencies(problem, modes):
    T, rh = problem.material.tension, problem.material.areal_density
    W, L = problem.width, problem.height
    return np.array([0.5 * np.sqrt(T / rh) * np.hypot(m / W, n / L) for m, n in modes])


def test_tension_from_prestrain(membrane_problem):
    assert membrane_problem.material.tension == pytest.approx(14.21875, rel=1e-14)


@pytest.mark.parametrize("nodes", list(TABLE_6_2))
def test_table_6_2_frequencies(membrane_models, nodes):
    f = membrane_models[nodes].frequencies_hz(4)
    np.testing.assert_allclose(f, TABLE_6_2[nodes], rtol=1e-8)


@pytest.mark.parametrize("nodes", list(TABLE_6_3))
def test_table_6_3_damped_eigenvalues(membrane_models, nodes):
    s = membrane_models[nodes].eigenvalues(5)
    ref = np.array([complex(*p) for p in TABLE_6_3[nodes]])
    assert np.abs(s.real - ref.real).max() < 2e-6
    assert np.abs(s.imag - ref.imag).max() < 2e-6


def test_exact_frequencies_of_table_6_2(membrane_problem):
    f = exact_frequencies(membrane_problem, [(1, 1), (2, 1), (3, 1), (1, 2)])
    np.testing.assert_allclose(f, [82.14063305736, 103.90059556, 132.44779106, 151.45984364], rtol=1e-9)


def test_frequencies_converge_at_the_cubic_spline_rate(membrane_problem, membrane_models):
    """Eigenvalue error of cubic splines is O(h^6); fit the observed order over the three meshes."""
    exact = exact_frequencies(membrane_problem, [(1, 1), (2, 1), (3, 1), (1, 2)])
    meshes = sorted(membrane_models)
    h = np.array([membrane_problem.width / (nx - 1) for nx, _ in meshes])
    err = np.array([np.abs(membrane_models[m].frequencies_hz(4) - exact) / exact for m in meshes])
    assert np.all(np.diff(err, axis=0) < 0)
    for j in range(4):
        rate = np.polyfit(np.log(h), np.log(err[:, j]), 1)[0]
        assert 5.8 < rate < 6.6, (j, rate)


def test_static_deflection_matches_double_sine_series(membrane_problem, membrane_models):
    model = membrane_models[(49, 25)]
    W, L, T = membrane_problem.width, membrane_problem.height, membrane_problem.material.tension
    P = 100.0
    z = np.linalg.solve(model.stiffness.toarray(), load_vector(model.space, lambda x, y: P + 0 * x))
    w_fe = model.space.evaluate(z, [W / 2], [L / 2])[0]
    m = np.arange(1, 600, 2)[:, None]
    n = np.arange(1, 600, 2)[None, :]
    terms = (
        16 * P / (np.pi**4 * m * n * T * ((m / W) ** 2 + (n / L) ** 2)) * np.sin(m * np.pi / 2) * np.sin(n * np.pi / 2)
    )
    w_series = terms.sum()
    assert abs(w_fe - w_series) / w_series < 1e-4
