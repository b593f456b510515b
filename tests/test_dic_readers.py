"""DICe, CSV and NPZ readers: round trips and every kind of bad input (one clear line or a warning)."""

import logging
import re
from pathlib import Path

import numpy as np
import pytest
from _dic import H, W, analytic_frames

from wingopt.errors import DataFileError, InputError
from wingopt.measurements.dic import DICMapping
from wingopt.measurements.dic_npz import read_dic_npz
from wingopt.measurements.dic_readers import read_dic_csv, read_dice
from wingopt.results.dic_files import write_dic_csv, write_dic_npz, write_dice


@pytest.fixture
def frames():
    return analytic_frames()


EXT = (W, H)
MAP = DICMapping(origin=(-70.0, 35.0), x_axis="+x", y_axis="-y", z_axis="-z", unit="mm")


@pytest.fixture
def dice_dir(tmp_path, frames):
    write_dice(frames, tmp_path / "dice", MAP)
    return tmp_path / "dice"


def _edit(path: Path, fn):
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(fn(lines)))


def _data_start(lines):
    return next(i for i, ln in enumerate(lines) if ln.startswith("SUBSET_ID")) + 1


def _set_cell(path: Path, row: int, col: int, value) -> None:
    """Replace one cell of a DICe file's data row ``row`` (``value``: text, or a function of the old text)."""

    def edit(lines):
        i = _data_start(lines) + row
        cells = lines[i].rstrip("\n").split(",")
        cells[col] = value(cells[col]) if callable(value) else value
        lines[i] = ",".join(cells) + "\n"
        return lines

    _edit(path, edit)


# -- DICe ---------------------------------------------------------------------------------------
def test_dice_round_trip(dice_dir, frames):
    files = sorted(dice_dir.iterdir())
    assert [f.name for f in files][:2] == ["DICe_solution_0.txt", "DICe_solution_1.txt"]
    head = files[0].read_text().splitlines()
    assert head[0] == "***" and any(ln.startswith("SUBSET_ID,COORDINATE_X") for ln in head)
    fr = read_dice(dice_dir, 300.0, MAP, EXT)
    assert fr.strain_kind == "surface" and fr.units == "mm" and fr.strain_reference == "prestrained"
    np.testing.assert_allclose(fr.t, frames.t)
    np.testing.assert_allclose(fr.x, frames.x, atol=1e-6)  # %4.4E in mm: 5 significant digits
    np.testing.assert_allclose(fr.y, frames.y, atol=1e-6)
    for k in ("u", "v", "w"):
        np.testing.assert_allclose(getattr(fr, k), getattr(frames, k), atol=1e-9, rtol=1e-4)
    for k in ("exx", "eyy", "exy"):
        np.testing.assert_allclose(getattr(fr, k), getattr(frames, k), atol=1e-9, rtol=1e-4)
    assert fr.report.dropped_total == 0 and fr.report.missing_frames == ()


def test_dice_flagged_points_dropped_and_counted(tmp_path):
    fr0 = analytic_frames(missing=0.05, seed=3)
    write_dice(fr0, tmp_path, MAP)
    j = int(np.argmax(fr0.valid[2]))  # a good point of frame 2, given a failure status with positive sigma

    _set_cell(tmp_path / "DICe_solution_2.txt", j, -1, "7.0000E+00")  # SEARCH_FAILED
    fr = read_dice(tmp_path, 300.0, MAP, EXT)
    assert dict(fr.report.dropped) == {"sigma": int((~fr0.valid).sum()), "status_flag": 1}
    expected = fr0.valid.copy()
    expected[2, j] = False
    assert np.array_equal(fr.valid, expected)


def test_dice_default_kind_is_inplane_and_time_from_frame_rate(dice_dir):
    for f in dice_dir.iterdir():
        _edit(f, lambda ls: [ln for ln in ls if "wingopt strain kind" not in ln])
    fr = read_dice(dice_dir, 150.0, MAP, EXT)
    assert fr.strain_kind == "inplane"
    np.testing.assert_allclose(np.diff(fr.t), 1 / 150)


def test_dice_space_delimited_without_header_block(tmp_path, frames):
    write_dice(frames, tmp_path, MAP, delimiter=" ")
    for f in tmp_path.iterdir():
        _edit(f, lambda ls: [ln for ln in ls if not ln.startswith("***")])
    fr = read_dice(tmp_path, 300.0, MAP, EXT)
    np.testing.assert_allclose(fr.w, frames.w, atol=1e-9, rtol=1e-4)


