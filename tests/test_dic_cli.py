"""DIC frames through the problem file, the readers' dispatch and the command line.

``[dic]`` declares the mapping (one-line errors naming the key); ``read_dic`` picks the layout by
the path; ``wingopt dic-sensors`` writes a record that ``wingopt identify --data`` reads; and
``wingopt identify --dic`` runs the full-field estimator on the tunnel stand-in's frames (or, with
another ``--method``, gives the frames' virtual sensors to that estimator).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _dic import H, W, analytic_frames

from wingopt.cli import main
from wingopt.errors import DataFileError, ProblemFileError
from wingopt.measurements import DICMapping, read_dic, read_measurements
from wingopt.problem import PROBLEMS_DIR, load_problem
from wingopt.results.dic_files import write_dic_csv, write_dic_npz, write_dice

ROOT = Path(__file__).resolve().parents[1]
STANDIN = ROOT / "examples" / "data" / "tunnel_dic_300Hz.npz"
DICE = ROOT / "examples" / "data" / "tunnel_dice"
DICE_PROBLEM = ROOT / "examples" / "tunnel_dice.toml"
EXT = (W, H)


def _problem(tmp_path, dic: str) -> Path:
    path = tmp_path / "p.toml"
    path.write_text((PROBLEMS_DIR / "membrane.toml").read_text() + "\n[dic]\n" + dic)
    return path


def test_dic_table_is_read_and_checked(tmp_path):
    p = load_problem(_problem(tmp_path, 'origin = [-70.0, 35.0]\ny_axis = "-y"\nunit = "mm"\nframe_rate = 300\n'))
    assert p.dic.mapping == DICMapping(origin=(-70.0, 35.0), y_axis="-y", unit="mm") and p.dic.frame_rate == 300.0
    assert load_problem("membrane").dic is None
    bad = {
        'unit = "cm"': r"\[dic\] unit = 'cm': expected one of m, mm",
        'x_axis = "+y"': r"\[dic\] y_axis = '\+y': expected a DIC axis other than x_axis = '\+y'",
        "frame_rate = 0": r"\[dic\] frame_rate = 0: expected a positive number \(Hz\)",
        'strain_unit = "microstrain"': r"\[dic\] strain_unit = 'microstrain': expected one of strain, percent",
        "origin = [1.0]": r"\[dic\] origin = \[1.0\]: expected a list of 2 numbers",
        "scale = 2": r"\[dic\] unknown key 'scale'",
    }
    for text, msg in bad.items():
        with pytest.raises(ProblemFileError, match=msg) as err:
            load_problem(_problem(tmp_path, text + "\n"))
        assert "\n" not in str(err.value)


def test_read_dic_dispatches_by_path(tmp_path):
    fr = analytic_frames(missing=0.05)
    write_dic_npz(fr, tmp_path / "f.npz")
    write_dic_csv(fr, tmp_path / "csv")
    write_dice(fr, tmp_path / "dice", DICMapping(origin=(-70.0, 35.0), y_axis="-y", unit="mm"))
    a = read_dic(tmp_path / "f.npz", EXT)
    b = read_dic(tmp_path / "csv", EXT, frame_rate=300.0)
    c = read_dic(
        tmp_path / "dice", EXT, mapping=DICMapping(origin=(-70.0, 35.0), y_axis="-y", unit="mm"), frame_rate=300
    )
    for g in (a, b, c):
        assert np.array_equal(g.valid, fr.valid)
        np.testing.assert_allclose(np.where(g.valid, g.w, 0), np.where(fr.valid, fr.w, 0), rtol=1e-4, atol=1e-9)
    with pytest.raises(DataFileError, match="carry no time: expected \\[dic\\] frame_rate"):
        read_dic(tmp_path / "csv", EXT)
    with pytest.raises(DataFileError, match="NPZ file is in the wing's frame.*origin"):
        read_dic(tmp_path / "f.npz", EXT, mapping=DICMapping(origin=(1.0, 0.0)))
    (tmp_path / "csv" / "DICe_solution_9.txt").write_text("x")
    with pytest.raises(DataFileError, match="both .txt \\(DICe\\) and .csv"):
        read_dic(tmp_path / "csv", EXT, frame_rate=300.0)
    with pytest.raises(DataFileError, match="no such file"):
        read_dic(tmp_path / "none.npz", EXT)


def test_npz_quantised_storage_and_extra_arrays(tmp_path):
    fr = analytic_frames(missing=0.05)
    q = {"w": 1e-7, "u": 1e-8, "exx": 1e-7}
    p = write_dic_npz(fr, tmp_path / "q.npz", quantum=q, extra={"truth_lift": np.arange(6.0)})
    with np.load(p) as z:
        assert z["w"].dtype == np.int32 and z["truth_lift"].size == 6
    back = read_dic(p, EXT)
    v = back.valid
    assert np.array_equal(v, fr.valid)
    assert np.max(np.abs(back.w - fr.w)[v]) <= 0.5e-7 + 1e-15 and np.max(np.abs(back.exx - fr.exx)[v]) <= 0.5e-7
    with pytest.raises(Exception, match="expected names other than the layout's own"):
        write_dic_npz(fr, tmp_path / "r.npz", extra={"w": 1})


def test_shipped_dice_files_read_as_the_npz_frames():
    """The stand-in's three DICe files (mm, origin at the centre, y flipped) are the same run's first frames."""
    p = load_problem(DICE_PROBLEM)
    from wingopt.workflows.dic import read_frames

    dice = read_frames(p, DICE)
    npz = read_dic(STANDIN, EXT)
    assert dice.n_frames == 3 and dice.units == "mm" and dice.strain_kind == "inplane"
    assert dict(dice.report.dropped)["sigma"] == int((~dice.valid).sum()) > 0
    np.testing.assert_allclose(dice.x, npz.x, atol=1e-7)
    both = dice.valid & npz.valid[:3]
    # independent noise draws of the same shapes (10 µm each)
    assert np.std((dice.w - npz.w[:3])[both]) == pytest.approx(np.sqrt(2) * 1e-5, rel=0.1)


def test_dic_sensors_command_then_identify_data(tmp_path, capsys):
    out = tmp_path / "vs"
    assert main(["dic-sensors", str(DICE_PROBLEM), "--dic", str(DICE), "--out", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["dic"]["route"] == "virtual sensors (slope, fit)" and s["samples"] == 3
    assert 0.005 < s["dic"]["initial_shape"]["peak_m"] < 0.008
    lines = (out / "sensors.csv").read_text().splitlines()
    assert lines[0] == "t,S1,S2,S3,S4" and len(lines) == 4
    assert (out / "initial_shape.csv").read_text().startswith("x,y,w_m")
    # the strain route is refused on DICe's in-plane strains, in one line naming the way out
    assert main(["dic-sensors", str(DICE_PROBLEM), "--dic", str(DICE), "--kind", "strain", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "strain_kind = 'inplane'" in err and "use kind = 'slope'" in err
    # a percent-strain mix-up is named
    bad = _problem(tmp_path, 'origin = [-70.0, 35.0]\ny_axis = "-y"\nunit = "m"\nframe_rate = 300\n')
    assert main(["dic-sensors", str(bad), "--dic", str(DICE), "--out", str(tmp_path / "x")]) == 2
    assert "mm read as m" in capsys.readouterr().err


def test_virtual_sensors_of_the_standin_feed_identify_data(tmp_path):
    """``dic-sensors`` on the 450 frames, then ``identify --data`` reads the record (the batch estimator)."""
    out = tmp_path / "vs"
    assert main(["dic-sensors", "membrane", "--dic", str(STANDIN), "--out", str(out)]) == 0
    rows = np.genfromtxt(out / "sensors.csv", delimiter=",", names=True)
    assert rows.size == 450 and np.all(np.isfinite(rows["S1"]))
    four, _ = read_measurements(ROOT / "examples" / "data" / "tunnel_300Hz.csv", ("S1", "S2", "S3", "S4"))
    # the same run's four-sensor record (2 % noise) and the virtual sensors (DIC noise) agree in the mean
    for i, name in enumerate(("S1", "S2", "S3", "S4")):
        a, b = np.nanmean(rows[name]), np.nanmean(four.values[:450, i])
        assert abs(a / b - 1) < 0.01


def test_identify_dic_full_field_on_the_standin(tmp_path, capsys):
    out = tmp_path / "ff"
    assert main(["identify", "membrane", "--dic", str(STANDIN), "--load-model", "constant", "--out", str(out),
                 "--no-plots", "--json"]) == 0  # fmt: skip
    s = json.loads(capsys.readouterr().out)
    with np.load(STANDIN) as z:
        true_lift = float(z["truth_lift"].mean())
    assert s["method"] == "fullfield" and s["estimator"]["mode"] == "steady"
    assert s["data"]["route"] == "full field (every point's deflection)" and s["data"]["frames"] == 450
    # the file's prior (±20 %) sets the band; the truth (prestrain 0.056, 0.046) is inside it
    assert abs(s["lift_N"] - true_lift) < s["lift_std_N"] and 0.08 < s["lift_std_N"] / true_lift < 0.15
    assert any("does not identify the tension" in w for w in s["warnings"])
    assert (out / "load.csv").exists() and (out / "lift.csv").exists()


def test_identify_dic_refusals(tmp_path, capsys):
    base = ["identify", "membrane", "--out", str(tmp_path / "o")]
    assert main([*base, "--dic", str(STANDIN), "--window", "0.1s"]) == 2
    err = capsys.readouterr().err
    assert "--window is not used by the fullfield estimator with the fvk membrane" in err
    assert main([*base, "--data", str(ROOT / "examples/data/tunnel_300Hz.csv"), "--method", "fullfield"]) == 2
    assert "estimates from DIC frames" in capsys.readouterr().err
    assert main([*base, "--dic", str(tmp_path / "none.npz")]) == 2
    assert "none.npz: no such file" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_widened_virtual_sensor_band_is_warned():
    """The stand-in's DIC virtual sensors misfit the load prior's mean (chi-square ~3 per sensor): the
    band is widened by the Birge factor, and the run says so (it came back with no warning)."""
    import wingopt as wo

    frames = Path(__file__).parents[1] / "examples" / "data" / "tunnel_dic_300Hz.npz"
    run = wo.identify("membrane", dic=frames, method="batch")
    widen = run.result.info["adequacy"]["band_widening"]
    assert widen > 1.5
    said = [w for w in run.warnings if "the band is widened" in w]
    assert len(said) == 1 and f"x{widen:.2f}" in said[0]
