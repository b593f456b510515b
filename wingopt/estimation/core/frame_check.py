"""Does the pressure reach the frame? Two load priors, weighed by the record's evidence.

Four interior sensors barely see the pressure near the frame (the membrane is fixed there: an
edge load hardly deflects it), yet it carries lift. The default load shapes vanish on the frame
(the seed's loads do); an aerodynamic pressure peaks at the leading edge and acts up to the frame
(spec §10). Both priors are fitted and weighed by their Laplace evidence ``log Z = -cost/2 -
log det(H)/2`` (the same record, so the data's normalisation cancels): the data decide which prior
explains them with a plausible load. Measured on FvK truth (49x25, the seed protocol, 1 % noise):
L1, LE and L2 (zero on the frame) favour the interior prior by 17–21 nats, keeping their accuracy;
L3 (largest on an edge) favours the frame prior by 8 nats (lift -3.9 % ± 7.7 % instead of -7.2 %
± 16 %). The lift is the evidence-weighted mixture of the two (its variance includes the spread of
their means); when both carry weight the record cannot tell, and a warning says so.

When one prior carries the weight but the other fits the data as well (its chi-square not above
the first's by :data:`REJECTS`), the preference is the Occam factor of the frame prior's ten
edge shapes, their prior volume, not the data: the record cannot tell whether the pressure
reaches the frame, and the lift it would give is added to the band in quadrature
(:func:`span_other`, ``info["frame_check"]["lift_spread"]``, a warning). Why: on FvK truth
(49x25, 1 s) L3 at noise seeds 1 and 2 chose the interior prior by 17–20 nats with the frame
prior's fit the better one (chi-square 5 lower), and said 0.7227 ± 0.0108 and 0.7196 ± 0.0107 N for
a true 0.7944: 6.6 and 7.0 bands off. L1, LE and L2 take the frame prior's lift into their bands
the same way (1.5–8.5 % of the lift apart): a load that vanishes on the frame is not what four
interior sensors can show; ``pressure_prior = "interior"`` declares it.

A prior the data do not reject and the evidence does not exclude (its log-evidence within
:data:`EXCLUDES` of the other's: either prior of a mixture, or the dropped one 7–12 nats behind)
is taken into the band whole: the band is at least that prior's posterior spread about the answer,
``sqrt((L_other - L)^2 + s_other^2)`` (:func:`covering`), and a fit that stopped short (a stall,
its iteration cap) counts the lift one Gauss–Newton step on as well as its own (its iterate's is
the start's, the interior fit's: :func:`reach`). The answer does not move. Why: on the fuzz's
loads that act up to the frame (``benchmarks/fuzz_records.py``, FvK truth 37x19) the frame prior's
fit, 7–9 nats behind, either stalled at the interior fit's lift (#65, a sharp leading-edge rise:
0.727 ± 0.64 N, one step on 0.918 N) or reached its cap there (#217, a trailing-edge tunnel load:
2.217 ± 0.23 N at 40 iterations, one step on 2.748, 2.49 after 300), and in a mixture at 4 % it
was the better fit (#109: 1.563 ± 0.088 N): the answers 0.750 ± 0.033, 2.195 ± 0.042 and
1.163 ± 0.085 N were 12, 14 and 3.7 bands from truths of 1.149, 2.777 and 1.475 N.

When the interior prior's fit conflicts with that prior (:mod:`.prior_check`: an edge load), the
frame prior is fitted first, from a fit of the record's start (:func:`.start.short_start`); if it
explains the record without a conflict of its own and :data:`.stopping.DECIDED_NATS` above the
conflicting fit, the interior prior's wider scales are not fitted (L3 on 49x25 truth, 1 s: they
reached 7 nats below the frame prior, which is 36 above the conflicting fit; the record's work
fell from 128 to 35 iterations, 6.2 to 1.5 s of CPU, the lift from 0.7532 ± 0.056 to
0.7485 ± 0.053 N for a true 0.7944). ``stop_early=False`` fits them all.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from wingopt.estimation.core.load_model import LoadShapes
from wingopt.estimation.core.result import IdentificationResult

__all__ = ["FRAME_SHAPES", "REJECTS", "log_evidence", "embed", "weigh", "span_other", "extrapolated"]
__all__ += ["decided", "mixture_note", "EXCLUDES", "reach", "covering"]

FRAME_SHAPES = 10
"""Free-edge shapes added for the frame prior (the constant, x, y, xy, ...): with the 15 interior
shapes they represent the thin-airfoil tunnel load to 1.3 % (L2), an off-centre bump to 5 %."""

DECISIVE = 1e-3
"""A prior whose weight is below this is dropped from the mixture (its lift may still widen the band:
:func:`span_other`)."""

REJECTS = 6.63
"""Chi-square excess (the 99 % point of chi-square with one degree of freedom) above which the
data, not the priors' volumes, reject the prior the evidence dropped."""

