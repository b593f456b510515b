"""Streaming identification as a workflow: rows in as they arrive, one estimate per sample, results out.

:func:`follow` reads a CSV that grows (``source`` a path) or standard input (``source=None``),
feeds each sample to a streaming estimator (:class:`~wingopt.estimation.streaming.StreamingEstimator`,
linear; :class:`~wingopt.estimation.streaming.nonlinear.NonlinearStreamingEstimator`, FvK or Berger),
appends every estimate, flushed, to ``lift.csv`` in the run's hidden working directory (readable while
the run goes) and, at the end, writes ``summary.json`` and moves the directory to ``out``
atomically. It stops at the end marker line ``# end``, at the end of standard input, after
``idle_timeout`` seconds without a new line, or when ``stop["signal"]`` is set (the CLI's signal
handler). Every sample's estimate is in ``lift.csv`` exactly once. A bad row ends the stream: the
record so far is written (``stopped``: ``bad input: ...``), then the error is raised.
"""

from __future__ import annotations

import logging
import os
import select
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wingopt.errors import DataFileError, InputError

__all__ = ["COLUMNS", "LatencyStats", "follow"]

log = logging.getLogger(__name__)

COLUMNS = ("t", "lift_N", "lift_std_N", "chi2_per_datum", "adequate", "phase")


class LatencyStats:
    """Percentiles of per-sample times in bounded memory (log-spaced bins of 1 %, exact maximum)."""

    def __init__(self) -> None:
        self._edges = 10.0 ** np.arange(-7.0, 2.0, 0.005)
        self._counts = np.zeros(self._edges.size + 1, dtype=np.int64)
        self.count, self.max = 0, 0.0

    def add(self, x: float) -> None:
        self._counts[int(np.searchsorted(self._edges, x))] += 1
        self.count += 1
        self.max = max(self.max, x)

    def percentile(self, q: float) -> float:
        if not self.count:
            return float("nan")
        i = int(np.searchsorted(np.cumsum(self._counts), q / 100.0 * self.count))
        return float(self._edges[min(i, self._edges.size - 1)])

    def summary(self, period: float | None) -> dict:
        out = {"samples": self.count, "p50_s": self.percentile(50), "p99_s": self.percentile(99), "max_s": self.max}
        if period:
            out.update({k.replace("_s", "_of_period"): v / period for k, v in list(out.items())[1:]})
        return out


class _Lines:
    """Complete lines of a growing file or of standard input; stops on EOF (stdin), idle or a signal."""

    def __init__(self, path: str | None, poll: float, idle: float | None, stop: dict) -> None:
        self.path, self.poll, self.idle, self.stop = path, poll, idle, stop
        self.reason = None

    def __iter__(self):
        buf = b""
        last = time.monotonic()
        fh = None
        fd = None if self.path else sys.stdin.fileno()
        try:
            while True:
                if self.stop.get("signal"):
                    self.reason = self.stop["signal"]
                    return
                chunk = b""
                if fd is None:
                    if fh is None and os.path.exists(self.path):
                        fh = open(self.path, "rb")
                    chunk = fh.read(65536) if fh is not None else b""
                else:
                    ready, _, _ = select.select([fd], [], [], self.poll)
                    if ready:
                        chunk = os.read(fd, 65536)
                        if not chunk:
                            if buf:
                                yield self._decode(buf)
                            self.reason = "end of input"
                            return
                if chunk:
                    buf += chunk
                    *lines, buf = buf.split(b"\n")
                    if lines:
                        last = time.monotonic()
                    for raw in lines:
                        yield self._decode(raw)
                    continue
                if self.idle is not None and time.monotonic() - last > self.idle:
                    self.reason = f"idle for {self.idle:g} s"
                    return
                if fd is None:
                    time.sleep(self.poll)
        finally:
            if fh is not None:
                fh.close()

    def _decode(self, raw: bytes) -> str:
        try:
            return raw.decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:
            raise DataFileError(f"{self.path or '<stdin>'}: not a text (UTF-8) CSV stream") from None


