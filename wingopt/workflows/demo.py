"""The main job on the built-in problems: ``wingopt demo`` / ``make demo``.

1. Morph the plate wing into twist, camber and bending with the QP controller within the
   actuators' limits (-500/+1500 V), next to the seed's LQR saturated at the same limits and the
   seed's unlimited LQR.
2. Identify loads L1–L3 on the membrane (truth on 49x25, estimators on 25x13, 1 % noise) with the
   moving-horizon estimator, the seed-faithful JEKF and the tuned JEKF.
3. Reproduce the seed's reference tables (membrane Table 6.2, plate Table 5.4).

Everything goes into one directory (default ``./wingopt-demo/``), written atomically: per-run
sub-directories with the ``morph``/``identify`` outputs, ``summary.json`` and a single
self-contained ``report.html``.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import InitVar, dataclass
from pathlib import Path

from wingopt import __version__
from wingopt.errors import InputError
from wingopt.estimation.options import IdentifyOptions
from wingopt.progress import Stages
from wingopt.results import ResultDirectory, write_json
from wingopt.workflows.demo_real import REAL_MODELS, REAL_PRESTRAIN, run_real_membrane
from wingopt.workflows.demo_report import REPORT_MORPH_FIGURES, SEED_JEKF_1PCT, demo_report
from wingopt.workflows.studies import METHODS as IDENTIFY_METHODS  # the MHE (with figures), the JEKFs
from wingopt.workflows.studies import SUBJECT

__all__ = ["DemoConfig", "run_demo", "overlay", "stage_costs", "SEED_TABLE_5_4", "SEED_TABLE_6_2", "SEED_JEKF_1PCT"]

SHAPES = ("twist", "camber", "bending")
LOADS = ("L1", "L2", "L3")

SEED_TABLE_5_4 = {(7, 31): [10.116, 40.902, 50.719, 121.488], (13, 61): [9.777, 40.329, 49.940, 119.560]}
SEED_TABLE_6_2 = {(25, 13): [82.14063341, 103.90059613, 132.44779727, 151.45989864]}


@dataclass(frozen=True)
class DemoConfig:
    """What the demo runs. ``quick`` shrinks meshes and durations (tests, smoke runs).

    ``noise_fraction``: the identification's sensor noise as a FRACTION of each sensor's peak
    (0.01 = 1 %). ``morph_figures``: the figures of each morphing run (names from
    :data:`wingopt.plots.morph.FIGURES`; ``None``: all six; the quick run draws the report's three,
    :data:`REPORT_MORPH_FIGURES`). The former keyword ``noise`` still works and warns (FutureWarning).
    """

    plate_nodes: tuple[int, int] = (13, 61)
    t_end: float = 2.0
    noise_fraction: float = 0.01
    seed: int = 0
    jekf_modes: int = 60
    identify_t_end: float = 1.0
    real_membrane: bool = True
    real_truth_nodes: tuple[int, int] = (49, 25)
    real_prestrain: tuple[float, float] = REAL_PRESTRAIN
    morph_figures: tuple[str, ...] | None = None
    noise: InitVar[float | None] = None

    def __post_init__(self, noise: float | None) -> None:
        if noise is not None:
            warnings.warn(
                "DemoConfig(noise=...) is deprecated, use noise_fraction (the same fraction)",
                FutureWarning,
                stacklevel=3,
            )
            object.__setattr__(self, "noise_fraction", float(noise))
        if not (0 <= self.noise_fraction <= 1):
            raise InputError(f"noise_fraction = {self.noise_fraction!r}: expected a fraction in [0, 1] (0.01 = 1 %)")
        if self.morph_figures is not None:
            from wingopt.plots.morph import figure_names

            object.__setattr__(self, "morph_figures", figure_names(self.morph_figures))  # checked before any work

    @classmethod
    def quick(cls) -> DemoConfig:
        return cls(
            plate_nodes=(7, 31),
            t_end=0.5,
            identify_t_end=0.3,
            jekf_modes=30,
            real_truth_nodes=(29, 15),
            morph_figures=REPORT_MORPH_FIGURES,
        )


def stage_costs(cfg: DemoConfig) -> list[tuple[str, float]]:
    """The demo's stages in order, each with its a-priori cost: CPU seconds measured on one core for
    the full (96 s in all) and the quick (37 s) configuration; the unlimited LQR's stage includes
    writing the shape's outputs and figures, the first QP stage building the plate model and its
    plant (shared by the nine runs). The progress lines rescale them as stages finish."""
    quick = cfg.plate_nodes[0] * cfg.plate_nodes[1] <= 7 * 31
    morph = (0.7, 0.3, 1.5) if quick else (4.5, 0.7, 2.8)
    ident = (
        {"mhe": 2.5, "jekf-seed": 2.3, "jekf-tuned": 1.5}
        if quick
        else {"mhe": 3.0, "jekf-seed": 6.5, "jekf-tuned": 3.0}
    )
    real = {"linear": 10.0, "fvk": 1.0} if quick else {"linear": 29.0, "fvk": 4.0}
    stages: list[tuple[str, float]] = []
    for shape in SHAPES:
        stages += [(f"morph {shape}: QP", morph[0]), (f"morph {shape}: saturated LQR", morph[1])]
        stages += [(f"morph {shape}: seed LQR (unlimited)", morph[2])]
    for load in LOADS:
        stages += [(f"identify {load}: {method}", ident[method]) for method in IDENTIFY_METHODS]
    if cfg.real_membrane:
        stages += [(f"real membrane: {m}", real.get(m, 5.0)) for m in REAL_MODELS]
    stages.append(("reference tables", 0.5 if quick else 1.0))
    return stages


def run_demo(out_dir: str | Path = "wingopt-demo", config: DemoConfig | None = None, progress: bool | None = None):
    """Run the demo (morphing QP vs LQR, identification MHE vs JEKF, the seed's tables) into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Output directory, replaced atomically: ``report.html`` plus every run's outputs.
    config : DemoConfig, optional
        Meshes, durations, loads (default: the full demo).
    progress : bool, optional
        ``False``: no stage lines. Otherwise each stage is announced, with the time so far and an
        estimate of the rest, on the ``wingopt.progress`` logger (:mod:`wingopt.progress`: the
        command line shows it on stderr; a library caller sees it once logging is configured).

    Returns
    -------
    dict
        The demo's summary (also written as ``summary.json``).
    """
    from wingopt.problem import load_problem

    if config is not None and not isinstance(config, DemoConfig):
        raise InputError(f"config = {config!r}: expected a DemoConfig (e.g. DemoConfig.quick()) or None")
    if progress is not None and not isinstance(progress, bool):
        raise InputError(f"progress = {progress!r}: expected True, False or None")
    cfg = config or DemoConfig()
    writer = ResultDirectory(out_dir)  # checked before any work
    t_start = time.perf_counter()
    plate = load_problem("plate")
    membrane = load_problem("membrane")
    summary: dict = {"version": __version__, "config": cfg.__dict__, "morph": {}, "identify": {}, "tables": {}}
    costs = stage_costs(cfg)
    what = f"demo{' --quick' if cfg == DemoConfig.quick() else ''}, {len(costs)} stages"
    stages = Stages([c for _, c in costs], what, seconds=True, enabled=progress is not False)
    inner = logging.getLogger("wingopt.progress.identify")  # the demo's own lines say which run is going
    inner_level = inner.level
    inner.setLevel(logging.WARNING)
    try:
        _run(cfg, writer, stages, summary, plate, membrane, t_start)
    finally:
        inner.setLevel(inner_level)
    stages.finish()
    return summary


def _run(cfg, writer, stages, summary, plate, membrane, t_start) -> None:
    from wingopt.membrane import MembraneModel
    from wingopt.plate import PlateModel
    from wingopt.workflows.identify import identify, write_identify_outputs
    from wingopt.workflows.morph import morph, write_morph_outputs

    with writer as tmp:
        # -- 1. morphing ----------------------------------------------------------------------
        pm = PlateModel.from_problem(plate, cfg.plate_nodes)  # the nine runs and the table share its cached ZOH
        for shape in SHAPES:
            stages.start(f"morph {shape}: QP")
            qp = morph(plate, shape, "qp", t_end=cfg.t_end, model=pm)
            stages.start(f"morph {shape}: saturated LQR")
            lo, hi = qp.vmin, qp.vmax
            lqr_sat = morph(plate, shape, "lqr", vmin=lo, vmax=hi, t_end=cfg.t_end, model=pm)
            stages.start(f"morph {shape}: seed LQR (unlimited)")
            lqr_free = morph(plate, shape, "lqr", t_end=cfg.t_end, model=pm)
            write_morph_outputs(qp, tmp / "morph" / shape, compare_with=lqr_sat, figures=cfg.morph_figures)
            # The report shows the QP's figures; the unlimited LQR's run keeps its data, not its figures.
            write_morph_outputs(lqr_free, tmp / "morph" / f"{shape}-lqr-unlimited", plots=False)
            summary["morph"][shape] = {
                "qp": qp.summary(),
                "lqr_saturated": lqr_sat.summary(),
                "lqr_unlimited": lqr_free.summary(),
            }
        # -- 2. load identification -------------------------------------------------------------
        for load in LOADS:
            summary["identify"][load] = {}
            runs = {}
            for method in IDENTIFY_METHODS:
                stages.start(f"identify {load}: {method}")
                run = runs[method] = identify(
                    membrane,
                    load=load,
                    noise_percent=100 * cfg.noise_fraction,
                    seed=cfg.seed,
                    method=method,
                    t_end=cfg.identify_t_end,
                    options=IdentifyOptions(modes=cfg.jekf_modes) if method != SUBJECT else None,
                )
                write_identify_outputs(run, tmp / "identify" / f"{load}-{method}", plots=(method == SUBJECT))
                summary["identify"][load][method] = run.summary()
            overlay(runs, tmp / "identify" / f"{load}-mhe-vs-jekf.png", f"{load}, {100 * cfg.noise_fraction:g} % noise")
        # -- 2b. a real membrane: FvK truth, prestrain off the file's ---------------------------------
        if cfg.real_membrane:
            summary["real_membrane"] = run_real_membrane(membrane, cfg, tmp / "real-membrane", stages.start)
        # -- 3. reference tables -----------------------------------------------------------------
        stages.start("reference tables")
        mem = MembraneModel.from_problem(membrane, (25, 13))
        summary["tables"]["membrane_6_2"] = {
            "mesh": [25, 13],
            "ours": mem.frequencies_hz(4),
            "seed": SEED_TABLE_6_2[(25, 13)],
        }
        seed_plate = SEED_TABLE_5_4.get(tuple(cfg.plate_nodes))
        summary["tables"]["plate_5_4"] = {
            "mesh": list(cfg.plate_nodes),
            "ours": pm.frequencies_hz(4),
            "seed": seed_plate,
        }
        summary["wall_s"] = time.perf_counter() - t_start
        write_json(tmp / "summary.json", summary)
        demo_report(tmp, summary, cfg).write(tmp / "report.html")


def overlay(runs: dict, path: Path, title: str = "") -> Path | None:
    """The MHE's and the JEKF's lift histories with their bands and the truth on one plot (``path``).

    ``runs``: :class:`~wingopt.workflows.identify.IdentifyRun` by method; the MHE and each JEKF
    present are drawn. Returns ``path`` (``None`` when fewer than two estimators are given).
    """
    from wingopt.plots.identify import plot_overlay

    names = {"mhe": "MHE", "jekf-tuned": "tuned JEKF", "jekf-seed": "seed JEKF", "jekf": "JEKF"}
    curves = [
        (names.get(m, m), r.result.t, r.result.lift, r.result.lift_std)
        for m, r in runs.items()
        if m in names and r is not None
    ]
    if len(curves) < 2:
        return None
    case = next((r.case for r in runs.values() if r is not None and r.case is not None), None)
    truth_t = truth = None
    if case is not None:
        truth_t, truth = case.trajectory.t, case.lift_history
    path.parent.mkdir(parents=True, exist_ok=True)
    plot_overlay(path, curves, truth_t, truth, title)
    return path
