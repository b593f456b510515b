"""The estimator registry: every (estimator, membrane) pair either uses an identify option or refuses it.

Issue 22: with ``--data FILE`` (default the FvK whole-record estimator) ``--lambda``, ``--window``,
``--backend``, ... were accepted and ignored. Here, for every registered pair and every option of
:class:`IdentifyOptions`: a used option changes what the estimator runs with (its settings, or its
result where the option is not a setting), and an option the pair does not use is refused with
one line naming the option and the pair.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wingopt.cli import main
from wingopt.errors import InputError
from wingopt.estimation.options import OPTION_FLAGS, IdentifyOptions
from wingopt.estimation.registry import REGISTRY, check_options, resolve
from wingopt.estimation.runners import build, settings_for
from wingopt.membrane import MembraneModel
from wingopt.problem import load_problem
from wingopt.values import LambdaChoice
from wingopt.workflows.protocols import simulate_case

VALUES = {
    "lam": LambdaChoice(value=3e-7),
    "window": "0.1s",
    "stride": "0.02s",
    "solver": "cvxpy",
    "qp_solver": "osqp",
    "modes": 12,
    "load_model": "varying",
    "load_timescale": 0.5,
    "state_prior": 0.1,
    "pressure_bounds": (-500.0, 500.0),
    "load_space": "free",
    "consistency": False,
    "noise_std": 3e-6,
    "initial_load": -150.0,
    "model_form": False,
}
"""A valid, non-default value of every option."""

ENABLERS = {
    "qp_solver": {"solver": "cvxpy"},
    "pressure_bounds": {"solver": "cvxpy"},
    "load_timescale": {"load_model": "varying"},
}
"""Options used only together with another one (the registry's ``requires``)."""


def test_every_option_has_a_test_value():
    assert set(VALUES) == set(OPTION_FLAGS) == {f.name for f in dataclasses.fields(IdentifyOptions)}


@pytest.fixture(scope="module")
def tiny():
    problem = load_problem("membrane").with_mesh((13, 7))
    model = MembraneModel.from_problem(problem)
    case = simulate_case(problem, "L1", 0.01, 0, (17, 9), 0.12, tell_noise=False)
    return model, case


@pytest.fixture(scope="module")
def tiny_misfit():
    """FvK truth with the prestrain off the file's: the linear MHE is flagged, its cross-check runs."""
    problem = load_problem("membrane").with_mesh((13, 7))
    case = simulate_case(problem, "L1", 0.01, 0, (17, 9), 0.12, truth="fvk", prestrain=(0.06, 0.04), tell_noise=False)
    return MembraneModel.from_problem(problem), case


def _settings(spec, opts):
    """What a pair runs with, for the options that are settings."""
    return None if spec.method.startswith("jekf") else settings_for(spec, opts)


@pytest.mark.parametrize("key", sorted(REGISTRY), ids=lambda k: f"{k[0]}-{k[1]}-{'stream' if k[2] else 'record'}")
@pytest.mark.parametrize("option", sorted(VALUES))
def test_an_option_is_used_or_refused(key, option, tiny, tiny_misfit):
    spec = REGISTRY[key]
    given = {option: VALUES[option], **ENABLERS.get(option, {})}
    base = IdentifyOptions(**ENABLERS.get(option, {}))
    opts = IdentifyOptions(**given)
    if option not in spec.options:
        with pytest.raises(InputError) as err:
            check_options(spec, IdentifyOptions(**{option: VALUES[option]}))
        msg = str(err.value)
        assert "\n" not in msg and OPTION_FLAGS[option] in msg and spec.method in msg and spec.model in msg
        return
    if any(o not in spec.options for o in ENABLERS.get(option, {})):
        pytest.skip("the option's enabler is not an option of this pair")
    check_options(spec, opts)
    settings = _settings(spec, opts)
    if settings is not None and settings != _settings(spec, base):
        return  # used: the estimator runs with other settings
    # Options that are not settings (noise level, sign prior, lambda and modes of the JEKF, the
    # cross-check): the estimate itself changes.
    model, case = tiny_misfit if option == "model_form" else tiny
    meas = case.measurements
    if option == "noise_std":
        meas = dataclasses.replace(meas, noise_std=np.full(4, VALUES["noise_std"]))
    a = build(spec, model, base, truth=case).run(case.measurements)
    b = build(spec, model, opts, truth=case).run(meas)
    differs = not np.allclose(a.lift, b.lift, rtol=1e-9, atol=0) or a.info != b.info
    assert differs, f"{option} changes nothing for {spec.label}"


def test_auto_resolves_to_the_documented_pairs():
    assert resolve().method == "batch" and resolve().model == "fvk"  # measured data
    assert resolve(simulated="linear").method == "mhe"
    assert resolve(simulated="berger").model == "berger"
    assert resolve(stream=True).method == "ekf" and resolve(stream=True).model == "fvk"
    assert resolve("mhe", stream=True).model == "linear"
    assert resolve("jekf", "auto").method == "jekf-seed"
    assert resolve("auto", "nonlinear").model == "berger"
    with pytest.raises(InputError, match="no such estimator"):
        resolve("mhe", "fvk")
    with pytest.raises(InputError, match="no such estimator"):
        resolve("jekf-tuned", stream=True)
    # DIC frames: the full-field estimator by default; it is refused without frames
    assert resolve(frames=True).method == "fullfield" and resolve(frames=True).model == "fvk"
    assert resolve("batch", frames=True).method == "batch"
    with pytest.raises(InputError, match="fullfield.*DIC frames.*--dic"):
        resolve("fullfield")


def test_the_command_line_refuses_an_unused_option_in_one_line(tmp_path, capsys):
    data = "examples/data/tunnel_calibration_300Hz.csv"  # any shipped record: the options are refused
    argv = ["identify", "membrane", "--data", data, "--out", str(tmp_path / "o")]
    cases = [(["--window", "0.1s"], "--window"), (["--lambda", "1e-6"], "--lambda")]
    cases += [(["--solver", "ipopt"], "--solver"), (["--state-prior", "0.1"], "--state-prior")]
    for extra, flag in cases:
        assert main(argv + extra) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and flag in err and "batch estimator with the fvk membrane" in err
    assert not (tmp_path / "o").exists()
