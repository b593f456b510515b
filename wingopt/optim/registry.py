"""The one vocabulary of solver names: what each solver is, the package it needs, what it serves.

Every solver name of the package is one entry of :data:`SOLVERS`. A consumer accepts the names
with its capability (:data:`CAPABILITIES`), listed by :func:`solver_names` and checked by
:func:`check_solver`, whose error lists the accepted names:

* ``qp``: the parametric QP backends (:class:`~wingopt.optim.qp.QPBackend`) of the morphing QP
  and the static optimum, built by :func:`make_backend`;
* ``least-distance``: the QPs of the MHE's whitened Levenberg–Marquardt steps
  (:class:`~wingopt.optim.least_distance.LeastDistanceQP`);
* ``window``: the MHE's window solvers (Levenberg–Marquardt with unconstrained or QP steps, IPOPT);
* ``sdp``: the semidefinite relaxation of the sensor design (solved through CVXPY).

:func:`available_backends` lists those whose package is installed (DAQP is a dependency; PIQP and
ProxQP are the optional extra ``fast``). The order of :data:`SOLVERS` is the order of every list:
the QP backends fastest measured on the morphing QP first (``benchmarks/bench_latency.py``, table
in ``docs/control_qp.md``); :func:`default_backend` is the fastest installed, falling back to
Clarabel. Command-line flags are the CLI's business: this module names solvers only.

The backend classes are imported here as they are; each backend module imports its solver package
inside the functions that use it, so that a missing optional package (PIQP, ProxQP) fails only when
that backend is chosen, and CVXPY and CasADi (slow to import) are not loaded at start-up.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass

from wingopt.errors import InputError
from wingopt.optim.casadi_backend import CasadiQPBackend, IpoptBackend
from wingopt.optim.cvxpy_backend import ClarabelBackend, OsqpBackend
from wingopt.optim.daqp_backend import DaqpBackend
from wingopt.optim.piqp_backend import PiqpBackend
from wingopt.optim.proxqp_backend import ProxqpBackend
from wingopt.optim.qp import ParametricQP, QPBackend

__all__ = [
    "BACKENDS",
    "CAPABILITIES",
    "FALLBACK",
    "SOLVERS",
    "SolverInfo",
    "available_backends",
    "backend_class",
    "check_solver",
    "default_backend",
    "make_backend",
    "preferred_formulation",
    "solver_names",
]

CAPABILITIES = {
    "qp": "parametric QP backend (morphing QP, static optimum)",
    "least-distance": "QP of a Levenberg–Marquardt step (MHE window solver cvxpy)",
    "window": "MHE window solver",
    "sdp": "semidefinite relaxation (sensor design, through CVXPY)",
}
"""What a consumer of solver names needs, by capability."""


@dataclass(frozen=True)
class SolverInfo:
    """One solver: the package it needs, the capabilities it serves, a line; its QP backend class."""

    package: str
    capabilities: tuple[str, ...]
    description: str
    backend: type[QPBackend] | None = None


SOLVERS = {
    "daqp": SolverInfo("daqp", ("qp", "least-distance"), "DAQP dual active set, dense", DaqpBackend),
    "clarabel": SolverInfo(
        "clarabel", ("qp", "least-distance", "sdp"), "Clarabel interior point via CVXPY", ClarabelBackend
    ),
    "osqp": SolverInfo("osqp", ("qp", "least-distance"), "OSQP ADMM (polished) via CVXPY", OsqpBackend),
    "piqp": SolverInfo("piqp", ("qp",), "PIQP proximal interior point, dense or sparse", PiqpBackend),
    "proxqp": SolverInfo("proxsuite", ("qp",), "ProxQP dense augmented Lagrangian", ProxqpBackend),
    "numpy": SolverInfo("numpy", ("window",), "Levenberg–Marquardt, unconstrained steps (no bounds)"),
    "cvxpy": SolverInfo("cvxpy", ("window",), "Levenberg–Marquardt, least-distance QP steps (bounds)"),
    "ipopt": SolverInfo("casadi", ("qp", "window"), "IPOPT via CasADi nlpsol", IpoptBackend),
    "casadi-qp": SolverInfo("casadi", ("qp",), "CasADi conic plugin (qpoases, ...)", CasadiQPBackend),
    "scs": SolverInfo("scs", ("sdp",), "SCS splitting conic solver via CVXPY"),
}
"""Every solver name of the package; the QP backends fastest measured first."""


def solver_names(capability: str) -> tuple[str, ...]:
    """The names of the solvers with ``capability`` (a key of :data:`CAPABILITIES`), in the order of
    :data:`SOLVERS`."""
    if capability not in CAPABILITIES:
        raise ValueError(f"capability = {capability!r}: expected one of {', '.join(CAPABILITIES)}")
    return tuple(name for name, info in SOLVERS.items() if capability in info.capabilities)


BACKENDS = solver_names("qp")
"""The QP backend names accepted by :func:`make_backend`."""

FALLBACK = "clarabel"
"""The QP backend used when the fastest is not installed, and for one large sparse QP."""


def check_solver(name: str, capability: str, field: str = "solver") -> str:
    """``name`` in lower case if it has ``capability``; else an :class:`InputError` naming ``field``,
    the value and every accepted name."""
    accepted = solver_names(capability)
    key = str(name).lower()
    if key not in accepted:
        raise InputError(f"{field} = {name!r}: expected one of {', '.join(accepted)}")
    return key


def _installed(name: str) -> bool:
    return importlib.util.find_spec(SOLVERS[name].package) is not None


def available_backends(capability: str = "qp") -> tuple[str, ...]:
    """The solvers with ``capability`` whose package is installed, in the order of :data:`SOLVERS`."""
    return tuple(name for name in solver_names(capability) if _installed(name))


def default_backend() -> str:
    """``daqp`` when installed (fastest measured), else :data:`FALLBACK`."""
    return "daqp" if _installed("daqp") else FALLBACK


def backend_class(name: str) -> type[QPBackend]:
    """The :class:`QPBackend` subclass of ``name``; an :class:`InputError` names a bad or missing one."""
    name = check_solver(name, "qp")
    info = SOLVERS[name]
    if not _installed(name):
        raise InputError(
            f"solver = {name!r}: its package {info.package!r} is not installed "
            f"(pip install '{info.package}', or wingopt[fast]); installed: {', '.join(available_backends())}"
        )
    return info.backend


def preferred_formulation(name: str, plugin: str | None = None) -> str:
    """The form of the morphing QP ``name`` is fastest on (``"condensed"`` or ``"sparse"``)."""
    if str(name).lower() == "casadi-qp":
        return "condensed" if (plugin or "qpoases") in ("qpoases", "daqp") else "sparse"
    return backend_class(name).formulation


def make_backend(
    name: str, qp: ParametricQP, *, tolerance: float | None = None, plugin: str | None = None
) -> QPBackend:
    """Build the backend ``name`` (one of :data:`BACKENDS`) for ``qp``.

    ``tolerance`` defaults to the backend's own (1e-8 interior point, 1e-7 OSQP polished, 1e-10
    IPOPT, 1e-9 DAQP/PIQP/ProxQP); ``plugin`` picks the CasADi QP plugin for ``casadi-qp``
    (default ``qpoases``).
    """
    cls = backend_class(name)
    tol = tolerance or None
    if str(name).lower() == "casadi-qp":
        return cls(qp, plugin=plugin, tolerance=tol)
    return cls(qp, tolerance=tol)
