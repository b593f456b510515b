"""The study engine: independent tasks on ``dask.distributed``, or in this process.

A study is a list of :class:`SweepTask` (one run each, returning a record ``dict``) that share
inputs (:class:`SharedInput`: a simulated truth, a built model), computed once and handed to every
task that names them. :class:`Engine` runs them

* ``mode="local"`` (default): an embedded ``LocalCluster``, one single-threaded worker process
  per core; BLAS libraries in the workers are capped to one thread (:data:`BLAS_ENV`, set before
  the worker imports numpy);
* ``mode="scheduler"``: attached to a running scheduler (``scheduler="tcp://host:8786"``);
* ``mode="slurm"`` / ``"pbs"``: a dask-jobqueue cluster (``pip install 'wingopt[cluster]'``)
  from the sweep spec's ``[cluster]`` table;
* ``mode="serial"``: every task in this process, in order (tests, debugging; no dask).

Tasks are submitted longest first (``cost``). A task whose worker dies is re-run on another
worker, an exception is retried, both up to ``retries`` times; then the task yields a failure
record (``status = "failed"`` and the error) instead of stopping the study. When no task has
finished for ``stall_s`` seconds, the tasks the workers hold are cancelled and submitted again,
preferring the other workers (a dask dependency fetch was once seen to wait forever), also up to
``retries`` times.
"""

from __future__ import annotations

import hashlib
import logging
import os
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from wingopt.errors import InputError
from wingopt.progress import Stages, task_label

__all__ = ["BLAS_ENV", "EngineSettings", "Engine", "SharedInput", "SweepTask", "MODES", "empty_task", "blas_threads"]

log = logging.getLogger(__name__)

MODES = ("local", "serial", "scheduler", "slurm", "pbs")

BLAS_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "VECLIB_MAXIMUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
}
"""Environment of the worker processes: one BLAS thread each (workers = cores already fill the machine)."""


@dataclass(frozen=True)
class SharedInput:
    """An input computed once per study (``fn(*args)``) and passed to the tasks that name ``key``."""

    key: str
    fn: Callable[..., Any]
    args: tuple = ()


@dataclass(frozen=True)
class SweepTask:
    """One run: ``fn(*shared_values, *args)`` returns the record (a JSON-able ``dict``).

    ``key`` identifies the task across runs (records are matched on it by ``--resume``); ``cost``
    is a relative run-time estimate (the longest tasks are submitted first).
    """

    key: str
    fn: Callable[..., dict]
    args: tuple = ()
    shared: tuple[str, ...] = ()
    cost: float = 1.0


@dataclass(frozen=True)
class EngineSettings:
    """How to run a study. ``workers``: processes of the local cluster (default: the CPU count),
    or the jobs to request from a batch cluster; ``cluster``: dask-jobqueue keyword arguments;
    ``progress``: a stage line per finished task (:mod:`wingopt.progress`, shown by the CLI)."""

    mode: str = "local"
    workers: int | None = None
    scheduler: str | None = None
    cluster: dict = field(default_factory=dict)
    retries: int = 2
    progress: bool = True
    dashboard: bool = True
    stall_s: float | None = 1800.0

    def __post_init__(self):
        if self.mode not in MODES:
            raise InputError(f"mode = {self.mode!r}: expected one of {', '.join(MODES)}")
        if self.workers is not None and self.workers < 1:
            raise InputError(f"workers = {self.workers}: expected a positive integer")
        if self.retries < 0:
            raise InputError(f"retries = {self.retries}: expected a non-negative integer")
        if self.stall_s is not None and not self.stall_s > 0:
            raise InputError(f"stall_s = {self.stall_s!r}: expected a positive number of seconds or None")
        if self.mode == "scheduler" and not self.scheduler:
            raise InputError("scheduler: expected an address such as tcp://host:8786")


def _dask_key(prefix: str, key: str, run: str) -> str:
    # Unique per run: a key cancelled by an interrupted run must not shadow the same task resubmitted.
    return f"{prefix}-{run}-{hashlib.sha1(key.encode()).hexdigest()[:20]}"


