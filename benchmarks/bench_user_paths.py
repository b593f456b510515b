"""CPU time of the paths a user runs (issue 26), each as the console runs it, children included.

* ``wingopt demo --quick`` (target 30 s of CPU) and, with ``--full``, ``wingopt demo`` (``make
  demo``, target 3 CPU-minutes);
* the smallest ``wingopt compare`` (one load, one noise level, one seed; target 2 CPU-minutes),
  with the JEKFs at their default 60 modes, and with ``--exact`` also at every mode;
* writing the outputs of one simulated ``identify`` (L1, 1 %, 1 s, truth 49x25; the error-history
  plot evaluates each basis once).

Each command's CPU time is the user + system time of its process and the processes it waited for
(``os.wait4``), so the machine's other load does not count; the wall time does depend on it.
Measured on the 2-core development machine (load ~2), before (main at a6cc0a3) -> after:
demo --quick 77.2 -> 27.3 s, demo 133.9 -> 81.8 s, smallest compare 91.5 -> 8.4 s (90.5 s with the
exact JEKFs; 29 min in the issue), outputs of one identify 8.2 -> 1.2 s. CPU times rise ~1.5x when
the machine is crowded (load 5: demo --quick 29-30 s). On the slower shared host (demo-speed
branch, /usr/bin/time, warm numba cache): demo --quick 60.7 -> 36.7 s (median of 3; target not
met: the linear MHE on the FvK truth with its FvK cross-check, the JEKFs' per-sample Python overhead
and matplotlib's figures are what is left), demo 178.0 -> 96.4 s.

Usage::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_user_paths.py [--full] [--exact] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGETS = {"demo --quick": 30.0, "demo": 180.0, "compare (smallest)": 120.0, "identify outputs": 2.0}


def cpu_of(argv: list[str]) -> tuple[float, float, int]:
    """(CPU seconds, wall seconds, exit code) of ``python -m wingopt ARGV``."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "wingopt", *argv], env=env, cwd=ROOT,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    _, status, usage = os.wait4(p.pid, 0)
    return usage.ru_utime + usage.ru_stime, time.perf_counter() - t0, os.waitstatus_to_exitcode(status)


def identify_outputs() -> float:
    """CPU seconds of :func:`write_identify_outputs` for one simulated run (figures included)."""
    from wingopt.problem import load_problem
    from wingopt.workflows.identify import identify, write_identify_outputs

    run = identify(load_problem("membrane"), load="L1", noise_percent=1, t_end=1.0, method="mhe")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.process_time()
        write_identify_outputs(run, Path(tmp) / "out")
        return time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="also the full demo (about 1.5 CPU-minutes)")
    ap.add_argument("--exact", action="store_true", help="also the smallest compare with the exact JEKFs")
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        runs = [("demo --quick", ["demo", "--quick", "--out", f"{tmp}/q"])]
        if args.full:
            runs.append(("demo", ["demo", "--out", f"{tmp}/d"]))
        small = ["compare", "membrane", "--loads", "L1", "--noise", "1", "--seeds", "1"]
        runs.append(("compare (smallest)", [*small, "--out", f"{tmp}/c"]))
        if args.exact:
            runs.append(("compare (smallest, exact JEKFs)", [*small, "--jekf-order", "full", "--out", f"{tmp}/e"]))
        for name, argv in runs:
            cpu, wall, code = cpu_of(argv)
            rows.append({"path": name, "cpu_s": round(cpu, 1), "wall_s": round(wall, 1), "exit": code,
                         "target_cpu_s": TARGETS.get(name)})  # fmt: skip
    rows.append({"path": "identify outputs", "cpu_s": round(identify_outputs(), 2), "target_cpu_s": 2.0})
    for r in rows:
        target = r.get("target_cpu_s")
        met = "" if target is None else ("  met" if r["cpu_s"] <= target else "  NOT MET")
        print(f"{r['path']:34} CPU {r['cpu_s']:7.1f} s" + (f" (target {target:g} s){met}" if target else ""))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
