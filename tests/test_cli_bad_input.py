"""Bad input across the command line and the API: one clear line, exit code 2, nothing half-written.

Covers the ten kinds of issue 6: bad TOML, unknown shape, unknown method, malformed mesh, missing CSV
column, empty CSV, NaN in the data, output directory not writable, vmin > vmax, sensor outside the
domain.
"""

import json

import pytest

from wingopt.cli import main
from wingopt.errors import InputError
from wingopt.problem import PROBLEMS_DIR, load_problem

LINEAR = ("--model", "linear", "--no-model-form")  # input handling is tested, not the membrane model


@pytest.fixture
def outdir(tmp_path):
    return tmp_path / "out"


def write(path, text):
    path.write_text(text)
    return str(path)


def membrane_with(tmp_path, old, new):
    src = (PROBLEMS_DIR / "membrane.toml").read_text()
    assert old in src
    return write(tmp_path / "bad.toml", src.replace(old, new))


def good_csv_rows(n=50):
    return "".join(f"{k * 1e-3:.3f},0.01,0.01,0.01,0.01\n" for k in range(n))


CASES = {
    "bad TOML": lambda tmp: (["modes", write(tmp / "broken.toml", "kind = membrane\n[geometry\n")], "not valid TOML"),
    "unknown shape": lambda tmp: (["morph", "plate", "--shape", "loop"], "shape"),
    "unknown method": lambda tmp: (["morph", "plate", "--shape", "twist", "--method", "pid"], "method"),
    "malformed mesh": lambda tmp: (["morph", "plate", "--shape", "twist", "--mesh", "13by61"], "mesh = '13by61'"),
    "vmin > vmax": lambda tmp: (["morph", "plate", "--shape", "twist", "--vmin", "100", "--vmax", "-100"], "vmin"),
    "sensor outside": lambda tmp: (
        [
            "identify",
            membrane_with(tmp, "[0.088, 0.128, 0.046, 0.058]", "[0.088, 0.148, 0.046, 0.058]"),
            "--load",
            "L1",
        ],
        "sensors[4]",
    ),
    "missing CSV column": lambda tmp: (
        ["identify", "membrane", *LINEAR, "--data", write(tmp / "d.csv", "t,S1,S2,S3\n" + "0,1e-2,1e-2,1e-2\n")],
        "S4",
    ),
    "empty CSV": lambda tmp: (
        ["identify", "membrane", *LINEAR, "--data", write(tmp / "e.csv", "")],
        "empty",
    ),
    "NaN time": lambda tmp: (
        [
            "identify",
            "membrane",
            *LINEAR,
            "--data",
            write(tmp / "n.csv", "t,S1,S2,S3,S4\n" + good_csv_rows(5) + "nan,0.01,0.01,0.01,0.01\n"),
        ],
        "t",
    ),
    "not writable": lambda tmp: (["modes", "membrane", "--json"], None),
}


@pytest.mark.parametrize("kind", list(CASES))
def test_bad_input_one_line_exit_2_nothing_written(kind, tmp_path, outdir, capsys):
    argv, needle = CASES[kind](tmp_path)
    if argv[0] in ("morph", "identify"):
        argv = [*argv, "--out", str(outdir)]
    if kind == "not writable":
        (tmp_path / "file").write_text("x")
        argv = ["morph", "plate", "--shape", "twist", "--out", str(tmp_path / "file" / "out")]
        needle = "not a directory"
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith("wingopt "), err
    assert needle in err, err
    assert not outdir.exists()
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]


def test_failure_keeps_earlier_results(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "summary.json").write_text(json.dumps({"lift_N": 1.0}))
    bad = write(tmp_path / "short.csv", "t,S1,S2,S3,S4\n0,0.01,0.01,0.01\n")
    assert main(["identify", "membrane", *LINEAR, "--data", bad, "--out", str(out)]) == 2
    assert json.loads((out / "summary.json").read_text()) == {"lift_N": 1.0}


def test_nan_sensor_rows_are_skipped_and_counted(tmp_path):
    """Missing sensor values are allowed: skipped by the estimator, never invented, and counted."""
    from wingopt.measurements.csv_file import read_measurements

    rows = good_csv_rows(20) + "0.020,,0.01,nan,0.01\n" + "0.021,0.01,0.01,0.01,0.01\n"
    meas, report = read_measurements(write(tmp_path / "gaps.csv", "t,S1,S2,S3,S4\n" + rows), ("S1", "S2", "S3", "S4"))
    assert report.missing_rows == 1 and meas.count == 22
    assert meas.missing.sum() == 1


def test_api_errors_name_the_field():
    from wingopt.workflows.identify import identify
    from wingopt.workflows.morph import morph

    plate, membrane = load_problem("plate"), load_problem("membrane")
    with pytest.raises(InputError, match="shape = 'loop'"):
        morph(plate, "loop", "qp")
    with pytest.raises(InputError, match="method = 'pid'"):
        morph(plate, "twist", "pid")
    with pytest.raises(InputError, match="vmin = 5.0, vmax = 1.0"):
        morph(plate, "twist", "qp", vmin=5.0, vmax=1.0)
    with pytest.raises(InputError, match="method = 'kalman'"):
        identify(membrane, load="L1", method="kalman")
    with pytest.raises(InputError, match="noise = 5"):
        identify(membrane, load="L1", noise=5)
    with pytest.raises(InputError, match="exactly one of load= .*data= .*dic="):
        identify(membrane)
