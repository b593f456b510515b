"""Window solvers of the moving-horizon estimator: one interface, three backends, by name.

* ``numpy`` and ``cvxpy``: Levenberg–Marquardt (:mod:`wingopt.estimation.mhe.lm`);
* ``ipopt``: the whole nonlinear window problem with IPOPT (:mod:`wingopt.estimation.mhe.ipopt`).

The QP steps, the names of their QP solvers, the status mapping and the failure path
(:class:`~wingopt.errors.SolverError` naming backend, raw status and hint) come from
:mod:`wingopt.optim`; the estimation modules keep the Gauss–Newton/LM logic and the window NLP.
"""

from __future__ import annotations

from wingopt.errors import InputError
from wingopt.estimation.mhe.ipopt import IPOPT_HESSIANS, IpoptSolver
from wingopt.estimation.mhe.lm import QP_SOLVERS, CvxpySolver, NumpySolver, WindowSolution, WindowSolver

__all__ = [
    "WindowSolution",
    "WindowSolver",
    "NumpySolver",
    "CvxpySolver",
    "IpoptSolver",
    "make_solver",
    "BACKENDS",
    "QP_SOLVERS",
    "IPOPT_HESSIANS",
]

BACKENDS = ("numpy", "cvxpy", "ipopt")


def make_solver(backend: str = "numpy", qp_solver: str = "clarabel", **kwargs) -> WindowSolver:
    """A window solver by name: ``numpy``, ``cvxpy`` (``qp_solver`` clarabel|osqp) or ``ipopt``."""
    if backend == "numpy":
        return NumpySolver(**kwargs)
    if backend == "cvxpy":
        return CvxpySolver(solver=qp_solver, **kwargs)
    if backend == "ipopt":
        if kwargs.get("hessian") in ("newton", "gauss-newton"):
            kwargs.pop("hessian")
        return IpoptSolver(**kwargs)
    raise InputError(f"backend = {backend!r}: expected one of {', '.join(BACKENDS)}")
