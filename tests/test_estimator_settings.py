"""Settings travel one way: an estimator's settings dataclass declares the options it takes.

The registry derives every row's options from its settings dataclass; ``settings_for`` applies
them. These tests pin the mapping (what an option sets) and that nothing else names it.
"""

import dataclasses

import pytest

from wingopt.estimation.mhe import STATE_PRIOR_EVIDENCE, MHESettings
from wingopt.estimation.options import OPTION_FLAGS, IdentifyOptions, apply_options, declared_options, option
from wingopt.estimation.registry import REGISTRY, resolve
from wingopt.estimation.runners import RECORD_RUNNERS, STREAM_BUILDERS, settings_for
from wingopt.values import LambdaChoice


def test_every_row_takes_its_settings_options_and_only_known_ones():
    for spec in REGISTRY.values():
        assert declared_options(spec.settings) <= spec.options <= set(OPTION_FLAGS)
        runners = STREAM_BUILDERS if spec.stream else RECORD_RUNNERS
        assert spec.method in runners  # one runner per method, no branch on its name elsewhere


def test_the_derived_options_are_the_rows_of_record():
    # the sets the registry listed by hand before they were derived (issue 31): unchanged
    mhe = {"lam", "window", "stride", "solver", "qp_solver", "modes", "load_model", "load_timescale"}
    mhe |= {"state_prior", "pressure_bounds", "load_space", "consistency", "model_form", "noise_std", "initial_load"}
    assert resolve("mhe").options == mhe
    assert resolve("jekf-seed").options == {"initial_load", "lam", "modes"}
    assert resolve("batch", "fvk").options == {"noise_std", "initial_load", "modes", "load_model"}
    assert resolve("ekf", stream=True).options == {"noise_std", "initial_load", "modes"}
    assert resolve("fullfield", frames=True).options == {"initial_load", "load_model"}
    stream = {"lam", "window", "modes", "state_prior", "load_space", "solver", "qp_solver", "noise_std", "initial_load"}
    assert resolve("mhe", stream=True).options == stream


@pytest.mark.parametrize(
    ("given", "expected"),
    [
        ({"window": 150}, {"window": 150}),  # whole samples
        ({"window": "0.3s"}, {"window_s": 0.3}),  # seconds
        ({"stride": "20ms"}, {"stride_s": 0.02}),
        ({"solver": "cvxpy", "qp_solver": "osqp"}, {"backend": "cvxpy", "qp_solver": "osqp"}),
        ({"load_model": "varying"}, {"load_model": "random_walk"}),
        ({"load_model": "auto"}, {"load_model": "constant"}),
        ({"state_prior": "evidence"}, {"state_prior_choices": STATE_PRIOR_EVIDENCE}),
        ({"state_prior": 0.01}, {"state_prior": 0.01}),
        ({"lam": LambdaChoice(1e-3)}, {"regularization": 1e-3}),
        ({"lam": LambdaChoice(None, "gcv")}, {"regularization": None, "lambda_rule": "gcv"}),
        ({"pressure_bounds": (-10, 500), "solver": "ipopt"}, {"pressure_bounds": (-10.0, 500.0), "backend": "ipopt"}),
    ],
)
def test_an_option_sets_the_mhe_settings_it_declares(given, expected):
    settings = settings_for(resolve("mhe"), IdentifyOptions(**given))
    assert settings == dataclasses.replace(MHESettings(), **expected)


def test_the_rows_membrane_and_a_base_are_kept():
    base = MHESettings(max_iterations=7)
    assert settings_for(resolve("mhe"), IdentifyOptions(modes=12), base) == MHESettings(max_iterations=7, modes=12)
    batch = settings_for(resolve("batch", "berger"), IdentifyOptions(load_model="varying"))
    assert batch.membrane_model == "berger" and batch.load_model == "gust"
    ff = settings_for(resolve("fullfield", frames=True), IdentifyOptions(initial_load=-150.0, load_model="constant"))
    assert ff.pressure == 150.0 and ff.mode == "steady"
    stream = settings_for(resolve("mhe", stream=True), IdentifyOptions(window=80, modes=10))
    assert stream.mhe.window == 80 and stream.mhe.modes == 10


def test_the_builder_fills_the_problems_declaration_and_keeps_a_given_one(membrane_problem):
    declared = membrane_problem.identification
    assert settings_for(resolve("mhe")).declaration is None  # no problem given: nothing to fill
    for spec in REGISTRY.values():
        settings = settings_for(spec, problem=membrane_problem)
        if any(f.name == "declaration" for f in dataclasses.fields(settings)):
            assert settings.declaration == declared, spec.label
    own = dataclasses.replace(declared, dt=2e-3)
    base = MHESettings(declaration=own)
    kept = settings_for(resolve("mhe"), IdentifyOptions(modes=12), base, problem=membrane_problem)
    assert kept == MHESettings(modes=12, declaration=own)


def test_nested_settings_take_only_the_options_they_name():
    @dataclasses.dataclass(frozen=True)
    class Inner:
        modes: int = dataclasses.field(default=1, metadata=option("modes"))
        window: int = dataclasses.field(default=1, metadata=option("window"))

    @dataclasses.dataclass(frozen=True)
    class Outer:
        inner: Inner = dataclasses.field(default_factory=Inner, metadata=option(uses=("modes",)))

    assert declared_options(Outer) == {"modes"}
    assert apply_options(Outer(), IdentifyOptions(modes=5, window=9)) == Outer(Inner(modes=5, window=1))


def test_a_declaration_must_name_an_option():
    with pytest.raises(ValueError, match="IdentifyOptions field"):
        option("windw")
    with pytest.raises(ValueError, match="IdentifyOptions field"):
        option()
