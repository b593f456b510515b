"""Sensor design, the ``wingopt design-sensors`` use case: a problem file in, a layout and files out.

:func:`design_layout` reads the membrane problem, runs the design engine (:mod:`wingopt.design`)
and, with ``montecarlo``, re-ranks its short list by the estimator; :func:`write_design_outputs`
hands the result to :mod:`wingopt.results` (``summary.json``, ``sensors.toml``, the problem file
with the designed sensors) and :mod:`wingopt.plots` (``layout.png``). :func:`run_design` is both,
with every output checked before the design starts: what the command calls.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from pathlib import Path

from wingopt.design import DesignResult, DesignSettings, InformationSettings, design_sensors, predicted_error_field
from wingopt.design.engine import STAGES, check_sensor_count
from wingopt.design.rerank import MonteCarloSettings, adopt, rerank
from wingopt.errors import InputError
from wingopt.plots.design import plot_layout
from wingopt.problem import load_problem, read_problem_table
from wingopt.problem.toml_text import problem_text, sensors_text
from wingopt.progress import Stages
from wingopt.results import (
    ResultDirectory,
    check_new_file,
    check_writable,
    write_json,
    write_text_atomic,
)

__all__ = [
    "DesignRun",
    "DesignProgress",
    "design_settings",
    "design_layout",
    "write_design_outputs",
    "run_design",
    "sensors_header",
]

log = logging.getLogger(__name__)


@dataclass(eq=False)
class DesignRun:
    """What :func:`run_design` produced: the design, its summary and the files written."""

    result: DesignResult
    summary: dict
    sensors_toml: str
    problem_file: Path | None = None
    backup: Path | None = None


class DesignProgress(Stages):
    """The stage lines of a design (``wingopt.progress``): one as each stage of
    :data:`wingopt.design.engine.STAGES` starts, then one at least every ``interval`` s within it
    (from a timer thread too, ``heartbeat``, for a stage that is one long call: the relaxation's
    solver), each with the elapsed time and an estimate of the rest (the stages' relative costs,
    measured on the default membrane, scaled by the time taken so far). Pass it as ``progress``;
    :meth:`finish` (or :meth:`stop`) ends the timer."""

    COSTS = {"model": 5.0, "information": 35.0, "criteria": 5.0, "relaxation": 6.0, "greedy": 20.0, "swaps": 100.0}
    LABELS = {
        "model": "modes and candidate matrices",
        "information": "information of every candidate",
        "criteria": "criteria",
        "relaxation": "convex relaxation",
        "greedy": "greedy starts",
        "swaps": "swaps",
    }

    def __init__(self, what: str, interval: float = 5.0, heartbeat: bool = True, **kw) -> None:
        self.fraction = 0.0
        self.interval = float(interval)
        self.last = None
        self._lock = threading.RLock()
        self._stop = threading.Event()
        super().__init__([self.COSTS[n] for n in STAGES], what, **kw)
        if heartbeat and self.enabled:
            threading.Thread(target=self._beat, name="design-progress", daemon=True).start()

    def _say(self, line: str) -> None:
        with self._lock:
            self.last = self.clock()
            super()._say(line)

    def _done_cost(self) -> float:
        done = sum(self.costs[: max(self.index - 1, 0)])
        return done + (self.fraction * self.costs[self.index - 1] if self.index else 0.0)

    def _line(self) -> None:
        stage = STAGES[self.index - 1]
        done = f"{100 * self.fraction:.0f} %" if self.fraction > 0 else "running"
        self._say(f"[{self.index}/{len(self.costs)}] {self.LABELS[stage]}, {done} ({self._when()})")

    def _beat(self) -> None:
        while not self._stop.wait(min(self.interval, 1.0)):
            with self._lock:
                if self.index and not self._stop.is_set() and self.clock() - self.last >= self.interval:
                    self._line()

    def __call__(self, stage: str, fraction: float) -> None:
        k = STAGES.index(stage) + 1
        with self._lock:
            self.fraction = min(max(float(fraction), 0.0), 1.0)
            if k != self.index:
                self.index = k - 1
                self.start(self.LABELS[stage])
            elif self.clock() - self.last >= self.interval:
                self._line()

    def stop(self) -> None:
        """End the timer thread (no more lines)."""
        self._stop.set()

    def finish(self) -> float:
        self.stop()
        with self._lock:
            return super().finish()


def design_settings(
    *, noise_fraction: float = 0.01, t_end: float = 1.0, noise: float | None = None, **fields
) -> DesignSettings:
    """The :class:`DesignSettings` of the command's options: ``noise_fraction`` (of each sensor's
    peak, 0.01 = 1 %; ``wingopt design-sensors --noise`` is in percent) and ``t_end`` (the record
    length, s) set its information; ``fields`` are its own (``criterion``, ``prior``,
    ``length_scale``, ``nominal_count``, ``aggregate``, ``allow_overlap``). The former ``noise`` is
    refused (:class:`InputError`): its unit was not in its name."""
    if noise is not None:
        raise InputError(f"noise = {noise!r}: give noise_fraction (0.01 = 1 % of each sensor's peak output)")
    window = min(0.2, t_end) if t_end > 0 else 0.2
    return DesignSettings(
        **fields, information=InformationSettings(noise_fraction=noise_fraction, t_end=t_end, window_s=window)
    )


def design_layout(
    problem, count: int, candidates=None, settings: DesignSettings | None = None, montecarlo: int = 0, progress=None
):
    """Design ``count`` sensors for ``problem`` (a problem file, a built-in name or a loaded problem).

    ``montecarlo = N > 0`` re-ranks the design's ``N`` best layouts by the estimator's mean error on
    the nominal loads (``risk`` only; :mod:`wingopt.design.rerank`), at the settings' noise and
    record length. ``progress``: ``True`` for the stage lines (:class:`DesignProgress`), or a
    ``progress(stage, fraction)`` callable, or ``None`` (quiet).
    """
    from wingopt.resources import check_count

    s = settings or DesignSettings()
    if isinstance(montecarlo, bool) or not isinstance(montecarlo, int):
        raise InputError(f"montecarlo = {montecarlo!r}: expected a whole number (a short-list size)")
    if montecarlo < 0 or (montecarlo and s.criterion != "risk"):
        raise InputError(f"montecarlo = {montecarlo}: expected a positive short-list size, with --criterion risk")
    check_count("montecarlo", montecarlo)
    prob = load_problem(problem) if isinstance(problem, (str, Path)) else problem
    if prob.kind != "membrane":
        raise InputError(f"problem = {str(problem)!r}: design-sensors needs a membrane problem, got {prob.kind!r}")
    check_sensor_count(count)  # before any stage line
    if progress is True:
        progress = DesignProgress(f"{count} sensors, criterion {s.criterion}")
    try:
        result = design_sensors(prob, count, candidates, s, progress=progress)
    finally:
        if isinstance(progress, DesignProgress):
            progress.stop()
    if isinstance(progress, DesignProgress):
        progress.finish()
    if montecarlo:
        mcs = MonteCarloSettings(
            shortlist=montecarlo, noise_fraction=s.information.noise_fraction, t_end=s.information.t_end
        )
        result = adopt(result, rerank(result, mcs))
    return result


def sensors_header(result: DesignResult) -> str:
    """The comment above the written ``[[sensors]]`` tables."""
    name = getattr(result.problem, "name", "membrane")
    return (
        f"{result.count} sensors designed by wingopt design-sensors ({result.settings.criterion}) for {name};\n"
        f"predicted mean relative load error {result.predictions['risk_relative_load_error']:.3f}"
    )


def write_design_outputs(
    result: DesignResult,
    out: str | Path,
    *,
    plots: bool = True,
    write_problem: str | Path | None = None,
    source=None,
    force: bool = False,
) -> DesignRun:
    """Write ``summary.json``, ``sensors.toml`` and ``layout.png`` into ``out`` (atomically).

    ``write_problem``: also write the problem file ``source`` (a path or built-in name; default the
    design's problem name) with its ``[[sensors]]`` replaced by the design, atomically; an existing
    file there (the input problem file included) is refused unless ``force``, and then first kept
    as ``NAME.bak`` (:mod:`wingopt.results.ownership`).
    """
    if not isinstance(result, DesignResult):
        raise InputError(f"result = {type(result).__name__}: expected the DesignResult of design_sensors")
    header = sensors_header(result)
    toml = sensors_text(result.rects, header=header)
    summary = result.summary()
    inputs = _inputs(source if source is not None else result.problem)
    if write_problem is not None:
        check_new_file(write_problem, "write-problem", force=force, inputs=inputs)
    with ResultDirectory(out, inputs=[*inputs, ("--write-problem", write_problem)]) as tmp:
        write_json(tmp / "summary.json", summary)
        (tmp / "sensors.toml").write_text(toml)
        if plots:
            default = [s.rect for s in result.problem.sensors]
            plot_layout(tmp / "layout.png", result, predicted_error_field(result), default)
    run = DesignRun(result, summary, toml)
    if write_problem is not None:
        table = read_problem_table(source if source is not None else result.problem.name)
        text = problem_text(table, result.rects, header=header)
        run.problem_file, run.backup = write_text_atomic(
            write_problem, text, what="write-problem", force=force, inputs=inputs
        )
        if run.backup is not None:
            log.info("kept the earlier %s as %s", run.problem_file.name, run.backup.name)
    return run


def run_design(
    problem,
    count: int,
    out: str | Path,
    *,
    candidates=None,
    montecarlo: int = 0,
    plots: bool = True,
    write_problem: str | Path | None = None,
    force: bool = False,
    progress=True,
    **options,
) -> DesignRun:
    """:func:`design_layout` then :func:`write_design_outputs`, both outputs checked first.

    ``problem`` is a problem file or built-in name (the source of ``write_problem``) or a loaded
    problem; ``options`` are those of :func:`design_settings`; ``force`` lets ``write_problem``
    replace an existing file (kept as ``NAME.bak``); ``progress`` as in :func:`design_layout`
    (default the stage lines, shown where ``wingopt.progress`` logs at INFO: the command line).
    """
    inputs = _inputs(problem)
    check_writable(out, inputs=[*inputs, ("--write-problem", write_problem)])
    settings = design_settings(**options)
    if write_problem is not None:
        check_new_file(write_problem, "write-problem", force=force, inputs=inputs)
    result = design_layout(problem, count, candidates, settings, montecarlo, progress=progress)
    source = problem if isinstance(problem, (str, Path)) else None
    return write_design_outputs(result, out, plots=plots, write_problem=write_problem, source=source, force=force)


def _inputs(problem) -> list[tuple[str, str]]:
    """The input problem file (a path, or a loaded problem's source) as ``(option, path)``."""
    if isinstance(problem, (str, Path)):
        return [("problem", str(problem))]
    src = getattr(problem, "source", None)
    return [("problem", str(src))] if src else []
