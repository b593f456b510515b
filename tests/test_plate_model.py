"""The plate-wing model against the dissertation (Tables 5.4, 5.5) and against plate/beam theory."""

import json

import numpy as np
import pytest

from wingopt.cli import main
from wingopt.plate.calibration import SEED_ORDER, TABLE_5_4, TABLE_5_5
from wingopt.plate.model import PlateModel
from wingopt.problem import load_problem
from wingopt.problem.plate import Laminate, Material, PlateProblem

MESHES = [(7, 31), (13, 61)]


@pytest.fixture(scope="module")
def plate_problem():
    return load_problem("plate")


@pytest.fixture(scope="module")
def models(plate_problem):
    return {nodes: PlateModel.from_problem(plate_problem, nodes) for nodes in MESHES}


@pytest.fixture(scope="module")
def modes(models):
    return {nodes: m.modes(5) for nodes, m in models.items()}


# -- invariants -------------------------------------------------------------------------------------


def test_sizes_and_build_time(models):
    m = models[(13, 61)]
    # x: free-free, 12 elements -> 15 splines; y: free tip, clamped root, 60 elements -> 61
    assert m.space.shape == (15, 61) and m.n == 915
    assert m.actuation.shape == (915, 9) and m.sensing.shape == (9, 915)
    assert m.build_seconds < 10.0


def test_matrices_are_symmetric_and_definite(models, modes):
    m = models[(7, 31)]
    M, K, Kd = (a.toarray() for a in (m.mass, m.stiffness, m.damping))
    for A in (M, K, Kd):
        assert np.abs(A - A.T).max() <= 1e-12 * np.abs(A).max()
        np.linalg.cholesky(A)  # raises unless positive definite
    # clamped root: no rigid-body motion, so K is positive definite, not only semi-definite
    assert modes[(7, 31)][0][0] > 5.0  # lowest mode above 5 Hz


def test_mass_is_the_areal_density_integral(models, plate_problem):
    """1^T M 1-ish check: the total mass from M equals the sum of rho h over the regions."""
    m = models[(7, 31)]
    props = m.properties
    total = float(np.sum(props.areal_density * props.cells.area))
    p = plate_problem
    skin = p.skin.areal_density * p.width * p.length
    extra = sum((p.batten.areal_density - p.skin.areal_density) * _area(b.rect) for b in p.battens)
    patches = sum(2 * p.piezo.material.density * p.piezo.thickness * _area(q.rect) for q in p.patches)
    assert total == pytest.approx(skin + extra + patches, rel=1e-12)
    # rigid translation is not in the clamped space; check against its L2 projection instead
    one = m.project(lambda x, y: np.ones_like(x))
    assert float(one @ (m.mass @ one)) == pytest.approx(total, rel=0.05)


def _area(r):
    return (r[1] - r[0]) * (r[3] - r[2])


# -- the dissertation's tables ----------------------------------------------------------------------


@pytest.mark.parametrize("nodes", MESHES)
def test_first_four_frequencies_match_table_5_4_in_the_seed_order(models, modes, nodes):
    m = models[nodes]
    freqs, shapes = modes[nodes]
    kinds = tuple(m.classify_mode(shapes[:, k]) for k in range(4))
    assert kinds == SEED_ORDER  # 1st bending, 1st torsion, 2nd bending, 2nd torsion
    np.testing.assert_allclose(freqs[:4], TABLE_5_4[nodes], rtol=0.10)


def test_mode_shapes_are_symmetric_or_antisymmetric_at_the_tip(models, modes):
    m = models[(13, 61)]
    _, shapes = modes[(13, 61)]
    corners = m.tip_corners(shapes[:, :4].T)  # (4, 2)
    assert corners[0, 0] == pytest.approx(corners[0, 1], rel=1e-6)  # bending: corners together
    assert corners[1, 0] == pytest.approx(-corners[1, 1], rel=1e-6)  # torsion: corners opposite


def test_frequencies_decrease_with_refinement(modes):
    coarse, fine = modes[(7, 31)][0][:4], modes[(13, 61)][0][:4]
    assert np.all(fine < coarse)
    assert np.all(fine > 0.97 * coarse)  # and they converge


@pytest.mark.parametrize("nodes", MESHES)
def test_decay_rates_match_table_5_5(models, nodes):
    eigs = models[nodes].eigenvalues(4)
    ref = np.asarray(TABLE_5_5[nodes])
    np.testing.assert_allclose(eigs.real, ref.real, rtol=0.25)
    np.testing.assert_allclose(eigs.imag, ref.imag, rtol=0.10)


def test_sparse_damped_eigenvalues_match_the_dense_first_order_matrix(plate_problem):
    """Damping is not proportional (rho h varies, gamma does not): check the sparse pencil solver.

    On a coarse 4x13 mesh (78 dofs) so that the dense reference is cheap.
    """
    m = PlateModel.from_problem(plate_problem, (4, 13))
    eigs = m.eigenvalues(6)
    lam = np.linalg.eigvals(m.system.state_space().A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(lam.imag)][:6]
    np.testing.assert_allclose(eigs, lam, rtol=1e-8)


# -- actuation, sensing, targets ---------------------------------------------------------------------


