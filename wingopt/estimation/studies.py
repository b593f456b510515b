"""Studies on the simulated protocol: estimator comparison and sensor-count consistency.

* :func:`comparison_study` — L1–L3 x noise levels x noise seeds for the MHE, the seed-faithful
  JEKF and the tuned JEKF (spec §5, issue 5): final load, deflection and lift errors, the sign,
  the lift band's coverage, the chosen lambda and, for the MHE, the oracle lambda (the best one
  given the truth, found on a grid of fixed lambdas: it is reported, never used).
* :func:`consistency_study` — the discontinuous rectangle load with growing sensor grids (seed
  §6.3.3); the error must fall as sensors are added.

The clean truth of each load is simulated once (fine mesh) and noise is added per seed, exactly
as :func:`~wingopt.estimation.protocol.simulate_case` does.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from wingopt.errors import InputError
from wingopt.estimation.data import IdentificationResult, Measurements
from wingopt.estimation.mhe import MHESettings, mhe_identify
from wingopt.estimation.protocol import TRUTH_NODES, SimulatedCase, simulate_case
from wingopt.fe import integrate
from wingopt.membrane import MembraneModel, add_noise
from wingopt.problem.membrane import MembraneProblem, StretchSensorSpec

__all__ = [
    "CaseRecord",
    "CleanCases",
    "evaluate",
    "load_field",
    "run_method",
    "METHODS",
    "comparison_study",
    "summarize",
    "comparison_markdown",
    "SEED_TABLE",
    "sensor_grid",
    "consistency_study",
    "oracle_lambda",
    "protocol_sign",
    "sign_and_band_study",
    "Task",
    "ORACLE_OFFSETS",
]

log = logging.getLogger(__name__)

METHODS = ("mhe", "jekf-seed", "jekf-tuned")

SEED_TABLE = {
    # load: (load err 1 %, load err 5 %, deflection err 1 %, deflection err 5 %), spec §5
    "L1": (1.343e-4, 0.2166, 1.537e-6, 2.633e-3),
    "L2": (0.1282, 0.1012, 2.482e-3, 9.419e-4),
    "L3": (0.05672, 0.05448, 2.423e-4, 1.22e-3),
}


def protocol_sign(load: str) -> float:
    """Nominal sign of a protocol load (+ for L1–L3, - for the consistency rectangle).

    The simulated protocol hands it to the estimators as the sign prior, as a lab would state
    whether the wing is loaded from below or above; it is not derived from the simulated truth.
    """
    return -1.0 if load == "consistency" else 1.0


class CleanCases:
    """Noise-free protocol runs, simulated once per load; :meth:`case` adds seeded noise.

    ``tell_noise=False`` (default) leaves ``Measurements.noise_std`` empty, so estimators must
    estimate the noise level from the data, as with measurements.
    """

    def __init__(
        self,
        problem: MembraneProblem,
        truth_nodes: tuple[int, int] | None = TRUTH_NODES,
        t_end: float = 1.0,
        tell_noise: bool = False,
    ):
        self.problem, self.truth_nodes, self.t_end = problem, truth_nodes, t_end
        # By default the estimators are not told the simulated noise level (they estimate it).
        self.tell_noise = tell_noise
        self._clean: dict[str, SimulatedCase] = {}

    def clean(self, load: str) -> SimulatedCase:
        if load not in self._clean:
            self._clean[load] = simulate_case(self.problem, load, 0.0, None, self.truth_nodes, self.t_end)
        return self._clean[load]

    def case(self, load: str, noise: float, seed: int) -> SimulatedCase:
        """The protocol case with noise ``noise`` (fraction) and ``seed``; same as ``simulate_case``."""
        c = self.clean(load)
        noisy, sigma = add_noise(c.trajectory.outputs, noise, seed)
        meas = dataclasses.replace(
            c.measurements,
            values=noisy,
            noise_std=sigma if self.tell_noise else None,
            source=c.measurements.source.replace("0% seed None", f"{100 * noise:g}% seed {seed}"),
        )
        return dataclasses.replace(c, measurements=meas, noise_fraction=noise, seed=seed)


def load_field(result: IdentificationResult, model: MembraneModel, k: int = -1) -> Callable:
    """Callable ``(x, y)``: the estimated pressure at sample ``k`` in the result's own basis."""
    space = result.load_space if result.load_space is not None else model.space
    coef = np.asarray(result.load[k], dtype=float)

    def pressure(x, y):
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        return space.evaluate(coef, x.ravel(), y.ravel()).reshape(x.shape)

    return pressure