def test_dice_stereo_file_without_strains(tmp_path):
    # the column set of DICe's stereo regression output (tests/regression/epipolar_distortion/gold)
    cols = "SUBSET_ID,COORDINATE_X,COORDINATE_Y,DISPLACEMENT_X,DISPLACEMENT_Y,MODEL_COORDINATES_X,"
    cols += (
        "MODEL_COORDINATES_Y,MODEL_COORDINATES_Z,MODEL_DISPLACEMENT_X,MODEL_DISPLACEMENT_Y,MODEL_DISPLACEMENT_Z,SIGMA"
    )
    xs, ys = np.meshgrid(np.linspace(5, 135, 6), np.linspace(5, 65, 4), indexing="ij")
    for k in range(3):
        rows = [
            f"{i},{5.55e2:.4E},{9.3e2:.4E},0,0,{x:.4E},{y:.4E},0,{0:.4E},{0:.4E},{0.1 * k:.4E},{4.4e-3:.4E}"
            for i, (x, y) in enumerate(zip(xs.ravel(), ys.ravel()))
        ]
        (tmp_path / f"DICe_solution_{k}.txt").write_text(cols + "\n" + "\n".join(rows) + "\n")
    fr = read_dice(tmp_path, 300.0, DICMapping(unit="mm"), EXT)
    assert fr.strain_kind == "none" and fr.exx is None and fr.w[2, 0] == pytest.approx(2e-4)


def test_dice_2d_file_is_refused(tmp_path):
    # the column set of DICe's 2-D example output (tests/examples/full_field/gold)
    text = "***\n*** Reference image: ref.tiff\n***\n"
    text += "SUBSET_ID,COORDINATE_X,COORDINATE_Y,DISPLACEMENT_X,DISPLACEMENT_Y,"
    text += "VSG_STRAIN_XX,VSG_STRAIN_YY,SIGMA,GAMMA,MATCH\n"
    text += "0,5.0000E+01,3.0000E+02,-1.0000E-01,-7.0000E-01,-5.0000E-04,7.0000E-04,1.1000E-02,2.0000E-03,0.0000E+00\n"
    (tmp_path / "DICe_solution_0.txt").write_text(text)
    with pytest.raises(DataFileError, match="DICe_solution_0.txt: no MODEL_DISPLACEMENT_Z .*stereo"):
        read_dice(tmp_path, 300.0, MAP, EXT)


def test_dice_missing_required_columns_are_named(dice_dir):
    p = dice_dir / "DICe_solution_0.txt"
    _edit(p, lambda ls: [ln.replace("MODEL_DISPLACEMENT_Z", "MODEL_DISP_Z").replace("SIGMA", "SIGMA_") for ln in ls])
    with pytest.raises(DataFileError, match=r"DICe_solution_0.txt: column\(s\) MODEL_DISPLACEMENT_Z, SIGMA missing"):
        read_dice(dice_dir, 300.0, MAP, EXT)


def test_dice_partial_strain_columns_are_named(dice_dir):
    _edit(dice_dir / "DICe_solution_0.txt", lambda ls: [ln.replace("VSG_STRAIN_XY", "VSG_XY") for ln in ls])
    with pytest.raises(DataFileError, match=r"column\(s\) VSG_STRAIN_XY missing"):
        read_dice(dice_dir, 300.0, MAP, EXT)


def test_dice_column_set_changes_between_frames(dice_dir):
    _edit(dice_dir / "DICe_solution_3.txt", lambda ls: [ln.replace("GAMMA", "BETA") for ln in ls])
    with pytest.raises(DataFileError, match="DICe_solution_3.txt: columns .*BETA.*expected the same columns"):
        read_dice(dice_dir, 300.0, MAP, EXT)


def test_dice_missing_frame_warns_and_keeps_an_invalid_frame(dice_dir, caplog):
    (dice_dir / "DICe_solution_3.txt").unlink()
    with caplog.at_level(logging.WARNING):
        fr = read_dice(dice_dir, 300.0, MAP, EXT)
    assert "1 missing frame(s)" in caplog.text and "[3]" in caplog.text
    assert fr.n_frames == 6 and not fr.valid[3].any() and fr.report.missing_frames == (3,)
    np.testing.assert_allclose(fr.t[4], 4 / 300)


def test_dice_missing_points_warn(dice_dir, caplog):
    _edit(dice_dir / "DICe_solution_2.txt", lambda ls: ls[:-5])
    with caplog.at_level(logging.WARNING):
        fr = read_dice(dice_dir, 300.0, MAP, EXT)
    assert "missing 5" in caplog.text
    assert fr.valid[2].sum() == fr.n_points - 5 and dict(fr.report.dropped)["missing"] == 5


def test_dice_nan_values_dropped_and_counted(dice_dir, caplog):
    _set_cell(dice_dir / "DICe_solution_1.txt", 4, 10, "-nan")
    with caplog.at_level(logging.WARNING):
        fr = read_dice(dice_dir, 300.0, MAP, EXT)
    assert "nan 1" in caplog.text and not fr.valid[1, 4]