def _execute(fn: Callable[..., dict], key: str, args: tuple, *shared) -> dict:
    """Run one task (on a worker, or here) and stamp its record with the key and its timings."""
    t0, c0 = time.perf_counter(), time.process_time()
    record = dict(fn(*shared, *args))
    record.update(
        key=key,
        status="ok",
        duration_s=time.perf_counter() - t0,
        cpu_s=time.process_time() - c0,
        pid=os.getpid(),
    )
    return record


MAX_WORKER_DEATHS = 5
"""Times a task is run again because its worker died under it (not counted against its retries)."""


def _worker_lost(exc) -> bool:
    """``exc`` says the task's worker died or the scheduler lost the task, not that the task raised."""
    if exc is None:
        return True
    name = type(exc).__name__
    return name in ("KilledWorker", "CancelledError", "FutureCancelledError", "CommClosedError") or isinstance(
        exc, (ConnectionError, EOFError)
    )


def _failure(task: SweepTask, exc: BaseException) -> dict:
    return {"key": task.key, "status": "failed", "error": f"{type(exc).__name__}: {exc}"}


def empty_task() -> dict:
    """A task that does nothing (the engine's per-task overhead, benchmarks/bench_sweep.py)."""
    return {}


def blas_threads() -> dict:
    """The BLAS thread pools of this process (threadpoolctl) and the thread variables it sees."""
    import numpy as np  # noqa: F401 - load BLAS before asking
    from threadpoolctl import threadpool_info

    return {
        "pools": [{"api": p["internal_api"], "threads": p["num_threads"]} for p in threadpool_info()],
        "env": {k: os.environ.get(k) for k in BLAS_ENV},
    }