@dataclass
class CaseRecord:
    """Final-time metrics of one estimator on one case."""

    load: str
    noise: float
    seed: int
    method: str
    load_error: float
    deflection_error: float
    lift: float
    true_lift: float
    lift_error: float
    lift_std: float | None
    covered: bool | None
    sign_ok: bool
    regularization: float
    wall_s: float
    oracle_regularization: float | None = None
    oracle_load_error: float | None = None
    onset_skipped_s: float | None = None
    restarts: int | None = None

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def evaluate(case: SimulatedCase, result: IdentificationResult, model: MembraneModel, method: str) -> CaseRecord:
    """Final load/deflection errors (relative L2 over the membrane), lift error and sign of a result.

    The lift error is ``|lift - true lift| / ∫|P|`` (L2 has no net lift). The sign is right when
    the estimated pressure correlates positively with the true one.
    """
    P = load_field(result, model)
    space = case.truth_model.space
    lerr = case.load_error(P)
    derr = case.deflection_error(model.field(result.final_deflection))
    lift = float(result.lift[-1])
    true = case.true_lift
    std = None if result.lift_std is None else float(result.lift_std[-1])
    corr = integrate(space, lambda x, y: case.load(x, y) * P(x, y), order=8)
    onset = result.info.get("onset")
    return CaseRecord(
        load=case.load.name,
        noise=case.noise_fraction,
        seed=int(case.seed),
        method=method,
        load_error=lerr,
        deflection_error=derr,
        lift=lift,
        true_lift=true,
        lift_error=abs(lift - true) / case.true_absolute_load,
        lift_std=std,
        covered=None if std is None or not np.isfinite(std) else bool(abs(lift - true) <= std),
        sign_ok=bool(corr > 0),
        regularization=float(result.regularization),
        wall_s=float(result.wall_s),
        # The MHE's consistency tests (a skipped load onset, restarts on a changed load).
        onset_skipped_s=None if onset is None else float(onset["t_start"] - case.trajectory.t[0]),
        restarts=None if "restarts" not in result.info else len(result.info["restarts"]),
    )


def run_method(
    method: str,
    model: MembraneModel,
    measurements: Measurements,
    mhe_settings: MHESettings | None = None,
    initial_load: float | None = None,
    truth: SimulatedCase | None = None,
    **kwargs,
) -> IdentificationResult:
    """Run ``mhe``, ``jekf-seed`` (the seed's filter, lambda tuned on the noise-free truth as in the
    seed) or ``jekf-tuned`` (zero initial load, lambda from the data) on ``measurements``."""
    if method == "mhe":
        return mhe_identify(model, measurements, mhe_settings, initial_load=initial_load, **kwargs)
    if method in ("jekf", "jekf-seed", "jekf-tuned"):
        try:
            from wingopt.estimation import jekf_tuning
        except ImportError as exc:  # pragma: no cover - the JEKF is built in parallel
            raise InputError(f"method {method}: the JEKF is not available ({exc})") from None
        variant = "tuned" if method == "jekf-tuned" else "seed"
        return jekf_tuning.identify(
            model, measurements, variant=variant, truth=truth, initial_load=initial_load, **kwargs
        )
    raise InputError(f"method = {method!r}: expected mhe, jekf-seed or jekf-tuned")


def oracle_lambda(
    case: SimulatedCase, model: MembraneModel, settings: MHESettings, grid: Sequence[float], initial_load=None
) -> tuple[float, float, list[tuple[float, float]]]:
    """The lambda of ``grid`` with the least final MHE load error *given the truth* (studies only)."""
    errs = []
    for lam in grid:
        res = mhe_identify(
            model, case.measurements, settings.replace(regularization=float(lam)), initial_load=initial_load
        )
        errs.append((float(lam), case.load_error(load_field(res, model))))
    lam, err = min(errs, key=lambda e: e[1])
    return lam, err, errs


@dataclass(frozen=True)
class Task:
    """One (case, seed, method) run of a study."""

    load: str
    noise: float
    seed: int
    method: str

    @property
    def key(self) -> tuple:
        return (self.load, round(self.noise, 6), self.seed, self.method)


_WORKER: dict = {}


def _worker_init(problem, truth_nodes, settings, oracle, oracle_offsets):
    _WORKER.update(
        model=MembraneModel.from_problem(problem),
        clean=CleanCases(problem, truth_nodes),
        settings=settings,
        oracle=oracle,
        offsets=oracle_offsets,
        problem=problem,
    )


