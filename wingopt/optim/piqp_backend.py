"""PIQP (proximal interior point): dense solver on the condensed QP, sparse solver on the sparse one.

Interior-point: robust on the ill-conditioned condensed Hessian, but every solve starts afresh
(no active-set warm start), so it is slower per step than DAQP on the morphing QP.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from wingopt.optim.qp import DenseForm, QPBackend
from wingopt.optim.status import SolveStatus, status_from

__all__ = ["PiqpBackend"]


class PiqpBackend(QPBackend):
    """PIQP built once (``setup``), then ``update`` of the linear term and bounds per step."""

    name = "piqp"
    formulation = "condensed"
    default_tolerance = 1e-9

    def _build(self) -> None:
        import piqp

        qp = self.qp
        zero = np.zeros(qp.n_parameters)
        self._sparse = qp.names.get("formulation") == "sparse"
        if self._sparse:
            self._solver = piqp.SparseSolver()
            self._q = qp.q
            H, A_in = sp.triu(qp.H, format="csc"), sp.csc_matrix(qp.A_in)
            Aeq = None if qp.A_eq is None else sp.csc_matrix(qp.A_eq)
            self._lu = lambda p: (qp.lower(p), qp.upper(p))
            self._b = qp.b if qp.A_eq is not None else None
        else:
            d = DenseForm(qp)
            self._solver = piqp.DenseSolver()
            self._q = d.q
            self._nb = d.n_bounds
            H, Aeq = np.asfortranarray(d.H), None if d.Aeq is None else np.asfortranarray(d.Aeq)
            A_in = np.asfortranarray(d.A)
            self._lu = d.bounds
            self._b = d.b if d.Aeq is not None else None
        s = self._solver.settings
        s.eps_abs = s.eps_rel = self.tolerance
        s.eps_duality_gap_abs = s.eps_duality_gap_rel = self.tolerance
        s.max_iter = min(self.max_iterations, 500)
        s.verbose = False
        lo, hi = self._lu(zero)
        b = None if self._b is None else self._b(zero)
        kw = dict(P=H, c=self._q(zero), A=Aeq, b=b)
        if self._sparse:
            kw.update(G=A_in, h_l=lo, h_u=hi)
        else:
            k = self._nb
            kw.update(G=A_in if A_in.shape[0] else None, x_l=self._pad(lo[:k]), x_u=self._pad(hi[:k], 1))
            if A_in.shape[0]:
                kw.update(h_l=lo[k:], h_u=hi[k:])
        self._solver.setup(**kw)

    def _pad(self, v, sign=-1):
        """Box bounds on all variables: the simple bounds, then +-inf for the rest."""
        out = np.full(self.qp.n_variables, sign * np.inf)
        out[: len(v)] = v
        return out

    def _solve(self, p, warm):
        lo, hi = self._lu(p)
        kw = dict(c=self._q(p))
        if self._b is not None:
            kw["b"] = self._b(p)
        if self._sparse:
            kw.update(h_l=lo, h_u=hi)
        else:
            k = self._nb
            kw.update(x_l=self._pad(lo[:k]), x_u=self._pad(hi[:k], 1))
            if len(lo) > k:
                kw.update(h_l=lo[k:], h_u=hi[k:])
        self._solver.update(**kw)
        st = self._solver.solve()
        res = self._solver.result
        raw = st.name.lower().removeprefix("piqp_")
        status = SolveStatus.OPTIMAL if raw == "solved" else status_from(self.name, raw)
        return np.asarray(res.x, dtype=float), raw, status, int(res.info.iter)
