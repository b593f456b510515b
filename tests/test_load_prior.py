"""The one load-prior builder (issue 31): what each prior is, and which priors a declaration asks for.

The record fits and the full-field fit build their priors through
:func:`~wingopt.estimation.core.load_prior.load_priors`; here its priors are the load model's
shapes themselves, and the full-field fit takes the problem file's ``pressure_prior`` (it ignored
it before) unless its settings name the priors.
"""

from __future__ import annotations

import numpy as np
import pytest

from wingopt.errors import InputError
from wingopt.estimation.core.frame_check import FRAME_SHAPES
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.load_prior import EDGES, PriorScales, leading_edges, load_priors, prior_kinds
from wingopt.estimation.core.record_settings import RecordSettings
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.fullfield.estimator import _priors
from wingopt.estimation.fullfield.settings import AUTO_PRIORS, FullFieldSettings
from wingopt.membrane import MembraneModel


@pytest.fixture(scope="module")
def model(membrane_problem):
    return MembraneModel.from_problem(membrane_problem, (13, 7))


def _same(a: LoadShapes, b: LoadShapes) -> bool:
    fields = ("shapes", "mu", "prior_std", "lift_row", "forces")
    return all(np.array_equal(getattr(a, f), getattr(b, f)) for f in fields)


def test_each_prior_is_the_load_models_shapes(model):
    """Interior: the smoothest shapes; frame: those and FRAME_SHAPES free-edge ones (the settings'
    count when given); aerodynamic: the thin-airfoil shapes at each leading edge, in that order."""
    sc = PriorScales(8, kappa=0.5, power=2.0)
    priors = load_priors(model, ("interior", "frame", "aerodynamic"), 150.0, sc)
    assert [label for label, _ in priors] == ["interior", "frame", "aerodynamic x0", "aerodynamic x1"]
    shapes = dict(priors)
    assert _same(shapes["interior"], LoadShapes.build(model, 8, 150.0, 0.5, 2.0))
    assert _same(shapes["frame"], LoadShapes.build(model, 8, 150.0, 0.5, 2.0, FRAME_SHAPES))
    assert _same(shapes["aerodynamic x1"], LoadShapes.aerodynamic(model, 150.0, "x1", 0.5))
    ((_, frame),) = load_priors(model, ("frame",), 150.0, PriorScales(8, edge_shapes=4))
    assert frame.count == 8 + 4
    assert [label for label, _ in load_priors(model, ("aerodynamic",), 150.0, sc, "x1")] == ["aerodynamic x1"]
    with pytest.raises(InputError, match="load prior 'wing'"):
        load_priors(model, ("wing",), 150.0, sc)


def test_the_declaration_picks_the_prior_and_auto_leaves_it_to_the_estimator(membrane_problem):
    auto = membrane_problem.identification
    declared = membrane_problem.with_identification(pressure_prior="interior").identification
    assert prior_kinds(auto, ("frame", "aerodynamic")) == ("frame", "aerodynamic")
    assert prior_kinds(declared, ("frame", "aerodynamic")) == ("interior",)
    assert leading_edges(None) == EDGES and leading_edges("x1") == ("x1",)
    s = RecordSettings(shapes=9, kappa=2.0, prior_power=1.5, edge_shapes=3)
    assert PriorScales.of(s) == PriorScales(9, 2.0, 1.5, 3)


@pytest.mark.parametrize(
    "declared, settings, labels",
    [
        ({}, {}, ["interior", "frame"]),
        ({"pressure_prior": "aerodynamic", "leading_edge": "x1"}, {}, ["aerodynamic x1"]),
        ({"pressure_prior": "interior"}, {}, ["interior"]),
        (
            {"pressure_prior": "interior"},
            {"priors": ("frame", "aerodynamic")},
            ["frame", "aerodynamic x0", "aerodynamic x1"],
        ),
        ({"leading_edge": "x0"}, {"priors": ("aerodynamic",), "leading_edge": "x1"}, ["aerodynamic x1"]),
    ],
)
def test_the_full_field_fit_takes_the_declared_pressure_prior(membrane_problem, declared, settings, labels):
    """The problem file's ``pressure_prior`` (``auto``: interior and frame); the settings' priors
    and leading edge, when given, win."""
    model = MembraneModel.from_problem(membrane_problem.with_identification(**declared), (13, 7))
    s = with_declaration(FullFieldSettings(shapes=10, edge_shapes=5, **settings), model.problem)
    assert [label for label, _ in _priors(model, s, 180.0)] == labels
    assert AUTO_PRIORS == ("interior", "frame")
    with pytest.raises(InputError, match="priors"):
        FullFieldSettings(priors=())
