"""DICFrames validation, DICMapping transforms and the plausibility checks."""

import dataclasses

import numpy as np
import pytest
from _dic import H, W, analytic_frames

from wingopt.errors import DataFileError, InputError
from wingopt.measurements.dic import DICMapping, check_plausible


@pytest.fixture
def frames():
    return analytic_frames()


def _replace(fr, **kw):
    return dataclasses.replace(fr, **kw)


def test_frames_validate_shapes_times_and_finiteness(frames):
    assert frames.n_frames == 6 and frames.n_points == 72 and frames.valid_fraction == 1.0
    with pytest.raises(InputError, match=r"w has shape \(6, 71\)"):
        _replace(frames, w=frames.w[:, 1:])
    with pytest.raises(InputError, match="strictly increasing"):
        _replace(frames, t=frames.t[::-1].copy())
    w = frames.w.copy()
    w[2, 5] = np.nan
    with pytest.raises(InputError, match=r"w\[frame 2, point 5\] = nan"):
        _replace(frames, w=w)
    valid = frames.valid.copy()
    valid[2, 5] = False
    assert _replace(frames, w=w, valid=valid).valid.sum() == frames.valid.size - 1  # NaN where invalid is fine
    with pytest.raises(InputError, match="strain_reference"):
        _replace(frames, strain_reference="relaxed")
    with pytest.raises(InputError, match="valid has shape"):
        _replace(frames, valid=frames.valid.astype(int))


def test_frames_without_strains(frames):
    fr = _replace(frames, exx=None, eyy=None, exy=None, strain_kind="none")
    assert fr.exx is None
    with pytest.raises(InputError, match="exx"):
        _replace(frames, exx=None)


@pytest.mark.parametrize("xa,ya,za", [("+x", "+y", "+z"), ("-y", "+x", "-z"), ("+y", "-x", "+z"), ("-x", "-y", "-z")])
def test_mapping_round_trip_and_tensor_rotation(xa, ya, za):
    m = DICMapping(origin=(12.0, -3.0), x_axis=xa, y_axis=ya, z_axis=za, unit="mm")
    rng = np.random.default_rng(1)
    x, y = rng.random(5) * W, rng.random(5) * H
    X, Y = m.inverse_points(x, y)
    np.testing.assert_allclose(m.points(X, Y), (x, y), atol=1e-15)
    u, v, w = rng.standard_normal((3, 5)) * 1e-3
    np.testing.assert_allclose(m.vectors(*m.inverse_vectors(u, v, w)), (u, v, w), atol=1e-15)
    e = rng.standard_normal((3, 5)) * 1e-2
    np.testing.assert_allclose(m.strains(*m.inverse_strains(*e)), e, atol=1e-15)
    # trace and determinant are invariants of the rotation
    exx, eyy, exy = m.strains(*e)
    np.testing.assert_allclose(exx + eyy, e[0] + e[1])
    np.testing.assert_allclose(exx * eyy - exy**2, e[0] * e[1] - e[2] ** 2)


def test_mapping_swaps_and_flips():
    m = DICMapping(x_axis="-y", y_axis="+x", unit="mm")
    x, y = m.points(np.array([10.0]), np.array([-20.0]))
    assert (x[0], y[0]) == pytest.approx((0.02, 0.01))
    exx, eyy, exy = m.strains(np.array([1e-3]), np.array([2e-3]), np.array([5e-4]))
    assert (exx[0], eyy[0], exy[0]) == pytest.approx((2e-3, 1e-3, -5e-4))
    assert DICMapping(strain_unit="percent").strains(1.0, 2.0, 0.5) == pytest.approx((0.01, 0.02, 0.005))


def test_mapping_rejects_bad_declarations():
    with pytest.raises(InputError, match="x_axis = 'x'"):
        DICMapping(x_axis="x")
    with pytest.raises(InputError, match="two different DIC axes"):
        DICMapping(x_axis="+x", y_axis="-x")
    with pytest.raises(InputError, match="unit = 'cm'"):
        DICMapping(unit="cm")
    with pytest.raises(InputError, match="origin"):
        DICMapping(origin=(0.0, float("nan")))
    with pytest.raises(InputError, match="unknown key"):
        DICMapping.from_dict({"orign": [0, 0]})
    assert DICMapping.from_dict({"origin": [1, 2], "unit": "mm"}).origin == (1.0, 2.0)


def test_plausible_accepts_the_wing(frames):
    check_plausible(frames, (W, H))


def test_plausible_mm_read_as_m(frames):
    fr = _replace(frames, x=frames.x * 1e3, y=frames.y * 1e3)
    with pytest.raises(DataFileError, match="x \\[5.833, 134.2\\] m.*mm read as m: declare unit = 'mm'"):
        check_plausible(fr, (W, H))


def test_plausible_m_read_as_mm(frames):
    fr = _replace(frames, x=frames.x * 1e-3, y=frames.y * 1e-3)
    with pytest.raises(DataFileError, match="m read as mm"):
        check_plausible(fr, (W, H))


def test_plausible_wrong_origin(frames):
    with pytest.raises(DataFileError, match="origin and axes"):
        check_plausible(_replace(frames, x=frames.x - 0.07), (W, H))


def test_plausible_displacements_in_mm(frames):
    with pytest.raises(DataFileError, match=r"w\[frame .*half the wing height"):
        check_plausible(_replace(frames, w=frames.w * 1e3), (W, H))


def test_plausible_percent_strains(frames):
    with pytest.raises(DataFileError, match="percent"):
        check_plausible(_replace(frames, exx=frames.exx * 100), (W, H))


def test_analytic_frames_with_missing_points():
    fr = analytic_frames(missing=0.1)
    assert 0.8 < fr.valid_fraction < 0.97
