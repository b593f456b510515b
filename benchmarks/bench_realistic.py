"""Speed of the realistic (nonlinear) estimator on 1 s of 1 kHz data, 25x13, one core.

Record: Berger truth (49x25, 120 modes), L1, the seed's bubble start, 1 % noise. Prints the CPU
time (``time.process_time``: insensitive to other processes on a shared machine) and the wall time
of the realistic estimator, its iterations and the cost of one exact Jacobian, beside the linear
MHE on the same record, and the ratio to the 1 s real-time budget::

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/bench_realistic.py [--modes 48] [--repeat 1]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from wingopt.estimation.realistic import RealisticSettings, realistic_identify  # noqa: E402
from wingopt.estimation.realistic import estimator as est_mod  # noqa: E402
from wingopt.membrane import MembraneModel  # noqa: E402
from wingopt.problem import load_problem  # noqa: E402
from wingopt.workflows.realistic_truth import berger_case  # noqa: E402
from wingopt.workflows.studies import run_method  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--modes", type=int, default=RealisticSettings().modes)
    ap.add_argument("--substeps", type=int, default=RealisticSettings().substeps)
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args(argv)
    problem = load_problem("membrane")
    model = MembraneModel.from_problem(problem)
    case = berger_case(problem, "L1", 0.01, 0)
    meas = dataclasses.replace(case.measurements, noise_std=None)
    s = RealisticSettings(modes=a.modes, substeps=a.substeps)
    captured = {}
    orig = est_mod._fit

    def spy(rp, th, settings):
        captured["rp"] = rp
        return orig(rp, th, settings)

    est_mod._fit = spy
    cpu, wall = [], []
    for _ in range(a.repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        res = realistic_identify(model, meas, s)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    est_mod._fit = orig
    rp = captured["rp"]
    c0 = time.process_time()
    rp.residuals(np.zeros(rp.dim), jacobian=True)
    jac = time.process_time() - c0
    c0 = time.process_time()
    rp.residuals(np.zeros(rp.dim))
    resid = time.process_time() - c0
    c0, w0 = time.process_time(), time.perf_counter()
    run_method("mhe", model, meas)
    mhe_cpu, mhe_wall = time.process_time() - c0, time.perf_counter() - w0
    fits = res.info["fits"]
    its = sum(f["iterations"] for f in fits.values())
    print(f"record: 1 s at 1 kHz ({meas.count} samples), 4 sensors, Berger truth 49x25, L1, 1 % noise")
    print(
        f"realistic estimator, {a.modes} modes x {a.substeps} sub-steps, {rp.dim} unknowns, load model "
        f"{res.info['load_model']}, {its} LM iterations"
    )
    print(f"  CPU {min(cpu):.2f} s (wall {min(wall):.2f} s): {min(cpu):.2f}x the 1 s real-time budget")
    print(f"  one exact Jacobian {jac:.3f} s CPU, one residual {resid:.3f} s CPU")
    print(f"linear MHE (seed protocol) on the same record: CPU {mhe_cpu:.2f} s (wall {mhe_wall:.2f} s)")
    print(f"ratio realistic / linear MHE (CPU): {min(cpu) / mhe_cpu:.1f}")


if __name__ == "__main__":
    main()
