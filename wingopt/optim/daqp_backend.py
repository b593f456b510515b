"""DAQP: a dual active-set solver for small dense QPs, made for MPC (the default QP backend).

The condensed morphing QP (``N m`` unknowns, a dense Hessian) is DAQP's case: it factors ``H``
once at setup and keeps its workspace and the *active set* of the previous solve in a
``daqp.Model``, so a re-solve that changes only the linear term and the bounds starts from the
last step's active set and typically needs a handful of iterations (tens of microseconds on the
13x61 plate). The leading identity rows of ``A_in`` (the voltage limits) are passed as DAQP's
simple bounds, the equality rows (terminal constraint) with DAQP's equality sense.
"""

from __future__ import annotations

import numpy as np

from wingopt.optim.qp import DenseForm, QPBackend
from wingopt.optim.status import SolveStatus, status_from

__all__ = ["DaqpBackend", "DAQP_EXITFLAGS"]

DAQP_EXITFLAGS = {
    1: "solved",
    2: "solved with soft constraints violated",
    -1: "infeasible",
    -2: "cycling",
    -3: "unbounded",
    -4: "max iterations reached",
    -5: "nonconvex problem",
    -6: "overdetermined initial active set",
}
"""DAQP's exit flags (its documentation) as status words for :func:`~wingopt.optim.status.status_from`."""

_EQUALITY = 5  # DAQP's "sense" flag of an equality row


class DaqpBackend(QPBackend):
    """DAQP (``daqp.Model``) on the dense data of the QP, active set kept between solves."""

    name = "daqp"
    formulation = "condensed"
    default_tolerance = 1e-9

    def _build(self) -> None:
        import daqp

        d = self._dense = DenseForm(self.qp)
        self._neq = 0 if d.Aeq is None else d.Aeq.shape[0]
        A = d.A if d.Aeq is None else np.vstack([d.A, d.Aeq])
        self._sense = np.zeros(d.n_bounds + A.shape[0], dtype=np.intc)
        self._sense[len(self._sense) - self._neq :] = _EQUALITY
        self._A = np.ascontiguousarray(A)
        zero = np.zeros(self.qp.n_parameters)
        lo, hi = self._bounds(zero)
        # The model keeps pointers into these arrays (no copy): they live as long as the backend and
        # are updated in place.
        self._f, self._hi, self._lo = d.q(zero), hi, lo
        self._model = daqp.Model()
        # primal_tol is in the QP's (scaled) units; the dual tolerance stays DAQP's default.
        self._model.settings = {"primal_tol": self.tolerance, "iter_limit": self.max_iterations}
        self._setup()

    def _setup(self) -> int:
        """(Re)build the workspace on the current data; a negative flag (e.g. bounds that cross at
        the build's ``p = 0``) leaves it to be set up again by the next solve."""
        d = self._dense
        flag, _ = self._model.setup(d.H, self._f, self._A, self._hi, self._lo, self._sense)
        self._ready = flag >= 0
        return int(flag)

    def _bounds(self, p):
        d = self._dense
        lo, hi = d.bounds(p)
        if self._neq:
            b = d.b(p)
            lo, hi = np.concatenate([lo, b]), np.concatenate([hi, b])
        return lo, hi

    def _solve(self, p, warm):
        lo, hi = self._bounds(p)
        self._f[:], self._hi[:], self._lo[:] = self._dense.q(p), hi, lo
        if not self._ready:
            flag = self._setup()
            if flag < 0:
                raw = DAQP_EXITFLAGS.get(flag, f"exit flag {flag}")
                return None, raw, status_from(self.name, raw), 0
        else:
            # Leaving `sense` out keeps the active set of the previous solve: the warm start DAQP is built for.
            self._model.update(f=self._f, bupper=self._hi, blower=self._lo)
        x, _, flag, info = self._model.solve()
        raw = DAQP_EXITFLAGS.get(int(flag), f"exit flag {flag}")
        status = SolveStatus.OPTIMAL if flag == 1 else status_from(self.name, raw)
        return np.asarray(x, dtype=float), raw, status, int(info.get("iterations", 0))
