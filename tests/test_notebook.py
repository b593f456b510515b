"""Notebook ergonomics (issue 26, items 4 and 5): ``dir(wingopt)``, short reprs with the key numbers,
one status word on every result, warnings once each naming their source, no unit hint on the
package's own simulations."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _ramp_record import write_record

import wingopt as wo
from wingopt.dynamics.statespace import StateSpace
from wingopt.estimation.calibration.fit import Calibration
from wingopt.estimation.core.result import IdentificationResult
from wingopt.estimation.options import IdentifyOptions
from wingopt.membrane import MembraneModel
from wingopt.status import RunStatus, from_info, from_solver_statuses, worst

ROOT = Path(__file__).resolve().parents[1]
SHORT = dict(truth_nodes=None, t_end=0.3, method="mhe", nodes=(13, 7))
REPR_MAX = 300
"""A repr a notebook prints in one or two lines (they were 1 000 to 90 000 characters)."""


@pytest.fixture(scope="module")
def ramp(tmp_path_factory):
    """A record from rest with a 40 ms load ramp, linear truth (tests/_ramp_record.py): the linear MHE
    flags it (the ramp it leaves out)."""
    return write_record(tmp_path_factory.mktemp("ramp") / "ramp.csv")


@pytest.fixture(scope="module")
def l1_run():
    return wo.identify("membrane", load="L1", **SHORT)


# -- dir -------------------------------------------------------------------------------------------


def test_dir_lists_the_lazy_entry_points():
    names = dir(wo)
    assert set(wo.__all__) <= set(names)
    assert {"identify", "load_problem", "morph", "read_measurements"} <= set(names)
    assert "importlib" not in names and "annotations" not in names  # the module's own helpers stay hidden
    assert names == sorted(names)


# -- reprs -----------------------------------------------------------------------------------------


def test_problem_reprs_are_short_and_name_mesh_and_sizes():
    membrane, plate = wo.load_problem("membrane"), wo.load_problem("plate")
    r = repr(membrane)
    assert len(r) <= REPR_MAX, r
    assert "'membrane'" in r and "mesh 25x13" in r and "4 sensors [S1,S2,S3,S4]" in r and "prestrain 0.05" in r
    assert "youngs_modulus" not in r  # the material constants stay attributes
    r = repr(plate)
    assert len(r) <= REPR_MAX, r
    assert "mesh 13x61" in r and f"{len(plate.patches)} patches" in r and "-500..1500 V" in r


def test_model_reprs_are_short_and_give_the_sizes():
    model = MembraneModel.from_problem(wo.load_problem("membrane"), (13, 7))
    r = repr(model)
    assert len(r) <= REPR_MAX and "mesh 13x7" in r and f"dofs={model.n}" in r and "sensors=4" in r, r
    ss = StateSpace(np.eye(3), np.ones((3, 2)), dt=0.01)
    assert repr(ss) == "StateSpace(states=3, inputs=2, outputs=3, discrete, dt=0.01 s)"


def test_identification_reprs_give_lift_band_and_status(l1_run):
    lift, std = l1_run.result.reported_lift
    for r in (repr(l1_run), repr(l1_run.result)):
        assert len(r) <= REPR_MAX, r
        assert f"{lift:.4g} ± {std:.3g} N" in r and "status='converged'" in r, r
    assert "mesh 13x7" in repr(l1_run) and "'L1'" in repr(l1_run)
    assert f"samples={l1_run.result.t.size}" in repr(l1_run.result)


# -- status ----------------------------------------------------------------------------------------


def test_status_vocabulary_orders_and_derives():
    assert worst() is RunStatus.CONVERGED
    assert worst(RunStatus.MISFIT, RunStatus.CONVERGED, RunStatus.NOT_CONVERGED) is RunStatus.NOT_CONVERGED
    assert from_solver_statuses(["optimal"]) is RunStatus.CONVERGED
    assert from_solver_statuses(["optimal", "optimal_inaccurate"]) is RunStatus.NOT_CONVERGED
    assert from_info({}, 0.4) is RunStatus.CONVERGED
    assert from_info({"model_adequate": False}, 0.4) is RunStatus.MISFIT
    assert from_info({"model_adequate": False, "converged": False}, 0.4) is RunStatus.NOT_CONVERGED
    assert from_info({"converged": True}, float("nan")) is RunStatus.FAILED
    assert str(RunStatus.MISFIT) == "misfit" and json.dumps(RunStatus.MISFIT) == '"misfit"'


def test_identification_status_comes_from_its_diagnostics(l1_run, tmp_path):
    assert l1_run.status is RunStatus.CONVERGED and l1_run.result.status is RunStatus.CONVERGED
    assert l1_run.summary()["status"] == "converged"
    res = l1_run.result
    flagged = IdentificationResult(
        res.method, res.t, res.load, res.deflection, res.lift, info={"model_adequate": False}
    )
    assert flagged.status is RunStatus.MISFIT and "status='misfit'" in repr(flagged)
    nan = IdentificationResult(res.method, res.t, res.load, res.deflection, res.lift * np.nan)
    assert nan.status is RunStatus.FAILED
    wo.write_identify_outputs(l1_run, tmp_path / "out", plots=False)
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["status"] == "converged"


def test_a_flagged_record_is_a_misfit_in_summary_json(tmp_path, ramp):
    run = wo.identify(
        wo.load_problem("membrane").with_mesh((13, 7)),
        data=ramp,
        model="linear",
        options=IdentifyOptions(model_form=False),
    )
    assert run.result.info["model_adequate"] is False
    assert run.status is RunStatus.MISFIT and run.summary()["status"] == "misfit"
    r = repr(run)
    assert len(r) <= REPR_MAX and "record='ramp.csv'" in r and "status='misfit'" in r, r
    assert "warnings=2" in r


def test_morph_status_and_repr():
    plate = wo.load_problem("plate")
    run = wo.morph(plate, "twist", "qp", nodes=(7, 31), t_end=0.5)
    assert run.extras["qp_statuses"] == ["optimal"]
    assert run.status is RunStatus.CONVERGED and run.summary()["status"] == "converged"
    r = repr(run)
    assert len(r) <= REPR_MAX and f"shape_error={run.closed_loop.final_shape_error:.4g}" in r, r
    r = repr(run.closed_loop)
    assert len(r) <= REPR_MAX and "t_end=0.5 s, steps=50" in r and "status='converged'" in r, r
    # 0.5 s is too short for the LQR: its shape error still falls 0.44 -> 0.37 over the last 0.1 s.
    short = wo.morph(plate, "twist", "lqr", nodes=(7, 31), t_end=0.5)
    assert short.closed_loop.settling_time() > 0.4
    assert short.status is RunStatus.NOT_CONVERGED and short.summary()["status"] == "not_converged"
    assert short.closed_loop.status is RunStatus.NOT_CONVERGED


def test_gains_status_and_repr():
    from wingopt.workflows.gains import plate_gains

    g = plate_gains(wo.load_problem("plate"), [(7, 31)])
    rec = g.summary["meshes"][0]
    assert rec["converged"] is True and rec["status"] == "converged"
    assert g.status is RunStatus.CONVERGED and g.summary["status"] == "converged"
    assert repr(g) == "GainsResult(problem='plate', r=1e-10, meshes=[7x31 (279 dofs)], status='converged')"
    assert json.loads(json.dumps(g.summary["status"])) == "converged"


def test_design_status_and_repr():
    from wingopt.workflows.design import design_layout, design_settings

    cands = "only-rects;rect=0.02:0.05:0.01:0.025;rect=0.08:0.11:0.045:0.06;rect=0.1:0.13:0.01:0.025"
    res = design_layout("membrane", 2, cands, design_settings(criterion="a", t_end=0.05, nominal_count=1))
    assert res.relaxation["status"] == "optimal" and res.status is RunStatus.CONVERGED
    r = repr(res)
    assert len(r) <= REPR_MAX and "count=2" in r and "candidates=7" in r and "status='converged'" in r, r
    assert res.summary()["status"] == "converged"


def test_calibration_status():
    pars = {"prestrain_x": 0.05, "prestrain_y": 0.04, "damping": 1.0}
    ok = Calibration(pars, pars, np.eye(3), 1.0, True, info={"converged": True})
    assert ok.status is RunStatus.CONVERGED
    assert Calibration(pars, pars, np.eye(3), 3.0, False, info={"converged": True}).status is RunStatus.MISFIT
    assert Calibration(pars, pars, np.eye(3), 1.0, True, info={"converged": False}).status is RunStatus.NOT_CONVERGED
    nan = {**pars, "damping": float("nan")}
    assert Calibration(nan, pars, np.eye(3), 1.0, True).status is RunStatus.FAILED


# -- warnings: once, with their source; none about units on our own simulations ----------------------


def test_simulated_records_get_no_unit_hint_and_neither_do_the_same_values_as_data():
    """The protocol's L2 reads beyond the pre-strain (it once raised "values in percent?" on the
    package's own simulation); the band reaches twice the pre-strain, the FvK regime, so neither the
    simulation nor the same values as data are hinted at, and values beyond it are, once, sourced."""
    from wingopt.estimation.core.sanity import SCALE_HIGH

    problem = wo.load_problem("membrane").with_mesh((13, 7))
    sim = wo.identify(problem, load="L2", truth_nodes=None, t_end=0.3, method="mhe")
    assert sim.measurements.simulated
    peak = float(np.nanmax(np.abs(sim.measurements.values)))
    assert problem.material.prestrain < peak < SCALE_HIGH * problem.material.prestrain
    assert not any("percent" in w for w in sim.warnings), sim.warnings
    m = sim.measurements
    data = wo.identify(problem, data=np.column_stack([m.t, m.values]), method="mhe", model="linear")
    assert not any("percent" in w for w in data.warnings), data.warnings
    big = wo.identify(problem, data=np.column_stack([m.t, 3 * m.values]), method="mhe", model="linear")
    hints = [w for w in big.warnings if "percent" in w]
    assert len(hints) == 1 and hints[0].startswith("[data check] "), big.warnings


def test_an_engine_warning_is_in_the_result_and_logged_once(caplog):
    """The MHE's undetermined sign used to be logged by the engine only (not in summary.json); it is
    now the estimator's warning, logged once by the workflow with the estimator's name."""
    import dataclasses
    import logging

    p = wo.load_problem("membrane").with_mesh((13, 7))
    p = dataclasses.replace(p, identification=dataclasses.replace(p.identification, initial_deflection=0.0))
    with caplog.at_level(logging.WARNING, logger="wingopt"):
        run = wo.identify(p, load="L2", truth_nodes=None, t_end=0.3, method="mhe")
    sign = [w for w in run.warnings if "sign of the load is not determined" in w]
    assert len(sign) == 1 and sign[0].startswith("[linear mhe] "), run.warnings
    logged = [r.getMessage() for r in caplog.records if "sign of the load" in r.getMessage()]
    assert logged == sign
    assert run.summary()["warnings"] == run.warnings


def test_cli_identify_prints_each_warning_once_with_its_source(tmp_path, ramp):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "wingopt", "identify", "membrane", "--data", str(ramp), "--model", "linear"]
    cmd += ["--no-model-form", "--mesh", "13x7", "--noise-std", "0.00035", "--no-plots", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    warnings = json.loads((out / "summary.json").read_text())["warnings"]
    # the fit check's noise level (22 % of S4's peak), the linear model's adequacy and its left-out start
    assert len(warnings) == 3, warnings
    assert sum(w.startswith("[linear mhe] ") for w in warnings) == 2
    assert sum(w.startswith("[fit check] ") and "mostly noise" in w for w in warnings) == 1
    both = proc.stdout + proc.stderr
    for w in warnings:
        assert both.count(w) == 1, (w, both)
    lines = [ln for ln in proc.stderr.splitlines() if ": warning: " in ln]
    assert len(lines) == 3 and all(ln.startswith("wingopt identify: warning: [") for ln in lines), lines
    assert "(3 warnings above;" in proc.stdout and " [misfit], " in proc.stdout  # the status on the result line


def test_the_cross_checks_warnings_say_they_are_its(monkeypatch, tmp_path, capsys, ramp):
    """The FvK cross-check of a flagged linear MHE (98 s of CPU on this record) replaced by a stub
    that warns: its warnings reach the summary and stderr once each, prefixed as the cross-check's."""
    from wingopt.cli import main
    from wingopt.estimation import runners

    def stub(model, meas, settings, initial_load=None):
        t = meas.t[-1:]
        res = IdentificationResult("batch", t, np.zeros((1, 1)), np.zeros((1, model.n)), np.array([0.4]))
        return IdentificationResult(**{**res.__dict__, "lift_std": np.array([0.01]), "info": {"warnings": ["stub"]}})

    monkeypatch.setattr(runners, "identify_record", stub)
    out = tmp_path / "run"
    args = ["identify", "membrane", "--data", str(ramp), "--model", "linear", "--mesh", "13x7", "--no-plots"]
    assert main([*args, "--out", str(out)]) == 0
    cap = capsys.readouterr()
    warnings = json.loads((out / "summary.json").read_text())["warnings"]
    cross = [w for w in warnings if w.startswith("[fvk cross-check] ")]
    assert len(cross) == 2 and "model-form uncertainty" in cross[0] and cross[1] == "[fvk cross-check] stub"
    for w in warnings:
        assert (cap.out + cap.err).count(w) == 1, w


