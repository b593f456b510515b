"""Studies as sweeps of independent runs on one engine (dask.distributed, or serial).

* :mod:`~wingopt.workflows.sweep.engine` — :class:`Engine`: local cluster, scheduler, SLURM/PBS or serial;
  shared inputs, longest tasks first, retries and failure records, BLAS capped in the workers.
* :mod:`~wingopt.workflows.sweep.spec` — TOML sweep specs (problem-field overrides, product or cases).
* :mod:`~wingopt.workflows.sweep.records` — append-only JSON-lines records, torn-line guard, per-case table.
* :mod:`~wingopt.workflows.sweep.protocol` — task functions and task lists of the protocol studies.
* :mod:`~wingopt.workflows.sweep.run` — the ``wingopt sweep`` workflow. See docs/studies.md.
"""
