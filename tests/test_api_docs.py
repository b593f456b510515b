"""Numpydoc ``Parameters`` and ``Returns`` on the top-level API and the engines' entry points."""

import importlib
import inspect

import pytest

import wingopt

ENTRY_POINTS = [
    *(f"wingopt:{name}" for name in wingopt.__all__ if name != "__version__"),
    "wingopt.control.lqr:lqr",
    "wingopt.control.lqr:dlqr",
    "wingopt.control.closed_loop:simulate_closed_loop",
    "wingopt.dynamics.reduction:reduce_system",
    "wingopt.dynamics.reduction:reduced_basis",
    "wingopt.dynamics.modes:lowest_modes",
    "wingopt.estimation.mhe:mhe_identify",
    "wingopt.estimation.jekf:jekf_identify",
    "wingopt.estimation.jekf:identify",
    "wingopt.estimation.core.noise:estimate_noise_std",
    "wingopt.workflows.protocols:simulate_case",
    "wingopt.membrane.truth:simulate_truth",
    "wingopt.membrane.forward:forward_model",
    "wingopt.estimation.fullfield:fullfield_identify",
    "wingopt.membrane.virtual_sensors:virtual_sensors",
    "wingopt.status:from_info",
]


@pytest.mark.parametrize("entry", ENTRY_POINTS)
def test_entry_point_has_parameters_and_returns(entry):
    module, name = entry.split(":")
    obj = getattr(importlib.import_module(module), name)
    doc = inspect.getdoc(obj) or ""
    assert "Parameters\n----------" in doc, f"{entry}: no numpydoc Parameters section"
    assert "Returns\n-------" in doc, f"{entry}: no numpydoc Returns section"