def follow(
    problem,
    out: str | Path,
    *,
    source: str | None = None,
    spec=None,
    options=None,
    poll: float = 0.05,
    idle_timeout: float | None = None,
    stop: dict | None = None,
    on_estimate: Callable[[int, tuple], None] | None = None,
) -> dict:
    """Identify a stream one sample at a time; returns the summary (also written to ``out/summary.json``).

    Parameters
    ----------
    problem : MembraneProblem
        The problem (mesh, sensors) of the estimator.
    out : path
        Output directory, replaced atomically at the end (``lift.csv``, ``summary.json``).
    source : str, optional
        A CSV file that grows; ``None`` reads standard input.
    spec : EstimatorSpec, optional
        A streaming estimator of :mod:`wingopt.estimation.registry` (default: ``resolve(stream=True)``,
        the FvK extended Kalman filter: on FvK truth L1 the linear stream ends -10.9 % ± 0.5 % and the
        Berger stream +12.1 % ± 1.9 %, both "adequate", the FvK stream -0.9 % ± 1.8 %).
    options : IdentifyOptions, optional
        Its options (noise std, sign prior, ...); those it does not use are refused.
    poll, idle_timeout : float
        Sleep at the end of a file; stop after this many seconds without a new line.
    stop : dict, optional
        Set ``stop["signal"] = NAME`` (from a signal handler) to end the stream cleanly.
    on_estimate : callable, optional
        ``on_estimate(k, row)`` after every sample (``row`` as :data:`COLUMNS`).

    Returns
    -------
    dict
        ``samples``, ``lift_N``, ``lift_std_N``, ``stopped``, ``latency``, ``warnings``, ...
    """
    from wingopt.estimation.options import IdentifyOptions
    from wingopt.estimation.registry import resolve
    from wingopt.estimation.runners import build
    from wingopt.measurements.csv_stream import CsvRowParser
    from wingopt.membrane import MembraneModel
    from wingopt.results import ResultDirectory, to_jsonable, write_json
    from wingopt.results.live import LiveCsv

    spec = resolve(stream=True) if spec is None else spec
    options = IdentifyOptions() if options is None else options
    stop = {} if stop is None else stop
    est = build(spec, MembraneModel.from_problem(problem), options, keep=False)
    method = f"{spec.method}-stream"
    name = source or "<stdin>"
    parser = CsvRowParser(problem.sensor_names, name)
    cpu, wall = LatencyStats(), LatencyStats()
    bad, first_bad = 0, None
    t_start = time.perf_counter()
    lines = _Lines(source, poll, idle_timeout, stop)
    failure = None
    with ResultDirectory(out) as tmp, LiveCsv(tmp / "lift.csv", COLUMNS) as live:
        log.info("streaming estimates appended to %s", tmp / "lift.csv")
        try:
            for line in lines:
                for t, y in parser.feed(line):
                    c0, w0 = time.thread_time(), time.perf_counter()
                    e = est.push(t, y)
                    cpu.add(time.thread_time() - c0)
                    wall.add(time.perf_counter() - w0)
                    row = (e.t, e.lift, e.lift_std, e.chi2_per_datum, int(e.adequate), e.phase)
                    live.append(row)
                    if not e.adequate and e.phase == "tracking":
                        bad += 1
                        first_bad = e.t if first_bad is None else first_bad
                    if on_estimate is not None:
                        on_estimate(e.k, row)
                if parser.ended:
                    lines.reason = "end marker"
                    break
                if stop.get("signal"):
                    lines.reason = stop["signal"]
                    break
        except InputError as exc:
            # A bad row ends the stream, but the estimates so far are kept (hours of them, maybe):
            # the record is written, then the error is reported.
            failure = exc
            lines.reason = f"bad input: {exc}"
        summary = _summary(est, parser, lines.reason, cpu, wall, bad, first_bad, name, problem, live.rows)
        summary["method"] = method
        summary["membrane"] = spec.model
        summary["options"] = options.as_dict()
        summary["wall_s"] = time.perf_counter() - t_start
        write_json(tmp / "summary.json", to_jsonable(summary))
    if failure is not None:
        raise failure
    return summary


def _summary(est, parser, reason, cpu, wall, bad, first_bad, source, problem, rows_written) -> dict:
    last = est.last
    finite = last is not None and np.isfinite(last.lift)
    info = est.info()
    warnings = []
    if est.count == 0:
        warnings.append("no data rows received")
    elif info["phase"] != "tracking":
        warnings.append(
            f"the stream ended in the {info['phase']} phase, before the start-up: the estimates are provisional "
            "(prior, provisional lambda and noise level)"
        )
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
        },
        "lift_N": float(last.lift) if finite else None,
        "lift_std_N": float(last.lift_std) if finite else None,
        "chi2_per_datum": float(last.chi2_per_datum) if finite else None,
        "adequate": bool(last.adequate) if last is not None else None,
        "inadequate_samples": bad,
        "latency": lat,
        "estimator": info,
        "warnings": warnings,
    }
