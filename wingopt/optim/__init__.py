"""One optimisation layer for the engines: the parametric QP, its backends, status and failure path.

* :mod:`~wingopt.optim.status`: :class:`SolveStatus`, the mapping of every backend's raw status,
  the hints, and the :class:`~wingopt.errors.SolverError` of a failure;
* :mod:`~wingopt.optim.qp`: :class:`ParametricQP` (built once, re-solved per parameter),
  :class:`QPSolution`, the :class:`QPBackend` interface;
* :mod:`~wingopt.optim.registry`: the one vocabulary of solver names (QP backends, least-distance
  and MHE window solvers, SDP), each consumer's subset by capability (:func:`solver_names`,
  :func:`check_solver`), :func:`make_backend`, the default;
* one module per backend family: ``daqp_backend``, ``cvxpy_backend`` (Clarabel, OSQP),
  ``piqp_backend``, ``proxqp_backend``, ``casadi_backend`` (CasADi conic plugins, IPOPT);
* :mod:`~wingopt.optim.least_distance`: the MHE's whitened Gauss–Newton step QPs.

Used by :mod:`wingopt.control` (morphing QP, static optimum) and :mod:`wingopt.estimation` (MHE
window solvers); imports neither.
"""

from wingopt.optim.qp import ParametricQP, QPBackend, QPSolution
from wingopt.optim.registry import (
    BACKENDS,
    available_backends,
    check_solver,
    default_backend,
    make_backend,
    solver_names,
)
from wingopt.optim.status import SolveStatus, fail, require_success, status_from

__all__ = [
    "BACKENDS",
    "ParametricQP",
    "QPBackend",
    "QPSolution",
    "SolveStatus",
    "available_backends",
    "check_solver",
    "default_backend",
    "fail",
    "make_backend",
    "require_success",
    "solver_names",
    "status_from",
]
