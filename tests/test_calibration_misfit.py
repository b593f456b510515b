"""A calibration that misfits its record is said in every run that takes its prior (issue 32)."""

import tomllib
from pathlib import Path

import pytest

import wingopt as wo
from wingopt.measurements import Measurements, read_measurements
from wingopt.problem import parse_problem
from wingopt.workflows.calibrate import calibrated_problem, calibrated_problem_text

DATA = Path(__file__).parents[1] / "examples" / "data"


@pytest.fixture(scope="module")
def loaded_calibration():
    """The tunnel record (the wing loaded by the flow) taken as a calibration: the unloaded model misfits it."""
    membrane = wo.load_problem("membrane")
    rec, _ = read_measurements(DATA / "tunnel_300Hz.csv", membrane.sensor_names)
    short = Measurements(rec.t[:300], rec.values[:300], rec.sensor_names, None, "tunnel_300Hz.csv")
    return membrane, short, wo.calibrate_membrane(membrane, short)


def test_the_misfit_travels_with_the_prior(loaded_calibration):
    membrane, _, run = loaded_calibration
    cal = run.calibration
    assert not cal.adequate and cal.chi2_per_datum > 2
    problem = calibrated_problem(run)
    assert problem.identification.calibration_misfit == pytest.approx(cal.chi2_per_datum, rel=1e-3)
    text = calibrated_problem_text(run)
    again = parse_problem(tomllib.loads(text), "calibrated")
    assert again.identification.calibration_misfit == problem.identification.calibration_misfit


def test_a_run_on_a_misfit_calibration_says_so(loaded_calibration):
    membrane, record, run = loaded_calibration
    said = wo.identify(calibrated_problem(run), data=record).warnings
    assert sum("[calibration] this run's prestrain prior comes from a calibration" in w for w in said) == 1
    shipped = wo.calibrate_membrane(membrane, DATA / "tunnel_calibration_300Hz.csv")
    assert shipped.calibration.adequate and calibrated_problem(shipped).identification.calibration_misfit is None
