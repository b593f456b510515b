"""Speed of the realistic (nonlinear) estimator on 1 s of 1 kHz data, 25x13, one core.

Record: FvK truth (49x25, the default; ``--truth berger``: the full-order Berger membrane on 49x25,
8 sub-steps per sample; :func:`wingopt.workflows.protocols.simulate_case`), L1, the seed's bubble
start, 1 % noise, noise level estimated from the data. Estimator: the default on data, the
cubic modal FvK model (48 modes, 16 cubic; ``--membrane-model berger`` for the Berger model).
Prints CPU times (``time.process_time``: insensitive to other processes on a shared machine):
the first call (compiled loops loaded or compiled, the modal model built), the per-record time
with the model built (best of ``--repeat``: a lab's records of one wing share the model) and its
ratio to the 1 s real-time budget, the LM iterations and the cost of one exact Jacobian, beside the
linear MHE on the same record::

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_realistic.py [--repeat 3] [--load LE]
    OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_realistic.py --repeat 1   # quickest

The Berger truth was a 120-mode modal Berger model before the model-layer refactor; the truth
generator is now the full-order model (a richer truth than the estimator's, as before).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wingopt.estimation.mhe import mhe_identify  # noqa: E402
from wingopt.estimation.records import RecordSettings, identify_record  # noqa: E402
from wingopt.estimation.transient import run as est_mod  # noqa: E402
from wingopt.membrane import MembraneModel  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.protocols import simulate_case  # noqa: E402

TRUTH_SUBSTEPS = {"fvk": 2, "berger": 8}
"""Integration sub-steps per sample of the truth (as the retired ``fvk_case`` / ``berger_case``)."""


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--modes", type=int, default=RecordSettings().modes)
    ap.add_argument("--substeps", type=int, default=RecordSettings().substeps)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--load", default="L1")
    ap.add_argument("--truth", choices=("fvk", "berger"), default="fvk")
    ap.add_argument("--membrane-model", choices=("fvk", "berger"), default="fvk")
    ap.add_argument(
        "--record",
        choices=("transient", "auto", "steady"),
        default="transient",
        help="RecordSettings.record (default transient: the whole-record fit timed here; 'auto' now sends "
        "this bubble-start FvK record to the steady estimator, which has no LM problem to time)",
    )
    a = ap.parse_args(argv)
    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem)
    case = simulate_case(problem, a.load, 0.01, 0, truth=a.truth, substeps=TRUTH_SUBSTEPS[a.truth], tell_noise=False)
    meas = dataclasses.replace(case.measurements, noise_std=None)  # the noise level is estimated
    s = RecordSettings(modes=a.modes, substeps=a.substeps, membrane_model=a.membrane_model, record=a.record)
    captured = {}
    orig = est_mod.levenberg_marquardt

    def spy(problem, *args, **kwargs):
        captured.setdefault("rp", getattr(problem, "problem", problem))  # the first fit's (a watched one unwrapped)
        return orig(problem, *args, **kwargs)

    est_mod.levenberg_marquardt = spy
    c0 = time.process_time()
    identify_record(model, meas, s)
    first = time.process_time() - c0
    cpu, wall = [], []
    for _ in range(a.repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        res = identify_record(model, meas, s)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    est_mod.levenberg_marquardt = orig
    rp = captured.get("rp")  # None: the steady-record estimator ran (no whole-record LM problem)
    if rp is not None:
        c0 = time.process_time()
        rp.residuals(np.zeros(rp.dim), jacobian=True)
        jac = time.process_time() - c0
        c0 = time.process_time()
        rp.residuals(np.zeros(rp.dim))
        resid = time.process_time() - c0
    c0, w0 = time.process_time(), time.perf_counter()
    mhe_identify(model, meas)
    mhe_cpu, mhe_wall = time.process_time() - c0, time.perf_counter() - w0
    fits = res.info.get("fits", {})
    its = sum(f.get("iterations", 0) for f in fits.values())
    unknowns = "steady fit, no" if rp is None else rp.dim
    truth = "FvK" if a.truth == "fvk" else "Berger"
    print(f"record: 1 s at 1 kHz ({meas.count} samples), 4 sensors, {truth} truth 49x25, {a.load}, 1 % noise")
    err = 100 * (res.lift[-1] - case.true_lift) / case.true_absolute_load  # of ∫|P| (L2 has no net lift)
    print(
        f"realistic estimator ({res.info['model']}), {a.modes} modes x {a.substeps} sub-steps, {unknowns} unknowns, "
        f"load model {res.info['load_model']}, {its} LM iterations; lift error {err:+.2f} % of ∫|P|"
    )
    print(f"  lift {res.lift[-1]:.5f} ± {res.lift_std[-1]:.5f} N (true {case.true_lift:.5f} N), "
          f"status {'converged' if res.info.get('converged') else 'not converged'}")  # fmt: skip
    print(f"  first call (compiled loops, modal model built): CPU {first:.2f} s")
    print(f"  per record, model built: CPU {min(cpu):.2f} s (median {np.median(cpu):.2f}, wall {min(wall):.2f} s): "
          f"{min(cpu):.2f}x the 1 s real-time budget")  # fmt: skip
    if rp is not None:
        print(f"  one exact Jacobian {jac:.3f} s CPU, one residual {resid:.3f} s CPU")
    print(f"linear MHE (seed protocol) on the same record: CPU {mhe_cpu:.2f} s (wall {mhe_wall:.2f} s)")
    print(f"ratio realistic / linear MHE (CPU): {min(cpu) / mhe_cpu:.1f}")


if __name__ == "__main__":
    main()