def test_positive_voltage_bends_the_patch_to_negative_curvature(models, plate_problem):
    m = models[(13, 61)]
    names = list(m.patch_names)
    for name, axis in [("PZ1", 0), ("PZ4", 0), ("PZ5", 1), ("PZ8", 1)]:
        u = np.zeros(9)
        u[names.index(name)] = 1000.0
        z = m.static_deflection(u)
        x0, x1, y0, y1 = plate_problem.patches[names.index(name)].rect
        xc, yc = np.array([(x0 + x1) / 2]), np.array([(y0 + y1) / 2])
        kappa = m.curvatures(z, xc, yc)[:, 0]
        assert kappa[axis] < 0, (name, kappa)
        # top face of the substrate stretches (eps = -(h/2) kappa)
        assert m.surface_strains(z, xc, yc)[axis, 0] > 0


def test_root_pair_twists_and_bends_the_tip(models):
    m = models[(13, 61)]
    u = np.zeros(9)
    u[7], u[8] = 4000.0, -4000.0  # PZ8 +, PZ9 -: twist
    left, right = m.tip_corners(m.static_deflection(u))
    assert left == pytest.approx(-right, rel=1e-9)
    assert abs(left) == pytest.approx(0.01, rel=0.05)  # the calibrated authority (seed §5.4.2)
    u[8] = 4000.0  # same sign: bending, tip down
    left, right = m.tip_corners(m.static_deflection(u))
    assert left == pytest.approx(right, rel=1e-9) and left < -0.05


def test_sensors_measure_h_times_the_mean_curvature_integral(models, plate_problem):
    """The bending target -(a/L^2)(y-L)^2 is in the space: S_i = h * (-2a/L^2) * area_i exactly."""
    m = models[(7, 31)]
    z = m.target("bending")
    a, L = plate_problem.targets.bending, plate_problem.length
    h = plate_problem.batten.thickness
    expected = [h * (-2 * a / L**2) * _area(p.rect) for p in plate_problem.patches]
    np.testing.assert_allclose(m.sensor_outputs(z), expected, rtol=1e-10)


def test_targets_are_projected(models):
    m = models[(13, 61)]
    np.testing.assert_allclose(m.tip_corners(m.target("bending")), [-0.1, -0.1], rtol=1e-9)
    twist = m.tip_corners(m.target("twist"))
    np.testing.assert_allclose(twist, [0.01, -0.01], rtol=0.02)  # L2 projection, not interpolation
    camber = m.target("camber")
    assert m.evaluate(camber, [0.075], [0.0])[0] == pytest.approx(0.005, rel=0.01)
    assert m.m_norm(camber) == pytest.approx(float(np.sqrt(camber @ (m.mass @ camber))))
    assert m.m_norm(np.stack([camber, 2 * camber])) == pytest.approx([m.m_norm(camber), 2 * m.m_norm(camber)])


def test_unknown_shape_is_an_input_error(models):
    with pytest.raises(ValueError, match="shape = 'sweep'"):
        models[(7, 31)].target("sweep")


# -- plate theory -----------------------------------------------------------------------------------

E, NU, RHO, H = 1.0e9, 0.33, 1000.0, 5.0e-4
BETA1 = 1.8751040687119611  # first root of 1 + cos(b) cosh(b) = 0 (cantilever)


def strip(width: float, nodes, nu: float = NU) -> PlateModel:
    mat = Material.isotropic(RHO, E, nu, kelvin_voigt=(0.0, 0.0), viscous=0.0)
    skin = Laminate(mat, H)
    return PlateModel.from_problem(PlateProblem(width, 0.6, skin, skin, None, (), (), nodes))


def beam_frequency(EI: float, mass_per_length: float, length: float) -> float:
    return BETA1**2 / (2 * np.pi * length**2) * np.sqrt(EI / mass_per_length)


def test_narrow_cantilever_strip_matches_euler_bernoulli():
    """A strip 30 mm x 600 mm: its first bending frequency within 1 % of beam theory.

    A narrow strip is free to curve anticlastically, so the beam stiffness is ``E I = E h^3 W / 12``
    (no ``1/(1 - nu^2)``); the plate rigidity ``D W`` applies to a wide plate in cylindrical bending.
    The clamp restrains the anticlastic curvature over about one width from the root, which
    stiffens the strip slightly (+0.5 % here, +1.9 % for the 150 mm wing).
    """
    W = 0.03
    f = strip(W, (4, 31)).frequencies_hz(1)[0]
    f_beam = beam_frequency(E * H**3 * W / 12, RHO * H * W, 0.6)
    assert f == pytest.approx(f_beam, rel=0.01)
    assert f > f_beam  # the clamp only adds stiffness


def test_wide_strip_lies_between_the_beam_and_the_cylindrical_plate():
    W = 0.15
    f = strip(W, (7, 31)).frequencies_hz(1)[0]
    f_beam = beam_frequency(E * H**3 * W / 12, RHO * H * W, 0.6)
    assert f_beam < f < f_beam / np.sqrt(1 - NU**2)


def test_strip_without_poisson_effect_is_exactly_a_beam():
    W = 0.15
    f = strip(W, (7, 31), nu=0.0).frequencies_hz(1)[0]
    assert f == pytest.approx(beam_frequency(E * H**3 * W / 12, RHO * H * W, 0.6), rel=1e-5)


# -- command line -----------------------------------------------------------------------------------


def test_modes_command_on_the_plate(capsys):
    assert main(["modes", "plate", "--mesh", "13x61", "--count", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mesh"] == [13, 61]
    np.testing.assert_allclose(out["frequencies_hz"], TABLE_5_4[(13, 61)], rtol=0.10)
    ims = [e[1] for e in out["eigenvalues"]]
    assert ims == sorted(ims) and min(ims) > 0
    np.testing.assert_allclose(np.array(ims) / (2 * np.pi), out["frequencies_hz"], rtol=1e-3)
