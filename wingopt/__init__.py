"""wingopt: control and estimation of flexible wings.

Data flow: mesh/basis (:mod:`wingopt.fe`) -> FE operators (:mod:`wingopt.membrane`,
:mod:`wingopt.plate`) -> state space (:mod:`wingopt.dynamics`) -> control QP
(:mod:`wingopt.control`) or estimation (:mod:`wingopt.estimation`) -> results
(:mod:`wingopt.results`).

The main entry points are available at the top level (imported on first use)::

    import wingopt as wo
    plate = wo.load_problem("plate")
    run = wo.morph(plate, "twist", method="qp")          # -> MorphResult
    membrane = wo.load_problem("membrane")
    est = wo.identify(membrane, load="L1", noise_percent=1)  # -> IdentifyRun
"""

from __future__ import annotations

import importlib

from wingopt.cache_dir import use_user_cache

__version__ = "0.1.0"

# numba's compiled kernels go to the user's cache directory, never into the installed package
# (issue 33): set before any wingopt module imports numba.
use_user_cache()

_LAZY = {
    "load_problem": "wingopt.problem",
    "parse_mesh": "wingopt.problem",
    "build_model": "wingopt.models",
    "morph": "wingopt.workflows.morph",
    "write_morph_outputs": "wingopt.workflows.morph",
    "identify": "wingopt.workflows.identify",
    "write_identify_outputs": "wingopt.workflows.identify",
    "calibrate_membrane": "wingopt.workflows.calibrate",
    "calibrated_problem": "wingopt.workflows.calibrate",
    "read_measurements": "wingopt.measurements.csv_file",
    "run_demo": "wingopt.workflows.demo",
    "plot_lift": "wingopt.plots.run",
    "plot_field": "wingopt.plots.run",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'wingopt' has no attribute {name!r}")


def __dir__() -> list[str]:
    # The lazy names live in _LAZY, not in the module's namespace: without this, dir(wingopt) and
    # tab completion (which calls dir) would list only the dunders and show no entry point.
    # Subpackages already imported count too; the helpers of this file (importlib) do not.
    loaded = {k for k, v in globals().items() if getattr(v, "__name__", "").startswith("wingopt.")}
    return sorted({k for k in globals() if k.startswith("__")} | loaded | set(__all__))
