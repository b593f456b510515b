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
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wingopt.errors import InputError
from wingopt.measurements.clock import RunningClock
from wingopt.measurements.lines import LineSource
from wingopt.workflows.stream_summary import describe, summarise

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
    channels=None,
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
    channels : ChannelMap, optional
        The stream's time and sensor columns and each sensor's gain and offset (``stretch = gain *
        (raw - offset)``); default: the problem's ``[measurements]`` table, if any. Recorded in the
        summary's ``channels``.

    Returns
    -------
    dict
        ``samples``, ``lift_N``, ``lift_std_N``, ``stopped``, ``latency``, ``warnings``, ...
    """
    from wingopt.estimation.runners import build
    from wingopt.measurements.csv_stream import CsvRowParser
    from wingopt.membrane import MembraneModel
    from wingopt.problem import as_problem
    from wingopt.results import ResultDirectory
    from wingopt.results.live import LiveCsv
    from wingopt.results.stream_files import write_stream_outputs

    problem = as_problem(problem, "membrane")
    source, spec, options, stop = _checked(source, spec, options, poll, idle_timeout, stop, on_estimate)
    inputs = [("--follow", source)] + [("problem", getattr(problem, "source", None))]
    writer = ResultDirectory(out, inputs=inputs)  # checked before any work
    check_stream_size(problem)
    est = build(spec, MembraneModel.from_problem(problem), options, keep=False)
    method = f"{spec.method}-stream"
    name = source or "<stdin>"
    channels = channels if channels is not None else problem.measurements
    parser = CsvRowParser(problem.sensor_names, name, channels, warm_up=RunningClock.WARM_UP)
    t_start = time.perf_counter()
    lines = LineSource(source, poll, idle_timeout, stop)
    with writer as tmp, LiveCsv(tmp / "lift.csv", COLUMNS) as live:
        log.info("streaming estimates appended to %s", tmp / "lift.csv")
        push = _Push(est, live, problem.sensor_names, on_estimate)
        failure = _feed(lines, parser, push, stop)
        live.close()
        steady, failure = _finish(est, failure, lines)
        summary = summarise(est, parser, lines, push, name, problem, live.rows, steady)
        mapped = parser if channels is not None else None
        describe(summary, problem, (push.peak, push.peak_sensor), method, spec, options, mapped)
        summary["wall_s"] = time.perf_counter() - t_start
        write_stream_outputs(tmp, summary, name, [("--data", source)] + inputs[1:], problem)
        writer.commit()
    if failure is not None:
        raise _as_stream_error(failure, method, live.rows, writer.target)
    return summary


def _checked(source, spec, options, poll, idle_timeout, stop, on_estimate) -> tuple:
    """``follow``'s arguments once checked, with their defaults: ``(source, spec, options, stop)``."""
    from wingopt.estimation.options import IdentifyOptions
    from wingopt.estimation.registry import resolve

    check_stream_settings(poll, idle_timeout)
    if source is not None:
        source = os.fspath(source) if isinstance(source, os.PathLike) else source
        if not isinstance(source, str) or not source:
            raise InputError(f"source = {source!r}: expected the path of a CSV file, or None for standard input")
        if os.path.isdir(source):
            raise InputError(f"follow = {source!r}: is a directory, expected a CSV file")
        if os.path.exists(source) and not os.path.isfile(source):
            raise InputError(f"follow = {source!r}: not a regular file (a device or a pipe cannot be followed)")
    if stop is not None and not isinstance(stop, dict):
        raise InputError(f"stop = {type(stop).__name__}: expected a dict (stop['signal'] ends the stream)")
    if on_estimate is not None and not callable(on_estimate):
        raise InputError(f"on_estimate = {on_estimate!r}: expected a callable on_estimate(k, row)")
    spec = resolve(stream=True) if spec is None else spec
    if not getattr(spec, "stream", False):
        raise InputError(f"spec = {spec!r}: expected a streaming estimator, resolve(..., stream=True)")
    options = IdentifyOptions() if options is None else options
    if not isinstance(options, IdentifyOptions):
        raise InputError(f"options = {type(options).__name__}: expected wingopt.estimation.options.IdentifyOptions")
    return source, spec, options, ({} if stop is None else stop)


