"""Lab data: a DAQ file's own columns and units through a channel map (issue 26, item 6).

A DAQ-style copy of the shipped record ``examples/data/tunnel_300Hz.csv`` (columns ``time_s,ch1..ch4``
in the order of the DAQ, not of the problem; millivolts with a per-sensor gain and offset) must
give the identified lift of the record it came from, on the batch path and on the stream, with
the map given on the command line or in the problem file's ``[measurements]`` table, and the map
must be recorded in ``summary.json``. Bad maps are refused in one line naming the field.

The reference is the shipped record with each value replaced by the stretch that survives the
round trip ``gain * ((s / gain + offset) - offset)`` (at most an ulp off): with it the DAQ copy
must give the same lift exactly (the same floats reach the estimator). Against the shipped record
itself the lift agrees to ~3e-8 relative: the estimator amplifies the 1e-16 round-off of the
conversion (measured: 1.0286509921 vs 1.0286509584 N on this problem).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wingopt.cli import main
from wingopt.errors import InputError, ProblemFileError
from wingopt.measurements import ChannelMap, read_measurements
from wingopt.measurements.csv_stream import CsvRowParser
from wingopt.problem import PROBLEMS_DIR, load_problem

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "examples" / "data" / "tunnel_300Hz.csv"
GAIN = {"S1": 1e-5, "S2": 1.1e-5, "S3": 0.9e-5, "S4": 1.25e-5}  # stretch per mV
OFFSET = {"S1": 250.0, "S2": -12.5, "S3": 0.0, "S4": 1000.0}  # mV at zero stretch
COLUMN = {"S1": "ch3", "S2": "ch1", "S3": "ch4", "S4": "ch2"}  # the DAQ's channel of each sensor
NAMES = ("S1", "S2", "S3", "S4")
CLI_MAP = [
    "--time-column",
    "time_s",
    "--columns",
    ",".join(f"{s}={c}" for s, c in COLUMN.items()),
    "--gain",
    ",".join(f"{s}={g!r}" for s, g in GAIN.items()),
    "--offset",
    "S1=250,S2=-12.5,S4=1000",  # S3: the default offset 0
]
FAST = ["--method", "mhe", "--model", "linear", "--no-model-form", "--window", "100", "--stride", "50"]
FAST += ["--modes", "20", "--no-plots"]  # the mapping is tested, not the estimator: the fast linear MHE


def _daq_files(tmp: Path, record: Path = RECORD, stem: str = "") -> tuple[Path, Path]:
    """``(daq.csv, reference.csv)`` from a shipped record (comment lines and missing cells kept)."""
    daq, ref = [], []
    header = None
    for line in record.read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            daq.append(line)
            ref.append(line)
            continue
        cells = line.split(",")
        if header is None:
            header = cells
            daq.append("time_s,ch1,ch2,ch3,ch4")
            ref.append(line)
            continue
        row = dict(zip(header, cells))
        raw, back = {}, {}
        for s in NAMES:
            text = row[s].strip()
            if text == "":
                raw[s] = back[s] = ""
                continue
            mv = float(text) / GAIN[s] + OFFSET[s]
            raw[s] = repr(mv)
            back[s] = repr(GAIN[s] * (mv - OFFSET[s]))
        by_channel = {COLUMN[s]: raw[s] for s in NAMES}
        daq.append(",".join([row["t"]] + [by_channel[c] for c in ("ch1", "ch2", "ch3", "ch4")]))
        ref.append(",".join([row["t"]] + [back[s] for s in NAMES]))
    (tmp / f"{stem}daq.csv").write_text("\n".join(daq) + "\n")
    (tmp / f"{stem}reference.csv").write_text("\n".join(ref) + "\n")
    return tmp / f"{stem}daq.csv", tmp / f"{stem}reference.csv"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lab")
    daq, ref = _daq_files(tmp)
    src = (PROBLEMS_DIR / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]")
    small = tmp / "small.toml"
    small.write_text(src)
    table = '\n[measurements]\ntime = "time_s"\n'
    table += "columns = { " + ", ".join(f'{s} = "{c}"' for s, c in COLUMN.items()) + " }\n"
    table += "gain = { " + ", ".join(f"{s} = {g!r}" for s, g in GAIN.items()) + " }\n"
    table += "offset = { S1 = 250.0, S2 = -12.5, S4 = 1000.0 }\n"
    mapped = tmp / "daq_problem.toml"
    mapped.write_text(src + table)
    return {"daq": daq, "ref": ref, "small": small, "mapped": mapped, "tmp": tmp}


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


# -- the map itself --------------------------------------------------------------------------


def test_the_map_converts_raw_readings_by_its_convention():
    cmap = ChannelMap("time_ms", "ms", {"S1": "a"}, {"S1": 2e-5, "*": 1e-5}, {"S2": 100.0}).check(NAMES)
    t, s = cmap.convert([10.0, 20.0], [[300.0, 300.0, 0.0, np.nan]] * 2, NAMES)
    assert t.tolist() == [0.01, 0.02]
    assert s[0].tolist()[:3] == [2e-5 * 300.0, 1e-5 * (300.0 - 100.0), 0.0] and np.isnan(s[0, 3])
    d = cmap.as_dict(NAMES)
    assert d["columns"] == {"S1": "a", "S2": "S2", "S3": "S3", "S4": "S4"}
    assert d["gain"] == {"S1": 2e-5, "S2": 1e-5, "S3": 1e-5, "S4": 1e-5} and d["offset"]["S2"] == 100.0
    assert d["convention"] == "stretch = gain * (raw - offset)"
    assert ChannelMap().is_identity and not cmap.is_identity


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"gain": {"S9": 1.0}}, "gain: 'S9'"),
        ({"gain": {"S1": 0.0}}, "gain: S1 = 0"),
        ({"gain": {"S1": float("nan")}}, "gain: S1"),
        ({"offset": {"S2": float("inf")}}, "offset: S2"),
        ({"columns": {"S1": "ch1", "S2": "ch1"}}, "columns: S1 and S2"),
        ({"columns": {"S1": "t"}}, "columns: S1"),
        ({"time_unit": "h"}, "time_unit"),
        ({"columns": {"S1": ""}}, "columns: S1"),
    ],
)
def test_a_bad_map_is_one_line_naming_the_field(kwargs, field):
    with pytest.raises(InputError) as exc:
        ChannelMap(**kwargs).check(NAMES)
    assert field in str(exc.value) and "\n" not in str(exc.value)


# -- one conversion for the batch reader and the stream --------------------------------------


def test_batch_reader_and_stream_parser_read_the_daq_file_as_the_reference(files):
    cmap = ChannelMap("time_s", "s", COLUMN, GAIN, OFFSET)
    meas, report = read_measurements(files["daq"], NAMES, cmap)
    ref, _ = read_measurements(files["ref"], NAMES)
    assert np.array_equal(meas.t, ref.t)
    assert np.array_equal(meas.values, ref.values, equal_nan=True)  # the same floats
    assert report.as_dict()["channels"]["columns"] == COLUMN
    parser = CsvRowParser(NAMES, "daq", cmap)
    rows = [r for line in files["daq"].read_text().splitlines() for r in parser.feed(line)]
    values = np.array([y for _, y in rows])
    assert values.shape == ref.values.shape
    assert np.array_equal(values, ref.values, equal_nan=True)
    assert parser.ignored_columns == []


def test_the_reader_names_the_missing_column_of_the_map(files):
    cmap = ChannelMap("time_s", "s", {**COLUMN, "S4": "ch9"}, GAIN, OFFSET)
    with pytest.raises(InputError, match=r"missing column\(s\) ch9 \(S4\)"):
        read_measurements(files["daq"], NAMES, cmap)
    with pytest.raises(InputError, match="time column 'time'"):
        read_measurements(files["daq"], NAMES, ChannelMap("time", "s", COLUMN, GAIN, OFFSET))
    # without a map the raw millivolts are refused as they were, with the hint to give gain and offset
    with pytest.raises(InputError, match="'t' column"):
        read_measurements(files["daq"], NAMES)


# -- the command line: batch, stream, problem file, summary.json -----------------------------


def test_cli_daq_file_gives_the_lift_of_the_record(files, capsys):
    tmp = files["tmp"]
    assert main(["identify", str(files["small"]), "--data", str(files["ref"]), *FAST, "--out", str(tmp / "ref")]) == 0
    assert main(["identify", str(files["small"]), "--data", str(RECORD), *FAST, "--out", str(tmp / "orig")]) == 0
    argv = ["identify", str(files["small"]), "--data", str(files["daq"]), *FAST, *CLI_MAP, "--out", str(tmp / "daq")]
    assert main(argv) == 0
    argv = ["identify", str(files["mapped"]), "--data", str(files["daq"]), *FAST, "--out", str(tmp / "table")]
    assert main(argv) == 0
    capsys.readouterr()
    ref, orig, daq, table = (_summary(tmp / d) for d in ("ref", "orig", "daq", "table"))
    assert daq["lift_N"] == pytest.approx(ref["lift_N"], rel=1e-12, abs=0)
    assert table["lift_N"] == pytest.approx(ref["lift_N"], rel=1e-12, abs=0)
    assert daq["lift_std_N"] == pytest.approx(ref["lift_std_N"], rel=1e-12)
    assert daq["lift_N"] == pytest.approx(orig["lift_N"], rel=1e-6)  # round-off of the conversion, amplified
    ch = daq["data"]["channels"]
    assert ch["time_column"] == "time_s" and ch["columns"] == COLUMN and ch["gain"] == GAIN
    assert ch["offset"] == OFFSET and ch["declared_in"] == "command line"
    assert ch["convention"] == "stretch = gain * (raw - offset)"
    assert table["data"]["channels"]["gain"] == GAIN and "[measurements]" in table["data"]["channels"]["declared_in"]
    assert "channels" not in ref["data"]  # a plain record: nothing mapped, nothing recorded


def _stream(problem, data: Path, out: Path, *extra) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    argv = [sys.executable, "-m", "wingopt", "identify", str(problem), "--data", "-", "--model", "linear"]
    argv += ["--print-every", "100000", "--out", str(out), *extra]
    with open(data) as fh:
        return subprocess.run(argv, stdin=fh, capture_output=True, text=True, env=env, timeout=300)


def test_cli_stream_applies_the_same_map(files):
    tmp = files["tmp"]
    ref = _stream(files["small"], files["ref"], tmp / "s_ref")
    daq = _stream(files["small"], files["daq"], tmp / "s_daq", *CLI_MAP)
    assert ref.returncode == 0 and daq.returncode == 0, daq.stderr
    a, b = _summary(tmp / "s_ref"), _summary(tmp / "s_daq")
    assert a["samples"] == b["samples"] > 1000
    assert b["lift_N"] == pytest.approx(a["lift_N"], rel=1e-12, abs=0)
    assert b["channels"]["columns"] == COLUMN and b["channels"]["gain"] == GAIN and "channels" not in a


@pytest.mark.parametrize(
    "extra, field",
    [
        (["--gain", "S9=1e-5"], "--gain: 'S9': not a sensor"),
        (["--columns", "S1=ch1,S2=ch1"], "--columns: S1 and S2 = 'ch1'"),
        (["--columns", "S1=ch3,S2=ch1,S3=ch4,S4=ch9"], "missing column(s) ch9 (S4)"),
        (["--gain", "S1=nan"], "--gain: S1 = 'nan': expected a finite number"),
        (["--gain", "0"], "--gain: * = 0"),
        (["--offset", "S1"], "--offset 'S1': expected SENSOR=VALUE"),
        (["--gain", "S1=abc"], "--gain: S1 = 'abc': expected a number"),
        (["--time-column", "time"], "time column 'time'"),
    ],
)
def test_cli_refuses_a_bad_map_in_one_line(files, tmp_path, capsys, extra, field):
    base = {"--time-column": "time_s", "--columns": CLI_MAP[3], "--gain": CLI_MAP[5]}
    for k in range(0, len(extra), 2):
        base[extra[k]] = extra[k + 1]
    argv = ["identify", str(files["small"]), "--data", str(files["daq"]), *FAST, "--out", str(tmp_path / "o")]
    assert main(argv + [x for kv in base.items() for x in kv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err, err
    assert not (tmp_path / "o").exists()


def test_calibrate_with_the_map_finds_the_parameters_of_the_record(files, tmp_path, capsys):
    daq, ref = _daq_files(tmp_path, RECORD.parent / "tunnel_calibration_300Hz.csv", "cal_")
    assert main(["calibrate", "membrane", "--data", str(ref), "--out", str(tmp_path / "r"), "--json"]) == 0
    a = json.loads(capsys.readouterr().out)
    assert main(["calibrate", "membrane", "--data", str(daq), *CLI_MAP, "--out", str(tmp_path / "d"), "--json"]) == 0
    b = json.loads(capsys.readouterr().out)
    assert b["parameters"] == a["parameters"] and b["parameters_std"] == a["parameters_std"]
    assert b["data_report"]["channels"]["columns"] == COLUMN and "channels" not in a["data_report"]


def test_write_problem_keeps_the_daq_map_the_record_was_read_with(files, tmp_path, capsys):
    daq, ref = _daq_files(tmp_path, RECORD.parent / "tunnel_calibration_300Hz.csv", "cal_")
    written = tmp_path / "calibrated.toml"
    argv = ["calibrate", "membrane", "--data", str(daq), *CLI_MAP, "--out", str(tmp_path / "c")]
    assert main([*argv, "--write-problem", str(written), "--json"]) == 0
    used = json.loads(capsys.readouterr().out)["data_report"]["channels"]
    problem = load_problem(written)
    kept = problem.measurements.as_dict(problem.sensor_names)
    assert {**kept, "declared_in": None} == {**used, "declared_in": None}
    # the written file alone reads the DAQ's file as the reference record reads
    by_file, _ = read_measurements(daq, problem.sensor_names, problem.measurements)
    reference, _ = read_measurements(ref, problem.sensor_names)
    assert np.allclose(by_file.t, reference.t) and np.allclose(by_file.values, reference.values, equal_nan=True)


def test_calibrate_takes_the_same_map(files, tmp_path, capsys):
    argv = ["calibrate", str(files["small"]), "--data", str(files["daq"]), *CLI_MAP[:4], "--gain", "S9=1e-5"]
    assert main(argv + ["--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--gain: 'S9': not a sensor" in err
    argv = ["calibrate", str(files["small"]), "--data", str(files["daq"]), "--out", str(tmp_path / "c")]
    assert main(argv) == 2  # without the map: the millivolt file has no 't' column
    assert "'t' column" in capsys.readouterr().err


def test_cli_refuses_a_map_without_measured_data(files, tmp_path, capsys):
    argv = ["identify", str(files["small"]), "--load", "L1", "--gain", "1e-5", "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert "apply to --data or --follow only" in capsys.readouterr().err


@pytest.mark.parametrize(
    "table, field",
    [
        ("gain = { S9 = 1.0 }", "[measurements] gain.S9"),
        ("gain = { S1 = 0.0 }", "[measurements] gain: S1 = 0"),
        ('gain = { S1 = "x" }', "[measurements] gain.S1"),
        ('offset = "a"', "[measurements] offset"),
        ("columns = { S1 = 3 }", "[measurements] columns.S1"),
        ('time_unit = "h"', "[measurements] time_unit"),
        ('colums = { S1 = "a" }', "unknown key 'colums'"),
    ],
)
def test_a_bad_measurements_table_is_one_line_naming_the_key(files, tmp_path, table, field):
    path = tmp_path / "p.toml"
    path.write_text(files["small"].read_text() + "\n[measurements]\n" + table + "\n")
    with pytest.raises(ProblemFileError) as exc:
        load_problem(path)
    assert field in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


def test_the_problem_table_loads_into_a_map(files):
    problem = load_problem(files["mapped"])
    assert problem.measurements.column("S2") == "ch1" and problem.measurements.time == "time_s"
    assert problem.measurements.calibration(NAMES)[1].tolist() == [250.0, -12.5, 0.0, 1000.0]
    assert load_problem("membrane").measurements is None
