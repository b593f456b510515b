import numpy as np
import pytest

from wingopt.errors import InputError
from wingopt.fe import EdgeCondition as E
from wingopt.fe import SplineBasis1D, gauss_legendre


def test_partition_of_unity_and_reproduction_of_linears():
    b = SplineBasis1D(2.0, 7, E.FREE, E.FREE)
    x = np.linspace(0, 2.0, 101)
    B = b.full_matrix(x).toarray()
    np.testing.assert_allclose(B.sum(axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(b.full_matrix(x, 1).toarray().sum(axis=1), 0.0, atol=1e-12)
    # x = Σ j h B_j (node-centred Greville points)
    greville = (np.arange(b.n_full) - 1) * b.h
    np.testing.assert_allclose(B @ greville, x, atol=1e-14)


@pytest.mark.parametrize(
    "left,right,count", [(E.ZERO, E.ZERO, 6), (E.CLAMPED, E.FREE, 6), (E.FREE, E.CLAMPED, 6), (E.FREE, E.FREE, 8)]
)
def test_dimension_per_boundary_condition(left, right, count):
    assert SplineBasis1D(1.0, 5, left, right).n == count


def test_end_values_match_the_spec():
    b = SplineBasis1D(1.0, 4, E.FREE, E.FREE)
    np.testing.assert_allclose(b.full_matrix([0.0]).toarray()[0, :3], [1 / 6, 2 / 3, 1 / 6], atol=1e-15)
    np.testing.assert_allclose(b.full_matrix([0.0], 1).toarray()[0, :3], [-1 / (2 * b.h), 0, 1 / (2 * b.h)], atol=1e-12)


def test_zero_and_clamped_conditions_hold():
    z = SplineBasis1D(0.3, 6, E.ZERO, E.ZERO)
    ends = z.matrix([0.0, 0.3]).toarray()
    np.testing.assert_allclose(ends, 0.0, atol=1e-15)
    c = SplineBasis1D(0.6, 6, E.FREE, E.CLAMPED)
    np.testing.assert_allclose(c.matrix([0.6]).toarray(), 0.0, atol=1e-15)
    np.testing.assert_allclose(c.matrix([0.6], 1).toarray(), 0.0, atol=1e-12)
    # the free end keeps non-trivial values and slopes
    assert np.abs(c.matrix([0.0]).toarray()).max() > 0.1
    assert np.abs(c.matrix([0.0], 1).toarray()).max() > 0.1


def test_derivatives_match_finite_differences():
    b = SplineBasis1D(1.3, 5, E.ZERO, E.FREE)
    x = np.array([0.11, 0.47, 0.93, 1.21])
    eps = 1e-6
    for d in (1, 2):
        fd = (b.matrix(x + eps, d - 1) - b.matrix(x - eps, d - 1)).toarray() / (2 * eps)
        np.testing.assert_allclose(b.matrix(x, d).toarray(), fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_gram_is_exact_symmetric_positive_definite():
    b = SplineBasis1D(0.7, 9, E.ZERO, E.ZERO)
    G = b.gram().toarray()
    np.testing.assert_allclose(G, G.T, atol=1e-16)
    assert np.linalg.eigvalsh(G).min() > 0
    # independent: 10-point Gauss per element
    t, w = gauss_legendre(10)
    x = (np.arange(9)[:, None] + t).ravel() * b.h
    B = b.matrix(x).toarray()
    np.testing.assert_allclose(G, B.T @ (np.tile(w * b.h, 9)[:, None] * B), atol=1e-15)


def test_too_few_elements_is_rejected_with_a_clear_message():
    with pytest.raises(InputError, match="n_elements = 2"):
        SplineBasis1D(1.0, 2)


def test_points_outside_are_rejected():
    with pytest.raises(InputError, match="outside"):
        SplineBasis1D(1.0, 4).matrix([1.5])