class _Push:
    """One sample into the estimator: its estimate appended to ``lift.csv``, its latency timed, the
    inadequate samples counted and the largest stretch reading kept (the units check)."""

    def __init__(self, est, live, sensor_names, on_estimate) -> None:
        self.est, self.live, self.sensor_names, self.on_estimate = est, live, sensor_names, on_estimate
        self.cpu, self.wall = LatencyStats(), LatencyStats()
        self.bad, self.first_bad = 0, None
        self.peak, self.peak_sensor = 0.0, ""

    def __call__(self, t, y) -> None:
        ay = np.abs(np.asarray(y, dtype=float))
        if np.isfinite(ay).any() and np.nanmax(ay) > self.peak:
            j = int(np.nanargmax(ay))
            self.peak, self.peak_sensor = float(ay[j]), self.sensor_names[j]
        c0, w0 = time.thread_time(), time.perf_counter()
        e = self.est.push(t, y)
        self.cpu.add(time.thread_time() - c0)
        self.wall.add(time.perf_counter() - w0)
        row = (e.t, e.lift, e.lift_std, e.chi2_per_datum, int(e.adequate), e.phase)
        self.live.append(row)
        if not e.adequate and e.phase == "tracking":
            self.bad += 1
            self.first_bad = e.t if self.first_bad is None else self.first_bad
        if self.on_estimate is not None:
            self.on_estimate(e.k, row)


def _feed(lines, parser, push: _Push, stop: dict) -> BaseException | None:
    """Push every sample of the stream until it stops; what stopped it when it was an error."""
    try:
        for line in lines:
            if lines.take_restart():
                parser.new_file()
            for t, y in parser.feed(line):
                push(t, y)
            if parser.ended:
                lines.reason = "end marker"
                break
            if stop.get("signal"):
                lines.reason = stop["signal"]
                break
        for t, y in parser.flush():  # a record shorter than the clock's warm-up
            push(t, y)
    except BaseException as exc:  # noqa: BLE001 - whatever stops the stream, the record so far is kept
        # A bad row, a numerical failure, an interrupt: the estimates so far (hours of them,
        # maybe) are written with the summary, then the error is raised.
        lines.reason = _stopped_by(exc)
        return exc
    return None


def _finish(est, failure: BaseException | None, lines) -> tuple:
    """``(steady refit, failure)``: an estimator with a ``finish`` (a steady stream's whole-record refit)
    finishes unless the stream failed; its own failure stops the stream as any other would."""
    if failure is not None or not hasattr(est, "finish"):
        return None, failure
    try:
        return est.finish(), None
    except BaseException as exc:  # noqa: BLE001 - the filter's record so far is still written
        lines.reason = _stopped_by(exc)
        return None, exc


def check_stream_settings(poll: float, idle_timeout: float | None) -> None:
    """``poll`` a positive finite number of seconds, ``idle_timeout`` positive (``inf``: none) or ``None``."""
    try:
        poll_ok = 0 < float(poll) <= 3600
    except (TypeError, ValueError):
        poll_ok = False
    if isinstance(poll, bool) or not poll_ok:
        raise InputError(f"poll = {poll!r}: expected a positive number of seconds, at most 3600 (e.g. 0.05)")
    if idle_timeout is not None:
        try:
            idle_ok = float(idle_timeout) > 0
        except (TypeError, ValueError):
            idle_ok = False
        if isinstance(idle_timeout, bool) or not idle_ok:
            raise InputError(f"idle-timeout = {idle_timeout!r}: expected a positive number of seconds")


def check_stream_size(problem) -> None:
    """Refuse, before any work, a stream whose estimator cannot fit (mesh, sensors)."""
    from wingopt import resources

    resources.check(resources.estimate_stream(problem.nodes, len(problem.sensor_names)))


def _stopped_by(exc: BaseException) -> str:
    if isinstance(exc, InputError):
        return f"bad input: {exc}"
    if isinstance(exc, KeyboardInterrupt):
        return "SIGINT"
    signum = getattr(exc, "signum", None)
    if signum is not None:
        import signal

        return signal.Signals(signum).name
    return f"error: {type(exc).__name__}: {exc}"


def _as_stream_error(exc: BaseException, method: str, rows: int, out) -> BaseException:
    """What :func:`follow` raises after it wrote the record so far: a bad row's ``InputError`` and an
    interrupt as they are; any other failure as a one-line :class:`~wingopt.errors.SolverError`."""
    from wingopt.errors import SolverError, WingoptError

    if isinstance(exc, (WingoptError, KeyboardInterrupt, SystemExit)) or not isinstance(exc, Exception):
        return exc
    what = "out of memory" if isinstance(exc, MemoryError) else f"{type(exc).__name__}: {exc}"
    return SolverError(
        method, " ".join(what.split()), f"the stream stopped; its {rows} estimates so far are in {str(out)!r}"
    )
