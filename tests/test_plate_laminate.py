"""Laminate rigidity (eqs. 4.4–4.11) and patch-pair rigidity (eqs. 4.23–4.25)."""

import numpy as np
import pytest

from wingopt.errors import InputError
from wingopt.materials import (
    isotropic_stiffness,
    laminate_rigidity,
    moment_integrals,
    plate_rigidity,
    reduced_stiffness,
    rotate,
    symmetric_pair_rigidity,
)

E, NU, H = 1.0e9, 0.33, 5.0e-4


def test_isotropic_single_ply_is_the_classical_plate_rigidity():
    D = plate_rigidity(isotropic_stiffness(E, NU), H)
    d = E * H**3 / (12 * (1 - NU**2))  # 0.01169... N m
    assert d == pytest.approx(0.01168967, rel=1e-6)
    expected = d * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])
    np.testing.assert_allclose(D, expected, rtol=1e-13, atol=1e-18)


def test_many_equal_plies_sum_to_one_ply():
    q = reduced_stiffness(20e9, 1.5e9, 3e9, 0.27)
    one = plate_rigidity(q, 4.6e-3, (90.0,))
    four = plate_rigidity(q, 4.6e-3, (90.0,) * 4)
    np.testing.assert_allclose(four, one, rtol=1e-13)


def test_orthotropic_ply_reciprocity_and_rotation_by_90_degrees():
    e1, e2, g, nu12 = 20e9, 1.5e9, 3e9, 0.27
    q = reduced_stiffness(e1, e2, g, nu12)
    nu21 = nu12 * e2 / e1
    assert q[0, 1] == q[1, 0] == pytest.approx(nu21 * e1 / (1 - nu12 * nu21))
    q90 = rotate(q, 90.0)  # fibres along y: the stiff entry moves to (y, y)
    np.testing.assert_allclose(q90, q[[1, 0, 2]][:, [1, 0, 2]], rtol=1e-12)


@pytest.mark.parametrize("angle", [15.0, 30.0, 45.0, 72.0])
def test_isotropic_ply_is_invariant_under_rotation(angle):
    q = isotropic_stiffness(E, NU)
    np.testing.assert_allclose(rotate(q, angle), q, rtol=1e-12, atol=1e-6 * E)


def test_rotated_ply_matches_the_transformed_compliance():
    """Qbar(alpha) is the inverse of the rotated compliance, an independent route."""
    q = reduced_stiffness(45e9, 15e9, 3e9, 0.3)
    a = np.deg2rad(30.0)
    c, s = np.cos(a), np.sin(a)
    S = np.linalg.inv(q)
    # stress rotation from global to material axes; the compliance transforms as T_sigma^T S T_sigma
    t_sig = np.array([[c * c, s * s, 2 * c * s], [s * s, c * c, -2 * c * s], [-c * s, c * s, c * c - s * s]])
    Sbar = t_sig.T @ S @ t_sig
    np.testing.assert_allclose(rotate(q, 30.0), np.linalg.inv(Sbar), rtol=1e-10)


def test_patch_pair_rigidity_is_two_plies_off_the_mid_plane():
    q = reduced_stiffness(15e9, 45e9, 3e9, 0.1)
    h, hp = 4.6e-3, 5e-4
    pair = symmetric_pair_rigidity(q, h, hp)
    # a three-ply stack (patch, core, patch) minus the core is the pair
    stack = laminate_rigidity([(q, 0.0)] * 3, [-h / 2 - hp, -h / 2, h / 2, h / 2 + hp])
    core = plate_rigidity(q, h)
    full = plate_rigidity(q, h + 2 * hp)
    np.testing.assert_allclose(pair, full - core, rtol=1e-12)
    np.testing.assert_allclose(pair, stack - core, rtol=1e-12)
    c2, c3 = moment_integrals(h, hp)
    assert c3 == pytest.approx(((h / 2 + hp) ** 3 - (h / 2) ** 3) / 3)
    assert c2 == pytest.approx(((h / 2 + hp) ** 2 - (h / 2) ** 2) / 2)
    np.testing.assert_allclose(pair, 2 * c3 * q, rtol=1e-13)


def test_unstable_ply_is_rejected():
    with pytest.raises(InputError, match="nu12"):
        reduced_stiffness(1e9, 1e9, 0.3e9, 1.2)
    with pytest.raises(InputError, match="interfaces"):
        laminate_rigidity([(np.eye(3), 0.0)], [0.0, 0.0])