# -- noise: one convention, the unit in the name --------------------------------------------------


def test_a_bare_noise_is_refused_naming_the_spellings_with_a_unit():
    from wingopt.errors import InputError
    from wingopt.membrane import RecordProtocol
    from wingopt.workflows.design import design_settings
    from wingopt.workflows.protocols import simulate_case

    problem = wo.load_problem("membrane")
    # identify(noise=1) simulated 100 % noise once: now no bare noise anywhere in the API.
    with pytest.raises(InputError, match="noise = 1: ambiguous unit; give noise_percent .* or noise_std"):
        wo.identify(problem, load="L1", noise=1)
    with pytest.raises(InputError, match=r"noise = 0.01: give noise_fraction \(0.01 = 1 %"):
        simulate_case(problem, "L1", noise=0.01)
    with pytest.raises(InputError, match="simulate_case: give noise_fraction"):
        simulate_case(problem, "L1")
    with pytest.raises(InputError, match="noise = 0.01: give noise_fraction"):
        RecordProtocol(noise=0.01)
    with pytest.raises(InputError, match="noise = 0.05: give noise_fraction"):
        design_settings(noise=0.05)
    assert RecordProtocol(noise_fraction=0.02).noise_fraction == 0.02
    assert design_settings(noise_fraction=0.05).information.noise_fraction == 0.05


def test_noise_percent_and_noise_fraction_simulate_the_same_record():
    from wingopt.workflows.protocols import simulate_case

    problem = wo.load_problem("membrane").with_mesh((13, 7))
    run = wo.identify(problem, load="L1", noise_percent=2, seed=3, truth_nodes=None, t_end=0.05, method="mhe")
    case = simulate_case(problem, "L1", noise_fraction=0.02, seed=3, truth_nodes=None, t_end=0.05)
    assert run.summary()["noise_percent"] == 2 and case.noise_fraction == 0.02
    np.testing.assert_array_equal(run.measurements.values, case.measurements.values)


def test_the_cli_spells_the_unit_too(tmp_path):
    from wingopt.cli import main

    out = tmp_path / "run"
    args = ["identify", "membrane", "--load", "L1", "--noise-percent", "2", "--seed", "3", "--same-mesh"]
    assert main([*args, "--mesh", "13x7", "--method", "mhe", "--t-end", "0.05", "--no-plots", "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["noise_percent"] == 2
