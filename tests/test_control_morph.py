"""``morph()`` API and the ``wingopt morph`` command: outputs, limits, bad input."""

import csv
import json

import numpy as np
import pytest

from wingopt.cli import main
from wingopt.errors import InputError
from wingopt.problem import load_problem
from wingopt.workflows.morph import METHODS, load_factory, morph, resolve_limits, write_morph_outputs


@pytest.fixture(scope="module")
def problem():
    return load_problem("plate")


@pytest.fixture(scope="module")
def twist7(problem):
    return morph(problem, "twist", "lqr", nodes=(7, 31), t_end=0.5)


def test_summary_has_the_spec_keys(twist7):
    s = twist7.summary()
    for key in ("shape_error", "tip_corners_m", "voltages_final_V", "peak_voltage_V", "method", "wall_s"):
        assert key in s
    assert s["method"] == "lqr" and s["shape"] == "twist" and s["mesh"] == [7, 31]
    assert len(s["voltages_final_V"]) == 9 and len(s["tip_corners_m"]) == 2
    assert s["vmin_V"] is None and s["vmax_V"] is None
    assert s["peak_voltage_V"][0] <= min(s["voltages_final_V"])


def test_outputs_and_comparison(twist7, problem, tmp_path):
    sat = morph(problem, "twist", "lqr", nodes=(7, 31), t_end=0.5, vmin=-500, vmax=1500, model=twist7.model)
    assert sat.closed_loop.u.min() >= -500 and sat.closed_loop.u.max() <= 1500
    out = tmp_path / "run"
    write_morph_outputs(twist7, out, compare_with=sat)
    names = {p.name for p in out.iterdir()}
    assert {"summary.json", "voltages.csv", "history.csv", "voltages.png", "tip_corners.png", "surface.png"} <= names
    assert {"strains.png", "shape_error.png", "snapshots.png"} <= names
    s = json.loads((out / "summary.json").read_text())
    assert s["compare_with"]["vmax_V"] == 1500.0
    rows = list(csv.reader(open(out / "voltages.csv")))
    assert rows[0] == ["t"] + [f"PZ{i}" for i in range(1, 10)]
    assert len(rows) == 1 + twist7.closed_loop.u.shape[0]
    assert float(rows[1][8]) == pytest.approx(twist7.closed_loop.u[0, 7], rel=1e-8)


def test_limits_per_method(problem):
    def pair(limits):
        return limits.scalar("lower"), limits.scalar("upper")

    assert pair(resolve_limits(problem, "lqr")) == (None, None)
    assert resolve_limits(problem, "lqr").is_unlimited
    assert pair(resolve_limits(problem, "lqr", vmax=1500)) == (None, 1500.0)
    assert pair(resolve_limits(problem, "qp")) == (-500.0, 1500.0)
    assert resolve_limits(problem, "qp").lower.shape == (9,)
    with pytest.raises(InputError, match="vmin < vmax"):
        resolve_limits(problem, "lqr", 5.0, 1.0)
    with pytest.raises(InputError, match="vmin < vmax"):  # equal limits are no range (was accepted by one check)
        resolve_limits(problem, "qp", 10.0, 10.0)
    with pytest.raises(InputError, match="finite"):
        resolve_limits(problem, "lqr", float("-inf"), 1.0)


def test_methods_and_factories():
    assert set(METHODS) >= {"lqr", "qp"}
    assert callable(load_factory("lqr"))
    with pytest.raises(InputError, match="method = 'pid'"):
        load_factory("pid")


def test_cli_lqr_json(tmp_path, capsys):
    out = tmp_path / "cli"
    argv = ["morph", "plate", "--shape", "bending", "--method", "lqr", "--mesh", "7x31", "--t-end", "0.3"]
    assert main(argv + ["--vmin", "-500", "--vmax", "1500", "--no-plots", "--out", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["vmin_V"] == -500.0 and s["peak_voltage_V"][1] <= 1500.0
    assert (out / "summary.json").exists() and (out / "voltages.csv").exists()


@pytest.mark.parametrize(
    "extra,needle",
    [
        (["--shape", "wave"], "shape = 'wave'"),
        (["--shape", "twist", "--method", "pid"], "method = 'pid'"),
        (["--shape", "twist", "--vmin", "100", "--vmax", "100"], "vmin < vmax"),
        (["--shape", "twist", "--t-end", "-1"], "t-end"),
        (["--shape", "twist", "--mesh", "7by31"], "mesh"),
        (["--shape", "twist", "--horizon", "10"], "apply to --method qp only"),
        (["--shape", "twist", "--sensor-noise", "-1"], "sensor-noise"),
    ],
)
def test_cli_bad_input_exit_2(tmp_path, capsys, extra, needle):
    out = tmp_path / "bad"
    rc = main(["morph", "plate", "--method", "lqr", *extra, "--out", str(out)] if "--method" not in extra
              else ["morph", "plate", *extra, "--out", str(out)])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_cli_unwritable_out_dir(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc = main(["morph", "plate", "--shape", "twist", "--method", "lqr", "--out", str(blocker / "sub")])
    assert rc == 2 and "out = " in capsys.readouterr().err


def test_cli_membrane_problem_refused(tmp_path, capsys):
    rc = main(["morph", "membrane", "--shape", "twist", "--method", "lqr", "--out", str(tmp_path / "m")])
    assert rc == 2 and "plate problem" in capsys.readouterr().err


def test_failed_run_leaves_no_directory(tmp_path, monkeypatch, twist7):
    import wingopt.workflows.morph as wm

    def boom(*a, **k):
        raise InputError("boom")

    monkeypatch.setattr(wm, "plot_morph", boom)  # the figure step, as the workflow calls it
    out = tmp_path / "half"
    with pytest.raises(InputError):
        write_morph_outputs(twist7, out)
    assert not out.exists() and not any(p.name.startswith(".half") for p in tmp_path.iterdir())
    assert np.isfinite(twist7.closed_loop.final_shape_error)


def test_selected_figures_only(twist7, tmp_path):
    """``figures=``: only those are drawn (the quick demo draws the report's three); a bad name is
    refused before anything is written."""
    out = tmp_path / "some"
    write_morph_outputs(twist7, out, figures=("surface", "voltages"))
    assert {p.name for p in out.glob("*.png")} == {"voltages.png", "surface.png"}
    with pytest.raises(InputError, match="figures"):
        write_morph_outputs(twist7, tmp_path / "bad", figures=("surface", "strain"))
    assert not (tmp_path / "bad").exists()
    with pytest.raises(InputError, match="figures"):
        write_morph_outputs(twist7, tmp_path / "bad", figures="surface")
