"""Frame synthesis from the FvK membrane and virtual stretch sensors against the exact integrals."""

import dataclasses
import logging

import numpy as np
import pytest

from wingopt.errors import InputError
from wingopt.measurements.dic import DICMapping
from wingopt.measurements.dic_readers import read_dice
from wingopt.measurements.series import Measurements
from wingopt.membrane.dic_synth import dic_grid, exact_sensor_parts, membrane_fields, synthesize_frames
from wingopt.membrane.full import FvKMembrane
from wingopt.membrane.loads import load_case
from wingopt.membrane.virtual_sensors import virtual_sensors
from wingopt.problem.membrane import StretchSensorSpec
from wingopt.results.dic_files import write_dice


@pytest.fixture(scope="module")
def loaded(membrane_problem):
    """FvK (25 x 13) loaded by L1 200 Pa: three states along the static solution (scaled)."""
    p = membrane_problem
    fvk = FvKMembrane(p, (25, 13))
    f = fvk.linear.project(load_case("L1", p.width, p.height))
    z = fvk.static(fvk.linear.gram @ f).z
    Z = np.stack([0.6 * z, 0.8 * z, z])
    return fvk, Z, exact_sensor_parts(fvk, Z, [s.rect for s in p.sensors])


def test_grid_and_exact_fields(loaded):
    fvk, Z, _ = loaded
    x, y = dic_grid(0.14, 0.07, (40, 20))
    assert x.size == 800 and x.min() == pytest.approx(0.00175) and y.max() == pytest.approx(0.07 - 0.00175)
    f = membrane_fields(fvk, Z, x, y)
    np.testing.assert_allclose(f["w"], fvk.space.evaluate(Z.T, x, y).T)
    # Lagrange strain from finite differences of the exact displacement fields at one point
    h, x0, y0 = 1e-6, np.array([0.03]), np.array([0.02])
    g = {k: membrane_fields(fvk, Z[2:], x0 + dx, y0 + dy) for k, (dx, dy) in {"px": (h, 0), "mx": (-h, 0)}.items()}
    ux = (g["px"]["u"] - g["mx"]["u"]) / (2 * h)
    vx = (g["px"]["v"] - g["mx"]["v"]) / (2 * h)
    wx = (g["px"]["w"] - g["mx"]["w"]) / (2 * h)
    exx = membrane_fields(fvk, Z[2:], x0, y0)["exx"]
    np.testing.assert_allclose(exx, ux + 0.5 * (ux**2 + vx**2 + wx**2), rtol=1e-5)


def test_exact_parts_match_package_sensor_and_vanish_over_the_wing(loaded, membrane_problem):
    fvk, Z, ex = loaded
    np.testing.assert_allclose(ex["slope"], fvk.linear.sensors.outputs(Z), rtol=1e-10)
    whole = exact_sensor_parts(fvk, Z, [(0.0, 0.14, 0.0, 0.07)])
    assert np.all(np.abs(whole["inplane"]) < 1e-9 * whole["slope"])  # u = v = 0 on the frame


def test_synthesis_noise_and_missing(loaded):
    fvk, Z, _ = loaded
    fr = synthesize_frames(fvk, np.arange(3) / 300, Z, seed=4)
    clean = synthesize_frames(fvk, np.arange(3) / 300, Z, noise_displacement=0, noise_strain=0, missing=0)
    assert fr.n_points == 800 and 0.97 < fr.valid_fraction < 0.99 and clean.valid.all()
    v = fr.valid
    assert np.std((fr.w - clean.w)[v]) == pytest.approx(1e-5, rel=0.05)
    assert np.std((fr.exy - clean.exy)[v]) == pytest.approx(1e-4, rel=0.05)
    assert np.isnan(fr.w[~v]).all()
    with pytest.raises(InputError, match="one deflection per time"):
        synthesize_frames(fvk, np.arange(2) / 300, Z)


@pytest.mark.parametrize("kind,method,part,tol", [
    ("slope", "fit", "slope", 0.01), ("strain", "fit", "trace", 0.01),
    ("strain", "points", "trace", 0.01), ("strain_minus_inplane", "fit", "slope", 0.15),
])  # fmt: skip
def test_virtual_sensors_reproduce_their_exact_integrals(loaded, membrane_problem, kind, method, part, tol):
    fvk, Z, ex = loaded
    fr = synthesize_frames(fvk, np.arange(3) / 300, Z, seed=5)
    m = virtual_sensors(fr, membrane_problem, kind=kind, method=method)
    assert isinstance(m, Measurements) and m.sensor_names == membrane_problem.sensor_names
    np.testing.assert_allclose(m.values, ex[part], atol=tol * ex[part].max())  # one frame: noise ~0.5 % of s


