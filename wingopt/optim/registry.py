"""One vocabulary of QP backend names: which class, which package, which is the default.

``make_backend(name, qp)`` builds any of :data:`BACKENDS`; :func:`available_backends` lists those
whose package is installed (DAQP, PIQP and ProxQP are the optional extra ``fast``, except DAQP,
which is a dependency). The default is the fastest backend measured on the morphing QP
(``benchmarks/bench_latency.py``, table in ``docs/control_qp.md``), falling back to Clarabel
when it is not installed.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass
from typing import TYPE_CHECKING

from wingopt.errors import InputError

if TYPE_CHECKING:  # type hints only: the backends import the status, which names the registry
    from wingopt.optim.qp import ParametricQP, QPBackend

__all__ = ["BACKENDS", "BackendInfo", "REGISTRY", "available_backends", "default_backend", "make_backend"]


@dataclass(frozen=True)
class BackendInfo:
    """Where a backend lives: ``module:class`` in :mod:`wingopt.optim`, the package it needs, a line."""

    target: str
    package: str
    description: str


REGISTRY = {
    "daqp": BackendInfo("daqp_backend:DaqpBackend", "daqp", "DAQP dual active set, dense (condensed form)"),
    "clarabel": BackendInfo("cvxpy_backend:ClarabelBackend", "clarabel", "Clarabel interior point via CVXPY"),
    "osqp": BackendInfo("cvxpy_backend:OsqpBackend", "osqp", "OSQP ADMM (polished) via CVXPY"),
    "piqp": BackendInfo("piqp_backend:PiqpBackend", "piqp", "PIQP proximal interior point, dense or sparse"),
    "proxqp": BackendInfo("proxqp_backend:ProxqpBackend", "proxsuite", "ProxQP dense augmented Lagrangian"),
    "ipopt": BackendInfo("casadi_backend:IpoptBackend", "casadi", "IPOPT via CasADi nlpsol"),
    "casadi-qp": BackendInfo("casadi_backend:CasadiQPBackend", "casadi", "CasADi conic plugin (qpoases, ...)"),
}
"""Every QP backend name of the package (``--solver``), fastest-measured first."""

BACKENDS = tuple(REGISTRY)
"""Names accepted by :func:`make_backend`."""

FALLBACK = "clarabel"


def _installed(name: str) -> bool:
    return importlib.util.find_spec(REGISTRY[name].package) is not None


def available_backends() -> tuple[str, ...]:
    """The backends whose package is installed, in the order of :data:`BACKENDS`."""
    return tuple(name for name in BACKENDS if _installed(name))


def default_backend() -> str:
    """``daqp`` when installed (fastest measured), else ``clarabel``."""
    return "daqp" if _installed("daqp") else FALLBACK


def backend_class(name: str) -> type[QPBackend]:
    """The :class:`QPBackend` subclass of ``name``; an :class:`InputError` names a bad or missing one."""
    name = str(name).lower()
    if name not in REGISTRY:
        raise InputError(f"solver = {name!r}: expected one of {', '.join(BACKENDS)}")
    info = REGISTRY[name]
    if not _installed(name):
        raise InputError(
            f"solver = {name!r}: its package {info.package!r} is not installed "
            f"(pip install '{info.package}', or wingopt[fast]); installed: {', '.join(available_backends())}"
        )
    module, cls = info.target.split(":")
    return getattr(importlib.import_module(f"wingopt.optim.{module}"), cls)


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
