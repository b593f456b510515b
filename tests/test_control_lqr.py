import numpy as np
import pytest

from wingopt.control import dlqe, dlqr, lqe, lqr
from wingopt.dynamics import StateSpace, discretize
from wingopt.errors import InputError


def test_scalar_lqr_matches_the_closed_form():
    a, b, q, r = 0.7, 2.0, 3.0, 0.5
    K, S, E = lqr(np.array([[a]]), np.array([[b]]), [[q]], [[r]])
    s = r * (a + np.sqrt(a**2 + b**2 * q / r)) / b**2
    assert S[0, 0] == pytest.approx(s, rel=1e-12)
    assert K[0, 0] == pytest.approx(b * s / r, rel=1e-12)
    assert E[0] == pytest.approx(-np.sqrt(a**2 + b**2 * q / r), rel=1e-12)


def test_lqr_accepts_a_state_space_and_stabilises_an_oscillator():
    sys = StateSpace(np.array([[0.0, 1.0], [-4.0, -0.1]]), np.array([[0.0], [1.0]]))
    K, S, E = lqr(sys, np.eye(2), [[0.1]])
    assert np.all(E.real < 0)
    np.testing.assert_allclose(S, S.T, atol=1e-12)
    # Riccati residual
    A, B = sys.A, sys.B
    res = A.T @ S + S @ A - S @ B @ np.linalg.solve([[0.1]], B.T) @ S + np.eye(2)
    assert np.abs(res).max() < 1e-10


def test_dlqr_residual_and_stability():
    sys = discretize(StateSpace(np.array([[0.0, 1.0], [-4.0, -0.1]]), np.array([[0.0], [1.0]])), 0.05)
    K, S, E = dlqr(sys, np.eye(2), [[0.1]])
    A, B, R = sys.A, sys.B, np.array([[0.1]])
    res = A.T @ S @ A - S - A.T @ S @ B @ np.linalg.solve(R + B.T @ S @ B, B.T @ S @ A) + np.eye(2)
    assert np.abs(res).max() < 1e-10
    assert np.all(np.abs(E) < 1)


def test_kalman_gains_make_the_error_dynamics_stable():
    A = np.array([[0.0, 1.0], [-4.0, -0.1]])
    C = np.array([[1.0, 0.0]])
    L, P, E = lqe(A, np.eye(2), C, np.eye(2) * 0.01, [[1e-3]])
    assert np.all(E.real < 0) and L.shape == (2, 1)
    Ad = np.array([[0.99, 0.05], [-0.2, 0.99]])
    Ld, Pd, Ed = dlqe(Ad, np.eye(2), C, np.eye(2) * 0.01, [[1e-3]])
    assert np.all(np.abs(Ed) < 1)
    np.testing.assert_allclose(Ld, Ad @ Pd @ C.T @ np.linalg.inv(C @ Pd @ C.T + 1e-3), rtol=1e-10)


def test_bad_weights_are_named():
    with pytest.raises(InputError, match="R: expected a symmetric positive definite"):
        lqr(np.eye(2), np.ones((2, 1)), np.eye(2), [[0.0]])
    with pytest.raises(InputError, match=r"Q: shape \(3, 3\)"):
        lqr(np.eye(2), np.ones((2, 1)), np.eye(3), [[1.0]])