def test_strain_route_differs_from_the_package_sensor_by_the_inplane_part(loaded, membrane_problem):
    fvk, Z, ex = loaded
    clean = synthesize_frames(fvk, np.arange(3) / 300, Z, noise_displacement=0, noise_strain=0, missing=0)
    m = virtual_sensors(clean, membrane_problem, kind="strain")
    np.testing.assert_allclose(m.values - ex["slope"], ex["inplane"] + ex["quadratic"], atol=2e-3 * ex["slope"].max())
    assert np.max(np.abs(ex["inplane"] / ex["slope"])) > 0.3  # not negligible on the default sensors


def test_dice_frames_refuse_the_strain_route_but_give_the_slope_route(tmp_path, loaded, membrane_problem):
    fvk, Z, ex = loaded
    fr = synthesize_frames(fvk, np.arange(3) / 300, Z, seed=6)
    mp = DICMapping(origin=(-70.0, -35.0), unit="mm")
    write_dice(fr, tmp_path, mp)
    back = read_dice(tmp_path, 300.0, mp, (0.14, 0.07), strain_kind="inplane")
    with pytest.raises(InputError, match="strain_kind = 'inplane'.*use kind = 'slope'"):
        virtual_sensors(back, membrane_problem, kind="strain")
    np.testing.assert_allclose(
        virtual_sensors(back, membrane_problem).values, ex["slope"], atol=0.01 * ex["slope"].max()
    )


def test_too_few_valid_points_give_nan(loaded, membrane_problem, caplog):
    fvk, Z, _ = loaded
    fr = synthesize_frames(fvk, np.arange(3) / 300, Z, seed=7)
    x0, x1, y0, y1 = membrane_problem.sensors[1].rect
    inside = (fr.x > x0 - 0.002) & (fr.x < x1 + 0.002) & (fr.y > y0 - 0.002) & (fr.y < y1 + 0.002)
    valid = fr.valid.copy()
    valid[1, inside] = False
    bad = dataclasses.replace(fr, valid=valid)
    with caplog.at_level(logging.WARNING):
        m = virtual_sensors(bad, membrane_problem, kind="strain")
    assert np.isnan(m.values[1, 1]) and np.isfinite(m.values[[0, 2], 1]).all() and np.isfinite(m.values[:, 0]).all()
    assert "too few valid DIC points" in caplog.text


def test_bad_requests(loaded, membrane_problem):
    fvk, Z, _ = loaded
    fr = synthesize_frames(fvk, np.arange(3) / 300, Z, grid=(8, 4), seed=8)
    with pytest.raises(InputError, match="kind = 'slope': expected method = 'fit'"):
        virtual_sensors(fr, membrane_problem, method="points")
    with pytest.raises(InputError, match="kind = 'area'"):
        virtual_sensors(fr, membrane_problem, kind="area")
    keep = fr.x < 0.06  # the DIC covers the leading half only
    half = dataclasses.replace(
        fr, x=fr.x[keep], y=fr.y[keep], valid=fr.valid[:, keep],
        **{k: getattr(fr, k)[:, keep] for k in ("u", "v", "w", "exx", "eyy", "exy")},
    )  # fmt: skip
    aft = [StretchSensorSpec("T", (0.09, 0.12, 0.02, 0.04))]
    with pytest.raises(InputError, match="sensor T rect .* no DIC point"):
        virtual_sensors(half, membrane_problem, sensors=aft)
    with pytest.raises(InputError, match="strain_reference = 'unstrained'"):
        virtual_sensors(dataclasses.replace(fr, strain_reference="unstrained"), membrane_problem, kind="strain")


def test_noise_std_is_predicted(loaded, membrane_problem):
    fvk, Z, _ = loaded
    Zs = np.repeat(Z[2:], 150, axis=0)
    fr = synthesize_frames(fvk, np.arange(150) / 300, Zs, seed=9)
    for kind in ("slope", "strain"):
        m = virtual_sensors(fr, membrane_problem, kind=kind)
        np.testing.assert_allclose(m.noise_std, np.std(m.values, axis=0), rtol=0.25)
    assert virtual_sensors(fr, membrane_problem, kind="strain", method="points").noise_std is None
