"""Streaming path of ``wingopt identify``: ``--follow FILE.csv`` (a file that grows) and ``--data -``.

Rows are read as they arrive (complete lines only; at the end of the file the follower sleeps
``--poll`` seconds and looks again), each sample goes through
:class:`~wingopt.estimation.streaming.StreamingEstimator`, its estimate is printed on stdout (every
``--print-every``-th sample, CSV) and appended, flushed, to ``lift.csv`` in the run's working
directory (the hidden sibling ``.OUT.tmp-*`` of ``--out``, readable while the run goes). The run
stops at the end marker line ``# end``, at the end of standard input, after ``--idle-timeout``
seconds without a new line, on SIGTERM / SIGINT / SIGHUP, or when stdout is closed (the estimates
still go to ``--out``); then ``summary.json`` is written and the directory is moved to ``--out``
atomically. Every sample's estimate is in ``lift.csv`` exactly once (gap rows filled by the reader
included). Whatever else ends the stream keeps the record so far (``stopped`` says why), then one
line: a bad row (irregular time, a non-numeric cell, a line longer than 1 MiB, a gap of more than
100,000 samples) exits 2, a numerical failure of the estimator exits 3. A followed file that is
truncated or rotated is read again from its start, as ``tail -F`` does, with a log line. The CLI
parses, installs the signal handlers and prints; the loop is :func:`wingopt.workflows.stream.follow`.
"""

from __future__ import annotations

import json
import logging
import math
import os
import signal
import sys

from wingopt.cli.helptext import advanced
from wingopt.errors import InputError

__all__ = ["add_options", "wants_stream", "run_stream"]

log = logging.getLogger(__name__)


def add_options(parser) -> None:
    """The streaming options of ``wingopt identify`` (``--follow`` itself is in the source group)."""
    # What a stream prints, keeps and when it stops: docs/cli.md (identify, streams). ``parser``: the
    # parser or the argument group (measured data) the options go in.
    g = parser
    g.add_argument("--print-every", type=int, default=1, metavar="K", help="stream: print every K-th estimate")
    g.add_argument(
        "--idle-timeout",
        type=float,
        metavar="S",
        help="stream: stop after S s without a new line",
    )
    advanced(
        g.add_argument(
            "--poll", type=float, default=0.05, metavar="S", help="sleep at the end of the file (default 0.05)"
        )
    )


def wants_stream(args) -> bool:
    return bool(getattr(args, "follow", None)) or getattr(args, "data", None) == "-"


def _fmt(v) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def run_stream(args, options, channels=None) -> int:
    """``wingopt identify PROBLEM --follow FILE`` / ``--data -``; returns the exit code."""
    from wingopt.cli import _quiet_stdout
    from wingopt.estimation.registry import check_options, resolve
    from wingopt.problem import load_problem, parse_mesh
    from wingopt.results import check_writable, to_jsonable
    from wingopt.workflows.stream import COLUMNS, check_stream_settings, check_stream_size, follow

    if args.print_every < 1:
        raise InputError(f"--print-every {args.print_every}: expected a positive integer")
    check_stream_settings(args.poll, args.idle_timeout)
    idle = args.idle_timeout if args.idle_timeout is not None and math.isfinite(args.idle_timeout) else None
    spec = resolve(args.method, args.model, stream=True)
    check_options(spec, options)
    if args.follow is not None and os.path.isdir(args.follow):
        raise InputError(f"--follow {args.follow!r}: is a directory, expected a CSV file")
    check_writable(args.out, inputs=[("--follow", args.follow), ("problem", args.problem)])
    problem = load_problem(args.problem)
    if problem.kind != "membrane":
        raise InputError(f"problem = {args.problem!r}: identify needs a membrane problem, got kind {problem.kind!r}")
    if args.mesh:
        problem = problem.with_mesh(parse_mesh(args.mesh))
    check_stream_size(problem)
    stop: dict = {}
    previous = {}

    def handler(signum, frame):
        stop["signal"] = signal.Signals(signum).name

    def show(k: int, row: tuple) -> None:
        if k % args.print_every == 0 and not stop.get("stdout closed"):
            try:
                print(",".join(_fmt(v) for v in row), flush=True)
            except BrokenPipeError:  # the reader went away: the estimates still go to --out
                _quiet_stdout()
                stop["stdout closed"] = True
                stop["signal"] = "stdout closed"

    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
        previous[sig] = signal.signal(sig, handler)
    try:
        try:
            print(",".join(COLUMNS), flush=True)
        except BrokenPipeError:
            _quiet_stdout()
            stop["stdout closed"] = True
        summary = follow(
            problem,
            args.out,
            source=args.follow,
            spec=spec,
            options=options,
            poll=args.poll,
            idle_timeout=idle,
            stop=stop,
            on_estimate=show,
            channels=channels,
        )
    finally:
        # A second signal after the stream ended (a double Ctrl-C) must not turn the written record
        # into "nothing written": the rest of the command only reports; main() restores the defaults.
        for sig in previous:
            signal.signal(sig, handler)
    line = f"{summary['method']}: {summary['samples']} samples, lift "
    line += "n/a" if summary["lift_N"] is None else f"{summary['lift_N']:.5g} N"
    if summary["lift_std_N"] is not None:
        line += f" ± {summary['lift_std_N']:.2g}"
    line += f", stopped: {summary['stopped']} -> {args.out}"
    print(json.dumps(to_jsonable(summary)) if args.json else line, file=sys.stderr)
    for w in summary["warnings"]:
        log.warning("%s", w)
    return 0
