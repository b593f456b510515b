"""``wingopt identify``: outputs, the noise convention, the CSV data workflow and its errors."""

import csv
import json

import numpy as np
import pytest

from wingopt.cli import main
from wingopt.problem import PROBLEMS_DIR, load_problem
from wingopt.workflows.protocols import simulate_case

LINEAR = ("--model", "linear", "--no-model-form")  # input handling is tested, not the membrane model

FAST = ["--window", "100", "--stride", "50", "--modes", "20", "--truth-mesh", "25x13", "--t-end", "0.3"]


@pytest.fixture(scope="module")
def small_file(tmp_path_factory):
    src = (PROBLEMS_DIR / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]")
    path = tmp_path_factory.mktemp("problem") / "small.toml"
    path.write_text(src)
    return path


@pytest.fixture(scope="module")
def record(small_file):
    """A simulated 0.4 s record on the small problem (truth 25x13), as measured data would be."""
    problem = load_problem(small_file)
    case = simulate_case(problem, "L1", 0.01, 4, (25, 13), t_end=0.4)
    return problem, case


def write_csv(path, t, values, names, extra=None):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", *names] + ([extra[0]] if extra else []))
        for k in range(t.size):
            row = [f"{t[k]:.6f}"] + ["" if np.isnan(v) else f"{v:.8e}" for v in values[k]]
            w.writerow(row + ([extra[1]] if extra else []))


