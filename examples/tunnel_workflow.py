"""The seed's wind-tunnel test, end to end, on the shipped stand-in (docs/tunnel.md).

A latex membrane (0.14 m x 0.07 m, 5 % prestrain nominal) in steady flow, already loaded when the
recording starts, four stretch sensors at 300 Hz; the lift is to be compared with a balance. The
records are SYNTHETIC (``make_tunnel_standin.py``: FvK truth on a 49x25 mesh, prestrain (0.056,
0.046) where the problem file says 0.05, a leading-edge pressure acting up to the frame, 3 %
buffeting, 2 % noise, 1 % dropped frames); the true lift in the file's header is printed for
comparison only, the estimators never read it.

The routes, each through the functions the CLI calls (``wingopt identify`` / ``wingopt calibrate``):

1. ``4 sensors``: the record alone. The sensors' mean cannot tell the pressure from the tension
   (they see about ``(p/T)^2``); the flow's buffeting rings the loaded membrane's first mode, whose
   frequency the tension sets: the estimator fits the mean and the spectrum together.
2. ``+ calibration``: ``wingopt calibrate`` on the no-flow release record first; its posterior on
   the prestrains is the prior of the tunnel run.
3. ``+ aerodynamic prior``: the problem file declares the flow (``pressure_prior = "aerodynamic"``,
   ``leading_edge = "x0"``): thin-airfoil load shapes, a narrower band (an assumption: a load they
   cannot make is refused and the frame prior answers).
4. ``DIC full field``: the frame set of the same run (``tunnel_dic_300Hz.npz``, its first 1.5 s).

    .venv/bin/python examples/tunnel_workflow.py [--frames N]      # about 15 s of CPU
"""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path

import wingopt as wo
from wingopt.measurements import Measurements, read_measurements

DATA = Path(__file__).parent / "data"
RECORD = DATA / "tunnel_300Hz.csv"
CALIBRATION = DATA / "tunnel_calibration_300Hz.csv"
FRAMES = DATA / "tunnel_dic_300Hz.npz"


def true_lift(path: Path) -> float:
    """The ``true mean lift X N`` of the stand-in's comment header (for the printout only)."""
    match = re.search(r"true mean lift ([0-9.eE+-]+) N", path.read_text().split("\nt,", 1)[0])
    if match is None:
        raise ValueError(f"{path}: no 'true mean lift' in its header")
    return float(match.group(1))


def first(record: Measurements, n: int | None) -> Measurements:
    """The first ``n`` samples of a record (all for ``None``)."""
    if n is None:
        return record
    return Measurements(record.t[:n], record.values[:n], record.sensor_names, record.noise_std, record.source)


def routes(frames: int | None = None) -> list[dict]:
    """Run every route on the stand-in; one row each: ``route``, ``lift_N``, ``band_N``, ``error``,
    ``tension`` (where the tension came from), ``adequate``, ``cpu_s``."""
    membrane = wo.load_problem("membrane")
    record, _ = read_measurements(RECORD, membrane.sensor_names)
    record = first(record, frames)
    truth = true_lift(RECORD)
    aero = {"pressure_prior": "aerodynamic", "leading_edge": "x0"}

    cal = wo.calibrate_membrane(membrane, CALIBRATION)
    calibrated = wo.calibrated_problem(cal)
    runs = [
        ("4 sensors", membrane, {"data": record}),
        ("+ calibration", calibrated, {"data": record}),
        ("+ aerodynamic prior", membrane.with_identification(**aero), {"data": record}),
        ("+ calibration + aerodynamic", calibrated.with_identification(**aero), {"data": record}),
        ("DIC full field", membrane, {"dic": FRAMES}),
        ("DIC full field + calibration", calibrated, {"dic": FRAMES}),
    ]
    rows = []
    for name, problem, source in runs:
        c0 = time.process_time()
        run = wo.identify(problem, **source)
        cpu = time.process_time() - c0
        lift, band = run.result.reported_lift
        info = run.result.info
        rows.append(
            {
                "route": name,
                "lift_N": lift,
                "band_N": band,
                "error": lift / truth - 1.0,
                "bands_off": abs(lift - truth) / band if band else float("inf"),
                "tension": info["tension"]["source"] if "tension" in info else info.get("prestrain_source", "-"),
                "adequate": info.get("model_adequate"),
                "cpu_s": cpu,
                "warnings": list(run.result.info.get("warnings", [])),
            }
        )
    rows.append({"route": "calibration", "prestrain": cal.calibration.parameters, "cpu_s": cal.wall_s})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, help="use the first N samples of the record (default: all 1381)")
    args = ap.parse_args(argv)
    truth = true_lift(RECORD)
    rows = routes(args.frames)
    cal = rows.pop()
    p = cal["prestrain"]
    print(f"calibration: prestrain ({p['prestrain_x']:.4f}, {p['prestrain_y']:.4f}) (truth 0.0560, 0.0460)")
    print(f"true mean lift {truth:.4f} N (the header; SYNTHETIC)")
    print(f"{'route':30s} {'lift N':>8s} {'band N':>8s} {'error':>7s} {'bands':>6s}  tension from         CPU s")
    for r in rows:
        print(
            f"{r['route']:30s} {r['lift_N']:8.4f} {r['band_N']:8.4f} {100 * r['error']:+6.1f}% {r['bands_off']:6.2f}"
            f"  {r['tension']:20s} {r['cpu_s']:5.1f}"
        )
        for w in r["warnings"]:
            print(f"    warning: {w}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