EXCLUDES = 12.0
"""Log-evidence gap beyond which the evidence excludes a prior (its weight below ``exp(-12)`` =
6e-6): its fit may stop there (:data:`.stopping.DECIDED_NATS`) and its band is not taken in."""


def log_evidence(fit) -> float:
    """Laplace log-evidence of a fit (up to the data's normalisation, common to both priors)."""
    return float(-0.5 * fit.cost - 0.5 * np.linalg.slogdet(fit.precision)[1])


def embed(rp_from, theta: np.ndarray, rp_to) -> np.ndarray:
    """``theta`` of ``rp_from`` as a start for ``rp_to`` (same unknowns; more load shapes at 0)."""
    out = np.zeros(rp_to.dim)
    for name in ("x0", "g", "par"):
        out[rp_to.slices[name]] = theta[rp_from.slices[name]]
    c_from, c_to = rp_from.slices["c"], rp_to.slices["c"]
    n = c_from.stop - c_from.start
    out[c_to.start : c_to.start + n] = theta[c_from]
    return out


def frame_shapes(model, shapes: LoadShapes, settings, pressure: float) -> LoadShapes:
    """The frame prior's shapes: the interior ones and :data:`FRAME_SHAPES` free-edge ones."""
    return LoadShapes.build(model, shapes.count, pressure, settings.kappa, settings.prior_power, FRAME_SHAPES)


def weigh(
    interior: IdentificationResult,
    frame: IdentificationResult,
    z_interior: float,
    z_frame: float,
    chi2: tuple[float, float] | None = None,
    frame_reach: np.ndarray | None = None,
) -> IdentificationResult:
    """The evidence-weighted mixture of the two priors' results (the dominant one's load field);
    ``chi2``: the two fits' data chi-squares (interior, frame), for :func:`span_other` when one
    prior carries the weight and for :func:`covering` when both do; ``frame_reach``: the lift ``(N,)``
    one Gauss–Newton step on from where the frame prior's fit stopped short (:func:`reach`)."""
    w_frame = float(1.0 / (1.0 + np.exp(np.clip(z_interior - z_frame, -700, 700))))
    info = {"log_evidence": {"interior": z_interior, "frame": z_frame}, "weight_frame": w_frame}
    info["lift_N"] = {"interior": float(interior.lift[-1]), "frame": float(frame.lift[-1])}
    frame_lifts = frame.lift if frame_reach is None else np.stack([frame.lift, frame_reach])
    if frame_reach is not None:
        info["frame_reach_N"] = float(frame_reach[-1])
    base = frame if w_frame >= 0.5 else interior
    if w_frame < DECISIVE or w_frame > 1 - DECISIVE:
        info["used"] = "frame" if w_frame >= 0.5 else "interior"
        base.info["frame_check"] = info
        if chi2 is None:
            return base
        other, lifts = (interior, interior.lift) if base is frame else (frame, frame_lifts)
        used_chi2, other_chi2 = chi2[::-1] if base is frame else chi2
        std = other.lift_std if abs(z_interior - z_frame) < EXCLUDES else None
        return span_other(base, lifts, used_chi2, other_chi2, "interior" if base is frame else "frame", std)
    w = np.array([1 - w_frame, w_frame])
    lifts = np.stack([interior.lift, frame.lift])
    stds = np.stack([interior.lift_std, frame.lift_std])
    mean = w @ lifts
    std = np.sqrt(np.maximum(w @ (stds**2 + lifts**2) - mean**2, 0.0))
    info["used"] = "mixture"
    note = mixture_note(1 - w_frame, w_frame)
    if chi2 is not None:  # each prior the data do not reject, whole: its weight is the priors' volumes
        kept = [
            (ls, r.lift_std)
            for ls, r, c in ((interior.lift, interior, 0), (frame_lifts, frame, 1))
            if chi2[c] - chi2[1 - c] < REJECTS
        ]
        wide = covering(mean, std, kept)
        if wide[-1] > std[-1]:
            info["mixture_std_N"] = float(std[-1])
            note += (
                f"; the band ({wide[-1]:.3g} N, the mixture's {std[-1]:.3g}) takes in each prior the data do not reject"
            )
        std = np.where(wide > std, wide, std)
    out_info = dict(base.info)
    out_info["frame_check"] = info
    out_info["warnings"] = list(base.info.get("warnings", [])) + [note]
    return dataclasses.replace(base, lift=mean, lift_std=std, info=out_info)


def covering(lift: np.ndarray, lift_std: np.ndarray, others) -> np.ndarray:
    """The band ``(N,)`` of the answer ``lift ± lift_std`` that takes in each of ``others``: pairs
    ``(lifts, std)`` of a prior the evidence does not exclude, ``lifts`` its lift ``(N,)`` or its
    candidate lifts ``(k, N)`` (where its fit stopped, one step on), ``std`` its band. The band is at
    least that prior's posterior spread about the answer, ``sqrt(max_k (L_k - lift)^2 + std^2)``."""
    var = np.asarray(lift_std, float) ** 2
    for lifts, std in others:
        gap = np.max(np.abs(np.atleast_2d(lifts) - lift), axis=0)
        var = np.maximum(var, gap**2 + np.asarray(std, float) ** 2)
    return np.sqrt(var)


