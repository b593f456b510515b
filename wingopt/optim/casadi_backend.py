"""CasADi backends: ``conic`` with a QP plugin (qpOASES, OSQP, DAQP, ...) and ``nlpsol`` with IPOPT.

Also the pieces the MHE's IPOPT window solver shares with the QP backend: the scipy-to-CasADi
sparse conversion, the IPOPT options and the mapping of a CasADi solver's stats to a status.
"""

from __future__ import annotations

import contextlib
import os
import sys

import numpy as np
import scipy.sparse as sp

from wingopt.optim.qp import QPBackend
from wingopt.optim.status import SolveStatus, status_from

__all__ = ["CasadiQPBackend", "IpoptBackend", "casadi_sparse", "ipopt_options"]


def casadi_sparse(A: sp.spmatrix):
    """A scipy sparse matrix as a CasADi ``DM`` with the same sparsity."""
    import casadi as ca

    A = sp.csc_matrix(A)
    A.sort_indices()
    sparsity = ca.Sparsity(A.shape[0], A.shape[1], A.indptr.tolist(), A.indices.tolist())
    return ca.DM(sparsity, A.data.tolist())


def ipopt_options(tol: float, max_iter: int, print_level: int = 0, **extra) -> dict:
    """IPOPT options of every IPOPT solve of the package (quiet, adaptive barrier); ``extra`` adds
    or overrides IPOPT options by name."""
    opts = {"print_level": print_level, "sb": "yes", "tol": tol, "max_iter": max_iter, "mu_strategy": "adaptive"}
    opts.update(extra)
    return opts


@contextlib.contextmanager
def _quiet_stdout():
    """Silence C-level stdout: qpOASES prints its licence banner on construction, whatever its
    print level, which would corrupt ``--json`` output on stdout."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):  # pragma: no cover - captured streams without an fd
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
            yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


class _CasadiBase(QPBackend):
    """Common part: one stacked constraint matrix ``[A_eq; A_in]`` with per-row bounds."""

    def _stack(self):
        qp = self.qp
        blocks = [qp.A_eq, qp.A_in] if qp.A_eq is not None else [qp.A_in]
        return sp.vstack(blocks).tocsc()

    def _bounds(self, p):
        qp = self.qp
        if qp.A_eq is None:
            return qp.lower(p), qp.upper(p)
        b = qp.b(p)
        return np.concatenate([b, qp.lower(p)]), np.concatenate([b, qp.upper(p)])


class CasadiQPBackend(_CasadiBase):
    """CasADi ``conic`` with a QP plugin (``qpoases`` by default; ``osqp``, ``daqp``, ``proxqp``, ...)."""

    name = "casadi-qp"
    default_tolerance = 1e-8

    def __init__(self, qp, plugin: str | None = None, **kw) -> None:
        self.plugin = plugin or "qpoases"
        super().__init__(qp, **kw)

    @property
    def formulation(self) -> str:
        # Measured (docs/control_qp.md): the dense active-set plugins are fastest on the condensed form.
        return "condensed" if self.plugin in ("qpoases", "daqp") else "sparse"

    def _build(self) -> None:
        import casadi as ca

        self._H = casadi_sparse(sp.triu(self.qp.H) + sp.triu(self.qp.H, 1).T)
        self._A = casadi_sparse(self._stack())
        opts: dict = {"error_on_fail": False, "print_time": False}
        if self.plugin == "qpoases":
            opts.update(printLevel="none", nWSR=self.max_iterations, sparse=False, schur=False)
        elif self.plugin == "osqp":
            tol = max(self.tolerance, 1e-9)
            opts["osqp"] = {"verbose": False, "eps_abs": tol, "eps_rel": tol, "max_iter": self.max_iterations}
            opts["warm_start_primal"] = True
        with _quiet_stdout():
            self._conic = ca.conic("wingopt_qp", self.plugin, {"h": self._H.sparsity(), "a": self._A.sparsity()}, opts)

    def _solve(self, p, warm):
        lo, hi = self._bounds(p)
        args = dict(h=self._H, g=self.qp.q(p), a=self._A, lba=lo, uba=hi)
        if warm is not None:
            args["x0"] = warm
        out = self._conic(**args)
        stats = self._conic.stats()
        raw = str(stats.get("return_status", stats.get("success")))
        status = SolveStatus.OPTIMAL if stats.get("success", False) else status_from(self.name, raw)
        if status is SolveStatus.OPTIMAL and not stats.get("success", True):  # pragma: no cover - defensive
            status = SolveStatus.UNKNOWN
        iters = int(stats.get("iter_count", stats.get("n_iter", 0)) or 0)
        return np.asarray(out["x"], dtype=float).ravel(), f"{self.plugin}: {raw}", status, iters


class IpoptBackend(_CasadiBase):
    """CasADi ``nlpsol`` with IPOPT on the QP (constant Hessian and Jacobian declared to IPOPT)."""

    name = "ipopt"
    default_tolerance = 1e-10

    def _build(self) -> None:
        import casadi as ca

        qp = self.qp
        n = qp.n_variables
        x = ca.MX.sym("v", n)
        g = ca.MX.sym("q", n)  # the linear term is the NLP's parameter: p enters only through it
        H = casadi_sparse(qp.H)
        A = casadi_sparse(self._stack())
        nlp = {"x": x, "p": g, "f": 0.5 * ca.dot(x, ca.mtimes(H, x)) + ca.dot(g, x), "g": ca.mtimes(A, x)}
        ipopt = ipopt_options(
            max(self.tolerance, 1e-12),
            min(self.max_iterations, 3000),
            hessian_constant="yes",
            jac_c_constant="yes",
            jac_d_constant="yes",
        )
        opts = {"print_time": False, "error_on_fail": False, "ipopt": ipopt}
        self._nlp = ca.nlpsol("wingopt_qp_ipopt", "ipopt", nlp, opts)

    def _solve(self, p, warm):
        lo, hi = self._bounds(p)
        args = dict(p=self.qp.q(p), lbg=lo, ubg=hi)
        if warm is not None:
            args["x0"] = warm
        out = self._nlp(**args)
        stats = self._nlp.stats()
        raw = str(stats.get("return_status", "unknown"))
        iters = int(stats.get("iter_count", 0))
        return np.asarray(out["x"], dtype=float).ravel(), raw, status_from(self.name, raw), iters