class Engine:
    """Context manager: starts (or attaches to) the cluster, runs studies, closes what it started.

    Examples
    --------
    >>> with Engine(EngineSettings(mode="serial")) as eng:     # doctest: +SKIP
    ...     for record in eng.run(tasks, shared):
    ...         save(record)
    """

    def __init__(self, settings: EngineSettings | None = None) -> None:
        self.settings = settings or EngineSettings()
        self.client = None
        self._cluster = None

    # -- cluster life cycle ------------------------------------------------------------------------
    def __enter__(self) -> Engine:
        s = self.settings
        if s.mode == "serial":
            return self
        import dask
        from distributed import Client

        # Worker deaths count against the same bound as exceptions (scheduler-side setting: it
        # takes effect for the clusters started here, not for an attached scheduler).
        config = {
            "distributed.scheduler.allowed-failures": s.retries,
            "distributed.nanny.pre-spawn-environ": dict(BLAS_ENV),
        }
        # dask logs every start and stop at INFO; keep its warnings (worker deaths) unless debugging.
        if logging.getLogger("wingopt").getEffectiveLevel() > logging.DEBUG:
            logging.getLogger("distributed").setLevel(logging.WARNING)
        with dask.config.set(config):
            if s.mode == "local":
                from distributed import LocalCluster

                self._cluster = LocalCluster(
                    n_workers=s.workers or os.cpu_count() or 1,
                    threads_per_worker=1,
                    processes=True,
                    # the scheduler serves its HTTP routes even without a dashboard, on 8787 unless
                    # told otherwise: a free port lets two sweeps (or test workers) run side by side
                    dashboard_address=":0",
                    scheduler_kwargs={"dashboard": s.dashboard},
                    env=dict(BLAS_ENV),
                    silence_logs=logging.ERROR,
                )
                self.client = Client(self._cluster)
            elif s.mode == "scheduler":
                try:
                    self.client = Client(s.scheduler, timeout=30)
                except (OSError, TimeoutError, ValueError) as exc:
                    raise InputError(f"scheduler = {s.scheduler!r}: cannot connect ({exc})") from None
            else:
                self._cluster = _jobqueue_cluster(s.mode, s.cluster)
                self._cluster.scale(jobs=s.workers or int(s.cluster.get("jobs", 1)))
                self.client = Client(self._cluster)
        log.info("dask client: %s", self.client)
        return self

    def __exit__(self, *exc) -> bool:
        if self.client is not None:
            self.client.close()
        if self._cluster is not None:
            self._cluster.close()
        self.client = self._cluster = None
        return False

    @property
    def dashboard_link(self) -> str | None:
        """The dashboard's address (``None`` in serial mode, when not asked for, or without bokeh installed)."""
        if self.client is None or not self.settings.dashboard:
            return None
        try:
            import bokeh  # noqa: F401 - the dashboard needs it
        except ImportError:
            return None
        return self.client.dashboard_link

    @property
    def n_workers(self) -> int:
        if self.client is None:
            return 1
        return len(self.client.nthreads())

    def run_on_workers(self, fn: Callable[[], Any]) -> dict:
        """``fn()`` on every worker (or here in serial mode), by worker address."""
        if self.client is None:
            return {"serial": fn()}
        return self.client.run(fn)

    # -- running a study ---------------------------------------------------------------------------
    def run(
        self, tasks: Sequence[SweepTask], shared: Iterable[SharedInput] = (), description: str = "sweep"
    ) -> Iterator[dict]:
        """Yield one record per task as tasks finish (a failure record when retries run out)."""
        shared = {sh.key: sh for sh in shared}
        for t in tasks:
            missing = [k for k in t.shared if k not in shared]
            if missing:
                raise InputError(f"task {t.key!r}: shared input {missing[0]!r} is not defined")
        order = sorted(tasks, key=lambda t: t.cost)  # the cheapest first: results arrive early
        # Stage lines (wingopt.progress): one per finished task, the time so far and the rest estimated
        where = "serial" if self.client is None else f"{self.n_workers} workers"
        what = f"{description}, {len(order)} tasks ({where})"
        stages = Stages([t.cost for t in order], what, seconds=True, enabled=self.settings.progress and bool(order))
        index = {t.key: i for i, t in enumerate(order)}
        runner = self._run_serial if self.client is None else self._run_dask
        for record in runner(order, shared):
            key, status = record.get("key", ""), record.get("status", "ok")
            stages.done(index.get(key, len(stages.finished)), task_label(key, status))
            yield record
        stages.finish()

    def _run_serial(self, tasks: Sequence[SweepTask], shared: dict[str, SharedInput]) -> Iterator[dict]:
        values: dict[str, Any] = {}
        for task in tasks:
            try:
                for k in task.shared:
                    if k not in values:
                        values[k] = shared[k].fn(*shared[k].args)
                args = [values[k] for k in task.shared]
            except Exception as exc:  # a shared input that cannot be computed fails its tasks
                yield _failure(task, exc)
                continue
            for attempt in range(self.settings.retries + 1):
                try:
                    yield _execute(task.fn, task.key, task.args, *args)
                    break
                except Exception as exc:
                    log.warning("task %s failed (attempt %d): %s", task.key, attempt + 1, exc)
                    if attempt == self.settings.retries:
                        yield _failure(task, exc)

    def _run_dask(self, tasks: Sequence[SweepTask], shared: dict[str, SharedInput]) -> Iterator[dict]:
        from distributed import wait

        client, retries = self.client, self.settings.retries
        run = uuid.uuid4().hex[:8]
        needed = {k for t in tasks for k in t.shared}
        # Shared inputs first (highest priority), then the tasks, longest first.
        top = len(tasks) + 1
        futures = {
            k: client.submit(
                shared[k].fn,
                *shared[k].args,
                key=_dask_key("shared", k, run),
                priority=top,
                retries=retries,
                pure=False,
            )
            for k in sorted(needed)
        }
        by_future = {}
        for rank, task in enumerate(tasks):
            fut = self._submit(task, futures, _dask_key("task", task.key, run), priority=len(tasks) - rank)
            by_future[fut.key] = (fut, task)
        attempts: dict[str, int] = {}
        deaths: dict[str, int] = {}
        try:
            while by_future:
                try:
                    done = wait([f for f, _ in by_future.values()], self.settings.stall_s, "FIRST_COMPLETED").done
                except TimeoutError:
                    yield from self._resubmit_stalled(by_future, futures, attempts, run)
                    continue
                for fut in done:
                    _, task = by_future.pop(fut.key)
                    if fut.status == "finished":
                        yield fut.result()
                        fut.release()
                        continue
                    try:
                        exc = fut.exception()
                    except Exception as err:  # cancelled (e.g. the scheduler restarted)
                        exc = err
                    fut.release()
                    if _worker_lost(exc):
                        # The worker died under it (or the scheduler lost it): not the task's failure,
                        # so it costs none of its retries; it runs again on a live worker, within
                        # a budget of its own (a task that kills every worker it runs on ends).
                        deaths[task.key] = n = deaths.get(task.key, 0) + 1
                        if n <= MAX_WORKER_DEATHS:
                            log.warning("task %s: its worker died (%s); running it again (%d)", task.key, exc, n)
                            again = f"{_dask_key('task', task.key, run)}-lost{n}"
                            new = self._submit(task, futures, again, priority=len(tasks) + 1)
                            by_future[new.key] = (new, task)
                            continue
                        exc = RuntimeError(f"its worker died {n} times while running it ({exc})")
                    log.warning("task %s failed after %d retries: %s", task.key, retries, exc)
                    yield _failure(task, exc)
        finally:
            # Interrupted (or done): nothing left running for this study.
            client.cancel([f for f, _ in by_future.values()] + list(futures.values()))

    def _submit(self, task: SweepTask, futures: dict, key: str, **placement):
        """Submit one task on the cluster, its shared inputs as futures (``placement``: priority, workers)."""
        shared = [futures[k] for k in task.shared]
        options = {"key": key, "retries": self.settings.retries, "pure": False, **placement}
        return self.client.submit(_execute, task.fn, task.key, task.args, *shared, **options)

    def _resubmit_stalled(self, by_future: dict, futures: dict, attempts: dict, run: str) -> Iterator[dict]:
        """Cancel the tasks the workers hold (all pending ones if none) and submit them again elsewhere."""
        client, retries = self.client, self.settings.retries
        held = {w: {k for k in keys if k in by_future} for w, keys in client.processing().items()}
        stuck = {w for w, keys in held.items() if keys}
        keys = set().union(*held.values()) or set(by_future)
        others = [w for w in client.scheduler_info()["workers"] if w not in stuck] or None
        log.warning(
            "no task finished for %.0f s: %d task(s) submitted again (held by %d worker(s))",
            self.settings.stall_s,
            len(keys),
            len(stuck),
        )
        for key in keys:
            fut, task = by_future.pop(key)
            fut.cancel()
            attempts[task.key] = n = attempts.get(task.key, 0) + 1
            if n > retries:
                yield _failure(task, TimeoutError(f"no progress for {self.settings.stall_s:g} s, {n} times"))
                continue
            again = f"{_dask_key('task', task.key, run)}-again{n}"
            new = self._submit(task, futures, again, workers=others, allow_other_workers=True)
            by_future[new.key] = (new, task)


def _jobqueue_cluster(kind: str, config: dict):
    """A dask-jobqueue ``SLURMCluster``/``PBSCluster`` from the spec's ``[cluster]`` table."""
    try:
        import dask_jobqueue
    except ImportError:
        raise InputError(
            f"cluster = {kind!r}: needs dask-jobqueue, install it with: pip install 'wingopt[cluster]'"
        ) from None
    cls = {"slurm": dask_jobqueue.SLURMCluster, "pbs": dask_jobqueue.PBSCluster}[kind]
    kwargs = {k: v for k, v in config.items() if k != "jobs"}
    kwargs.setdefault("processes", kwargs.get("cores", 1))
    # One BLAS thread per worker process on the nodes too.
    prologue = [f"export {k}={v}" for k, v in BLAS_ENV.items()]
    kwargs["job_script_prologue"] = list(kwargs.get("job_script_prologue", [])) + prologue
    return cls(**kwargs)
