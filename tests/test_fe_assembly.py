import numpy as np
import pytest
import scipy.sparse as sp

from wingopt.fe import (
    DX,
    DXX,
    DXY,
    DY,
    DYY,
    VALUE,
    BilinearForm,
    SplineBasis1D,
    TensorSpace,
    assemble,
    project,
    separable,
)
from wingopt.fe import EdgeCondition as E


@pytest.fixture(scope="module")
def free_space():
    return TensorSpace(SplineBasis1D(0.15, 6, E.FREE, E.FREE), SplineBasis1D(0.6, 8, E.FREE, E.CLAMPED))


FORMS = {
    "mass": separable((1.0, VALUE, VALUE)),
    "tension": separable((14.2, DX, DX), (7.1, DY, DY)),
    "smoothness": separable((1.0, DXX, DXX), (1.0, DYY, DYY)),
    "plate-like": separable((2.0, DXX, DXX), (0.7, DXX, DYY), (0.7, DYY, DXX), (3.0, DYY, DYY), (4.0, DXY, DXY)),
}


@pytest.mark.parametrize("name", list(FORMS))
def test_kronecker_and_cellwise_paths_agree(free_space, name):
    form = FORMS[name]
    A_kron = assemble(free_space, form, method="kron")
    A_cell = assemble(free_space, form, method="cells")
    scale = abs(A_kron).max()
    assert abs(A_kron - A_cell).max() <= 1e-13 * scale
    assert abs(A_kron - A_kron.T).max() <= 1e-14 * scale


def test_piecewise_constant_coefficients(free_space):
    """Element-wise path with per-cell data equals the sum of per-region integrals."""
    cells = free_space.cells()
    c = np.where(cells.x1 < 0.06, 3.0, 1.0)  # elements left of the edge x = 0.05
    heavy = BilinearForm(lambda u, v, w: w.c * u.value * v.value)
    A = assemble(free_space, heavy, cells, data={"c": c})
    mass = FORMS["mass"]
    left = assemble(free_space, mass, free_space.cells((0, 0.05, 0, 0.6)))
    right = assemble(free_space, mass, free_space.cells((0.05, 0.15, 0, 0.6)))
    np.testing.assert_allclose((A - (3 * left + right)).toarray(), 0, atol=1e-15)
    # a region edge that is not on an element edge still splits exactly
    a = assemble(free_space, mass, free_space.cells((0, 0.0371, 0, 0.6)))
    b = assemble(free_space, mass, free_space.cells((0.0371, 0.15, 0, 0.6)))
    M = assemble(free_space, mass)
    assert abs(a + b - M).max() < 1e-15


def test_basis_derivatives_match_finite_differences(free_space):
    rng = np.random.default_rng(0)
    c = rng.standard_normal(free_space.n)
    x, y = np.array([0.013, 0.071, 0.14]), np.array([0.05, 0.33, 0.58])
    eps = 1e-6
    fx = (free_space.evaluate(c, x + eps, y) - free_space.evaluate(c, x - eps, y)) / (2 * eps)
    fxy = (free_space.evaluate(c, x, y + eps, dx=1) - free_space.evaluate(c, x, y - eps, dx=1)) / (2 * eps)
    np.testing.assert_allclose(free_space.evaluate(c, x, y, dx=1), fx, rtol=1e-7)
    np.testing.assert_allclose(free_space.evaluate(c, x, y, dx=1, dy=1), fxy, rtol=1e-6)


def test_l2_projection_reproduces_a_bicubic_polynomial(free_space):
    def g(x, y):
        return 1 + x**3 - 2 * x * y + (0.6 - y) ** 2 * (0.6 - y) * x

    M = assemble(free_space, FORMS["mass"])
    c = project(free_space, lambda x, y: np.zeros_like(x) + g(x, y), M)
    x, y = np.random.default_rng(1).uniform([0, 0], [0.15, 0.6], (50, 2)).T
    # not in the clamped space (g has value at y=0.6) -> compare in a free-free space instead
    free = TensorSpace(free_space.bx, SplineBasis1D(0.6, 8, E.FREE, E.FREE))
    c = project(free, g, assemble(free, FORMS["mass"]))
    np.testing.assert_allclose(free.evaluate(c, x, y), g(x, y), rtol=1e-11, atol=1e-12)
    assert sp.issparse(M)
