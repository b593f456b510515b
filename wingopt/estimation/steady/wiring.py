"""Wiring checks: a sensor's gain set wrong, an offset forgotten, two sensors swapped.

A wiring mistake does not make a fit fail: four stretch sensors under a flexible load prior can be
matched by some load whatever their readings (measured on the tunnel stand-in: sensor S2 at 0.1x
its gain was fitted at chi-square 0.08 per sensor, lift -0.15 N for 1.76 N; S1 and S2 swapped,
chi-square 0.5, 1.55 N). What exposes it is a prior that *predicts* the sensors from one another:
the thin-airfoil shapes of :meth:`~.realistic.load_model.LoadShapes.aerodynamic` (three amplitudes
that four sensors over-determine, with the prestrains' prior). Under it each mistake is a
hypothesis whose correction makes the readings consistent again:

* **one sensor off** (a gain or an offset): the sensor left out, the other three fitted, and the
  left-out sensor predicted; the chi-square the left-out sensor alone carried is the evidence;
* **a swapped pair**: the pair's means exchanged and refitted.

The hypothesis that lowers the cost most is reported when it lowers it by at least
:data:`EVIDENCE` (a chi-square: ~5 sigma) and leaves a consistent fit (at most :data:`CONSISTENT` per
datum); a sensor left out pays :data:`OCCAM` for its free level. Hypotheses within :data:`TIE` of the
best are told apart by the buffeting: below the first mode every sensor follows the load factor in
proportion to its slope ``d s_i / d load`` (:func:`fluctuation_slopes`, the leading eigenvector of
the low-frequency cross-spectrum), which a gain scales with the mean, an offset leaves as predicted,
and a swap exchanges. Without buffeting (a transient record's settled half) the equally consistent
hypotheses are all named. The checks run on a steady record's mean (:func:`check_steady`) and on a
transient record's late mean, the static state it settles to (:func:`check_transient`), and never
change an answer: :func:`attach` adds ``info["wiring"]`` and a warning naming the sensors and the
likely mistake.

The checks rest on the load being a thin-airfoil one: four means cannot tell a wiring mistake from
a load those shapes cannot make, and every finding says so (:data:`OR_THE_LOAD`; what they tell
on loads outside those shapes: ``docs/tunnel.md``, ``benchmarks/wiring_reach.py``). A mistake on
a sensor the others cannot predict (two sensors placed symmetrically and swapped) is not seen.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging

import numpy as np

from wingopt.errors import InputError, SolverError
from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.record_fit import levenberg_marquardt
from wingopt.estimation.core.record_problem import ParameterPrior
from wingopt.estimation.declaration import with_declaration
from wingopt.estimation.steady.problem import SteadyData, SteadyProblem, starts, steady_data
from wingopt.estimation.steady.wiring_report import Finding, WiringReport, skipped
from wingopt.membrane.model import MembraneModel

__all__ = ["Finding", "WiringReport", "check_steady", "check_transient", "attach", "fluctuation_slopes", "EVIDENCE"]

log = logging.getLogger(__name__)

EVIDENCE = 25.0
"""Chi-square a hypothesis must remove from the all-sensor fit to be reported (~5 sigma)."""

CONSISTENT = 4.0
"""Largest chi-square per remaining datum of a corrected fit (as the steady fit's adequacy)."""

GAIN_OFF = 3.0
"""A mean this many times (or this fraction of) its prediction is read as a gain, whatever the
fluctuation says (an offset rarely scales a reading by 3x)."""

MATERIAL = 1.5
"""A sensor's mean within this factor of its prediction is not reported as a wiring mistake: the
load prior's own misfit reaches that far (a mistake this small is not told from a load it cannot
make)."""

TOL = 0.2
"""The hypotheses' fits stop when a step would lower the chi-square by less than this: they are
compared at :data:`EVIDENCE`, not to the last digit."""

OR_THE_LOAD = (
    " Or a load the thin-airfoil shapes cannot make: the means cannot tell the two apart (a clean record"
    " under a leading-edge load or an off-centre bump reads this way; docs/tunnel.md, the wiring checks)."
)
"""Said with every finding: what else makes the means inconsistent with the shapes (module docstring)."""

_FAILURES = (InputError, SolverError, ArithmeticError, np.linalg.LinAlgError)


def _fit(sp_: SteadyProblem, th0: list[np.ndarray], max_iter: int, sign: float | None = None):
    """The best Levenberg-Marquardt fit from ``th0``; with ``sign``, also from the lobe starts when
    those do not reach a consistent fit (the other lobe pattern)."""
    best = None
    for th in th0:
        try:
            f = levenberg_marquardt(sp_, th, max_iter, tol=TOL)
        except _FAILURES as exc:
            log.debug("wiring fit start failed: %s", exc)
            continue
        if np.isfinite(f.cost) and (best is None or f.cost < best.cost):
            best = f
    p = sp_.data.mean.size
    if sign is not None and (best is None or best.data_cost > CONSISTENT * p):
        alt = _fit(sp_, starts(sp_, sign), max_iter)
        if alt is not None and (best is None or alt.cost < best.cost):
            best = alt
    return best


def _problem(base: SteadyProblem, data: SteadyData) -> SteadyProblem:
    sp_ = SteadyProblem(base.model, base.shapes, data, base.prior)
    sp_.defect = base.defect.copy()
    for shared in ("modal", "fvk", "forces"):  # the same model and shapes: built once
        sp_.__dict__[shared] = getattr(base, shared)
    return sp_


TIE = 25.0
"""Hypotheses whose costs lie within this of the best are told apart by the fluctuation (a swap
and an offset can make equally consistent means)."""

LOW_HZ = (1.0, 25.0)
"""The band of the fluctuation's quasi-static part (below the membrane's first mode, ~100 Hz): there
every sensor follows the load factor in proportion to its slope ``d s_i / d load``."""


def fluctuation_slopes(t: np.ndarray, values: np.ndarray) -> np.ndarray | None:
    """Each column's response to the common load factor, up to one scale: the leading eigenvector of
    the fluctuation's cross-spectral matrix summed over :data:`LOW_HZ` (``None``: no such band)."""
    y = np.asarray(values, dtype=float)
    ok = np.all(np.isfinite(y), axis=1)
    if ok.sum() < 64:
        return None
    x = np.where(ok[:, None], y - np.nanmean(y[ok], axis=0), 0.0)
    dt = float(np.median(np.diff(t)))
    f = np.fft.rfftfreq(y.shape[0], dt)
    X = np.fft.rfft(x, axis=0)[(f >= LOW_HZ[0]) & (f <= LOW_HZ[1])]
    if X.shape[0] < 4:
        return None
    C = np.real(X.T @ X.conj())
    w, V = np.linalg.eigh(C)
    if w[-1] <= 4 * max(w[-2], 0.0):  # no dominant common factor
        return None
    v = V[:, -1]
    return v * np.sign(v.sum())


def _mismatch(k_meas: np.ndarray, k_pred: np.ndarray) -> float:
    """Scale-free mismatch of two slope vectors: the spread of their log ratios (inf on a sign change)."""
    r = k_meas / k_pred
    if np.any(r <= 0) or not np.all(np.isfinite(r)):
        return float("inf")
    lr = np.log(r)
    return float(np.sqrt(np.mean((lr - lr.mean()) ** 2)))


def _slopes(sp_: SteadyProblem, theta: np.ndarray) -> np.ndarray:
    """``d s_i / d (load factor)`` of the physical sensors at ``theta`` (a 1 % step of the load)."""
    th = theta.copy()
    th[: sp_.shapes.count] *= 1.01
    return (sp_.outputs(th) - sp_.outputs(theta)) / 0.01


OCCAM = 6.0
"""Chi-square charged to the one-sensor-off hypothesis for its free parameter (the sensor's level):
without it a sensor left out always fits better than a swap, whose correction has none (measured: S3
and S4 swapped on the stand-in, the swap at 3.4 against S4 left out at 1.9)."""


def _wired(base: SteadyProblem, data: SteadyData, sign: float, max_iter: int):
    """The all-sensor fit as wired, corrected once to the full order: ``(fit, problem)``."""
    sp0 = _problem(base, data)
    fit0 = _fit(sp0, starts(sp0, sign), max_iter)
    if fit0 is None:
        return None, sp0
    try:  # one full-order correction, kept for every hypothesis (they differ by far more than it)
        sp0._z = None
        sp0.defect = sp0.outputs(fit0.theta, full=True) - sp0.outputs(fit0.theta)
        fit0 = _fit(sp0, [fit0.theta], max_iter) or fit0
    except _FAILURES as exc:
        log.debug("wiring: full-order correction failed: %s", exc)
    return fit0, sp0


def _hypotheses(sp0: SteadyProblem, fit0, data: SteadyData, sign: float, max_iter: int):
    """Every hypothesis's fit: ``[(kind, idx, fit, problem, cost)]``, ``cost`` the hypothesis's cost
    with :data:`OCCAM` on a sensor left out."""
    p = data.mean.size
    hyps = []
    for i in range(p):
        se = data.std_error.copy()
        se[i] = 1e6 * max(abs(data.mean[i]), 1e-30)
        sp_ = _problem(sp0, dataclasses.replace(data, std_error=se))
        f = _fit(sp_, [fit0.theta], max_iter, sign)
        if f is not None:
            hyps.append(("one", (i,), f, sp_, f.cost + OCCAM))
    for i, j in itertools.combinations(range(p), 2):
        perm = np.arange(p)
        perm[[i, j]] = perm[[j, i]]
        sp_ = _problem(sp0, dataclasses.replace(data, mean=data.mean[perm], std_error=data.std_error[perm]))
        f = _fit(sp_, [fit0.theta], max_iter, sign)
        if f is not None:
            hyps.append(("swap", (i, j), f, sp_, f.cost))
    for h in hyps:
        log.debug("wiring hypothesis %s %s: cost %.2f (as wired %.2f)", h[0], h[1], h[4], fit0.cost)
    return hyps


def _predicted_slopes(hyp, data: SteadyData):
    """The columns' slopes a hypothesis predicts: ``[(variant, slopes)]`` (a sensor off: as a gain,
    the whole reading scaled, and as an offset, the fluctuation as predicted)."""
    kind, idx, f, sp_, _ = hyp
    try:
        k = _slopes(sp_, f.theta)
    except _FAILURES:
        return []
    if kind == "swap":
        perm = np.arange(k.size)
        perm[list(idx)] = perm[list(idx[::-1])]
        return [("swap", k[perm])]
    i = idx[0]
    pred = sp_.outputs(f.theta)[i]
    g = k.copy()
    g[i] *= data.mean[i] / pred
    return [("gain", g), ("offset", k)]


def _finding(kind, idx, f, sp_, gain, data, names, hint, label) -> Finding:
    if kind == "swap":
        who = tuple(names[k] for k in idx)
        msg = (
            f"sensors {who[0]} and {who[1]} read as each other's (their means exchanged fit the load prior "
            f"{label} by chi-square {gain:.0f} better): swapped wires or columns?"
        )
        return Finding("swap", who, float("nan"), float(gain), msg)
    i = idx[0]
    pred = float(sp_.outputs(f.theta)[i])
    ratio = data.mean[i] / pred if pred != 0 else float("inf")
    mistake = "gain or offset" if hint is None else hint
    if not (1 / GAIN_OFF < abs(ratio) < GAIN_OFF):
        mistake = "gain"
    what = {
        "gain": "a gain set wrong?",
        "offset": f"an offset forgotten (it reads {data.mean[i] - pred:+.3g} off)?",
        "gain or offset": f"a gain set wrong, or an offset forgotten ({data.mean[i] - pred:+.3g})?",
    }[mistake]
    msg = (
        f"sensor {names[i]}'s mean is {ratio:.2g}x what the fit of the other sensors predicts (load prior {label}; "
        f"left out, the fit improves by chi-square {gain:.0f}): {what}"
    )
    return Finding(mistake, (names[i],), float(ratio), float(gain), msg)


def check_steady(
    model: MembraneModel,
    t: np.ndarray | None,
    values: np.ndarray,
    prior: ParameterPrior,
    initial_load: float,
    kappa: float = 1.0,
    edges: tuple[str, ...] = ("x0", "x1"),
    max_iter: int = 30,
    fluctuation: bool = True,
) -> WiringReport:
    """The wiring checks of a steady record (``values`` ``(N, p)``) under the thin-airfoil shapes at
    each possible leading edge (module docstring). The best corrected fit over the edges and the
    hypotheses is compared with the best fit as wired. ``fluctuation``: the record's fluctuation is
    the load factor's (buffeting), which tells a gain from an offset."""
    data = steady_data(values)
    if not np.all(np.isfinite(data.mean)) or data.mean.size < 3:
        return skipped("fewer than three sensors with a mean")
    sign = float(np.sign(initial_load) or 1.0)
    wired, corrected = [], []
    modal = None
    for e in edges:
        try:
            base = SteadyProblem(model, LoadShapes.aerodynamic(model, initial_load, e, kappa), data, prior)
            if modal is not None:  # the same membrane at either edge: its modal model built once
                base.__dict__["modal"], base.__dict__["fvk"] = modal
            modal = (base.modal, base.fvk)
            fit0, sp0 = _wired(base, data, sign, max_iter)
        except _FAILURES as exc:
            log.debug("wiring check at edge %s failed: %s", e, exc)
            continue
        if fit0 is not None:
            wired.append((fit0.cost, fit0.data_cost / data.mean.size, f"aerodynamic {e}", fit0, sp0))
    if not wired:
        return skipped("the predictive prior's fits failed")
    cost0, chi2, label0 = min(wired, key=lambda w: w[0])[:3]
    report = WiringReport((), label0, float(chi2))
    if cost0 < EVIDENCE:  # no correction can remove EVIDENCE from a cost below it: the wiring is fine
        return report
    for *_, label, fit0, sp0 in wired:
        try:
            corrected += [(h, label) for h in _hypotheses(sp0, fit0, data, sign, max_iter)]
        except _FAILURES as exc:
            log.debug("wiring hypotheses under %s failed: %s", label, exc)
    if not corrected:
        return report
    p = data.mean.size
    fine = [c for c in corrected if c[0][2].data_cost / (p - (c[0][0] == "one")) <= CONSISTENT]
    best_cost = min((c[0][4] for c in fine), default=np.inf)
    if cost0 - best_cost < EVIDENCE:
        return report
    close = [c for c in fine if c[0][4] <= best_cost + TIE]
    slopes = fluctuation_slopes(t, values) if fluctuation and t is not None else None
    choice = min(close, key=lambda c: c[0][4])
    kind_hint = None
    if slopes is not None and len(close) > 1:
        scored = []
        for c in close:
            for variant, k in _predicted_slopes(c[0], data):
                scored.append((_mismatch(slopes, k), variant, c))
        mis, kind_hint, choice = min(scored, key=lambda x: x[0])
        log.debug("wiring: the fluctuation picks %s %s (log-slope mismatch %.3f)", kind_hint, choice[0][1], mis)
    (kind, idx, f, sp_, cost), label = choice
    gain = cost0 - cost
    log.debug("wiring: hypothesis %s %s (%s) removes chi-square %.1f", kind, idx, label, gain)
    names = model.problem.sensor_names
    finding = _finding(kind, idx, f, sp_, gain, data, names, kind_hint, label)
    if kind != "swap" and 1 / MATERIAL < abs(finding.ratio) < MATERIAL:
        # a load the prior cannot quite make leaves this much (clean L1 on FvK truth: S2 at 1.2x, chi2 182)
        log.debug("wiring: %s at %.2fx of its prediction: within the model's reach, not reported", idx, finding.ratio)
        return report
    others = {_who(c[0], names) for c in close if c[0][:2] != (kind, idx)} if slopes is None else set()
    if others:  # the means alone cannot tell them apart (no fluctuation of the load factor to compare)
        also = "; ".join(sorted(others))
        finding = dataclasses.replace(finding, message=f"{finding.message} (as consistent: {also})")
    finding = dataclasses.replace(finding, message=finding.message + OR_THE_LOAD)
    return WiringReport((finding,), label, float(chi2))


def _who(hyp, names) -> str:
    kind, idx = hyp[0], hyp[1]
    if kind == "swap":
        return f"{names[idx[0]]} and {names[idx[1]]} swapped"
    return f"sensor {names[idx[0]]}'s gain or offset"


def check_transient(
    model: MembraneModel,
    t: np.ndarray,
    values: np.ndarray,
    prior: ParameterPrior,
    initial_load: float,
    kappa: float = 1.0,
    edges: tuple[str, ...] = ("x0", "x1"),
    late: float = 0.5,
) -> WiringReport:
    """The wiring checks of a transient record on its last ``late`` fraction: the static state the
    release settles to (a record still ringing there is checked on its mean all the same; the
    ringing's fluctuation is not the load factor's and is not used to tell a gain from an offset)."""
    y = np.asarray(values, dtype=float)
    tail = y[int((1.0 - late) * y.shape[0]) :]
    if tail.shape[0] < 20:
        return skipped("too few late samples")
    return check_steady(model, None, tail, prior, initial_load, kappa, edges, fluctuation=False)


def attach(info: dict, model: MembraneModel, t, values, settings, initial_load: float, steady: bool = True) -> None:
    """Run the checks of a route's record and record them in its ``info``: ``info["wiring"]`` and, for
    each finding, a line of ``info["warnings"]`` (the answer is not changed). ``settings``: the realistic
    estimator's (``kappa``, the parameter priors, the ``declaration``'s leading edge; filled when ``None``)."""
    s = with_declaration(settings, model.problem)
    try:
        prior = ParameterPrior.from_problem(model.problem, s.free, s.prestrain_rel, s.damping_rel, s.declaration)
        edges = (s.declaration.leading_edge,) if s.declaration.leading_edge else ("x0", "x1")
        if steady:
            rep = check_steady(model, t, values, prior, initial_load, s.kappa, edges)
        else:
            rep = check_transient(model, t, values, prior, initial_load, s.kappa, edges)
    except _FAILURES as exc:
        rep = skipped(f"the checks failed ({exc})")
    info["wiring"] = rep.as_dict()
    info.setdefault("warnings", []).extend(rep.warnings)