def span_other(
    res: IdentificationResult,
    lift_other: np.ndarray,
    chi2_used: float,
    chi2_other: float,
    other: str,
    std_other: np.ndarray | None = None,
) -> IdentificationResult:
    """``res`` with the lift ``lift_other`` of the prior the evidence dropped added to its band in
    quadrature, when the data do not reject that prior (chi-square excess below :data:`REJECTS`):
    ``(N,)``, or ``(k, N)`` candidates (where its fit stopped, one step on: the farthest counts).
    ``std_other``: that prior's band when the evidence does not exclude it (:data:`EXCLUDES`): the
    band then takes in its posterior spread too (:func:`covering`)."""
    fc = res.info["frame_check"]
    excess = float(chi2_other - chi2_used)
    fc["chi2"] = {"used": float(chi2_used), other: float(chi2_other)}
    if not (np.isfinite(excess) and excess < REJECTS):
        return res
    lifts = np.atleast_2d(np.asarray(lift_other, float))
    spread = np.max(np.abs(lifts - res.lift), axis=0)
    std = np.sqrt(res.lift_std**2 + spread**2)
    fc["lift_spread"] = float(spread[-1])
    where = "reaches" if other == "frame" else "vanishes on"
    step = f" (one Gauss-Newton step on from where its fit stopped: {lifts[-1, -1]:.4g} N)" if len(lifts) > 1 else ""
    note = (
        f"the sensors do not tell whether the pressure {where} the frame: "
        f"the {other} prior (a load that {where} the frame) fits the data as well (chi-square {chi2_other:.1f} against "
        f"{chi2_used:.1f}) with a lift of {float(lifts[0, -1]):.4g} N{step}; the evidence's preference is the edge "
        f"shapes' prior volume, not the data, so the difference ({float(spread[-1]):.3g} N) is added to the band"
    )
    wide = None if std_other is None else covering(res.lift, res.lift_std, [(lifts, std_other)])
    if wide is not None and wide[-1] > std[-1]:  # the band: sqrt(spread^2 + max(own, other's band)^2)
        std = np.maximum(std, wide)
        fc.update(other_band_N=float(std_other[-1]), lift_spread=float(np.sqrt(std[-1] ** 2 - res.lift_std[-1] ** 2)))
        note += (
            f", and, the evidence not excluding it, that prior's own band ({float(std_other[-1]):.3g} N): "
            f"the band is {float(std[-1]):.3g} N"
        )
    info = dict(res.info, warnings=list(res.info.get("warnings", [])) + [note])
    return dataclasses.replace(res, lift_std=std, info=info)


def reach(rp, theta: np.ndarray, precision: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """The lift ``(N,)`` one undamped Gauss–Newton step from ``theta`` (``gradient``: the cost's
    half gradient there, ``precision``: its Gauss–Newton matrix): where a fit stopped short was going."""
    return rp.lift(theta - np.linalg.solve(precision, gradient))


def extrapolated(rp, it) -> tuple[np.ndarray, float]:
    """The lift ``(N,)`` a fit stopped at iterate ``it`` (a decided comparison,
    :func:`.stopping.behind`) would reach, by one undamped Gauss–Newton step (:func:`reach`), and the data
    chi-square where it stopped (above its optimum's). The step's lift, not its cost: on these
    records the full step raises the chi-square (the residuals are far from linear along it) but
    lands near the finished fit's lift (frame prior, FvK truth 49x25, 1 s: L3 seed 2 0.791 N,
    finished 0.784; seed 1 0.766 / 0.770; L1 0.871 / 0.854; LE seed 1 0.640 / 0.624; L1 at 5 %
    noise 0.817 / 0.794), where the stopped iterate's lift is the start's (0.722 for 0.784)."""
    lift = rp.lift(it.theta) if it.gradient is None else reach(rp, it.theta, it.precision, it.gradient)
    rd, _ = rp.residuals(it.theta)
    return lift, float(rd @ rd)


def decided(z_interior: float, w) -> dict:
    """``info["frame_check"]`` when the frame prior's fit stopped decided (:func:`.stopping.behind`):
    its log-evidence and weight are upper bounds (``"bound": True``)."""
    return {
        "log_evidence": {"interior": z_interior, "frame": w.reach},
        "weight_frame": float(np.exp(min(w.reach - z_interior, 0.0))),
        "bound": True,
        "used": "interior",
        "frame_fit": f"stopped after {len(w.costs) - 1} iterations, {w.reason}",
    }


def mixture_note(w_interior: float, w_frame: float) -> str:
    return (
        f"the sensors do not tell whether the pressure reaches the frame (evidence: {w_interior:.1%} a load that "
        f"vanishes there, {w_frame:.1%} one that acts up to it): the lift and its band mix the two"
    )