def test_dice_bad_cell_names_line_and_column(dice_dir):
    _set_cell(dice_dir / "DICe_solution_1.txt", 2, 1, "abc")
    with pytest.raises(DataFileError, match=r"DICe_solution_1.txt:\d+: COORDINATE_X = 'abc': expected a number"):
        read_dice(dice_dir, 300.0, MAP, EXT)


def test_dice_grid_change_between_frames(dice_dir):
    _set_cell(dice_dir / "DICe_solution_4.txt", 0, 5, lambda c: f"{float(c) + 2.0:.4E}")  # MODEL_COORDINATES_X + 2 mm
    with pytest.raises(DataFileError, match="DICe_solution_4.txt: reference coordinates differ .* grid"):
        read_dice(dice_dir, 300.0, MAP, EXT)


def test_dice_frame_from_another_test(tmp_path, dice_dir):
    other = analytic_frames(grid=(10, 5))
    write_dice(other, tmp_path / "other", MAP)
    (tmp_path / "other" / "DICe_solution_2.txt").replace(dice_dir / "DICe_solution_2.txt")
    with pytest.raises(DataFileError, match="DICe_solution_2.txt: .*another test"):
        read_dice(dice_dir, 300.0, MAP, EXT)


def test_dice_frame_with_other_reference_image(dice_dir):
    _edit(
        dice_dir / "DICe_solution_5.txt",
        lambda ls: [re.sub("Reference image: .*", "Reference image: b.tif", s) for s in ls],
    )
    with pytest.raises(DataFileError, match="DICe_solution_5.txt: reference image 'b.tif'.*another test"):
        read_dice(dice_dir, 300.0, MAP, EXT)


def test_dice_mm_read_as_m(dice_dir):
    with pytest.raises(DataFileError, match="mm read as m"):
        read_dice(dice_dir, 300.0, DICMapping(origin=(-70.0, 35.0), y_axis="-y", z_axis="-z", unit="m"), EXT)


def test_dice_percent_strains(tmp_path):
    fr0 = analytic_frames()
    write_dice(fr0, tmp_path, DICMapping(unit="mm", strain_unit="percent"))
    with pytest.raises(DataFileError, match="percent"):
        read_dice(tmp_path, 300.0, DICMapping(unit="mm"), EXT)
    fr = read_dice(tmp_path, 300.0, DICMapping(unit="mm", strain_unit="percent"), EXT)
    np.testing.assert_allclose(fr.exx, fr0.exx, rtol=1e-4, atol=1e-9)


def test_dice_file_naming_problems(tmp_path, dice_dir):
    with pytest.raises(DataFileError, match="no frame files"):
        read_dice(tmp_path / "none", 300.0, MAP, EXT)
    f = [dice_dir / f"DICe_solution_{k}.txt" for k in range(6)]
    par = dice_dir / "DICe_solution_3.4.0.txt"
    par.write_text(f[3].read_text())
    with pytest.raises(DataFileError, match="per-processor"):
        read_dice(dice_dir, 300.0, MAP, EXT)
    par.rename(dice_dir / "DICe_solution_03.txt")
    with pytest.raises(DataFileError, match="frame 3 also in"):
        read_dice(dice_dir, 300.0, MAP, EXT)
    with pytest.raises(DataFileError, match="frame 5 after 4: expected frame numbers in steps of 2"):
        read_dice([f[0], f[2], f[4], f[5]], 300.0, MAP, EXT)
    with pytest.raises(DataFileError, match="no frame number"):
        (dice_dir / "DICe_solution.txt").write_text(f[0].read_text())
        read_dice([f[0], dice_dir / "DICe_solution.txt"], 300.0, MAP, EXT)


def test_dice_empty_and_header_only(tmp_path):
    (tmp_path / "DICe_solution_0.txt").write_text("***\n***\n")
    with pytest.raises(DataFileError, match="no header row"):
        read_dice(tmp_path, 300.0, MAP, EXT)
    (tmp_path / "DICe_solution_0.txt").write_text("SUBSET_ID,SIGMA\n")
    with pytest.raises(DataFileError, match="no data rows"):
        read_dice(tmp_path, 300.0, MAP, EXT)


def test_dice_bad_frame_rate(dice_dir):
    with pytest.raises(InputError, match="frame_rate"):
        read_dice(dice_dir, 0.0, MAP, EXT)


# -- CSV per frame ------------------------------------------------------------------------------
def test_csv_round_trip_and_missing_point(tmp_path, caplog):
    fr0 = analytic_frames(missing=0.05, seed=2)
    write_dic_csv(fr0, tmp_path)
    fr = read_dic_csv(tmp_path, 300.0, EXT)
    assert np.array_equal(fr.valid, fr0.valid)
    np.testing.assert_allclose(np.where(fr.valid, fr.w, 0), np.where(fr0.valid, fr0.w, 0), rtol=1e-8)
    _edit(tmp_path / "frame_1.csv", lambda ls: ls[:3] + ls[4:])  # one point's row removed
    with caplog.at_level(logging.WARNING):
        fr = read_dic_csv(tmp_path, 300.0, EXT)
    assert "missing 1" in caplog.text and not fr.valid[1, 1]