def test_identify_simulated_writes_the_contract(small_file, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["identify", str(small_file), "--load", "L1", "--noise", "1", "--seed", "0", "--out", str(out)]
    assert main(argv + FAST + ["--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    on_disk = json.loads((out / "summary.json").read_text())
    assert summary == on_disk
    for key in ("lift_N", "method", "wall_s", "load_error", "deflection_error"):
        assert key in summary
    assert summary["method"] == "mhe" and summary["noise_percent"] == 1.0 and summary["truth_mesh"] == [25, 13]
    assert summary["load_error"] < 0.05 and summary["sign_ok"]
    assert summary["lift_N"] == pytest.approx(summary["true_lift_N"], rel=0.03)
    with open(out / "load.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["x", "y", "pressure_Pa", "pressure_std_Pa"] and len(rows) == 1 + 57 * 29
    xy = np.array(rows[1:], dtype=float)
    assert xy[:, 0].min() == 0 and xy[:, 0].max() == pytest.approx(0.14) and xy[:, 1].max() == pytest.approx(0.07)
    with open(out / "lift.csv") as fh:
        lift = list(csv.reader(fh))
    assert lift[0] == ["t", "lift_N", "lift_std_N", "reported_lift_N", "reported_lift_std_N"] and len(lift) == 1 + 301
    for png in ("load_field.png", "lift.png", "errors.png"):
        assert (out / png).stat().st_size > 1000


def test_same_mesh_protocol_option(small_file, tmp_path, capsys):
    out = tmp_path / "same"
    argv = ["identify", str(small_file), "--load", "L2", "--noise", "5", "--same-mesh", "--no-plots"]
    assert main(argv + FAST + ["--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["truth_mesh"] == [13, 7] and summary["protocol"].startswith("same-mesh")
    assert not list(out.glob("*.png"))


@pytest.mark.parametrize(
    "noise,needle",
    [
        ("0.01", "ambiguous"),
        ("0.05", "for 5 % write 5"),
        ("150", "between 0 and 100"),
        ("one", "expected a percentage"),
    ],
)
def test_noise_convention_rejects_ambiguous_values(small_file, tmp_path, capsys, noise, needle):
    out = tmp_path / "bad"
    argv = ["identify", str(small_file), "--load", "L1", "--noise", noise, "--out", str(out)]
    assert main(argv + FAST) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not out.exists()


def test_noise_percent_sign_is_explicit():
    from wingopt.cli.identify import parse_noise

    assert parse_noise("1") == 0.01 and parse_noise("5") == 0.05 and parse_noise("1%") == 0.01
    assert parse_noise("0.05%") == pytest.approx(5e-4) and parse_noise("0") == 0.0


def test_identify_from_a_csv_with_missing_rows_and_gaps(record, small_file, tmp_path, capsys):
    problem, case = record
    meas = case.measurements
    vals = meas.values.copy()
    vals[150:160] = np.nan  # ten rows of missing values
    keep = np.ones(meas.count, bool)
    keep[300:305] = False  # five rows dropped: a gap in time
    data = tmp_path / "tunnel.csv"
    write_csv(data, meas.t[keep], vals[keep], problem.sensor_names, extra=("balance_N", "0.8"))
    out = tmp_path / "csvrun"
    argv = ["identify", str(small_file), "--data", str(data), "--out", str(out), "--json", "--model", "linear"]
    assert main(argv + FAST[:6]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["data"]["missing_rows"] == 10 and summary["data"]["gap_rows_filled"] == 5
    assert summary["data"]["ignored_columns"] == ["balance_N"]
    assert summary["missing_samples"] == 15 and summary["samples"] == meas.count
    assert summary["estimator"]["noise_source"] == "estimated from the data"
    assert "load_error" not in summary
    assert summary["lift_N"] == pytest.approx(case.true_lift, rel=0.03)
    assert (out / "lift.csv").exists() and (out / "load_field.png").exists()


def _bad_files(tmp_path, record):
    problem, case = record
    meas = case.measurements
    names = problem.sensor_names
    files = {}
    p = tmp_path / "empty.csv"
    p.write_text("")
    files["empty"] = (p, "empty file")
    p = tmp_path / "header.csv"
    p.write_text("t,S1,S2,S3,S4\n")
    files["header only"] = (p, "no data rows")
    p = tmp_path / "missing.csv"
    write_csv(p, meas.t[:50], meas.values[:50, :3], names[:3])
    files["missing column"] = (p, "missing sensor column(s) S4")
    t = meas.t[:50].copy()
    t[20] = t[19]
    p = tmp_path / "mono.csv"
    write_csv(p, t, meas.values[:50], names)
    files["non-monotonic"] = (p, "strictly increasing")
    t = meas.t[:50] + np.where(np.arange(50) > 25, 0.0004, 0.0)
    p = tmp_path / "irregular.csv"
    write_csv(p, t, meas.values[:50], names)
    files["irregular"] = (p, "irregular sampling")
    p = tmp_path / "units.csv"
    write_csv(p, meas.t[:50], meas.values[:50] * 1e6, names)
    files["units"] = (p, "percent or microstrain")
    p = tmp_path / "text.csv"
    write_csv(p, meas.t[:50], meas.values[:50], names)
    lines = p.read_text().splitlines()
    lines[7] = lines[7].replace(lines[7].split(",")[2], "abc")
    p.write_text("\n".join(lines) + "\n")
    files["non-numeric"] = (p, ":8: S2 = 'abc'")
    files["no file"] = (tmp_path / "nowhere.csv", "no such file")
    return files


@pytest.mark.parametrize(
    "which", ["empty", "header only", "missing column", "non-monotonic", "irregular", "units", "non-numeric", "no file"]
)
def test_bad_csv_is_one_line_exit_2_and_no_output(record, small_file, tmp_path, capsys, which):
    path, needle = _bad_files(tmp_path, record)[which]
    out = tmp_path / "never"
    assert main(["identify", str(small_file), *LINEAR, "--data", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err, err
    assert err.count("\n") == 1
    assert not out.exists() and not list(tmp_path.glob(".never*"))


def test_existing_output_survives_a_failed_run(record, small_file, tmp_path, capsys):
    out = tmp_path / "keep"
    out.mkdir()
    (out / ".wingopt-result").write_text("")  # an earlier wingopt result: replaceable, kept on failure
    (out / "summary.json").write_text("{}")
    bad = tmp_path / "empty.csv"
    bad.write_text("")
    assert main(["identify", str(small_file), *LINEAR, "--data", str(bad), "--out", str(out)]) == 2
    assert (out / "summary.json").read_text() == "{}"


def test_help_has_an_example(capsys):
    with pytest.raises(SystemExit):
        main(["identify", "--help"])
    text = capsys.readouterr().out
    assert "wingopt identify membrane --load L1" in text and "PERCENT" in text


def test_identify_with_the_tuned_jekf(small_file, tmp_path, capsys):
    out = tmp_path / "jekf"
    argv = ["identify", str(small_file), "--load", "L1", "--noise", "1", "--method", "jekf-tuned", "--no-plots"]
    assert main(argv + ["--truth-mesh", "25x13", "--t-end", "0.3", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["method"] == "jekf-tuned" and summary["load_error"] < 0.1
    assert (out / "lift.csv").exists()


@pytest.mark.parametrize("method", ["jekf", "jekf-tuned", "mhe"])
def test_a_fixed_lambda_reaches_every_method(small_file, tmp_path, capsys, method):
    """``--lambda X`` is the estimator's lambda for every method (it was silently ignored by the JEKF)."""
    out = tmp_path / method
    argv = ["identify", str(small_file), "--load", "L1", "--noise", "1", "--method", method, "--lambda", "3.5e-7"]
    extra = FAST if method == "mhe" else ["--truth-mesh", "25x13", "--t-end", "0.2"]
    assert main(argv + extra + ["--no-plots", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["regularization"] == pytest.approx(3.5e-7, rel=1e-12)


def test_lambda_rules_have_distinct_names_per_method(small_file, tmp_path, capsys):
    from wingopt.estimation.core.lambda_rules import resolve

    # One word, two rules: "discrepancy" was Morozov's principle for the MHE and a likelihood-ratio
    # test on late innovations for the JEKF. Each now has its own name; the old word still resolves.
    assert resolve("discrepancy", "mhe").name == "morozov"
    assert resolve("discrepancy", "jekf").name == "late-innovation-lr"
    assert resolve(None, "mhe").name == "knee" and resolve(None, "jekf").name == "late-innovation-lr"
    assert resolve("seed-nelder-mead", "jekf-seed").uses_truth
    argv = ["identify", str(small_file), "--load", "L1", "--method", "jekf-tuned", "--lambda-rule", "gcv"]
    assert main(argv + ["--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    failures = [ln for ln in err.strip().splitlines() if ": error:" in ln]  # after the run's stage lines
    assert "the jekf estimator accepts late-innovation-lr" in err and len(failures) == 1


def test_options_of_the_mhe_only_are_refused_for_the_jekf(small_file, tmp_path, capsys):
    argv = ["identify", str(small_file), "--load", "L1", "--method", "jekf", "--solver", "ipopt"]
    assert main(argv + ["--out", str(tmp_path / "x")]) == 2
    assert "--solver is not used by the jekf-seed estimator" in capsys.readouterr().err


def test_data_at_another_sample_rate(small_file, tmp_path, capsys):
    """DIC at 300 Hz: the estimator uses the data's own sample period."""
    from wingopt.membrane import MembraneModel, add_noise, bubble, forward_model, load_case

    problem = load_problem(small_file)
    truth = MembraneModel.from_problem(problem, (25, 13))
    traj = forward_model(truth, "linear").run(load_case("L1", 0.14, 0.07), t_end=1.0, dt=1 / 300, z0=bubble(0.14, 0.07))
    y, _ = add_noise(traj.outputs, 0.01, 0)
    data = tmp_path / "dic300.csv"
    write_csv(data, traj.t, y, problem.sensor_names)
    out = tmp_path / "dic"
    argv = ["identify", str(small_file), *LINEAR, "--data", str(data), "--out", str(out), "--json", "--no-plots"]
    assert main(argv + ["--window", "60", "--stride", "20", "--modes", "20", "--model", "linear"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["data"]["dt_s"] == pytest.approx(1 / 300, rel=1e-3)  # times written to 1 us
    assert summary["lift_N"] == pytest.approx(truth.lift(truth.project(load_case("L1", 0.14, 0.07))), rel=0.03)


def test_compare_command_writes_records_and_resumes(small_file, tmp_path, capsys):
    out = tmp_path / "cmp"
    argv = ["compare", str(small_file), "--loads", "L1", "--noise", "5", "--n-seeds", "1", "--methods", "mhe"]
    argv += ["--no-oracle", "--truth-mesh", "25x13", "--out", str(out), "--doc", str(tmp_path / "doc.md")]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "| L1 | 5 % | mhe |" in text and "MHE mean load error L1 5 %" in text
    recs = (out / "records.jsonl").read_text().splitlines()
    assert len(recs) == 1 and json.loads(recs[0])["method"] == "mhe"
    assert (tmp_path / "doc.md").read_text().startswith("# Load identification")
    # Resuming recomputes nothing; the existing --doc is replaced only with --force (kept as .bak).
    assert main(argv + ["--resume"]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(argv + ["--resume", "--force"]) == 0
    assert len((out / "records.jsonl").read_text().splitlines()) == 1
    assert (tmp_path / "doc.md.bak").read_text().startswith("# Load identification")
    assert main(["compare", str(small_file), "--methods", "kalman", "--out", str(out)]) == 2


def test_compare_resume_counts_a_repeated_run_once(small_file, tmp_path, capsys):
    """The sign study re-runs the table's 5 % seeds and appends them again: a resumed report must
    still count each (load, noise, seed, method) once (it said 10/10 for 5 seeds before the fix)."""
    out = tmp_path / "cmp"
    argv = ["compare", str(small_file), "--loads", "L1", "--noise", "5", "--n-seeds", "1", "--methods", "mhe"]
    argv += ["--no-oracle", "--truth-mesh", "25x13", "--n-sign-seeds", "2", "--out", str(out)]
    assert main(argv) == 0
    first = json.loads((out / "summary.json").read_text())
    # table seed 0 (= sign seed 0: one task on the study engine) and sign seed 1
    assert len((out / "records.jsonl").read_text().splitlines()) == 2
    assert main(argv + ["--resume"]) == 0
    again = json.loads((out / "summary.json").read_text())
    assert again["comparison"][0]["seeds"] == first["comparison"][0]["seeds"] == 1
    assert again["sign_and_band"][0]["seeds"] == first["sign_and_band"][0]["seeds"] == 2


def test_state_prior_option():
    from wingopt.errors import InputError
    from wingopt.estimation.mhe import STATE_PRIOR_EVIDENCE
    from wingopt.estimation.options import IdentifyOptions
    from wingopt.estimation.registry import resolve
    from wingopt.estimation.runners import settings_for

    mhe = resolve("mhe")
    assert settings_for(mhe, IdentifyOptions(state_prior="evidence")).state_prior_choices == STATE_PRIOR_EVIDENCE
    assert settings_for(mhe, IdentifyOptions(state_prior="0.01")).state_prior == 0.01
    for bad in ("-1", "tight", "nan"):
        with pytest.raises(InputError, match="state_prior"):
            IdentifyOptions(state_prior=bad)


def test_identify_data_with_the_nonlinear_model(record, small_file, tmp_path, capsys):
    """``--data --model nonlinear``: the realistic estimator (prestrain identified, the membrane
    model chosen by the chi-square: here linear, as the record is from the linear model)."""
    problem, case = record
    data = tmp_path / "lin.csv"
    write_csv(data, case.measurements.t, case.measurements.values, problem.sensor_names)
    out = tmp_path / "nl"
    argv = ["identify", str(small_file), "--data", str(data), "--model", "nonlinear", "--out", str(out)]
    assert main(argv + ["--json", "--no-plots"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["method"] == "batch" and summary["estimator"]["backend"].startswith("realistic")
    assert summary["estimator"]["membrane_selection"]["chosen"] == "linear" and summary["model"] == "linear"
    assert summary["dropped"] == []
    assert set(summary["parameters"]) == {"prestrain_x", "prestrain_y", "damping"}
    # linear truth on 25x13, estimator on the coarse 13x7 mesh: the lift within 3 % ...
    assert summary["lift_N"] == pytest.approx(case.true_lift, rel=0.03)
    # ... a flagged record says so and widens its band at least by sqrt(chi-square per datum)
    ad = summary["estimator"]["adequacy"]
    if not summary["model_adequate"]:
        assert summary["warnings"] and ad["band_inflation"] >= np.sqrt(summary["chi2_per_datum"]) - 1e-12
