"""Tunnel records as a DAQ hands them over: anti-aliasing filters, then decimation (SYNTHETIC).

Truth: the full-order FvK membrane on a 49x25 mesh (the estimators use 25x13), prestrains off the
problem file's, a leading-edge tunnel pressure (180 Pa) times a buffeting load factor (3 % RMS,
corner 30 Hz), started in the static equilibrium, simulated CLEAN at ``R = 8`` times the output
rate (2400 Hz for 300 Hz) and cached under ``--cache``. The DAQ is applied to that signal:

* ``point``: every ``R``-th sample, white noise at the output rate (the package's own records);
* ``delta-sigma``: white noise of the same density added at the high rate (the sensor's and the
  bridge's noise come before the converter), a linear-phase FIR (Kaiser, passband to 0.45 fs,
  stopband from 0.5 fs, 100 dB: no alias left), then every ``R``-th sample: as a delta-sigma
  converter's wideband decimation filter hands them over; ``half-band``: the same with the
  stopband from 0.55 fs (0.45-0.5 fs aliased);
* ``butterworth``: the same noise, a 4th-order Butterworth at ``fs / 3`` (causal, as the analog
  filter before the converter), then every ``R``-th sample;
* ``resample``: the point-sampled record resampled to 250 Hz (``scipy.signal.resample_poly``).

Each record is run through ``wingopt.identify`` with the acquisition declared (``--declared``) or
not, and one row per record is printed: lift error, bands off, status, warnings about the DAQ::

    python benchmarks/daq_records.py --cache /tmp/daq --seeds 0 1 2 --prestrain 0.04 0.06
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import scipy.signal as sig

from wingopt.measurements import Measurements
from wingopt.measurements.acquisition import Acquisition
from wingopt.membrane import Buffeting, MembraneParameters, RecordProtocol, forward_model, simulate_truth, tunnel_load
from wingopt.problem import load_problem

RATE_HZ, OVER, NODES = 300.0, 8, (49, 25)
NOISE, DROP = 0.02, 0.01


def clean(prestrain: float, seed: int, frames: int, cache: Path) -> dict:
    """The clean high-rate record (cached): ``t``, ``outputs`` ``(N R, p)``, ``lift``."""
    path = cache / f"LE_e{prestrain}_s{seed}_n{frames}_x{OVER}.npz"
    if path.exists():
        d = np.load(path)
        return {k: d[k] for k in d.files}
    problem = load_problem("membrane")
    params = MembraneParameters(prestrain, prestrain * 0.046 / 0.056, 1.0, 1.0)
    fwd = forward_model(problem, "fvk", nodes=NODES, params=params, substeps=1)
    duration = frames / RATE_HZ
    factor = Buffeting(0.03, 30.0, 2, seed, duration + 0.2).factor
    dt = 1.0 / (RATE_HZ * OVER)
    protocol = RecordProtocol(t_end=duration, dt=dt, start="static", noise_fraction=0.0, seed=None, load_factor=factor)
    t0 = time.process_time()
    rec = simulate_truth(fwd, tunnel_load("tunnel-LE", problem.width, problem.height), protocol)
    out = {
        "t": rec.measurements.t,
        "outputs": rec.trajectory.outputs,
        "lift": np.float64(rec.true_lift / rec.load_factor[-1]),
        "params": np.array([params.eps0_x, params.eps0_y]),
    }
    cache.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **out)
    print(f"{path.name}: {time.process_time() - t0:.0f} s CPU", file=sys.stderr, flush=True)
    return out


def delta_sigma_taps(rate: float, stop: float = 0.5) -> np.ndarray:
    """A linear-phase Kaiser FIR at ``rate`` (the high rate): passband 0.45 fs, stopband from ``stop`` fs
    (0.5: no alias at all, as the wideband filters of strain-bridge converters; 0.55: the half-band
    kind, which lets 0.45-0.5 fs alias), 100 dB."""
    fs = rate / OVER
    n, beta = sig.kaiserord(100.0, (stop - 0.45) * fs / (0.5 * rate))
    return sig.firwin(n | 1, 0.5 * (0.45 + stop) * fs, window=("kaiser", beta), fs=rate)


def daq(rec: dict, kind: str, seed: int) -> Measurements:
    """The record ``kind`` hands over (module docstring), with 2 % noise and 1 % dropped frames."""
    t, y = rec["t"], rec["outputs"]
    rng = np.random.default_rng(1000 + seed)
    sigma = NOISE * np.abs(y).max(axis=0)
    rate = 1.0 / (t[1] - t[0])
    if kind in ("point", "resample"):
        out = y[::OVER] + sigma * rng.standard_normal(y[::OVER].shape)
        tt = t[::OVER]
        if kind == "resample":
            out = sig.resample_poly(out - out.mean(axis=0), 5, 6, axis=0) + out.mean(axis=0)
            tt = np.arange(out.shape[0]) / 250.0
    else:
        noisy = y + np.sqrt(OVER) * sigma * rng.standard_normal(y.shape)  # the same density over [0, fs/2]
        if kind in ("delta-sigma", "half-band"):
            h = delta_sigma_taps(rate, 0.5 if kind == "delta-sigma" else 0.55)
            m = noisy.mean(axis=0)
            full = sig.fftconvolve(noisy - m, h[:, None], axes=0)[(h.size - 1) // 2 :][: y.shape[0]] + m
        elif kind == "butterworth":
            sos = sig.butter(4, RATE_HZ / 3, fs=rate, output="sos")
            zi = sig.sosfilt_zi(sos)[:, :, None] * noisy[0][None, None, :]
            full, _ = sig.sosfilt(sos, noisy, axis=0, zi=zi)
        else:
            raise SystemExit(f"unknown DAQ {kind!r}")
        out, tt = full[::OVER], t[::OVER]
    out = out[:-1] if out.shape[0] % 2 else out
    tt = tt[: out.shape[0]]
    out[rng.choice(out.shape[0], out.shape[0] // 100, replace=False)] = np.nan
    return Measurements(tt, out, load_problem("membrane").sensor_names)


DECLARED = {
    "point": Acquisition(),
    "delta-sigma": Acquisition("delta-sigma"),
    "half-band": Acquisition("delta-sigma"),
    "butterworth": Acquisition("butterworth", order=4, cutoff_hz=RATE_HZ / 3),
    "resample": Acquisition("fir", passband=0.45, stopband=0.55),  # resample_poly: -6 dB at Nyquist
}


def run(prestrain: float, seed: int, kind: str, frames: int, cache: Path, declared: bool) -> dict:
    import wingopt as wo

    rec = clean(prestrain, seed, frames, cache)
    meas = daq(rec, kind, seed)
    problem = wo.load_problem("membrane")
    if declared:
        problem = dataclasses.replace(problem, acquisition=DECLARED[kind])
    t0 = time.process_time()
    res = wo.identify(problem, data=meas).result
    lift, band = res.reported_lift
    truth = float(rec["lift"])
    warns = res.info.get("warnings", [])
    return {
        "case": f"{kind:11s} e{prestrain} s{seed}" + (" declared" if declared else ""),
        "error": lift / truth - 1,
        "bands": abs(lift - truth) / band,
        "converged": bool(res.info.get("converged")),
        "daq_warned": any("anti-alias" in w or "Nyquist" in w for w in warns),
        "warnings": len(warns),
        "prestrain_x": res.info["parameters"]["prestrain_x"],
        "cpu_s": time.process_time() - t0,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=Path("records/daq"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--prestrain", type=float, nargs="+", default=[0.04])
    ap.add_argument("--kinds", nargs="+", default=["point", "delta-sigma", "butterworth"])
    ap.add_argument("--frames", type=int, default=1400)
    ap.add_argument("--declared", action="store_true", help="declare the acquisition in the problem")
    ap.add_argument("--make-only", action="store_true", help="only make the clean records")
    args = ap.parse_args(argv)
    for e in args.prestrain:
        for s in args.seeds:
            clean(e, s, args.frames, args.cache)
            if args.make_only:
                continue
            for kind in args.kinds:
                r = run(e, s, kind, args.frames, args.cache, args.declared)
                print(
                    f"{r['case']:34s} {r['error']:+7.1%} {r['bands']:5.2f} bands  converged={r['converged']!s:5s} "
                    f"daq-warned={r['daq_warned']!s:5s} warnings={r['warnings']} ex={r['prestrain_x']:.4f} "
                    f"{r['cpu_s']:.0f} s",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