def _pool_worker_init(*init):
    """Worker set-up with BLAS capped at one thread: ``jobs`` workers each running a threaded BLAS
    oversubscribe the cores (measured up to 10x slower, docs/jekf.md). threadpoolctl applies the
    cap after numpy is loaded (environment variables would be read too late in a forked worker)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)
    _worker_init(*init)


def _run_task(task: Task) -> CaseRecord:
    w = _WORKER
    model, settings = w["model"], w["settings"]
    case = w["clean"].case(task.load, task.noise, task.seed)
    sign = protocol_sign(task.load) * abs(w["problem"].identification.initial_load)
    t0 = time.perf_counter()
    res = run_method(task.method, model, case.measurements, settings, initial_load=sign, truth=case)
    rec = evaluate(case, res, model, task.method)
    rec.wall_s = time.perf_counter() - t0
    if task.method == "mhe" and w["oracle"]:
        grid = [rec.regularization * 10.0**e for e in w["offsets"]]
        lam, err, _ = oracle_lambda(case, model, settings, grid, initial_load=sign)
        rec.oracle_regularization, rec.oracle_load_error = lam, min(err, rec.load_error)
    return rec


ORACLE_OFFSETS = tuple(np.arange(-2.0, 1.01, 0.5))
"""Oracle grid, in decades around the data-chosen lambda (the rule sits half a decade below the knee)."""


def comparison_study(
    problem: MembraneProblem,
    loads: Sequence[str] = ("L1", "L2", "L3"),
    noises: Sequence[float] = (0.01, 0.05),
    seeds: Iterable[int] = range(5),
    methods: Sequence[str] = METHODS,
    mhe_settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    oracle: bool = True,
    oracle_offsets: Sequence[float] = ORACLE_OFFSETS,
    done: Sequence[CaseRecord] = (),
    jobs: int = 1,
    on_record: Callable[[CaseRecord], None] | None = None,
) -> list[CaseRecord]:
    """Run every method on every case; one :class:`CaseRecord` per (case, seed, method).

    ``oracle``: also find the MHE's oracle lambda per case (least final load error given the
    truth) on ``chosen lambda * 10**oracle_offsets``, to report the gap to the data-only rule.
    ``done``: records already computed (skipped, returned with the new ones). ``jobs``: worker
    processes. ``on_record`` is called with every new record as it arrives (progress, saving).
    """
    settings = mhe_settings or MHESettings()
    have = {(r.load, round(r.noise, 6), r.seed, r.method) for r in done}
    tasks = [
        Task(load, float(noise), int(seed), method)
        for load in loads
        for noise in noises
        for seed in seeds
        for method in methods
        if (load, round(float(noise), 6), int(seed), method) not in have
    ]
    records = list(done)
    init = (problem, truth_nodes, settings, oracle, tuple(oracle_offsets))
    if jobs <= 1 or len(tasks) <= 1:
        _worker_init(*init)
        results = map(_run_task, tasks)
        for rec in results:
            records.append(rec)
            if on_record:
                on_record(rec)
        return records
    import multiprocessing as mp

    with mp.get_context("fork").Pool(jobs, initializer=_pool_worker_init, initargs=init) as pool:
        for rec in pool.imap_unordered(_run_task, tasks):
            records.append(rec)
            if on_record:
                on_record(rec)
    return records


def sign_and_band_study(
    problem: MembraneProblem,
    loads: Sequence[str] = ("L1", "L2", "L3"),
    noise: float = 0.05,
    seeds: Iterable[int] = range(20),
    mhe_settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    done: Sequence[CaseRecord] = (),
    jobs: int = 1,
    on_record: Callable[[CaseRecord], None] | None = None,
) -> list[CaseRecord]:
    """MHE only, many noise seeds: sign right and lift band coverage per load (records as above)."""
    return comparison_study(
        problem, loads, (noise,), seeds, ("mhe",), mhe_settings, truth_nodes, False, (), done, jobs, on_record
    )


def summarize(records: Sequence[CaseRecord]) -> list[dict]:
    """Mean and spread (min–max) over seeds per (load, noise, method)."""
    groups: dict[tuple, list[CaseRecord]] = {}
    for r in records:
        groups.setdefault((r.load, r.noise, r.method), []).append(r)
    out = []
    for (load, noise, method), rs in groups.items():
        row = {"load": load, "noise": noise, "method": method, "seeds": len(rs)}
        for key in ("load_error", "deflection_error", "lift_error", "wall_s"):
            v = np.array([getattr(r, key) for r in rs])
            row[key] = {"mean": float(v.mean()), "min": float(v.min()), "max": float(v.max()), "std": float(v.std())}
        row["sign_ok"] = int(sum(r.sign_ok for r in rs))
        if any(r.restarts is not None for r in rs):
            row["restarts"] = int(sum(r.restarts or 0 for r in rs))
            row["onsets_skipped"] = int(sum(bool(r.onset_skipped_s) for r in rs))
        cov = [r.covered for r in rs if r.covered is not None]
        row["covered"] = int(sum(cov)) if cov else None
        orc = [r.oracle_load_error for r in rs if r.oracle_load_error is not None]
        if orc:
            row["oracle_load_error_mean"] = float(np.mean(orc))
            row["oracle_ratio_max"] = float(max(r.load_error / r.oracle_load_error for r in rs if r.oracle_load_error))
        out.append(row)
    return out


def _fmt(stat: dict) -> str:
    return f"{stat['mean']:.4g} ({stat['min']:.3g}–{stat['max']:.3g})"


def comparison_markdown(summary: Sequence[dict], title: str = "") -> str:
    """The comparison table (mean and min–max over seeds) next to the seed's numbers (spec §5)."""
    lines = []
    if title:
        lines += [title, ""]
    lines.append(
        "| load | noise | method | load error | deflection error | lift error / ∫\\|P\\| | sign ok "
        "| seed's load err | seed's defl. err |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|")
    order = {m: i for i, m in enumerate(METHODS)}
    for row in sorted(summary, key=lambda r: (r["load"], r["noise"], order.get(r["method"], 9))):
        seed = SEED_TABLE.get(row["load"])
        col = 0 if row["noise"] <= 0.011 else 1
        seed_l = f"{seed[col]:.4g}" if seed and row["method"] == "mhe" else ""
        seed_d = f"{seed[2 + col]:.4g}" if seed and row["method"] == "mhe" else ""
        lines.append(
            f"| {row['load']} | {100 * row['noise']:g} % | {row['method']} | {_fmt(row['load_error'])} | "
            f"{_fmt(row['deflection_error'])} | {_fmt(row['lift_error'])} | {row['sign_ok']}/{row['seeds']} | "
            f"{seed_l} | {seed_d} |"
        )
    return "\n".join(lines)


