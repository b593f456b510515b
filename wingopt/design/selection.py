"""Choosing K of N candidates: convex relaxation (bound), rounding, swaps and greedy selection.

* :func:`relax` — the relaxation of Joshi & Boyd (IEEE TSP 2009): weights ``w in [0, 1]``,
  ``sum w = K``, minimise the linear criterion of ``I + sum w_i F~_i`` (A and lift:
  ``matrix_frac``, D: ``-log_det``), an SDP solved with CVXPY (Clarabel, SCS as fallback). Its
  optimum bounds the criterion of *every* K-subset from below (a K-subset is a feasible ``w``).
* :func:`round_weights` — the K largest weights (skipping overlapping rectangles).
* :func:`swap_improve` — exchange one chosen candidate for an unchosen one while the criterion
  improves; every accepted swap lowers it (monotone), so it stops at a 1-swap local optimum.
* :func:`greedy` — add the best candidate one at a time (the baseline).

Criteria are objects with ``info`` ``(N, ...)`` (summed over a layout) and a batched
``values(sums, sensors)`` (lower is better): :class:`~wingopt.design.criteria.LinearCriterion`
and :class:`~wingopt.design.risk.BayesRisk`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.optim.registry import check_solver, solver_names

__all__ = ["Relaxation", "relax", "round_weights", "swap_improve", "greedy", "overlap_matrix", "random_layouts"]

log = logging.getLogger(__name__)


def overlap_matrix(rects: np.ndarray) -> np.ndarray:
    """``(N, N)`` bool: rectangles ``i`` and ``j`` overlap with positive area (diagonal True)."""
    r = np.asarray(rects, dtype=float)
    return (
        (r[:, None, 0] < r[None, :, 1])
        & (r[:, None, 1] > r[None, :, 0])
        & (r[:, None, 2] < r[None, :, 3])
        & (r[:, None, 3] > r[None, :, 2])
    )


def random_layouts(
    rects: np.ndarray, K: int, count: int, rng: np.random.Generator, pool: np.ndarray | None = None
) -> list[np.ndarray]:
    """``count`` random non-overlapping ``K``-subsets of the candidates (``pool``: allowed indices).

    Each layout takes candidates in a random order, keeping one when it overlaps none kept so far;
    draws that cannot reach ``K`` are discarded. The baseline of the design validations.
    """
    ov = overlap_matrix(rects)
    pool = np.arange(len(rects)) if pool is None else pool
    out = []
    while len(out) < count:
        chosen: list[int] = []
        for i in rng.permutation(pool):
            if not chosen or not ov[i, chosen].any():
                chosen.append(int(i))
                if len(chosen) == K:
                    break
        if len(chosen) == K:
            out.append(np.array(chosen))
    return out


@dataclass(frozen=True)
class Relaxation:
    """Relaxed weights, the optimal value (a lower bound of every K-subset's reduced criterion),
    the solver used and its status."""

    weights: np.ndarray
    bound: float
    solver: str
    status: str
    rank: int
    dropped: float


def relax(criterion, count: int, rank: int = 12, solver: str | None = None, reduced=None) -> Relaxation:
    """Solve the convex relaxation of a :class:`~wingopt.design.criteria.LinearCriterion`.

    The problem is cut to ``rank`` leading whitened directions per nominal response
    (:meth:`~wingopt.design.criteria.LinearCriterion.reduced`); the bound is for that reduced
    criterion (``dropped`` says how much information the cut ignores). ``reduced``: that reduction,
    when already computed (``criterion.reduced(rank)``).
    """
    import cvxpy as cp

    N = criterion.count
    if not 1 <= count <= N:
        raise InputError(f"count = {count!r}: expected 1..{N} (the number of candidates)")
    info_r, weight_r, const_r, dropped = criterion.reduced(rank) if reduced is None else reduced
    r = info_r.shape[-1]
    J = info_r.shape[1]
    w = cp.Variable(N)
    terms = []
    for j in range(J):
        # Scale: tr(X^T Y^-1 X) is unchanged by (Y, X) -> (Y / s, X / sqrt(s)); s = the information
        # of K average candidates keeps the SDP's entries O(1) (whitened information reaches 1e8).
        s = max(1.0, count * float(np.trace(info_r[:, j].mean(axis=0))) / r)
        Fm = (info_r[:, j] / s).reshape(N, r * r).T  # column i = F_i / s (symmetric: order irrelevant)
        Y = np.eye(r) / s + cp.reshape(Fm @ w, (r, r), order="F")
        Y = 0.5 * (Y + Y.T)
        if criterion.kind == "d":
            terms.append(-cp.log_det(Y) - r * np.log(s))
        else:
            ev = np.diag(weight_r[j])
            keep = ev > 1e-12 * max(ev.max(), 1e-300)
            Xh = np.eye(r)[:, keep] * np.sqrt(ev[keep] / s)
            terms.append((const_r[j] + cp.matrix_frac(Xh, Y)) / criterion.scale[j])
    agg = cp.sum(cp.hstack(terms)) / J if criterion.aggregate == "mean" else cp.max(cp.hstack(terms))
    prob = cp.Problem(cp.Minimize(agg), [w >= 0, w <= 1, cp.sum(w) == count])
    tried = [check_solver(solver, "sdp").upper()] if solver else [n.upper() for n in solver_names("sdp")]
    last = None
    for name in tried:
        try:
            prob.solve(solver=name)
        except (cp.error.SolverError, Exception) as exc:  # noqa: BLE001 - try the next solver
            last = f"{name}: {exc}"
            log.info("relaxation with %s failed: %s", name, exc)
            continue
        if prob.status in ("optimal", "optimal_inaccurate") and w.value is not None:
            val = float(prob.value)
            bound = val if criterion.kind == "d" else float(np.sqrt(max(val, 0.0)))
            return Relaxation(np.clip(w.value, 0, 1), bound, name, prob.status, r, dropped)
        last = f"{name}: status {prob.status}"
    raise SolverError(
        "sensor-design relaxation", f"no solver succeeded ({last})", "try fewer candidates or the greedy selection"
    )


def round_weights(weights: np.ndarray, count: int, overlap: np.ndarray | None = None) -> np.ndarray:
    """The ``count`` largest weights, skipping candidates that overlap one already taken."""
    order = np.argsort(-weights, kind="stable")
    chosen: list[int] = []
    for i in order:
        if overlap is not None and chosen and overlap[i, chosen].any():
            continue
        chosen.append(int(i))
        if len(chosen) == count:
            break
    if len(chosen) < count:
        raise InputError(f"count = {count}: only {len(chosen)} non-overlapping candidates")
    return np.array(chosen)


def _evaluate(criterion, base, cand: np.ndarray, sensors: int, chunk: int = 32, tick=None) -> np.ndarray:
    """Criterion values of ``base`` plus each candidate ``cand``, ``chunk`` at a time (a chunk's
    dense sums are ``chunk J 2 d^2`` numbers: 25 MB at 32 on the default membrane);
    ``tick(fraction)`` after each chunk."""
    out = np.empty(cand.size)
    for a in range(0, cand.size, chunk):
        idx = cand[a : a + chunk]
        sums = base[None] + criterion.info[idx] if base is not None else criterion.info[idx]
        out[a : a + chunk] = criterion.values(sums, sensors)
        if tick is not None:
            tick(min(a + chunk, cand.size) / cand.size)
    return out


def _allowed(N: int, others: list[int], overlap: np.ndarray | None) -> np.ndarray:
    ok = np.ones(N, dtype=bool)
    if others:
        ok[others] = False
        if overlap is not None:
            ok &= ~overlap[others].any(axis=0)
    return np.flatnonzero(ok)


def greedy(criterion, count: int, overlap: np.ndarray | None = None, tick=None) -> tuple[np.ndarray, list[float]]:
    """Add the candidate that lowers the criterion most, ``count`` times; returns layout and path.

    ``tick(fraction)``: called as the work goes (the fraction of it done)."""
    N = criterion.count
    if not 1 <= count <= N:
        raise InputError(f"count = {count!r}: expected 1..{N} (the number of candidates)")
    chosen: list[int] = []
    path = []
    base = None
    for k in range(count):
        cand = _allowed(N, chosen, overlap)
        if cand.size == 0:
            raise InputError(f"count = {count}: only {k} non-overlapping candidates")
        step = None if tick is None else (lambda f, k=k: tick((k + f) / count))
        vals = _evaluate(criterion, base, cand, k + 1, tick=step)
        i = int(cand[np.argmin(vals)])
        chosen.append(i)
        path.append(float(vals.min()))
        base = criterion.info[i] if base is None else base + criterion.info[i]
    return np.array(chosen), path


def swap_improve(
    criterion, layout, overlap: np.ndarray | None = None, max_passes: int = 20, rtol: float = 1e-9, tick=None
) -> tuple[np.ndarray, list[float]]:
    """Best-improvement 1-swaps until none helps; returns the layout and the (decreasing) values.

    ``tick(passes)``: called as the work goes, with the passes done so far (a float)."""
    layout = [int(i) for i in layout]
    K = len(layout)
    total = criterion.info[layout].sum(axis=0)
    current = float(criterion.values(total[None], K)[0])
    path = [current]
    for npass in range(max_passes):
        improved = False
        for k in range(K):
            others = layout[:k] + layout[k + 1 :]
            base = total - criterion.info[layout[k]]
            cand = _allowed(criterion.count, others + [layout[k]], overlap)
            if overlap is not None:
                # the swapped-out candidate's own overlaps are free again
                cand = np.union1d(cand, _allowed(criterion.count, others, overlap))
                cand = cand[cand != layout[k]]
            if cand.size == 0:
                continue
            step = None if tick is None else (lambda f, k=k, p=npass: tick(p + (k + f) / K))
            vals = _evaluate(criterion, base, cand, K, tick=step)
            j = int(np.argmin(vals))
            if vals[j] < current - rtol * abs(current):
                layout[k] = int(cand[j])
                total = base + criterion.info[layout[k]]
                current = float(vals[j])
                path.append(current)
                improved = True
        if not improved:
            break
    return np.array(layout), path