def test_csv_first_frame_missing_a_point(tmp_path, caplog):
    fr0 = analytic_frames()
    write_dic_csv(fr0, tmp_path)
    _edit(tmp_path / "frame_0.csv", lambda ls: ls[:2] + ls[3:])  # point 0 missing in the first frame
    with caplog.at_level(logging.WARNING):
        fr = read_dic_csv(tmp_path, 300.0, EXT)
    assert fr.n_points == fr0.n_points and not fr.valid[0, 0] and fr.valid[1:].all()
    np.testing.assert_allclose(fr.x, fr0.x)


def test_csv_grid_change_and_missing_column(tmp_path):
    write_dic_csv(analytic_frames(), tmp_path)
    _edit(tmp_path / "frame_2.csv", lambda ls: ls[:2] + [ls[2].replace(ls[2].split(",")[0], "0.0555", 1)] + ls[3:])
    with pytest.raises(DataFileError, match="frame_2.csv: 1 point.*not in .*frame_0.csv.*the same grid"):
        read_dic_csv(tmp_path, 300.0, EXT)
    _edit(tmp_path / "frame_0.csv", lambda ls: [ls[0], ls[1].replace(",w,", ",z,")] + ls[2:])
    with pytest.raises(DataFileError, match=r"frame_0.csv: column\(s\) w missing"):
        read_dic_csv(tmp_path, 300.0, EXT)


def test_csv_mm_declared_for_metres(tmp_path):
    write_dic_csv(analytic_frames(), tmp_path)
    with pytest.raises(DataFileError, match="m read as mm"):
        read_dic_csv(tmp_path, 300.0, EXT, units="mm")


# -- NPZ ----------------------------------------------------------------------------------------
def test_npz_round_trip(tmp_path):
    fr0 = analytic_frames(missing=0.05)
    p = write_dic_npz(fr0, tmp_path / "frames.npz")
    assert sorted(tmp_path.iterdir()) == [p]  # no temp file left
    fr = read_dic_npz(p, EXT)
    assert np.array_equal(fr.valid, fr0.valid) and fr.strain_kind == "surface"
    np.testing.assert_array_equal(np.where(fr.valid, fr.exy, 0), np.where(fr0.valid, fr0.exy, 0))


def _npz(tmp_path, **over):
    fr = analytic_frames()
    d = {k: getattr(fr, k) for k in ("t", "x", "y", "u", "v", "w", "exx", "eyy", "exy", "valid")}
    d.update(units="m", strain_reference="prestrained")
    d.update(over)
    d = {k: v for k, v in d.items() if v is not None}
    np.savez(tmp_path / "f.npz", **d)
    return tmp_path / "f.npz"


def test_npz_missing_arrays_named(tmp_path):
    with pytest.raises(DataFileError, match=r"f.npz: array\(s\) valid, eyy missing"):
        read_dic_npz(_npz(tmp_path, valid=None, eyy=None), EXT)


def test_npz_nan_where_valid_is_dropped(tmp_path, caplog):
    w = analytic_frames().w.copy()
    w[1, 3] = np.nan
    with caplog.at_level(logging.WARNING):
        fr = read_dic_npz(_npz(tmp_path, w=w), EXT)
    assert not fr.valid[1, 3] and dict(fr.report.dropped) == {"nan": 1} and "NaN" in caplog.text


def test_npz_units_and_bad_files(tmp_path):
    fr0 = analytic_frames()
    fr = read_dic_npz(_npz(tmp_path, x=fr0.x * 1e3, y=fr0.y * 1e3, w=fr0.w * 1e3, units="mm"), EXT)
    np.testing.assert_allclose(fr.w, fr0.w)
    with pytest.raises(DataFileError, match="mm read as m"):
        read_dic_npz(_npz(tmp_path, x=fr0.x * 1e3, y=fr0.y * 1e3), EXT)
    with pytest.raises(DataFileError, match="units = 'inch'"):
        read_dic_npz(_npz(tmp_path, units="inch"), EXT)
    (tmp_path / "bad.npz").write_text("not a zip")
    with pytest.raises(DataFileError, match="bad.npz: cannot be read as an NPZ file"):
        read_dic_npz(tmp_path / "bad.npz", EXT)
    with pytest.raises(DataFileError, match=r"w has shape \(6, 71\)"):
        read_dic_npz(_npz(tmp_path, w=fr0.w[:, 1:]), EXT)