def sensor_grid(problem: MembraneProblem, nx: int, ny: int, fill: float = 0.5) -> tuple[StretchSensorSpec, ...]:
    """``nx * ny`` equal sensors on a regular grid, each covering ``fill`` of its cell per direction."""
    W, L = problem.width, problem.height
    out = []
    for i in range(nx):
        for j in range(ny):
            cx, cy = (i + 0.5) * W / nx, (j + 0.5) * L / ny
            hx, hy = 0.5 * fill * W / nx, 0.5 * fill * L / ny
            out.append(StretchSensorSpec(f"G{i + 1}_{j + 1}", (cx - hx, cx + hx, cy - hy, cy + hy)))
    return tuple(out)


def consistency_study(
    problem: MembraneProblem,
    layouts: Sequence[tuple[int, int] | None] = (None, (4, 3), (8, 4)),
    noise: float = 0.01,
    seeds: Iterable[int] = range(3),
    mhe_settings: MHESettings | None = None,
    truth_nodes: tuple[int, int] | None = TRUTH_NODES,
    progress: Callable[[str], None] | None = None,
) -> list[dict]:
    """Consistency load with the problem's 4 sensors (``None``) and sensor grids; error per layout."""
    out = []
    sign = protocol_sign("consistency") * abs(problem.identification.initial_load)
    for layout in layouts:
        prob = problem if layout is None else problem.with_sensors(sensor_grid(problem, *layout))
        model = MembraneModel.from_problem(prob)
        clean = CleanCases(prob, truth_nodes)
        errs, lifts = [], []
        t0 = time.perf_counter()
        for seed in seeds:
            case = clean.case("consistency", noise, seed)
            res = mhe_identify(model, case.measurements, mhe_settings, initial_load=sign)
            rec = evaluate(case, res, model, "mhe")
            errs.append(rec.load_error)
            lifts.append(rec.lift_error)
        row = {
            "sensors": len(prob.sensors),
            "layout": "problem" if layout is None else f"{layout[0]}x{layout[1]}",
            "load_error_mean": float(np.mean(errs)),
            "load_error_min": float(np.min(errs)),
            "load_error_max": float(np.max(errs)),
            "lift_error_mean": float(np.mean(lifts)),
            "seconds": time.perf_counter() - t0,
        }
        out.append(row)
        if progress:
            progress(f"consistency, {row['sensors']} sensors: load error {row['load_error_mean']:.4f}")
    return out
