"""Make the steady tunnel records of ``benchmarks/tunnel_study.py`` (SYNTHETIC; minutes of CPU each).

Truth: the full-order Föppl–von Kármán membrane on a 49x25 mesh (the estimators use 25x13), with
the prestrains and damping factor of the case, under a tunnel pressure that acts up to the frame
(:func:`wingopt.membrane.loads.tunnel_load`: ``LE`` peaks at the leading edge, ``TE`` mirrored,
``bump`` off-centre, ``anti`` zero net lift; 180 Pa mean) times a buffeting load factor
(:class:`~wingopt.membrane.loads.Buffeting`), started in the static equilibrium of the mean load (no
release transient), sampled at 300 Hz. Stored CLEAN (the study adds noise and drops frames): ``t``,
``outputs``, ``params = [e0x, e0y, damping]``, ``lift_mean`` (the steady load's lift), named as the
study expects: ``LOAD_e<ex>_<ey>_d<damping>_o<order>_fc<corner>_r<rms>_s<seed>_n<frames>.npz``.

A case is ``LOAD:ex:ey:damping:order:corner:seed[:frames[:rms]]``::

    python benchmarks/make_tunnel_records.py --out records LE:0.05:0.05:1:2:30:0 LE:0.04:0.04:1:2:30:1:450
    python benchmarks/tunnel_study.py --records records --frames 450 --seeds 0 1
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from wingopt.membrane import Buffeting, MembraneParameters, RecordProtocol, forward_model, simulate_truth, tunnel_load
from wingopt.membrane.loads import PressureLoad
from wingopt.problem import load_problem

RATE_HZ, NODES, SUBSTEPS = 300.0, (49, 25), 8


def _independent(name: str, width: float, height: float, mean: float = 180.0) -> PressureLoad:
    """Loads that are not of the package's tunnel family nor of its aerodynamic prior's shapes (so a
    prior built on that family is tested off its own ground): ``LEs``, a sharper leading-edge peak
    (flat plate regularised 5x less, ``d = 0.01``), a parabolic camber term and a span profile that
    is flat in the middle and drops to 0.45 on the frame; ``uniform``, a uniform pressure."""
    W, L = width, height

    def les(xi, eta):
        chord = 0.28 * np.sqrt((1 - xi + 0.01) / (xi + 0.01)) + 2.2 * xi * (1 - xi)
        return chord * (0.45 + 0.55 * (1 - (2 * eta - 1) ** 4))

    shapes = {"LEs": les, "uniform": lambda xi, eta: np.ones_like(xi)}
    g = (np.arange(400) + 0.5) / 400
    X, E = np.meshgrid(g, g, indexing="ij")
    shape = shapes[name]
    scale = mean / float(np.mean(shape(X, E)))
    return PressureLoad(name, lambda x, y: scale * shape(x / W, y / L), f"{name}, mean {mean:g} Pa")


def pressure(load: str, width: float, height: float) -> PressureLoad:
    if load in ("LEs", "uniform"):
        return _independent(load, width, height)
    return tunnel_load(f"tunnel-{load}", width, height)


def record_name(load, ex, ey, damping, order, corner, rms, seed, frames) -> str:
    return f"{load}_e{ex}_{ey}_d{damping}_o{order}_fc{corner}_r{rms}_s{seed}_n{frames}.npz"


def make(case: str, out: Path) -> Path:
    parts = case.split(":")
    if len(parts) < 7:
        raise SystemExit(f"case {case!r}: expected LOAD:ex:ey:damping:order:corner:seed[:frames[:rms]]")
    load, ex, ey, damping, order, corner, seed = parts[:7]
    frames = int(parts[7]) if len(parts) > 7 else 1400
    rms = parts[8] if len(parts) > 8 else "0.03"
    path = out / record_name(load, ex, ey, damping, order, corner, rms, seed, frames)
    if path.exists():
        print(f"{path.name}: exists, kept")
        return path
    problem = load_problem("membrane")
    d = float(damping)
    params = MembraneParameters(float(ex), float(ey), d, d)
    fwd = forward_model(problem, "fvk", nodes=NODES, params=params, substeps=SUBSTEPS)
    duration = (frames - 1) / RATE_HZ
    factor = Buffeting(float(rms), float(corner), int(order), int(seed), duration + 0.1).factor
    protocol = RecordProtocol(
        t_end=duration, dt=1 / RATE_HZ, start="static", noise_fraction=0.0, seed=None, load_factor=factor
    )
    t0 = time.process_time()
    rec = simulate_truth(fwd, pressure(load, problem.width, problem.height), protocol)
    lift_mean = float(rec.true_lift / rec.load_factor[-1])  # the steady load's: the last sample's over its factor
    out.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, t=rec.measurements.t, outputs=rec.trajectory.outputs,
                        params=np.array([float(ex), float(ey), d]), lift_mean=lift_mean)  # fmt: skip
    tmp.replace(path)
    print(f"{path.name}: {rec.measurements.count} frames, mean lift {lift_mean:.4f} N, "
          f"{time.process_time() - t0:.0f} s CPU", flush=True)  # fmt: skip
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", help="LOAD:ex:ey:damping:order:corner:seed[:frames[:rms]]")
    ap.add_argument("--out", type=Path, default=Path("records"), help="directory of the records (default records)")
    args = ap.parse_args(argv)
    for case in args.cases:
        make(case, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
