"""Stage lines with a time estimate, through :mod:`logging` (the engines stay quiet).

A workflow that runs several stages (the demo's runs, a study's tasks, an identification's
steps) announces each one on the ``wingopt.progress`` logger::

    [3/17] identify L1: mhe (12 s so far, about 40 s left)

The command line shows these lines on stderr, as plain lines whether or not stderr is a
terminal (a pipe, a file, CI, ``nohup``), unless ``--quiet``; a library user sees nothing unless
they configure logging (``logging.getLogger("wingopt.progress").setLevel("INFO")`` and a
handler). The estimate of what is left is the stages' own a-priori costs (seconds, or any unit
in proportion), scaled by how long the stages done so far took against their costs.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Sequence

__all__ = ["Stages", "LOGGER", "fmt_duration", "task_label"]

LOGGER = "wingopt.progress"
"""The logger the stage lines go to (the CLI shows it at INFO unless ``--quiet``)."""


def fmt_duration(seconds: float) -> str:
    """``"40 s"``, ``"3.2 min"``, ``"1.5 h"``, ``"2.1 days"``."""
    if seconds >= 86400:
        return f"{seconds / 86400:.2g} days"
    if seconds >= 3600:
        return f"{seconds / 3600:.2g} h"
    if seconds >= 90:
        return f"{seconds / 60:.2g} min"
    return f"{seconds:.0f} s"


def task_label(key: str, status: str = "ok") -> str:
    """A study task's key (canonical JSON of its parameters) as ``name=value`` pairs for a stage line."""
    try:
        params = json.loads(key)
    except (TypeError, ValueError):
        params = None
    text = " ".join(f"{k}={v}" for k, v in params.items()) if isinstance(params, dict) else str(key)
    return text if status == "ok" else f"{text} [{status}]"


class Stages:
    """Announce the stages of one run, each with the elapsed time and an estimate of the rest.

    Parameters
    ----------
    costs : sequence of float
        A-priori cost of every stage, in order (seconds, or any unit in proportion: the estimate
        rescales them by the time the finished stages took).
    what : str
        Name of the run, e.g. ``"demo, 21 stages"`` (the first and last lines).
    seconds : bool
        ``costs`` are seconds (the first line then says how long the whole run should take).
    logger : logging.Logger, optional
        Default the ``wingopt.progress`` logger.
    clock : callable, optional
        Seconds now (default :func:`time.perf_counter`; tests pass a fake clock).
    enabled : bool
        ``False``: log nothing (the lines are still kept in :attr:`lines`).

    Examples
    --------
    >>> st = Stages([1.0, 3.0], "demo")          # doctest: +SKIP
    >>> st.start("morph twist")                  # doctest: +SKIP
    >>> st.start("identify L1")                  # doctest: +SKIP
    >>> st.finish()                              # doctest: +SKIP
    """

    def __init__(
        self,
        costs: Sequence[float],
        what: str = "run",
        *,
        seconds: bool = False,
        logger: logging.Logger | None = None,
        clock: Callable[[], float] | None = None,
        enabled: bool = True,
    ) -> None:
        self.costs = [max(float(c), 0.0) for c in costs]
        self.what = what
        self.log = logger or logging.getLogger(LOGGER)
        self.clock = clock or time.perf_counter
        self.t0 = self.clock()
        self.index = 0  # stages started (sequential use: ``start``)
        self.finished: set[int] = set()  # stages finished (side-by-side use: ``done``)
        self.lines: list[str] = []
        self.enabled = bool(enabled)
        self.seconds = bool(seconds)
        total = sum(self.costs)
        self._say(f"{what}: about {fmt_duration(total)}" if seconds and total > 0 else what)

    def _say(self, line: str) -> None:
        self.lines.append(line)
        if self.enabled:
            self.log.info("%s", line)

    def remaining(self) -> float | None:
        """Estimated seconds left: the cost not yet done, scaled by the time the done part took
        (before any is done: the a-priori costs when they are seconds, else ``None``)."""
        done = self._done_cost()
        left = sum(self.costs) - done
        if done <= 0:
            return left if self.seconds else None
        return (self.clock() - self.t0) * left / done

    def _done_cost(self) -> float:
        if self.finished:
            return sum(self.costs[i] for i in self.finished)
        return sum(self.costs[: max(self.index - 1, 0)])

    def _when(self) -> str:
        left = self.remaining()
        when = f"{fmt_duration(self.clock() - self.t0)} so far"
        return when + (f", about {fmt_duration(left)} left" if left is not None else "")

    def start(self, label: str) -> None:
        """The next stage begins (stages run one after the other): ``[k/n] label (elapsed, about ... left)``."""
        self.index += 1
        self._say(f"[{self.index}/{len(self.costs)}] {label} ({self._when()})")

    def done(self, index: int, label: str) -> None:
        """Stage ``index`` (0-based) has finished (stages that run side by side, in any order):
        ``[k/n] done: label (elapsed, about ... left)``, ``k`` the stages finished so far."""
        self.finished.add(int(index))
        self._say(f"[{len(self.finished)}/{len(self.costs)}] done: {label} ({self._when()})")

    def finish(self) -> float:
        """The run is done: one line with its total time; returns the seconds it took."""
        elapsed = self.clock() - self.t0
        self._say(f"{self.what}: done in {fmt_duration(elapsed)}")
        return elapsed
