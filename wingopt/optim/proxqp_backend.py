"""ProxQP (proxsuite, dense augmented-Lagrangian) on the condensed QP, warm-started from the last solve.

Measured on the morphing QP (condition number ~1e7) it reports success with answers that can be far
from the optimum at its default tolerances; :mod:`benchmarks.bench_latency` checks every backend's
objective and bounds against the others, and it is kept for that comparison, never chosen by default.
"""

from __future__ import annotations

import numpy as np

from wingopt.optim.qp import DenseForm, QPBackend
from wingopt.optim.status import SolveStatus, status_from

__all__ = ["ProxqpBackend"]


class ProxqpBackend(QPBackend):
    """``proxsuite.proxqp.dense.QP`` with box constraints for the simple bounds."""

    name = "proxqp"
    formulation = "condensed"
    default_tolerance = 1e-9

    def _build(self) -> None:
        from proxsuite import proxqp

        d = self._dense = DenseForm(self.qp)
        n, k = self.qp.n_variables, d.n_bounds
        self._box = k == n
        n_eq = 0 if d.Aeq is None else d.Aeq.shape[0]
        C = d.A if self._box else np.vstack([np.eye(n)[:k], d.A])
        self._C = C
        self._qp = proxqp.dense.QP(n, n_eq, C.shape[0], self._box)
        s = self._qp.settings
        s.eps_abs = self.tolerance
        s.eps_rel = 0.0
        # Few iterations suffice on a feasible QP (tens, warm); an infeasible one runs to the limit.
        s.max_iter = min(self.max_iterations, 1000)
        s.verbose = False
        zero = np.zeros(self.qp.n_parameters)
        self._qp.init(**self._data(zero, d.H, d.Aeq, C))
        # Warm start from the previous result only once there is one (proxsuite 0.8 crashes otherwise).
        self._qp.solve()
        s.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT

    def _data(self, p, H=None, A=None, C=None) -> dict:
        d = self._dense
        lo, hi = d.bounds(p)
        out = dict(H=H, g=d.q(p), A=A, b=None if d.Aeq is None else d.b(p), C=C)
        k = d.n_bounds
        if self._box:
            out.update(l=lo[k:], u=hi[k:], l_box=lo[:k], u_box=hi[:k])
        else:
            out.update(l=lo, u=hi)
        if out["l"].size == 0:  # proxsuite wants no argument, not empty arrays, for a missing block
            out.update(C=None, l=None, u=None)
        return {key: value for key, value in out.items() if value is not None}

    def _solve(self, p, warm):
        self._qp.update(**self._data(p))
        self._qp.solve()
        res = self._qp.results
        raw = str(res.info.status).split(".")[-1].lower().removeprefix("proxqp_")
        status = SolveStatus.OPTIMAL if raw == "solved" else status_from(self.name, raw)
        return np.asarray(res.x, dtype=float), raw, status, int(res.info.iter)
