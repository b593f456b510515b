"""Streaming path of ``wingopt identify``: ``--follow FILE.csv`` (a file that grows) and ``--data -``.

Rows are read as they arrive (complete lines only; at the end of the file the follower sleeps
``--poll`` seconds and looks again), each sample goes through
:class:`~wingopt.estimation.streaming.StreamingEstimator`, its estimate is printed on stdout (every
``--print-every``-th sample, CSV) and appended, flushed, to ``lift.csv`` in the run's working
directory (the hidden sibling ``.OUT.tmp-*`` of ``--out``, readable while the run goes). The run
stops at the end marker line ``# end``, at the end of standard input, after ``--idle-timeout``
seconds without a new line, or on SIGTERM / SIGINT; then ``summary.json`` is written and the
directory is moved to ``--out`` atomically. Every sample's estimate is in ``lift.csv`` exactly once
(gap rows filled by the reader included). A bad row (irregular time, a non-numeric cell) ends the
stream: the record so far is written (``stopped``: ``bad input: ...``), then the one-line error
(exit 2).
"""

from __future__ import annotations

import json
import logging
import os
import select
import signal
import sys
import time

import numpy as np

from wingopt.errors import DataFileError, InputError

__all__ = ["add_options", "wants_stream", "run_stream", "LatencyStats"]

log = logging.getLogger(__name__)

COLUMNS = ("t", "lift_N", "lift_std_N", "chi2_per_datum", "adequate", "phase")


def add_options(parser) -> None:
    """The streaming options of ``wingopt identify`` (``--follow`` itself is in the source group)."""
    g = parser.add_argument_group(
        "streaming (--follow FILE.csv or --data -)",
        "one estimate per sample: CSV on stdout (t,lift_N,lift_std_N,chi2_per_datum,adequate,phase), appended "
        "and flushed to lift.csv in the hidden working directory .OUT.tmp-*, moved to --out with summary.json at "
        "the end; stops at a line '# end', at the end of stdin, after --idle-timeout or on SIGTERM/SIGINT; the "
        "summary line (or --json) goes to stderr; --model nonlinear streams the Berger membrane (an extended Kalman "
        "filter, prestrains and damping identified), otherwise the linear MHE",
    )
    g.add_argument("--print-every", type=int, default=1, metavar="K", help="print every K-th estimate (default 1)")
    g.add_argument(
        "--idle-timeout",
        type=float,
        metavar="S",
        help="stop after S seconds without a new line (default: wait until '# end', end of input or SIGTERM)",
    )
    g.add_argument("--poll", type=float, default=0.05, metavar="S", help="sleep at the end of the file (default 0.05)")


def wants_stream(args) -> bool:
    return bool(getattr(args, "follow", None)) or getattr(args, "data", None) == "-"


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


def _fmt(v) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def run_stream(args, mhe_settings) -> int:
    """``wingopt identify PROBLEM --follow FILE`` / ``--data -``; returns the exit code."""
    from wingopt.estimation.csv_stream import CsvRowParser
    from wingopt.estimation.streaming import StreamingEstimator, StreamSettings
    from wingopt.membrane import MembraneModel
    from wingopt.problem import load_problem, parse_mesh
    from wingopt.results import ResultDirectory, check_writable, to_jsonable, write_json
    from wingopt.results.live import LiveCsv

    if args.method != "mhe":
        raise InputError(f"--method {args.method}: streaming (--follow, --data -) supports mhe only")
    if args.print_every < 1:
        raise InputError(f"--print-every {args.print_every}: expected a positive integer")
    if args.idle_timeout is not None and not args.idle_timeout > 0:
        raise InputError(f"--idle-timeout {args.idle_timeout}: expected a positive number of seconds")
    if not args.poll > 0:
        raise InputError(f"--poll {args.poll}: expected a positive number of seconds")
    check_writable(args.out)
    problem = load_problem(args.problem)
    if problem.kind != "membrane":
        raise InputError(f"problem = {args.problem!r}: identify needs a membrane problem, got kind {problem.kind!r}")
    if args.mesh:
        problem = problem.with_mesh(parse_mesh(args.mesh))
    model = MembraneModel.from_problem(problem)
    if getattr(args, "model", "auto") == "fvk":
        raise InputError(
            "--model fvk: the FvK membrane is batch only (wingopt identify --data FILE); a stream runs the linear "
            "MHE (--model auto or linear) or the Berger membrane (--model nonlinear)"
        )
    # auto streams the linear MHE: the nonlinear stream (Berger) is not measured on FvK truth
    if getattr(args, "model", "auto") == "nonlinear":
        from wingopt.estimation.streaming.nonlinear import NonlinearStreamingEstimator

        est = NonlinearStreamingEstimator(model, noise_std=args.noise_std, initial_load=args.initial_load)
        method = "nonlinear-stream"
    else:
        est = StreamingEstimator(model, StreamSettings(mhe=mhe_settings), args.noise_std, args.initial_load)
        method = "mhe-stream"
    source = args.follow or "<stdin>"
    parser = CsvRowParser(problem.sensor_names, source)
    stop: dict = {}
    previous = {}

    def handler(signum, frame):
        stop["signal"] = signal.Signals(signum).name

    for sig in (signal.SIGTERM, signal.SIGINT):
        previous[sig] = signal.signal(sig, handler)
    cpu, wall = LatencyStats(), LatencyStats()
    bad, first_bad = 0, None
    t_start = time.perf_counter()
    lines = _Lines(args.follow, args.poll, args.idle_timeout, stop)
    try:
        with ResultDirectory(args.out) as tmp, LiveCsv(tmp / "lift.csv", COLUMNS) as live:
            log.info("streaming estimates appended to %s", tmp / "lift.csv")
            print(",".join(COLUMNS), flush=True)
            failure = None
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
                        if e.k % args.print_every == 0:
                            print(",".join(_fmt(v) for v in row), flush=True)
                    if parser.ended:
                        lines.reason = "end marker"
                        break
                    if stop.get("signal"):
                        lines.reason = stop["signal"]
                        break
            except InputError as exc:
                # A bad row ends the stream, but the estimates so far are kept (hours of them, maybe):
                # the record is written, then the error is reported (exit 2).
                failure = exc
                lines.reason = f"bad input: {exc}"
            summary = _summary(est, parser, lines.reason, cpu, wall, bad, first_bad, source, problem, live.rows)
            summary["method"] = method
            summary["wall_s"] = time.perf_counter() - t_start
            write_json(tmp / "summary.json", to_jsonable(summary))
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)
    if failure is not None:
        raise failure
    line = f"{method}: {summary['samples']} samples, lift {summary['lift_N']:.5g} N"
    if summary["lift_std_N"] is not None:
        line += f" ± {summary['lift_std_N']:.2g}"
    line += f", stopped: {summary['stopped']} -> {args.out}"
    print(json.dumps(to_jsonable(summary)) if args.json else line, file=sys.stderr)
    for w in summary["warnings"]:
        log.warning("%s", w)
    return 0


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
