"""Window solvers of the moving-horizon estimator: one interface, three backends, by name.

* ``numpy`` and ``cvxpy``: Levenberg–Marquardt (:mod:`wingopt.estimation.mhe.lm`);
* ``ipopt``: the whole nonlinear window problem with IPOPT (:mod:`wingopt.estimation.mhe.ipopt`).

The names (:data:`WINDOW_SOLVERS`, and the QP solvers of the ``cvxpy`` steps) are the ``window``
and ``least-distance`` capabilities of :mod:`wingopt.optim.registry`; the QP steps, the status
mapping and the failure path (:class:`~wingopt.errors.SolverError` naming backend, raw status and
hint) come from :mod:`wingopt.optim` too. The estimation modules keep the Gauss–Newton/LM logic
and the window NLP.
"""

from __future__ import annotations

from wingopt.errors import InputError
from wingopt.estimation.mhe.ipopt import IPOPT_HESSIANS, IpoptSolver
from wingopt.estimation.mhe.lm import CvxpySolver, NumpySolver, WindowSolution, WindowSolver
from wingopt.optim.registry import solver_names

__all__ = [
    "WindowSolution",
    "WindowSolver",
    "NumpySolver",
    "CvxpySolver",
    "IpoptSolver",
    "make_solver",
    "WINDOW_SOLVERS",
    "IPOPT_HESSIANS",
]

WINDOW_SOLVERS = solver_names("window")
"""The window solvers (``MHESettings.backend``): numpy, cvxpy, ipopt."""


def make_solver(backend: str = "numpy", qp_solver: str = "clarabel", **kwargs) -> WindowSolver:
    """A window solver by name (:data:`WINDOW_SOLVERS`); ``qp_solver`` is the QP solver of ``cvxpy``'s steps."""
    if backend == "numpy":
        return NumpySolver(**kwargs)
    if backend == "cvxpy":
        return CvxpySolver(solver=qp_solver, **kwargs)
    if backend == "ipopt":
        if kwargs.get("hessian") in ("newton", "gauss-newton"):
            kwargs.pop("hessian")
        return IpoptSolver(**kwargs)
    raise InputError(f"backend = {backend!r}: expected one of {', '.join(WINDOW_SOLVERS)}")
