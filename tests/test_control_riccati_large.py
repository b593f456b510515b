"""Newton–Kleinman with low-rank ADI: Lyapunov accuracy, agreement with the dense Riccati solution."""

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from wingopt.cli import main
from wingopt.control.lqr import lqr
from wingopt.control.riccati_large import (
    _adi_gain,
    _ShiftedSolver,
    care_nk_adi,
    functional_gains,
    gain_profiles,
    gain_relative_error,
    plate_lqr_gain,
    plate_weight,
)
from wingopt.errors import InputError
from wingopt.plate import PlateModel
from wingopt.problem import load_problem


def _toy(n=30, m=2, seed=0):
    rng = np.random.default_rng(seed)
    L = rng.standard_normal((n, n))
    Kst = L @ L.T + n * np.eye(n)
    M = np.eye(n) + 0.1 * np.diag(rng.random(n))
    D = 2.0 * np.eye(n)
    b = rng.standard_normal((n, m))
    return M, D, Kst, b, rng


def test_adi_solves_the_closed_loop_lyapunov_equation():
    M, D, Kst, b, rng = _toy()
    n, m = b.shape
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Kst, -D]])
    E = sla.block_diag(np.eye(n), M)
    B = np.vstack([np.zeros((n, m)), b])
    K = 0.02 * rng.standard_normal((m, 2 * n))
    F = A - B @ K
    G = np.hstack([rng.standard_normal((2 * n, 3)), K.T])
    op = np.kron(E.T, F.T) + np.kron(F.T, E.T)  # vec(F^T X E + E X F)
    X = np.linalg.solve(op, -(G @ G.T).ravel(order="F")).reshape(2 * n, 2 * n, order="F")
    s = _ShiftedSolver(sp.csc_matrix(M), sp.csc_matrix(D), sp.csc_matrix(Kst), b)

    def AT(Y):
        return np.vstack([-(s.Kst @ Y[n:]), Y[:n] - s.D @ Y[n:]])

    U0 = rng.standard_normal((2 * n, 20))
    acc, steps, res, _ = _adi_gain(s, AT, K, G, U0, tol=1e-14, max_steps=300)
    assert res < 1e-14
    assert gain_relative_error(acc, b.T @ X[n:] @ E) < 1e-10


def test_nk_adi_matches_the_dense_riccati_solution_on_a_toy_system():
    M, D, Kst, b, rng = _toy(seed=2)
    n, m = b.shape
    C = rng.standard_normal((4, 2 * n))
    R = 0.5 * np.eye(m)
    res = care_nk_adi(sp.csc_matrix(M), sp.csc_matrix(D), sp.csc_matrix(Kst), b, C, R, shift_modes=10)
    assert res.converged and res.newton_steps < 15
    # dense reference in standard form: x' = E^-1 A x + E^-1 B u
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Kst, -D]])
    E = sla.block_diag(np.eye(n), M)
    B = np.vstack([np.zeros((n, m)), b])
    Kd, _, _ = lqr(np.linalg.solve(E, A), np.linalg.solve(E, B), C.T @ C, R)
    assert gain_relative_error(res.K, Kd) < 1e-8


@pytest.fixture(scope="module")
def model7():
    return PlateModel.from_problem(load_problem("plate"), (7, 31))


def test_plate_gain_nk_adi_equals_dense_on_7x31(model7):
    """Band-limited seed weight (10 modes), r = 1e-10: NK-ADI against the dense Newton reference.

    Measured (issue 16 settings: each ADI solve stops when 40 shifts change the gain by < 2e-5,
    later Newton steps replay the first step's shifts): 3 Newton steps of 120 shifts (gain changes
    5.0e-4, 3.9e-5, 2.4e-6), relative gain error 4.0e-5 in 1.6 s CPU. Before: 4 steps of up to 800
    shifts, error 2.0e-6. The issue's bound is 1e-4."""
    K, info = plate_lqr_gain(model7, 1e-10, weight_modes=10)
    Kd, dinfo = plate_lqr_gain(model7, 1e-10, weight_modes=10, method="dense")
    assert info["converged"] and info["newton_steps"] <= 6
    assert max(info["adi_steps"]) <= 200
    assert dinfo["riccati_residual"] < 1e-8
    assert gain_relative_error(K, Kd) < 1e-4
    # the previous settings (every solve to its residual floor or 800 shifts) agree with it
    Kp, pinfo = plate_lqr_gain(model7, 1e-10, weight_modes=10, gain_tol=0.0, reuse_shifts=False, max_adi=400)
    assert gain_relative_error(K, Kp) < 1e-4


def test_weight_is_the_seed_weight_on_the_band(model7):
    C = plate_weight(model7, 1.0, 1.0, weight_modes=None)
    n = model7.n
    z = model7.target("bending")
    x = np.concatenate([z, 0.3 * z])
    # With every mode in the band, ||C x||^2 = z'Mz + z_dot'M z_dot.
    assert np.sum((C @ x) ** 2) == pytest.approx(1.09 * model7.m_norm(z) ** 2, rel=1e-8)
    assert C.shape == (2 * n, 2 * n)
    with pytest.raises(InputError, match="weight_modes"):
        plate_weight(model7, weight_modes=0)


def test_functional_gains_reproduce_the_gain(model7):
    rng = np.random.default_rng(0)
    K = rng.standard_normal((9, 2 * model7.n))
    kb, kv = functional_gains(model7, K)
    np.testing.assert_allclose(kb.T @ (model7.stiffness @ np.ones(model7.n)), K[:, : model7.n].sum(axis=1), rtol=1e-8)
    np.testing.assert_allclose((model7.mass @ kv).T, K[:, model7.n :], rtol=1e-8, atol=1e-8 * np.abs(K).max())
    prof = gain_profiles(model7, K)
    assert prof["bending"].shape == (3, prof["y"].size) and prof["patches"] == ["PZ1", "PZ4", "PZ7"]


def test_gains_command_bad_input(tmp_path, capsys):
    assert main(["gains", "plate", "--meshes", "7by31", "--out", str(tmp_path / "g")]) == 2
    assert "mesh" in capsys.readouterr().err
    assert main(["gains", "plate", "--r", "-1", "--out", str(tmp_path / "g")]) == 2
    assert not (tmp_path / "g").exists()


def test_gains_command_writes_profiles_and_caches(tmp_path, capsys):
    """``wingopt gains`` on 7x31: summary, functional-gain profiles, figure; a second run reuses the cache."""
    import json

    out, cache = tmp_path / "g", tmp_path / "cache"
    args = ["gains", "plate", "--meshes", "7x31", "--weight-modes", "10", "--cache", str(cache), "--out", str(out)]
    assert main([*args, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    rec = summary["meshes"][0]
    assert rec["mesh"] == "7x31" and rec["states"] == 558 and rec["converged"] and rec["newton_steps"] <= 6
    assert summary["r"] == 1e-10 and summary["weight_modes"] == 10
    header = (out / "profiles.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "y" and "bending_PZ1_7x31" in header and "velocity_PZ7_7x31" in header
    assert (out / "functional_gains.png").stat().st_size > 10_000
    assert (cache / "gains_7x31.npz").exists()
    assert main([*args, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["meshes"][0]["cached"] is True
