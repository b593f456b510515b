"""CPU per second of data of the default ``wingopt identify --data`` on shipped, protocol and misfit
records (issue 26: <= 2 s of CPU for 1 s of data on every one, a record the model does not fit
included): the estimate (:func:`wingopt.workflows.identify.identify`, what the command calls, in
this process: the membrane's operators built by the first record) and the writing of its outputs
(``summary.json``, CSVs, plots: :func:`~wingopt.workflows.identify.write_identify_outputs`) timed
apart, and, for reference, the whole console command (a new process: imports and start-up, about
2 s, come on top of both).

Records: the tunnel stand-in (steady, 300 Hz, 4.6 s) and its first 1.5 s; its calibration record
(a release, 300 Hz, 0.5 s); the protocol's records L1, L2, L3 and LE on FvK truth (1 kHz, 1 s,
written here from :func:`wingopt.workflows.protocols.simulate_case`, 1 % noise); and two records the model does not
fit: the stand-in with two sensors' columns swapped, and white noise at the stand-in's level. Each
line gives CPU s, CPU s per second of data, the lift, the run's status and its first warning::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_records.py [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_user_paths import cpu_of  # noqa: E402 - the sibling script (benchmarks/ is on sys.path)

from wingopt.measurements import read_measurements

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "examples" / "data"
BUDGET = 2.0  # CPU s per s of data
SENSORS = ("S1", "S2", "S3", "S4")
PROTOCOL = ("L1", "L2", "L3", "LE")


def _write(path: Path, t: np.ndarray, values: np.ndarray, note: str) -> Path:
    rows = [f"# {note}", "t,S1,S2,S3,S4"]
    rows += [",".join([f"{ti:.6f}"] + ["" if not np.isfinite(v) else f"{v:.8g}" for v in row])
             for ti, row in zip(t, values)]  # fmt: skip
    path.write_text("\n".join(rows) + "\n")
    return path


def records(tmp: Path) -> dict[str, Path]:
    from wingopt.measurements import read_measurements
    from wingopt.problem import load_problem
    from wingopt.workflows.protocols import simulate_case

    problem = load_problem("membrane")
    tunnel, _ = read_measurements(DATA / "tunnel_300Hz.csv", problem.sensor_names)
    n15 = int(np.searchsorted(tunnel.t - tunnel.t[0], 1.5 - 1e-9)) + 1
    swapped = tunnel.values[:, [0, 2, 1, 3]]
    rng = np.random.default_rng(0)
    noise = np.abs(rng.normal(0.0, np.nanstd(tunnel.values), tunnel.values.shape))
    protocol = {}
    for load in PROTOCOL:
        m = simulate_case(problem, load, 0.01, 0, (49, 25), 1.0, truth="fvk").measurements
        path = _write(tmp / f"{load.lower()}.csv", m.t, m.values, f"{load} FvK 49x25, 1 % noise")
        protocol[f"{load} protocol, FvK truth (1 kHz)"] = path
    return {
        "tunnel stand-in (steady, 300 Hz)": DATA / "tunnel_300Hz.csv",
        "tunnel stand-in, first 1.5 s": _write(tmp / "first.csv", tunnel.t[:n15], tunnel.values[:n15], "first 1.5 s"),
        "calibration release (300 Hz)": DATA / "tunnel_calibration_300Hz.csv",
        **protocol,
        "misfit: S2 and S3 swapped": _write(tmp / "swapped.csv", tunnel.t, swapped, "columns swapped"),
        "misfit: white noise": _write(tmp / "noise.csv", tunnel.t, noise, "white noise"),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args(argv)
    import wingopt as wo

    rows, worst = [], 0.0
    print(
        f"{'record':36s} {'data':>6s}  {'estimate':>8s}  {'outputs':>7s}  {'per s':>6s}  {'console':>7s}  lift, status"
    )
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for name, path in records(tmp).items():
            t = read_measurements(path, SENSORS)[0].t
            seconds = float(t[-1] - t[0])
            c0 = time.process_time()
            run = wo.identify("membrane", data=path)
            est = time.process_time() - c0
            wo.write_identify_outputs(run, tmp / ("api-" + path.stem))
            outs = time.process_time() - c0 - est
            cpu, _, rc = cpu_of(["identify", "membrane", "--data", str(path), "--out", str(tmp / path.stem), "-q"])
            per = (est + outs) / seconds
            worst = max(worst, per)
            s = run.summary()
            warn = (s.get("warnings") or ["-"])[0]
            rows.append({"record": name, "seconds": seconds, "estimate_cpu_s": est, "outputs_cpu_s": outs,
                         "cpu_per_s": per, "console_cpu_s": cpu, "console_exit": rc, "lift_N": s.get("lift_N"),
                         "lift_std_N": s.get("lift_std_N"), "status": s.get("status"),
                         "first_warning": warn})  # fmt: skip
            lift = f"{s['lift_N']:.4f} ± {s['lift_std_N']:.3f} N"
            print(f"{name:36s} {seconds:5.2f}s  {est:7.2f}s  {outs:6.2f}s  {per:5.2f}  {cpu:6.2f}s  {lift}, "
                  f"{s.get('status')}; {warn[:80]}", flush=True)  # fmt: skip
    print(f"worst: {worst:.2f} s CPU (estimate + outputs) per s of data (budget {BUDGET:g})")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0 if worst <= BUDGET else 1


if __name__ == "__main__":
    sys.exit(main())
