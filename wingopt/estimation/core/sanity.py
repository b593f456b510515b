"""Sanity of a record and of a sensor layout, beyond syntax: what would give a confident wrong answer.

Two kinds of checks, both pure functions of arrays and the model:

* refusals (:class:`~wingopt.errors.InputError`, one line with a hint): a time step that can only be
  milliseconds/microseconds/nanoseconds, stretch columns that are negated (stretch sensors give
  ``s >= 0``), reserved sensor names;
* warnings (one-line strings, stored in ``summary.json`` under ``"warnings"`` and printed by the
  command line): sensors that carry the same information (duplicates, a rank-deficient layout),
  sensors bunched in a small part of the wing (the load elsewhere comes from the prior), values
  that look like percent, data that do not fit the model (chi-square per datum well above 1), and a
  noise level that is a large part of the signal (then everything fits).

Thresholds are stated next to each check with the measurement that motivated them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from wingopt.errors import InputError
from wingopt.estimation.core.noise import MHE_NOISE, estimate_noise_std
from wingopt.measurements.clock import IrregularSampling, jitter_note, on_clock

__all__ = [
    "RESERVED_NAMES",
    "as_measurements",
    "check_sensor_names",
    "check_time_step",
    "check_duration",
    "check_record_length",
    "check_stretch_sign",
    "sensitivity_correlation",
    "layout_warnings",
    "units_warnings",
    "scale_warnings",
    "SCALE_BAND",
    "SCALE_HIGH",
    "fit_warnings",
    "noise_warnings",
    "residual_chi2_per_datum",
    "record_checks",
    "fit_checks",
    "used_sigma",
    "sourced",
]

RESERVED_NAMES = frozenset({"t", "time"})
"""Column names a sensor may not take: ``t`` is the CSV time column."""

MAX_DT = 0.5
"""Largest plausible sample period (s). The membrane's first mode is ~30 Hz (Table 6.3): a step of
0.5 s or more can only be another unit (1 kHz written in ms has a step of 1)."""

MIN_DT = 1.0e-7
"""Smallest plausible sample period (s): 10 MHz; smaller steps are seconds mistaken for another unit."""

CHI2_WARN = 4.0
"""Chi-square per datum above which the data do not fit the model. With the noise estimated from the
data it is 0.8–1.6 on the shipped and simulated records (measured: tunnel record 1.1, L1 1 % 1.0);
negated or re-timed records give 30 to 2000."""

NOISE_DOMINATED = 0.2
"""Noise std above this fraction of a sensor's peak reading: the record is mostly noise. The protocol's
noise is 1–5 % of the peak (the tunnel record ~1 %); a record alternating every sample (no membrane
does that) is read as 22–30 % "noise", fits any model at that level and gave a lift with a 2–14 %
band, flagged adequate."""

MAX_STRETCH = 0.5
"""Refused outright: ``s = 0.5`` means surface slopes of 45° on average (same limit as the CSV reader)."""

DUPLICATE_CORRELATION = 0.995
"""Two sensors whose load sensitivities correlate this much measure the same thing (identical
rectangles give 1.000; the default layout's largest is 0.59)."""

RANK_RATIO = 1.0e-3
"""Smallest/largest eigenvalue of the sensitivity correlation below which the layout is rank-deficient."""

BUNCHED = 0.25
"""Sensor centres spanning less than this fraction of the chord AND of the span are bunched (the
default layout spans 0.57 x 0.51; four sensors in one corner 0.11 x 0.14 gave a lift 55 % low)."""


def as_measurements(data, names: Sequence[str]):
    """A :class:`Measurements` from one, or from an array ``(N, 1 + p)`` of rows ``t, s_1 .. s_p``."""
    from wingopt.measurements.series import Measurements

    if isinstance(data, Measurements):
        if tuple(data.sensor_names) != tuple(names):
            raise InputError(f"data: sensors {list(data.sensor_names)}: expected the problem's {list(names)}")
        return data if data.simulated or data.count < 2 else on_uniform_clock(data)
    expected = "expected a CSV path, a Measurements or an array of rows t, " + ", ".join(names)
    try:
        raw = np.asarray(data)
    except Exception:  # noqa: BLE001 - ragged lists and the like: the caller's mistake
        raw = None
    if raw is None or raw.dtype.kind not in "biuf":
        kind = {"c": " of complex numbers", "U": " of text", "S": " of bytes"}.get(
            getattr(raw, "dtype", np.dtype("O")).kind, ""
        )
        raise InputError(f"data: got {type(data).__name__}{kind}: {expected} (real numbers)")
    arr = raw.astype(float)
    if arr.size > 10**9:
        raise InputError(f"data: {arr.size} values: more than the limit of 1e9")
    if arr.ndim != 2 or arr.shape[1] != 1 + len(names) or arr.shape[0] < 2:
        raise InputError(
            f"data: array of shape {arr.shape}: expected (N, {1 + len(names)}) rows t, {', '.join(names)} with N >= 2"
        )
    if not np.all(np.isfinite(arr[:, 0])):
        raise InputError("data: the time column has NaN or inf: every row needs a time")
    if np.isinf(arr[:, 1:]).any():
        raise InputError("data: a sensor value is infinite: expected finite numbers (NaN for missing)")
    return on_uniform_clock(Measurements(t=arr[:, 0], values=arr[:, 1:], sensor_names=tuple(names), source="array"))


def on_uniform_clock(meas):
    """``meas`` on its uniform clock (:func:`~wingopt.measurements.clock.on_clock`), the checks of the
    CSV reader: rounded or jittered stamps (at most 10 % of a step) read as the fitted clock and
    reported (``meas.clock``, a data check's warning), gaps filled with missing rows, larger
    irregularity refused (an array whose time column jitters by 20 % passed without a word)."""
    try:
        clock, t, values = on_clock(meas.t, meas.values)
    except IrregularSampling as exc:
        raise InputError(f"{meas.source or 'data'}: row {exc.position}: {exc.message}") from None
    if not clock.jittered and values.shape == meas.values.shape:
        return meas
    return dataclasses.replace(meas, t=t, values=values, clock=clock.as_dict() if clock.jittered else None)


def check_sensor_names(names: Sequence[str], where: str = "sensors") -> None:
    """Refuse reserved or empty names and names a CSV header cannot hold."""
    for i, name in enumerate(names):
        if name.strip().lower() in RESERVED_NAMES:
            raise InputError(f"{where}[{i + 1}] name = {name!r}: reserved for the time column; rename the sensor")
        if not name.strip() or any(c in name for c in ',"\n#'):
            raise InputError(f'{where}[{i + 1}] name = {name!r}: expected a non-empty name without , " # or newline')


MIN_SAMPLES = 30
"""Fewest samples of a record: the noise level is estimated from second differences of the data."""


def check_duration(t_end: float, dt: float) -> None:
    """Refuse a simulated duration that gives fewer than :data:`MIN_SAMPLES` samples."""
    samples = int(round(t_end / dt)) + 1
    if samples < MIN_SAMPLES:
        raise InputError(
            f"t_end = {t_end:g} s: {samples} samples at dt = {dt:g} s; expected at least {MIN_SAMPLES} "
            f"(t_end >= {(MIN_SAMPLES - 1) * dt:g} s)"
        )


def check_record_length(meas) -> None:
    """Refuse a record with fewer than :data:`MIN_SAMPLES` complete samples."""
    complete = int(np.count_nonzero(~meas.missing))
    if complete < MIN_SAMPLES:
        raise InputError(
            f"{meas.source or 'data'}: {complete} complete samples: expected at least {MIN_SAMPLES} "
            "(the noise level is estimated from the data)"
        )


def check_time_step(dt: float, source: str = "data") -> None:
    """Refuse a sample period that can only be in another unit than seconds."""
    if not np.isfinite(dt) or dt <= 0:
        raise InputError(f"{source}: time step {dt!r}: expected a positive step in seconds")
    if dt >= MAX_DT:
        unit = "ms" if dt < 500 else "µs" if dt < 5e5 else "ns"
        scale = {"ms": 1e-3, "µs": 1e-6, "ns": 1e-9}[unit]
        raise InputError(
            f"{source}: time step {dt:g} s is far longer than the membrane's dynamics (first mode ~30 Hz): "
            f"are the times in {unit}? "
            + (
                f"Give --time-unit {unit.replace('µ', 'u')} (step {dt * scale:g} s)"
                if unit != "ns"
                else f"Write t in seconds (step {dt * scale:g} s)"
            )
        )
    if dt < MIN_DT:
        raise InputError(
            f"{source}: time step {dt:g} s (faster than 10 MHz): expected t in seconds; are the times in another unit?"
        )


def check_stretch_sign(values: np.ndarray, names: Sequence[str], source: str = "data") -> None:
    """Refuse a sensor column whose typical value is negative: stretch ``s = alpha/(2A) ∫|grad w|^2 >= 0``."""
    v = np.asarray(values, dtype=float)
    for j, name in enumerate(names):
        col = v[:, j][np.isfinite(v[:, j])]
        if col.size == 0:
            continue
        med, peak = float(np.median(col)), float(np.max(np.abs(col)))
        if med < 0 and abs(med) > 0.05 * peak:
            raise InputError(
                f"{source}: sensor {name}: median value {med:.4g} < 0: stretch sensors give s >= 0 "
                "(s = alpha/(2A) ∫|grad w|^2); is the column negated, or is it another quantity?"
            )


def sensitivity_correlation(model, reference_load: float) -> np.ndarray:
    """Correlation ``(p, p)`` of the sensors' load sensitivities ``ds_i/df`` at a uniform load.

    ``s_i = z^T C_i z`` with ``K z = M f`` gives ``ds_i/df = 2 M K^{-1} C_i z0``; the inner product is the
    dual (load) one, ``a^T M^{-1} b``. Two sensors that see the load alike have correlation ~1.
    """
    K = spla.splu(sp.csc_matrix(model.stiffness))
    M = spla.splu(sp.csc_matrix(model.gram))
    f0 = np.full(model.n, float(reference_load))  # ~uniform load (B-spline partition of unity inside)
    z0 = K.solve(model.gram @ f0)
    H = np.stack([2.0 * (model.gram @ K.solve(C @ z0)) for C in model.sensors.matrices])
    G = H @ np.stack([M.solve(h) for h in H]).T
    d = np.sqrt(np.clip(np.diag(G), 1e-300, None))
    return G / np.outer(d, d)


def layout_warnings(rects, names: Sequence[str], width: float, height: float, corr: np.ndarray | None) -> list[str]:
    """Warnings about a sensor layout that cannot identify the load (duplicates, rank, bunching)."""
    out: list[str] = []
    p = len(names)
    if corr is not None and p > 1:
        pairs = [(i, j) for i in range(p) for j in range(i + 1, p) if corr[i, j] > DUPLICATE_CORRELATION]
        if pairs:
            txt = ", ".join(f"{names[i]}/{names[j]} ({corr[i, j]:.4f})" for i, j in pairs)
            out.append(
                f"sensors {txt} measure nearly the same thing (load-sensitivity correlation): "
                "fewer independent sensors than listed, the load is set by the prior, not the data"
            )
        ev = np.linalg.eigvalsh(corr)
        if not pairs and ev[0] / ev[-1] < RANK_RATIO:
            out.append(
                f"sensor layout is nearly rank-deficient (eigenvalue ratio {ev[0] / ev[-1]:.2g} of the "
                "sensitivity correlation): the sensors cannot tell load shapes apart"
            )
    centres = np.array([[(r[0] + r[1]) / 2, (r[2] + r[3]) / 2] for r in rects])
    sx = float(np.ptp(centres[:, 0])) / width
    sy = float(np.ptp(centres[:, 1])) / height
    if sx < BUNCHED and sy < BUNCHED:
        out.append(
            f"sensors bunched: their centres span {100 * sx:.0f} % of the chord and {100 * sy:.0f} % of the span; "
            "the load away from them (and the lift) comes from the prior, not the data"
        )
    return out


SCALE_BAND = 1.0e-3
"""A record's peak stretch below ``SCALE_BAND`` times the membrane's pre-strain is warned about, as one
above ``SCALE_HIGH`` times it is: one plausibility band, ``[prestrain / 1000, 2 prestrain]``, both
ways. The shipped and simulated records peak at 0.004–0.06 (pre-strain 0.05; band 5e-5..0.1); a
record times 1e-3 gave a lift 30 times too small, times 1e-6 a lift 1000 times too small (the load
goes with the square root of the stretch), both silently before."""

SCALE_HIGH = 2.0
"""The band's top, in pre-strains. The deflection's stretch reaches the order of the pre-strain on a
loaded tunnel wing and in a hard calibration push (the shipped release record peaks at 0.061, 1.2
pre-strains: the FvK models' regime); a record in percent reads 100 times its stretch."""


def scale_warnings(peak: float, name: str, prestrain: float) -> list[str]:
    """The plausibility band of a record's peak stretch reading (:data:`SCALE_BAND`), both ways."""
    if not np.isfinite(peak) or peak <= 0:
        return []
    if peak > SCALE_HIGH * prestrain:
        return [
            f"sensor {name} reads up to {peak:.3g}, more than {SCALE_HIGH:g} times the membrane's pre-strain "
            f"{prestrain:g}: beyond the membrane models' regime; are the values in another unit (percent: divide "
            "by 100)?"
        ]
    low = SCALE_BAND * prestrain
    if peak < low:
        return [
            f"sensor readings peak at {peak:.3g} (sensor {name}), implausibly small: below {low:.2g}, 1/1000 of the "
            f"membrane's pre-strain {prestrain:g} (records peak at 1e-4..1e-1); are the values in another unit or "
            "scale (multiplied by 1e-3 or 1e-6)? The load goes with the square root of the stretch: a wrong scale "
            "gives a lift wrong by its square root"
        ]
    return []


def units_warnings(values: np.ndarray, names: Sequence[str], prestrain: float) -> list[str]:
    """Refuse a stretch beyond 0.5; warn when the peak is outside the plausibility band (:func:`scale_warnings`).

    The linear membrane model keeps the tension of the pre-strain: the extra strain of the deflection,
    which is what a stretch sensor reads, must stay well below it; the FvK models follow it up to the
    order of the pre-strain. A record of 0.0043 peak (pre-strain 0.05) in percent peaks at 0.43 and
    gave a lift 10 times too high.
    """
    v = np.asarray(values, dtype=float)
    finite = v[np.isfinite(v)]
    if finite.size == 0:
        raise InputError("data: every sensor value is missing")
    peak = float(np.max(np.abs(finite)))
    j = int(np.nanargmax(np.abs(np.where(np.isfinite(v), v, 0.0)).max(axis=0)))
    if peak > MAX_STRETCH:
        raise InputError(
            f"data: sensor {names[j]} values up to {peak:.4g}: expected the dimensionless stretch "
            "s = alpha/(2A) ∫|grad w|^2 (typically 1e-4..1e-1); are the values in percent or microstrain?"
        )
    return scale_warnings(peak, names[j], prestrain)


def residual_chi2_per_datum(predicted: np.ndarray, measured: np.ndarray, sigma: np.ndarray) -> float:
    """Mean of ``((y - y_hat) / sigma)^2`` over the finite data."""
    r = (np.asarray(measured) - np.asarray(predicted)) / np.asarray(sigma)
    r = r[np.isfinite(r)]
    return float(np.mean(r**2)) if r.size else float("nan")


def fit_warnings(chi2_per_datum: float | None, where: str = "") -> list[str]:
    """Warn when the data do not fit the model (chi-square per datum well above 1)."""
    if chi2_per_datum is None or not np.isfinite(chi2_per_datum) or chi2_per_datum <= CHI2_WARN:
        return []
    return [
        f"data do not fit the model{where}: chi-square per datum {chi2_per_datum:.3g} (expected ~1); the estimate "
        "and its band are not trustworthy (wrong units, negated or mislabelled columns, another sensor layout?)"
    ]


def noise_warnings(values: np.ndarray, sigma: np.ndarray, names: Sequence[str]) -> list[str]:
    """Warn when the noise level (given or estimated) is a large part of a sensor's signal."""
    peak = np.nanmax(np.abs(np.asarray(values, dtype=float)), axis=0)
    ratio = np.broadcast_to(np.asarray(sigma, dtype=float), peak.shape) / np.where(peak > 0, peak, np.nan)
    if not np.any(ratio > NOISE_DOMINATED):
        return []
    j = int(np.nanargmax(ratio))
    return [
        f"sensor {names[j]}: noise std {100 * ratio[j]:.0f} % of its peak reading (expected a few %): the record is "
        "mostly noise at this level, so any model fits it and the band says little (sample-to-sample jumps, a "
        "wrong column, another sampling rate?)"
    ]


def record_checks(model, meas, reference_load: float, frames: bool = False) -> list[str]:
    """Refusals and warnings before a record is identified; returns the warnings. ``frames``: the
    record's DIC frames are the data (the full field: a steady answer from a single frame), so the
    sensor series' minimum length does not apply."""
    names = meas.sensor_names
    check_sensor_names(names)
    if not frames:
        check_record_length(meas)
    if meas.count >= 2:
        check_time_step(float(np.median(np.diff(meas.t))), meas.source or "data")
    check_stretch_sign(meas.values, names, meas.source or "data")
    warnings = units_warnings(meas.values, names, model.problem.material.prestrain)
    if meas.simulated:
        # The package wrote these values itself, in its own unit: a "values in percent?" hint on
        # them (the protocol's L2 peaks above the pre-strain) would only teach users to ignore it.
        warnings = []
    if meas.clock is not None:
        warnings.append(jitter_note(meas.source or "data", meas.clock))
    load = abs(reference_load) if reference_load else 200.0
    corr = sensitivity_correlation(model, load)
    problem = model.problem
    warnings += layout_warnings([s.rect for s in problem.sensors], names, problem.width, problem.height, corr)
    return warnings


def used_sigma(meas, result):
    """The noise std the estimator used (or the data's own estimate) for the fit check; ``None``
    when the data give none."""
    sigma = result.info.get("noise_std", meas.noise_std)
    if sigma is None:
        try:
            sigma = estimate_noise_std(meas.values, MHE_NOISE, meas.sensor_names)
        except InputError:
            return None
    return np.asarray(sigma, dtype=float)


def sourced(source: str, warnings: Sequence[str]) -> list[str]:
    """``warnings`` each prefixed ``[source]`` so that a reader knows which check or fit said it
    (one that already names its source, an inner cross-check's, keeps that)."""
    return [w if w.startswith("[") else f"[{source}] {w}" for w in warnings]


def fit_checks(model, meas, result, sigma: np.ndarray | None) -> list[str]:
    """Warnings after the estimate: the noise level against the signal, the residual of the estimated
    deflection over the second half."""
    if sigma is None:
        return []
    warnings = noise_warnings(meas.values, sigma, meas.sensor_names)
    if result.deflection is None or len(result.t) == 0:
        return warnings
    if result.info.get("steady_lift_N") is not None:
        # A steady answer describes the mean (and the buffeting's spectrum), not each sample: its own
        # adequacy test is on those. Sample by sample, a steady DIC fit read chi-square 236 while
        # explaining the frames' mean to chi-square 1.5.
        return warnings
    idx = np.searchsorted(meas.t, result.t)
    idx = np.clip(idx, 0, meas.count - 1)
    half = slice(len(idx) // 2, None)
    pred = model.sensors.outputs(np.asarray(result.deflection)[half])
    chi2 = residual_chi2_per_datum(pred, meas.values[idx[half]], np.asarray(sigma, dtype=float))
    return warnings + fit_warnings(chi2)
