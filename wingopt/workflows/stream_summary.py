"""The ``summary.json`` of a stream (:func:`wingopt.workflows.stream.follow`): its answer and what it ran on.

The last estimate and its status, the data's rows, latency and warnings (:func:`summarise`); a steady
stream's whole-record refit as its answer; what ran on what (:func:`describe`).
"""

from __future__ import annotations

import numpy as np

from wingopt.estimation.core import sanity
from wingopt.measurements.clock import jitter_note
from wingopt.status import RunStatus

__all__ = ["summarise", "describe"]


def summarise(est, parser, lines, push, source: str, problem, rows: int, steady) -> dict:
    """The summary of the stream read from ``lines`` through ``parser`` by ``est`` (``push``: its
    latency and misfit counts; ``steady``: the whole-record refit of a steady stream, or ``None``)."""
    try:
        args = (push.cpu, push.wall, push.bad, push.first_bad)
        summary = _summary(est, parser, lines.reason, *args, source, problem, rows)
    except Exception as exc:  # noqa: BLE001 - the estimator's state after a failure may not summarise
        summary = _failed_summary(problem, source, lines.reason, rows, exc)
    if steady is not None:
        summary.update(_steady_summary(est, steady, summary))
    if lines.restarts:
        summary["restarts"] = list(lines.restarts)
    return summary


def describe(summary: dict, problem, peak: tuple[float, str], method: str, spec, options, parser) -> None:
    """What ran on what, into ``summary``: every warning named by its source (the data's units check
    beside the estimator's: ``peak``, the largest stretch read and its sensor), the method, membrane and
    options, and the channel map (``parser``: the rows' parser when a map was given, else ``None``)."""
    scale = sanity.scale_warnings(peak[0], peak[1], problem.material.prestrain)
    own = sanity.sourced(method, summary.get("warnings", []))  # each names its source, as identify's
    summary["warnings"] = own + sanity.sourced("data check", scale)
    summary["method"] = method
    summary["membrane"] = spec.model
    summary["options"] = options.as_dict()
    if parser is not None:
        summary["channels"] = parser.channels.as_dict(problem.sensor_names)


def _failed_summary(problem, source: str, reason: str, rows: int, exc: Exception) -> dict:
    """The summary of a stream whose estimator could not summarise its state after a failure."""
    return {
        "problem": problem.name,
        "source": source,
        "stopped": reason,
        "samples": rows,
        "rows_written": rows,
        "lift_N": None,
        "lift_std_N": None,
        "summary_error": f"{type(exc).__name__}: {exc}",
        "warnings": [],
        "status": "failed",
    }


def _status(finite: bool, info: dict, last) -> RunStatus:
    """The stream's :class:`~wingopt.status.RunStatus`: ``failed`` without a finite estimate,
    ``not_converged`` before the start-up finished, ``misfit`` when the last window is not explained."""
    if not finite:
        return RunStatus.FAILED
    if info.get("phase") not in ("tracking", "steady"):
        return RunStatus.NOT_CONVERGED
    return RunStatus.CONVERGED if last.adequate else RunStatus.MISFIT


def _summary(est, parser, reason, cpu, wall, bad, first_bad, source, problem, rows_written) -> dict:
    last = est.last
    finite = last is not None and np.isfinite(last.lift)
    info = est.info()
    warnings = list(info.get("warnings", []))  # the estimator's own (a recovered numerical failure)
    if parser.clock is not None:  # stamps as a logger writes them, read on one uniform clock
        warnings.append(jitter_note(source or "the stream", parser.clock))
    if est.count == 0:
        warnings.append("no data rows received")
    elif info["phase"] != "tracking":
        warnings.append(
            f"the stream ended in the {info['phase']} phase, before the start-up: the estimates are provisional "
            "(prior, provisional lambda and noise level)"
        )
    verdict = info.get("verdict")
    if verdict is not None:  # the window's own test, not the whole record's flags the estimate also carries
        bad = verdict["misfit_samples"]
    if bad:
        warnings.append(
            f"the window misfit exceeded the chi-square bound at {bad} samples (first at t = {first_bad:.6g} s): "
            "the data are not explained by a constant load there (the streaming estimator does not restart; "
            "run the batch identify on the stored record)"
        )
    sign = info.get("sign")
    if sign is not None and not sign["determined"]:
        warnings.append("the sign of the load is not determined by the prior (initial_load / initial_deflection)")
    period = est.dt
    lat = {"cpu": cpu.summary(period), "wall": wall.summary(period), "clock_cpu": "thread_time"}
    if period and cpu.count and cpu.percentile(99) > period:
        warnings.append(f"per-sample CPU time p99 {cpu.percentile(99):.3g} s exceeds the sample period {period:.3g} s")
    return {
        "problem": problem.name,
        "method": "mhe-stream",
        "mesh": list(problem.nodes),
        "source": source,
        "stopped": reason,
        "samples": est.count,
        "rows_written": rows_written,
        "data": {
            "rows": parser.rows,
            "missing_rows": parser.missing_rows,
            "gap_rows_filled": parser.gap_rows,
            "ignored_columns": parser.ignored_columns,
            "dt_s": parser.dt,
            "clock": parser.clock,
        },
        "status": str(_status(finite, info, last)),
        "lift_N": float(last.lift) if finite else None,
        "lift_std_N": float(last.lift_std) if finite else None,
        "chi2_per_datum": float(last.chi2_per_datum) if finite else None,
        "adequate": bool(last.adequate) if last is not None else None,
        "inadequate_samples": bad,
        "latency": lat,
        "estimator": info,
        "warnings": warnings,
    }


_STEADY_KEYS = ("tension", "solutions", "chosen", "model", "parameters", "parameters_std")
"""What a steady stream's summary keeps of the whole-record fit's diagnostics."""


def _steady_summary(est, result, summary: dict) -> dict:
    """A steady stream's final answer: the whole-record estimate of its samples (the batch's), the
    live filter's last estimate beside it, and the refits' trace."""
    lift, std = result.reported_lift
    live = {k: summary.get(k) for k in ("lift_N", "lift_std_N", "chi2_per_datum", "adequate")}
    diagnostics = result.diagnostics
    own = [w for w in summary.get("warnings", []) if "window misfit" not in w]  # the refit explains the record
    refit = sanity.sourced("steady refit", list(diagnostics.warnings))
    return {
        "lift_N": lift,
        "lift_std_N": std,
        "chi2_per_datum": diagnostics.chi2_per_datum,
        "adequate": diagnostics.model_adequate is not False,
        "record": "steady",
        "answer": "the whole-record (batch) estimate of the stream's samples: a steady record, no release transient",
        "live_filter": live,
        "refits": est.refits,
        "steady": {k: result.info.get(k) for k in _STEADY_KEYS},
        "status": str(result.status),
        "warnings": own + refit,
    }
