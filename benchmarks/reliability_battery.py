"""Reliability battery, round two (issue 25): every command that writes, every stream that fails,
every size that cannot fit, and the Python API -- counts what must be zero.

Every case runs in a child process (``python -m wingopt ...`` or a short API script) in its own
scratch directory seeded with a user's files (a record, notes, a notebook ``analysis.ipynb``, and
where relevant a user's ``summary.json`` / ``table.csv`` / ``records.jsonl``), under a wall-clock
timeout and an address-space cap (``RLIMIT_AS``). Streams (``--data -`` from a pipe, ``--follow``)
are fed by a separate writer process at about the record's rate and stopped by a signal, a closed
stdin, a closed stdout or an internal error mid-stream.

Counters (each must be 0):
  foreign_changed  a file the package did not write was changed, deleted or moved (hashes of the
                   whole scratch tree before/after; inputs the command read count as foreign)
  estimates_lost   a stream stopped by a signal, a closed pipe or an error does not leave one row
                   in --out/lift.csv per sample it processed (= estimate lines it printed)
  tracebacks       "Traceback" on stderr, an exit code not in {0, 2, 3, 129, 130, 143}, or an API
                   call raising something that is not a ``wingopt.errors.WingoptError``
  hangs            the wall-clock timeout or the memory cap was hit (a refusal must come first)
  silent_wrong     exit 0 with a result wrong by a large factor and no warning saying why (lift
                   off by >10x, an empty study table, a --follow that missed the rows of a
                   rotated/truncated file, an API call that silently accepted an absurd value)
  unclear          an error that is not one line naming the option/field/file, control
                   characters printed raw, or an output file not readable by group/other
                   although the umask (022) allows it

Run (from the repository root; ~25 min on 2 shared cores, --quick ~5 min):
  OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 nice -n 10 python benchmarks/reliability_battery.py \
      [--quick] [--only SUBSTRING] [--list] [--json results.json]
WINGOPT_ROOT selects the source tree under test (default: two levels up from this script).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(os.environ.get("WINGOPT_ROOT") or Path(__file__).resolve().parent.parent).resolve()
RECORD = ROOT / "examples" / "data" / "tunnel_300Hz.csv"  # the tunnel stand-in: FvK truth, steady, 1381 rows
CALIBRATION = ROOT / "examples" / "data" / "tunnel_calibration_300Hz.csv"
MEMBRANE = (ROOT / "problems" / "membrane.toml").read_text()
PLATE = (ROOT / "problems" / "plate.toml").read_text()
TRUE_LIFT = 1.763967  # the record's header: "true mean lift 1.763967 N"

TIMEOUT = 120.0  # s; a case still running is a HANG
SIZE_TIMEOUT = 45.0  # s; cases whose right answer is a quick refusal before any work
MEM_CAP = 3 * 1024**3  # bytes of address space per child process
OK_CODES = {0, 2, 3, 129, 130, 143}
DT = 0.003333  # the record's sample period (300 Hz)

FAST = ["--mesh", "13x7", "--no-plots"]
LIN = ["--model", "linear", "--no-model-form"]
REC = "proj/rec.csv"
NOTEBOOK = json.dumps({"cells": [{"cell_type": "markdown", "source": ["# my analysis"]}], "nbformat": 4}) + "\n"
BASE_FILES = {
    "work/proj/rec.csv": RECORD.read_text(),
    "work/proj/notes.txt": "my notes\n",
    "work/keep.txt": "do not delete\n",
    "work/analysis.ipynb": NOTEBOOK,
    "outside.txt": "a file one level above the working directory\n",
}
USER_SUMMARY = '{"mine": true, "note": "the user\'s own summary"}\n'
USER_TABLE = "a,b\n1,2\n"
SCALE_WORDS = (
    "percent",
    "divide",
    "multipl",
    "unit",
    "scale",
    "microstrain",
    "implausib",
    "magnitude",
    "too small",
    "too large",
    "tiny",
    "resolution",
    "below the noise",
    "mostly noise",
)

# -- record helpers ------------------------------------------------------------------------------


def _record_values() -> list[list[str]]:
    out = []
    for ln in RECORD.read_text().splitlines():
        if ln and not ln.startswith("#") and not ln.startswith("t,"):
            out.append(ln.split(",")[1:])
    return out


VALUES = _record_values()  # 1381 rows of 4 cells (13 empty: dropped frames)


def rows(i0: int = 0, i1: int | None = None, k0: int | None = None, scale: float = 1.0) -> list[str]:
    """Record rows i0..i1 with times (k0 + j) * DT (default k0 = i0), values scaled."""
    i1 = len(VALUES) if i1 is None else i1
    k0 = i0 if k0 is None else k0
    out = []
    for j, cells in enumerate(VALUES[i0:i1]):
        vals = [f"{float(c) * scale:.9g}" if c else "" for c in cells]
        out.append(f"{(k0 + j) * DT:.6f}," + ",".join(vals))
    return out


HEADER = "t,S1,S2,S3,S4"


def csv_text(lines: list[str], header: str = HEADER) -> str:
    return header + "\n" + "\n".join(lines) + "\n"


def scaled_record(k: float) -> str:
    head = [ln for ln in RECORD.read_text().splitlines() if ln.startswith("#")]
    return "\n".join(head) + "\n" + csv_text(rows(scale=k))


def steady(n: int, v: str = "1e-4,1e-4,1e-4,1e-4", dt: float = 1e-3) -> list[str]:
    return [f"{k * dt:.6f},{v}" for k in range(n)]


def membrane(old: str, new: str, text: str = MEMBRANE) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


M13 = membrane("nodes = [25, 13]", "nodes = [13, 7]")


def with_sensors(specs: list[tuple[str, tuple]], base: str = MEMBRANE) -> str:
    head, tail = base[: base.index("[[sensors]]")], base[base.index("[identification]") :]
    body = "".join(f'[[sensors]]\nname = "{n}"\nrect = {list(r)}\n\n' for n, r in specs)
    return head + body + tail


DEFAULT_SENSORS = [
    ("S1", (0.010, 0.045, 0.010, 0.022)),
    ("S2", (0.070, 0.105, 0.016, 0.028)),
    ("S3", (0.030, 0.060, 0.040, 0.052)),
    ("S4", (0.088, 0.128, 0.046, 0.058)),
]


def renamed_s1(name_toml: str) -> str:
    return membrane('name = "S1"', f'name = "{name_toml}"')


def many_sensors(n: int) -> str:
    specs = []
    for i in range(n):
        x = 0.005 + (i % 100) * 0.0012
        y = 0.005 + (i // 100 % 50) * 0.0011
        specs.append((f"S{i + 1}", (round(x, 6), round(x + 0.01, 6), round(y, 6), round(y + 0.01, 6))))
    return with_sensors(specs)


SPEC = """problem = "membrane"
truth_mesh = "19x10"
t_end = 0.2
title = "battery"

[grid]
load = ["L1"]
noise = [1]
seed = [0]
method = ["mhe"]
"mesh.nodes" = [[13, 7]]
"""


def spec(**repl) -> str:
    text = SPEC
    for k, v in repl.items():
        pat = re.compile(rf"^{re.escape(k)} = .*$", re.M)
        assert pat.search(text), k
        text = pat.sub(lambda _m, k=k, v=v: f"{k} = {v}", text)
    return text


def _user_npz() -> bytes:
    """A user's own (valid) archive named like a cached gain, for another input weight."""
    import io

    import numpy as np

    buf = io.BytesIO()
    np.savez(buf, K=np.zeros((9, 10)), r=1e-3, weight_modes=20, info="{}")
    return buf.getvalue()


# -- cases ---------------------------------------------------------------------------------------


def cases() -> list[dict]:
    C: list[dict] = []

    def add(name, cmd, argv=None, **kw):
        kw.setdefault("files", {})
        kw.setdefault("kind", "cli")
        kw.setdefault("timeout", TIMEOUT)
        C.append({"name": name, "cmd": cmd, "argv": argv or [], **kw})

    def size(name, cmd, argv, **kw):
        add(name, cmd, argv, timeout=SIZE_TIMEOUT, **kw)

    out = ["--out", "res"]
    nb = {"res/analysis.ipynb": NOTEBOOK}
    mine = {"res/mine/data.csv": "x\n1\n"}

    # == identify --load (simulated) =============================================================
    SIM = ["identify", "membrane", "--load", "L1", "--t-end", "0.2", "--truth-mesh", "19x10", *FAST]
    add(
        "idl rerun into result dir holding a notebook",
        "identify --load",
        [*SIM, *out],
        pre=[[*SIM, *out]],
        add=nb,
        quick=True,
    )
    add(
        "idl rerun into result dir holding a user subdir", "identify --load", [*SIM, *out], pre=[[*SIM, *out]], add=mine
    )
    add(
        "idl --out symlink to result dir holding a notebook",
        "identify --load",
        [*SIM, "--out", "link"],
        pre=[[*SIM, *out]],
        add={**nb, "link@": "res"},
    )
    add("idl --out dangling symlink", "identify --load", [*SIM, "--out", "link"], files={"link@": "gone/deeper"})
    for v in ["1e308", "-1e308", "1e-300"]:
        add(
            f"idl --initial-load {v}",
            "identify --load",
            [*SIM, "--initial-load", v, *out],
            names=["initial-load", "initial_load"],
            quick=v == "1e308",
        )
    for v in ["1e308", "1e-300"]:
        add(
            f"idl --noise-std {v}",
            "identify --load",
            [*SIM, "--noise-std", v, *out],
            names=["noise-std", "noise_std"],
            quick=v == "1e308",
        )
    add(
        "idl --truth-damping nan",
        "identify --load",
        [*SIM, "--truth-damping", "nan", *out],
        names=["truth-damping", "damping"],
    )
    add(
        "idl --truth-damping -1",
        "identify --load",
        [*SIM, "--truth-damping", "-1", *out],
        names=["truth-damping", "damping"],
    )
    add(
        "idl --truth-prestrain nan nan",
        "identify --load",
        [*SIM, "--truth", "berger", "--truth-prestrain", "nan", "nan", *out],
        names=["truth-prestrain", "prestrain"],
    )
    add(
        "idl --truth-prestrain 1e308 1e308",
        "identify --load",
        [*SIM, "--truth", "berger", "--truth-prestrain", "1e308", "1e308", *out],
        names=["truth-prestrain", "prestrain"],
    )
    add(
        "idl --pressure-bounds nan nan",
        "identify --load",
        [*SIM, "--solver", "cvxpy", "--pressure-bounds", "nan", "nan", *out],
        names=["pressure-bounds", "pressure_bounds"],
    )
    add("idl --lambda 1e308", "identify --load", [*SIM, "--lambda", "1e308", *out], names=["lambda"])
    add("idl --lambda-rule bogus", "identify --load", [*SIM, "--lambda-rule", "bogus", *out], names=["--lambda-rule"])
    add(
        "idl --load-timescale 1e-308",
        "identify --load",
        [*SIM, "--load-model", "random_walk", "--load-timescale", "1e-308", *out],
        names=["load-timescale", "load_timescale"],
    )
    add(
        "idl --state-prior nan",
        "identify --load",
        [*SIM, "--state-prior", "nan", *out],
        names=["state-prior", "state_prior"],
    )
    add(
        "idl --max-memory nan",
        "identify --load",
        [*SIM, "--max-memory", "nan", *out],
        names=["max-memory", "max_memory"],
    )
    add(
        "idl --max-memory 1",
        "identify --load",
        [*SIM, "--max-memory", "1", *out],
        names=["max-memory", "max_memory", "memory"],
    )
    size("idl --mesh 10000x10000", "identify --load", [*SIM, "--mesh", "10000x10000", *out], names=["mesh"])
    size("idl --window 100000000", "identify --load", [*SIM, "--window", "100000000", *out], names=["window"])
    size("idl --modes 1000000", "identify --load", [*SIM, "--modes", "1000000", *out], names=["modes"])
    size(
        "idl --method jekf-tuned --modes 1000000",
        "identify --load",
        [*SIM, "--method", "jekf-tuned", "--modes", "1000000", *out],
        names=["modes"],
    )
    size(
        "idl --truth fvk --truth-mesh 4000x4000",
        "identify --load",
        [*SIM, "--truth", "fvk", "--truth-mesh", "4000x4000", *out],
        names=["truth-mesh", "truth_mesh"],
    )
    add("idl --out /sys (read-only fs)", "identify --load", [*SIM, "--out", "/sys/wingopt-battery"], names=["out"])

    # == identify --data FILE ====================================================================
    DATA = ["identify", "membrane", "--data", REC, *FAST, *LIN]
    daq = {"res/daq.csv": RECORD.read_text()}
    add(
        "idd --data res/daq.csv --out res (input inside the result dir)",
        "identify --data",
        ["identify", "membrane", "--data", "res/daq.csv", *FAST, *LIN, *out],
        pre=[[*DATA, *out]],
        add=daq,
        quick=True,
    )
    add(
        "idd --data res/raw/daq.csv --out res (input below the result dir)",
        "identify --data",
        ["identify", "membrane", "--data", "res/raw/daq.csv", *FAST, *LIN, *out],
        pre=[[*DATA, *out]],
        add={"res/raw/daq.csv": RECORD.read_text()},
    )
    add("idd --out equal to the input's directory", "identify --data", [*DATA, "--out", "proj"], names=["out", "proj"])
    add(
        "idd --out a parent of the input's directory",
        "identify --data",
        ["identify", "membrane", "--data", "data/run1/rec.csv", *FAST, *LIN, "--out", "data"],
        files={"data/run1/rec.csv": RECORD.read_text()},
        names=["out", "data"],
    )
    add(
        "idd rerun into result dir holding a notebook",
        "identify --data",
        [*DATA, *out],
        pre=[[*DATA, *out]],
        add=nb,
        quick=True,
    )
    add(
        "idd --out symlink to result dir holding a notebook",
        "identify --data",
        [*DATA, "--out", "link"],
        pre=[[*DATA, *out]],
        add={**nb, "link@": "res"},
    )
    add(
        "idd --out empty dir that is a symlink to proj/..",
        "identify --data",
        [*DATA, "--out", "up"],
        files={"up@": "proj/.."},
        names=["out", "up"],
    )
    for k, quick in [(1e-6, True), (1e-4, False), (1e-3, False), (1e3, False), (1e6, False)]:
        add(
            f"idd record x{k:g} (wrong unit)",
            "identify --data",
            ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
            files={"x.csv": scaled_record(k)},
            truth=TRUE_LIFT,
            quick=quick,
        )
    add(
        "idd record x1e-6, default (FvK) model",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *out],
        files={"x.csv": scaled_record(1e-6)},
        truth=TRUE_LIFT,
        timeout=240,
    )
    add(
        "idd record with BOM and CRLF",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": ("\ufeff" + scaled_record(1.0)).replace("\n", "\r\n")},
        truth=TRUE_LIFT,
    )
    perm = rows()
    perm = [",".join([r.split(",")[0], *reversed(r.split(",")[1:])]) for r in perm]
    add(
        "idd columns in another order (t,S4,S3,S2,S1)",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": csv_text(perm, "t,S4,S3,S2,S1")},
        truth=TRUE_LIFT,
    )
    size(
        "idd a 40 MB line without a newline",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": HEADER + "\n" + "0.001," * 6_700_000},
        names=["x.csv", "line"],
        quick=True,
    )
    size(
        "idd a 40 MB header",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": "t," + ",".join(f"C{i}" for i in range(5_000_000)) + "\n0,1\n"},
        names=["x.csv", "header", "column"],
    )
    add(
        "idd binary garbage after the header",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": (HEADER + "\n").encode() + os.urandom(200_000)},
        names=["x.csv"],
    )
    add(
        "idd NUL bytes inside a row",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": csv_text(rows()).replace("0.033330,", "0.0333\x0030,", 1)},
        names=["x.csv"],
    )
    add(
        "idd all-zero record",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": csv_text(steady(300, "0,0,0,0"))},
    )
    add(
        "idd values that underflow (1e-400)",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": csv_text(steady(300, "1e-400,1e-400,1e-400,1e-400"))},
    )
    add(
        "idd a 100000-digit number",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": csv_text(["0.000000,0.00" + "1" * 100_000 + ",1e-4,1e-4,1e-4", *rows(1)])},
        names=["x.csv"],
    )
    negative = [f"{(k - len(VALUES)) * DT:.6f}," + r.split(",", 1)[1] for k, r in enumerate(rows())]
    add(
        "idd negative start time",
        "identify --data",
        ["identify", "membrane", "--data", "x.csv", *FAST, *LIN, *out],
        files={"x.csv": csv_text(negative)},
        truth=TRUE_LIFT,
    )
    size(
        "idd --data /dev/zero",
        "identify --data",
        ["identify", "membrane", "--data", "/dev/zero", *FAST, *LIN, *out],
        names=["/dev/zero", "data"],
        quick=True,
    )
    add(
        "idd --data a directory symlink",
        "identify --data",
        ["identify", "membrane", "--data", "lnk", *FAST, *LIN, *out],
        files={"lnk@": "proj"},
        names=["lnk", "data"],
    )
    for opt, v in [
        ("--initial-load", "1e308"),
        ("--noise-std", "1e308"),
        ("--noise-std", "1e-300"),
        ("--lambda", "1e-300"),
    ]:
        add(f"idd {opt} {v}", "identify --data", [*DATA, opt, v, *out], names=[opt, opt[2:].replace("-", "_")])
    add(
        "idd --load-timescale 1e-300 random walk",
        "identify --data",
        [*DATA, "--load-model", "random_walk", "--load-timescale", "1e-300", *out],
        names=["load-timescale", "load_timescale"],
    )
    size("idd --window 1000000", "identify --data", [*DATA, "--window", "1000000", *out], names=["window"])
    size("idd --stride 1000000", "identify --data", [*DATA, "--stride", "1000000", *out], names=["stride"])
    size("idd --mesh 10000x10000", "identify --data", [*DATA, "--mesh", "10000x10000", *out], names=["mesh"])
    add(
        "idd --max-memory 1",
        "identify --data",
        [*DATA, "--max-memory", "1", *out],
        names=["max-memory", "max_memory", "memory"],
    )

    # == problem files (through identify and modes) ==============================================
    add(
        "prob sensor name with a carriage return",
        "identify --data",
        ["identify", "p.toml", "--data", REC, *FAST, *LIN, *out],
        files={"p.toml": renamed_s1("S\\r1")},
        quick=True,
    )
    add(
        "prob sensor name with an ANSI escape",
        "identify --data",
        ["identify", "p.toml", "--data", REC, *FAST, *LIN, *out],
        files={"p.toml": renamed_s1("S\\u001b[2J1")},
    )
    add(
        "prob sensor name with a newline",
        "identify --data",
        ["identify", "p.toml", "--data", REC, *FAST, *LIN, *out],
        files={"p.toml": renamed_s1("S\\n1")},
    )
    add(
        "prob sensor name with a NUL",
        "identify --data",
        ["identify", "p.toml", "--data", REC, *FAST, *LIN, *out],
        files={"p.toml": renamed_s1("S\\u00001")},
    )
    add(
        "prob sensor name 20000 characters",
        "identify --data",
        ["identify", "p.toml", "--data", REC, *FAST, *LIN, *out],
        files={"p.toml": renamed_s1("S" * 20000)},
    )
    add(
        "prob sensor name with backspaces",
        "identify --data",
        ["identify", "p.toml", "--data", REC, *FAST, *LIN, *out],
        files={"p.toml": renamed_s1("S1\\b\\b\\bXX")},
    )
    size(
        "prob 100000 sensors (identify --load)",
        "identify --load",
        ["identify", "p.toml", "--load", "L1", "--t-end", "0.2", "--truth-mesh", "19x10", *FAST, *out],
        files={"p.toml": many_sensors(100_000)},
        names=["sensors", "p.toml"],
        quick=True,
    )
    size(
        "prob 100000 sensors (modes)",
        "modes",
        ["modes", "p.toml", "--mesh", "13x7"],
        files={"p.toml": many_sensors(100_000)},
        names=["sensors", "p.toml"],
    )
    add(
        "prob initial_load = 1e308",
        "identify --load",
        ["identify", "p.toml", "--load", "L1", "--t-end", "0.2", "--truth-mesh", "19x10", *FAST, *out],
        files={"p.toml": membrane("initial_load = 200.0", "initial_load = 1e308")},
        names=["initial_load", "p.toml"],
    )
    size(
        "prob a 40 MB comment line (modes)",
        "modes",
        ["modes", "p.toml", "--mesh", "13x7"],
        files={"p.toml": "# " + "x" * 40_000_000 + "\n" + MEMBRANE},
        names=["p.toml"],
    )
    size("prob /dev/zero (modes)", "modes", ["modes", "/dev/zero"], names=["/dev/zero", "problem"])

    # == modes ===================================================================================
    size(
        "modes --mesh 10000x10000", "modes", ["modes", "membrane", "--mesh", "10000x10000"], names=["mesh"], quick=True
    )
    size("modes plate --mesh 10000x10000", "modes", ["modes", "plate", "--mesh", "10000x10000"], names=["mesh"])
    size(
        "modes --count 1000000", "modes", ["modes", "membrane", "--mesh", "13x7", "--count", "1000000"], names=["count"]
    )
    size(
        "modes --count 10**30",
        "modes",
        ["modes", "membrane", "--mesh", "13x7", "--count", "1" + "0" * 30],
        names=["count"],
    )
    add("modes --mesh nanxnan", "modes", ["modes", "membrane", "--mesh", "nanxnan"], names=["mesh"])
    add(
        "modes --json into a closed pipe",
        "modes",
        ["modes", "membrane", "--mesh", "13x7", "--count", "30", "--json"],
        close_stdout=0,
    )

    # == identify --data - (stdin stream) ========================================================
    STD = ["identify", "membrane", "--data", "-", *FAST]
    for model, margs in [("fvk", []), ("linear", ["--model", "linear"])]:
        for sig in ["TERM", "INT", "HUP"]:
            add(
                f"stdin {model} SIG{sig} mid-stream",
                "identify --data -",
                [*STD, *margs, *out],
                kind="stream",
                feed={"actions": [["write", "record"], ["hold", 60]]},
                signal=sig,
                after=100,
                quick=(sig == "HUP" or (sig == "TERM" and model == "fvk")),
            )
    add(
        "stdin nonlinear (Berger) SIGTERM mid-stream",
        "identify --data -",
        [*STD, "--model", "nonlinear", *out],
        kind="stream",
        feed={"actions": [["write", "record"], ["hold", 60]]},
        signal="TERM",
        after=100,
    )
    add(
        "stdin SIGTERM during start-up",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "record"], ["hold", 60]]},
        signal="TERM",
        after=-0.4,
    )
    add(
        "stdin two SIGTERMs 20 ms apart",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "record"], ["hold", 60]]},
        signal="TERM",
        after=100,
        twice=True,
    )
    add(
        "stdin SIGINT then SIGTERM",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={"actions": [["write", "record"], ["hold", 60]]},
        signal="INT",
        after=100,
        then="TERM",
    )
    add(
        "stdin closed mid-line (writer exits)",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "first150"], ["partial", "0.500000,0.0001"]]},
        quick=True,
    )
    add(
        "stdin writer killed mid-stream (SIGKILL)",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={"actions": [["write", "record"], ["hold", 60]]},
        kill_writer_after=100,
    )
    add(
        "stdin steady 1 kHz record, default model (internal error)",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "steady"]]},
        quick=True,
    )
    add(
        "stdin steady 1 kHz record, Berger model",
        "identify --data -",
        [*STD, "--model", "nonlinear", *out],
        kind="stream",
        feed={"actions": [["write", "steady"]]},
    )
    add(
        "stdin time goes back after 120 rows",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "first150"], ["raw", "0.001000,1e-4,1e-4,1e-4,1e-4\n"], ["hold", 30]]},
    )
    add(
        "stdin 1e300 values after 150 rows",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={
            "actions": [
                ["write", "first150"],
                ["raw", "".join(f"{(150 + j) * DT:.6f},1e300,1e300,1e300,1e300\n" for j in range(20))],
                ["hold", 30],
            ]
        },
    )
    add(
        "stdin 1e300 values after 150 rows, linear",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={
            "actions": [
                ["write", "first150"],
                ["raw", "".join(f"{(150 + j) * DT:.6f},1e300,1e300,1e300,1e300\n" for j in range(20))],
                ["hold", 30],
            ]
        },
    )
    add(
        "stdin time jumps by 1e6 s after 150 rows",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={"actions": [["write", "first150"], ["raw", "1000000.000000,1e-4,1e-4,1e-4,1e-4\n"], ["hold", 30]]},
        timeout=SIZE_TIMEOUT,
    )
    add(
        "stdin header only",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["raw", HEADER + "\n"]]},
        quick=True,
    )
    add("stdin empty", "identify --data -", [*STD, *out], kind="stream", feed={"actions": []}, quick=True)
    add(
        "stdin comments only",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["raw", "# a\n# b\n"]]},
    )
    add(
        "stdin header then '# end'",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={"actions": [["raw", HEADER + "\n# end\n"]]},
    )
    add(
        "stdin binary garbage after the header",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "first150"], ["garbage", 100000], ["hold", 30]]},
    )
    add(
        "stdin a 40 MB line",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "first150"], ["big", 40_000_000], ["hold", 60]]},
        timeout=SIZE_TIMEOUT,
    )
    add(
        "stdin from /dev/zero",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        stdin_file="/dev/zero",
        timeout=SIZE_TIMEOUT,
        quick=True,
    )
    add(
        "stdin stdout closed after 10 lines",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={"actions": [["write", "record"], ["hold", 60]]},
        close_stdout=10,
    )
    add(
        "stdin record x1e-6 (wrong unit)",
        "identify --data -",
        [*STD, *out],
        kind="stream",
        feed={"actions": [["write", "record_1e-6"]]},
        truth=TRUE_LIFT,
    )
    add(
        "stdin record with BOM and CRLF",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={"actions": [["write", "record_bomcrlf"]]},
        truth=TRUE_LIFT,
    )
    add(
        "stdin rerun into result dir holding a notebook",
        "identify --data -",
        [*STD, "--model", "linear", *out],
        kind="stream",
        feed={"actions": [["write", "first150"]]},
        pre=[[*DATA, *out]],
        add=nb,
    )
    size(
        "stdin --mesh 10000x10000",
        "identify --data -",
        ["identify", "membrane", "--data", "-", "--mesh", "10000x10000", *out],
        kind="stream",
        feed={"actions": [["write", "first150"], ["hold", 60]]},
        names=["mesh"],
    )
    add(
        "stdin --initial-load 1e308",
        "identify --data -",
        [*STD, "--initial-load", "1e308", *out],
        kind="stream",
        feed={"actions": [["write", "record"]]},
        names=["initial-load", "initial_load"],
    )
    add(
        "stdin --noise-std 1e308",
        "identify --data -",
        [*STD, "--noise-std", "1e308", *out],
        kind="stream",
        feed={"actions": [["write", "record"]]},
        names=["noise-std", "noise_std"],
    )
    add(
        "stdin --noise-std 1e308 linear",
        "identify --data -",
        [*STD, "--model", "linear", "--noise-std", "1e308", *out],
        kind="stream",
        feed={"actions": [["write", "record"]]},
        names=["noise-std", "noise_std"],
    )

    # == identify --follow FILE ==================================================================
    FOL = ["identify", "membrane", "--follow", "daq.csv", *FAST]
    for sig in ["TERM", "INT", "HUP"]:
        add(
            f"follow SIG{sig} mid-stream",
            "identify --follow",
            [*FOL, *out],
            kind="stream",
            feed={"target": "daq.csv", "actions": [["write", "record"], ["hold", 60]]},
            signal=sig,
            after=100,
            quick=sig != "INT",
        )
    add(
        "follow file truncated and rewritten",
        "identify --follow",
        [*FOL, "--model", "linear", "--idle-timeout", "4", *out],
        kind="stream",
        feed={
            "target": "daq.csv",
            "actions": [["write", "first150"], ["sleep", 2], ["truncate"], ["write", "second150"], ["hold", 30]],
        },
        all_rows=True,
        quick=True,
    )
    add(
        "follow file rotated (renamed and recreated)",
        "identify --follow",
        [*FOL, "--model", "linear", "--idle-timeout", "4", *out],
        kind="stream",
        feed={
            "target": "daq.csv",
            "actions": [
                ["write", "first150"],
                ["sleep", 2],
                ["rotate", "daq.csv.1"],
                ["write", "second150"],
                ["hold", 30],
            ],
        },
        all_rows=True,
        quick=True,
    )
    add(
        "follow rotated, no idle timeout, new file ends with '# end'",
        "identify --follow",
        [*FOL, "--model", "linear", *out],
        kind="stream",
        feed={
            "target": "daq.csv",
            "actions": [
                ["write", "first150"],
                ["sleep", 2],
                ["rotate", "daq.csv.1"],
                ["write", "second150"],
                ["raw", "# end\n"],
                ["hold", 60],
            ],
        },
        all_rows=True,
        timeout=SIZE_TIMEOUT,
    )
    add(
        "follow file deleted mid-stream",
        "identify --follow",
        [*FOL, "--model", "linear", "--idle-timeout", "3", *out],
        kind="stream",
        feed={"target": "daq.csv", "actions": [["write", "first150"], ["sleep", 1], ["delete"], ["hold", 30]]},
    )
    add(
        "follow file that appears after 2 s",
        "identify --follow",
        [*FOL, "--model", "linear", *out],
        kind="stream",
        feed={"target": "daq.csv", "actions": [["sleep", 2], ["write", "record"], ["raw", "# end\n"], ["hold", 30]]},
        all_rows=True,
    )
    add(
        "follow /dev/zero",
        "identify --follow",
        ["identify", "membrane", "--follow", "/dev/zero", *FAST, "--idle-timeout", "2", *out],
        timeout=SIZE_TIMEOUT,
        names=["/dev/zero", "follow"],
        quick=True,
    )
    add(
        "follow a 40 MB line",
        "identify --follow",
        [*FOL, "--idle-timeout", "5", *out],
        kind="stream",
        feed={"target": "daq.csv", "actions": [["write", "first150"], ["big", 40_000_000], ["hold", 60]]},
        timeout=SIZE_TIMEOUT,
    )
    add(
        "follow a directory",
        "identify --follow",
        ["identify", "membrane", "--follow", "proj", *FAST, "--idle-timeout", "2", *out],
        names=["proj", "follow"],
    )
    add(
        "follow --follow res/daq.csv --out res (input inside result dir)",
        "identify --follow",
        ["identify", "membrane", "--follow", "res/daq.csv", *FAST, "--model", "linear", *out],
        kind="stream",
        feed={"target": "res/daq.csv", "actions": [["write", "first150"], ["raw", "# end\n"], ["hold", 30]]},
        pre=[[*DATA, *out]],
        keep_exists=["res/daq.csv"],
    )
    add(
        "follow rerun into result dir holding a notebook",
        "identify --follow",
        [*FOL, "--model", "linear", *out],
        kind="stream",
        feed={"target": "daq.csv", "actions": [["write", "first150"], ["raw", "# end\n"], ["hold", 30]]},
        pre=[[*DATA, *out]],
        add=nb,
    )
    add(
        "follow record x1e-6 (wrong unit)",
        "identify --follow",
        [*FOL, *out],
        kind="stream",
        feed={"target": "daq.csv", "actions": [["write", "record_1e-6"], ["raw", "# end\n"], ["hold", 30]]},
        truth=TRUE_LIFT,
    )
    add(
        "follow --poll inf",
        "identify --follow",
        [*FOL, "--poll", "inf", "--idle-timeout", "2", *out],
        kind="stream",
        feed={"target": "daq.csv", "actions": [["write", "first150"], ["hold", 30]]},
        names=["poll"],
        timeout=SIZE_TIMEOUT,
    )
    add(
        "follow --idle-timeout inf",
        "identify --follow",
        [*FOL, "--idle-timeout", "inf", "--model", "linear", *out],
        kind="stream",
        feed={"target": "daq.csv", "actions": [["write", "first150"], ["raw", "# end\n"], ["hold", 30]]},
        timeout=SIZE_TIMEOUT,
    )
    add(
        "follow --print-every 0",
        "identify --follow",
        [*FOL, "--print-every", "0", *out],
        names=["print-every", "print_every"],
    )
    size(
        "follow --mesh 10000x10000",
        "identify --follow",
        ["identify", "membrane", "--follow", REC, "--mesh", "10000x10000", "--idle-timeout", "2", *out],
        names=["mesh"],
    )

    # == morph ===================================================================================
    MOR = ["morph", "plate", "--shape", "twist", "--mesh", "7x31", "--t-end", "0.2", "--no-plots"]
    add("morph rerun into result dir holding a notebook", "morph", [*MOR, *out], pre=[[*MOR, *out]], add=nb, quick=True)
    add("morph --out . (working directory)", "morph", [*MOR, "--out", "."], names=["out"])
    add(
        "morph --out symlink to result dir holding a notebook",
        "morph",
        [*MOR, "--out", "link"],
        pre=[[*MOR, *out]],
        add={**nb, "link@": "res"},
    )
    size("morph --horizon 100000", "morph", [*MOR, "--horizon", "100000", *out], names=["horizon"], quick=True)
    size("morph --horizon 1000000000", "morph", [*MOR, "--horizon", "1000000000", *out], names=["horizon"])
    size(
        "morph --mesh 10000x10000",
        "morph",
        ["morph", "plate", "--shape", "twist", "--mesh", "10000x10000", "--no-plots", *out],
        names=["mesh"],
        quick=True,
    )
    size("morph --period 1e-9", "morph", [*MOR, "--period", "1e-9", *out], names=["period"])
    for opt, v in [
        ("--period", "nan"),
        ("--period", "inf"),
        ("--t-end", "inf"),
        ("--t-end", "nan"),
        ("--sensor-noise", "nan"),
        ("--sensor-noise", "1e308"),
        ("--vmin", "nan"),
        ("--r", "inf"),
    ]:
        add(
            f"morph {opt} {v}",
            "morph",
            [*MOR, opt, v, *out],
            names=[opt, opt[2:].replace("-", "_")],
            timeout=SIZE_TIMEOUT if v == "inf" else TIMEOUT,
        )
    for v in ["nan", "1e-308"]:
        add(f"morph --method lqr --r {v}", "morph", [*MOR, "--method", "lqr", "--r", v, *out], names=["--r", "r ="])
    add(
        "morph --vmin -1e308 --vmax 1e308",
        "morph",
        [*MOR, "--vmin", "-1e308", "--vmax", "1e308", *out],
        names=["vmin", "vmax"],
    )
    add("morph --solver bogus", "morph", [*MOR, "--solver", "bogus", *out], names=["solver"])
    add("morph --mode bogus", "morph", [*MOR, "--mode", "bogus", *out], names=["mode"])
    add(
        "morph --shape ''",
        "morph",
        ["morph", "plate", "--shape", "", "--mesh", "7x31", "--t-end", "0.2", *out],
        names=["shape"],
    )
    add(
        "morph --max-memory 1", "morph", [*MOR, "--max-memory", "1", *out], names=["max-memory", "max_memory", "memory"]
    )
    add("morph --out /sys (read-only fs)", "morph", [*MOR, "--out", "/sys/wingopt-battery"], names=["out"])

    # == sweep ===================================================================================
    SW = ["sweep", "s.toml", "--serial"]
    sfile = {"s.toml": SPEC}
    add(
        "sweep --out DIR holding a user's summary.json and table.csv",
        "sweep",
        [*SW, *out],
        files={**sfile, "res/summary.json": USER_SUMMARY, "res/table.csv": USER_TABLE},
        quick=True,
    )
    add(
        "sweep --out . (user's summary.json in the working dir)",
        "sweep",
        [*SW, "--out", "."],
        files={**sfile, "summary.json": USER_SUMMARY, "table.csv": USER_TABLE},
        quick=True,
    )
    add(
        "sweep --out .. (files one level up)",
        "sweep",
        [*SW, "--out", ".."],
        files={**sfile, "../summary.json": USER_SUMMARY},
    )
    add("sweep --out DIR holding a notebook only", "sweep", [*SW, *out], files={**sfile, **nb})
    add(
        "sweep --resume on a user's records.jsonl (last line without newline)",
        "sweep",
        [*SW, "--resume", *out],
        files={**sfile, "res/records.jsonl": '{"run": 1, "value": 3.5}\n{"run": 2, "value": 4.25}'},
        quick=True,
    )
    add(
        "sweep --resume on a foreign JSONL (other schema)",
        "sweep",
        [*SW, "--resume", *out],
        files={**sfile, "res/records.jsonl": '{"run": 1}\n{"run": 2}\n'},
    )
    add(
        "sweep --resume on a records.jsonl broken in the middle",
        "sweep",
        [*SW, "--resume", *out],
        files={**sfile, "res/records.jsonl": '{"run": 1}\n{"run": \n{"run": 3}\n'},
        names=["records.jsonl"],
    )
    add(
        "sweep --resume on a binary records.jsonl",
        "sweep",
        [*SW, "--resume", *out],
        files={**sfile, "res/records.jsonl": os.urandom(5000)},
        names=["records.jsonl"],
    )
    add(
        "sweep rerun --resume into its result dir holding a notebook",
        "sweep",
        [*SW, "--resume", *out],
        files=sfile,
        pre=[[*SW, *out]],
        add=nb,
    )
    size(
        "sweep grid of 10^6 tasks",
        "sweep",
        [*SW, *out],
        files={"s.toml": spec(seed="[" + ",".join(map(str, range(10102))) + "]", noise=str(list(range(1, 100))))},
        names=["grid", "tasks", "s.toml"],
        quick=True,
    )
    size(
        "sweep mesh.nodes 10000x10000",
        "sweep",
        [*SW, *out],
        files={"s.toml": spec(**{'"mesh.nodes"': "[[10000, 10000]]"})},
        names=["mesh", "nodes"],
    )
    size(
        "sweep truth_mesh 10000x10000",
        "sweep",
        [*SW, *out],
        files={"s.toml": spec(truth_mesh='"10000x10000"')},
        names=["truth_mesh", "mesh"],
    )
    size("sweep t_end 1e9", "sweep", [*SW, *out], files={"s.toml": spec(t_end="1e9")}, names=["t_end"])
    add(
        "sweep empty grid list (load = [])",
        "sweep",
        [*SW, *out],
        files={"s.toml": spec(load="[]")},
        names=["load", "grid"],
        quick=True,
    )
    add("sweep t_end = nan", "sweep", [*SW, *out], files={"s.toml": spec(t_end="nan")}, names=["t_end"])
    add("sweep noise = [nan]", "sweep", [*SW, *out], files={"s.toml": spec(noise="[nan]")}, names=["noise"])
    add("sweep noise = [1e308]", "sweep", [*SW, *out], files={"s.toml": spec(noise="[1e308]")}, names=["noise"])
    add("sweep seed = [-1]", "sweep", [*SW, *out], files={"s.toml": spec(seed="[-1]")}, names=["seed"])
    size("sweep spec /dev/zero", "sweep", ["sweep", "/dev/zero", "--serial", *out], names=["/dev/zero", "spec"])
    size(
        "sweep spec with a 40 MB comment",
        "sweep",
        [*SW, *out],
        files={"s.toml": "# " + "x" * 40_000_000 + "\n" + SPEC},
        names=["s.toml"],
    )
    add(
        "sweep problem = '/dev/zero'",
        "sweep",
        [*SW, *out],
        files={"s.toml": spec(problem='"/dev/zero"')},
        names=["problem", "/dev/zero"],
        timeout=SIZE_TIMEOUT,
    )
    add(
        "sweep --out /sys (read-only fs)",
        "sweep",
        [*SW, "--out", "/sys/wingopt-battery"],
        files=sfile,
        names=["out", "/sys"],
    )
    add("sweep --out an existing file", "sweep", [*SW, "--out", "keep.txt"], files=sfile, names=["out", "keep.txt"])
    add("sweep --retries -1", "sweep", [*SW, "--retries", "-1", *out], files=sfile, names=["retries"])
    add(
        "sweep --scheduler nobody listening",
        "sweep",
        ["sweep", "s.toml", "--scheduler", "tcp://127.0.0.1:9", *out],
        files=sfile,
        names=["scheduler", "127.0.0.1"],
        timeout=SIZE_TIMEOUT,
    )
    add(
        "sweep local cluster, 1 worker, result dir holding a notebook",
        "sweep",
        ["sweep", "s.toml", "--workers", "1", *out],
        files={**sfile, **nb},
    )

    # == compare =================================================================================
    CMP = [
        "compare",
        "membrane",
        "--loads",
        "L1",
        "--noise",
        "1",
        "--n-seeds",
        "1",
        "--methods",
        "mhe",
        "--no-oracle",
        "--truth-mesh",
        "19x10",
    ]
    add(
        "compare --out DIR holding a user's summary.json",
        "compare",
        [*CMP, *out],
        files={"res/summary.json": USER_SUMMARY},
        quick=True,
    )
    add(
        "compare --out DIR holding a user's records.jsonl",
        "compare",
        [*CMP, *out],
        files={"res/records.jsonl": '{"mine": 1}\n'},
    )
    add(
        "compare --resume on a user's records.jsonl (torn last line)",
        "compare",
        [*CMP, "--resume", *out],
        files={"res/records.jsonl": '{"mine": 1}\n{"mine": 2'},
    )
    add(
        "compare --out . (user's summary.json in the working dir)",
        "compare",
        [*CMP, "--out", "."],
        files={"summary.json": USER_SUMMARY},
    )
    add("compare --doc onto a user's file", "compare", [*CMP, *out, "--doc", "keep.txt"])
    add(
        "compare --doc onto the input problem file",
        "compare",
        [*CMP[:1], "p.toml", *CMP[2:], *out, "--doc", "p.toml"],
        files={"p.toml": MEMBRANE},
    )
    add("compare --doc onto a directory", "compare", [*CMP, *out, "--doc", "proj"], names=["doc", "proj"])
    add("compare --out an existing file", "compare", [*CMP, "--out", "keep.txt"], names=["out", "keep.txt"])
    add("compare --out /sys (read-only fs)", "compare", [*CMP, "--out", "/sys/wingopt-battery"], names=["out", "/sys"])
    for opt in ["--methods", "--loads", "--noise"]:
        argv = list(CMP)
        argv[argv.index(opt) + 1] = ""
        add(f"compare {opt} ''", "compare", [*argv, *out], names=[opt, opt[2:]], quick=opt == "--methods")
    add("compare --table no (nothing else to run)", "compare", [*CMP, "--table", "no", *out], names=["table"])
    size("compare --seeds 1000000", "compare", [*CMP[:7], "1000000", *CMP[8:], *out], names=["seeds"])
    size(
        "compare --truth-mesh 10000x10000",
        "compare",
        [*CMP[:-1], "10000x10000", *out],
        names=["truth-mesh", "truth_mesh"],
    )
    add("compare --noise nan", "compare", [*CMP[:5], "nan", *CMP[6:], *out], names=["noise"])
    add(
        "compare --state-prior nan",
        "compare",
        [*CMP, "--state-prior", "nan", *out],
        names=["state-prior", "state_prior"],
    )
    add("compare --retries -5", "compare", [*CMP, "--retries", "-5", *out], names=["retries"])

    # == design-sensors ==========================================================================
    DS = ["design-sensors", "m13.toml", "--count", "2", "--criterion", "a", "--nominal", "1", "--no-plots"]
    m13 = {"m13.toml": M13}
    add(
        "design --write-problem onto the input problem file",
        "design-sensors",
        [*DS, *out, "--write-problem", "m13.toml"],
        files=m13,
        quick=True,
    )
    add(
        "design --write-problem onto a user's file",
        "design-sensors",
        [*DS, *out, "--write-problem", "proj/notes.txt"],
        files=m13,
    )
    add(
        "design --write-problem onto the notebook",
        "design-sensors",
        [*DS, *out, "--write-problem", "analysis.ipynb"],
        files=m13,
    )
    add(
        "design --write-problem onto a symlink to a user's file",
        "design-sensors",
        [*DS, *out, "--write-problem", "lnk.toml"],
        files={**m13, "lnk.toml@": "keep.txt"},
    )
    add(
        "design --write-problem into a missing directory",
        "design-sensors",
        [*DS, *out, "--write-problem", "nodir/new.toml"],
        files=m13,
        names=["write-problem", "write_problem", "nodir"],
    )
    add(
        "design --write-problem onto a directory",
        "design-sensors",
        [*DS, *out, "--write-problem", "proj"],
        files=m13,
        names=["write-problem", "write_problem", "proj"],
    )
    add(
        "design rerun into result dir holding a notebook",
        "design-sensors",
        [*DS, *out],
        files=m13,
        pre=[[*DS, *out]],
        add=nb,
    )
    add("design --out . (working directory)", "design-sensors", [*DS, "--out", "."], files=m13, names=["out"])
    add("design --out a user's project dir", "design-sensors", [*DS, "--out", "proj"], files=m13, names=["out", "proj"])
    size("design --count 100000", "design-sensors", [*DS[:3], "100000", *DS[4:], *out], files=m13, names=["count"])
    size(
        "design --nominal 1000000", "design-sensors", [*DS[:7], "1000000", *DS[8:], *out], files=m13, names=["nominal"]
    )
    size(
        "design --montecarlo 1000000",
        "design-sensors",
        ["design-sensors", "m13.toml", "--count", "2", "--montecarlo", "1000000", "--nominal", "1", "--no-plots", *out],
        files=m13,
        names=["montecarlo"],
    )
    size(
        "design problem mesh 10000x10000",
        "design-sensors",
        ["design-sensors", "big.toml", *DS[2:], *out],
        files={"big.toml": membrane("nodes = [25, 13]", "nodes = [10000, 10000]")},
        names=["nodes", "mesh", "big.toml"],
    )
    size(
        "design --candidates step=0",
        "design-sensors",
        [*DS, "--candidates", "step=0", *out],
        files=m13,
        names=["candidates", "step"],
    )
    add(
        "design --candidates garbage",
        "design-sensors",
        [*DS, "--candidates", "sizes=axb;;rect=1:2", *out],
        files=m13,
        names=["candidates", "sizes", "rect"],
    )
    for opt in ["--noise", "--t-end", "--length-scale"]:
        add(
            f"design {opt} nan",
            "design-sensors",
            [*DS, opt, "nan", *out],
            files=m13,
            names=[opt, opt[2:].replace("-", "_")],
        )
    add(
        "design --t-end inf",
        "design-sensors",
        [*DS, "--t-end", "inf", *out],
        files=m13,
        names=["t-end", "t_end"],
        timeout=SIZE_TIMEOUT,
    )

    # == gains ===================================================================================
    G = ["gains", "plate", "--meshes", "7x31"]
    add("gains rerun into result dir holding a notebook", "gains", [*G, *out], pre=[[*G, *out]], add=nb, quick=True)
    add(
        "gains --cache DIR holding a user's gains_7x31.npz (other r)",
        "gains",
        [*G, "--cache", "cache", "--r", "1e-9", *out],
        files={"cache/gains_7x31.npz": _user_npz()},
        names=["cache", "gains_7x31.npz"],
    )
    add(
        "gains --cache a corrupt npz",
        "gains",
        [*G, "--cache", "cache", *out],
        files={"cache/gains_7x31.npz": os.urandom(3000)},
        names=["cache", "gains_7x31.npz"],
    )
    add("gains --cache an existing file", "gains", [*G, "--cache", "keep.txt", *out], names=["cache", "keep.txt"])
    size(
        "gains --meshes 10000x10000",
        "gains",
        ["gains", "plate", "--meshes", "10000x10000", *out],
        names=["meshes", "mesh"],
        quick=True,
    )
    size(
        "gains --weight-modes 1000000",
        "gains",
        [*G, "--weight-modes", "1000000", *out],
        names=["weight-modes", "weight_modes"],
    )
    add("gains --r 1e-308", "gains", [*G, "--r", "1e-308", *out], names=["--r", "r ="])
    add("gains --r inf", "gains", [*G, "--r", "inf", *out], names=["--r", "r ="])
    add("gains --out . (working directory)", "gains", [*G, "--out", "."], names=["out"])

    # == calibrate ===============================================================================
    CAL = ["calibrate", "membrane", "--data", "cal.csv", "--mesh", "13x7"]
    cal = {"cal.csv": CALIBRATION.read_text()}
    garbage = (HEADER + "\n").encode() + os.urandom(200_000)
    # (name, argv after CAL's, files, names, extra keyword arguments); a size case is quick to refuse
    for name, argv, files, names, extra in [
        ("outputs and --write-problem to a new file", [*CAL, *out, "--write-problem", "new.toml"], cal, None,
         {"quick": True}),
        ("--write-problem onto the input problem file", ["calibrate", "p.toml", *CAL[2:], *out, "--write-problem",
         "p.toml"], {**cal, "p.toml": MEMBRANE}, ["write-problem", "p.toml"], {"quick": True}),
        ("--write-problem onto a user's file", [*CAL, *out, "--write-problem", "proj/notes.txt"], cal,
         ["write-problem", "notes.txt"], {}),
        ("rerun into result dir holding a notebook", [*CAL, *out], cal, None, {"pre": [[*CAL, *out]], "add": nb}),
        ("--data res/cal.csv --out res (input inside the result dir)", [*CAL[:3], "res/cal.csv", *CAL[4:], *out],
         cal, ["out", "res/cal.csv"], {"pre": [[*CAL, *out]], "add": {"res/cal.csv": CALIBRATION.read_text()}}),
        ("--data /dev/zero", [*CAL[:3], "/dev/zero", *CAL[4:], *out], {}, ["/dev/zero", "data"],
         {"timeout": SIZE_TIMEOUT}),
        ("--data binary garbage after the header", [*CAL, *out], {"cal.csv": garbage}, ["cal.csv"], {}),
        ("--data a 40 MB line", [*CAL, *out], {"cal.csv": HEADER + "\n" + "0.001," * 6_700_000},
         ["cal.csv", "line"], {"timeout": SIZE_TIMEOUT}),
        ("--data header only", [*CAL, *out], {"cal.csv": HEADER + "\n"}, ["cal.csv"], {}),
        ("--mesh 10000x10000", [*CAL[:-1], "10000x10000", *out], cal, ["mesh"], {"timeout": SIZE_TIMEOUT}),
        ("--release-peak nan", [*CAL, "--release-peak", "nan", *out], cal, ["release-peak", "release_peak"], {}),
        ("--noise-std 1e308", [*CAL, "--noise-std", "1e308", *out], cal, ["noise-std", "noise_std"], {}),
        ("--out an existing file", [*CAL, "--out", "keep.txt"], cal, ["out", "keep.txt"], {}),
    ]:  # fmt: skip
        add(f"calibrate {name}", "calibrate", argv, files=files, names=names, **extra)

    # == demo ====================================================================================
    add(
        "demo --quick into a result dir holding a notebook",
        "demo",
        ["demo", "--quick", *out],
        pre=[[*SIM, *out]],
        add=nb,
        timeout=300,
    )
    add(
        "demo default --out ./wingopt-demo holding user files",
        "demo",
        ["demo", "--quick"],
        files={"wingopt-demo/mine.txt": "mine\n"},
        names=["out", "wingopt-demo"],
    )
    add("demo --out . (working directory)", "demo", ["demo", "--quick", "--out", "."], names=["out"])
    add("demo --out an existing file", "demo", ["demo", "--quick", "--out", "keep.txt"], names=["out", "keep.txt"])
    add(
        "demo --out symlink to a user's dir",
        "demo",
        ["demo", "--quick", "--out", "lnk"],
        files={"lnk@": "proj"},
        names=["out", "lnk"],
    )
    add("demo --quick SIGTERM after 8 s", "demo", ["demo", "--quick", *out], kind="signal", signal="TERM", after=-8.0)

    # == Python API ==============================================================================
    P13 = (
        "P = wo.load_problem('membrane').with_mesh((13, 7))\n"
        "from wingopt.estimation.options import IdentifyOptions\nLIN = IdentifyOptions(model_form=False)\n"
    )
    SIMK = "load='L1', t_end=0.2, nodes=(13, 7), truth_nodes=(19, 10)"

    def api(name, code, names=None, warn=None, truth=None, timeout=TIMEOUT, quick=False, **kw):
        add(
            f"api {name}",
            "api",
            kind="api",
            code=code,
            names=names,
            warn=warn,
            truth=truth,
            timeout=timeout,
            quick=quick,
            **kw,
        )

    api("load_problem(None)", "wo.load_problem(None)", ["problem"])
    api("load_problem(123)", "wo.load_problem(123)", ["problem"])
    api("load_problem(b'membrane')", "wo.load_problem(b'membrane')", ["problem"])
    api("load_problem(a directory)", "wo.load_problem(D / 'proj')", ["proj"])
    api("load_problem(dict)", "wo.load_problem({'kind': 'membrane'})", ["problem"])
    api("load_problem('/dev/zero')", "wo.load_problem('/dev/zero')", ["/dev/zero"], timeout=SIZE_TIMEOUT)
    api(
        "build_model(mesh '13x7' string)",
        "wo.build_model(wo.load_problem('membrane'), '13x7')",
        ["nodes", "mesh"],
        quick=True,
    )
    api("build_model(mesh (13,))", "wo.build_model(wo.load_problem('membrane'), (13,))", ["nodes", "mesh"])
    api("build_model(mesh (13.5, 7))", "wo.build_model(wo.load_problem('membrane'), (13.5, 7))", ["nodes", "mesh"])
    api("build_model(mesh (-13, 7))", "wo.build_model(wo.load_problem('membrane'), (-13, 7))", ["nodes", "mesh"])
    api(
        "build_model(mesh (nan, 7))",
        "wo.build_model(wo.load_problem('membrane'), (float('nan'), 7))",
        ["nodes", "mesh"],
    )
    api(
        "build_model(mesh 10000x10000)",
        "wo.build_model(wo.load_problem('membrane'), (10000, 10000))",
        ["nodes", "mesh"],
        timeout=SIZE_TIMEOUT,
        quick=True,
    )
    api(
        "build_model(plate, 10000x10000)",
        "wo.build_model(wo.load_problem('plate'), (10000, 10000))",
        ["nodes", "mesh"],
        timeout=SIZE_TIMEOUT,
    )
    api("build_model(None)", "wo.build_model(None)", ["problem"])
    api("parse_mesh(None)", "wo.parse_mesh(None)", ["mesh"])
    api("parse_mesh(137)", "wo.parse_mesh(137)", ["mesh"])
    api(
        "identify(noise=1) = 100 % noise",
        P13 + f"run = wo.identify(P, noise=1, {SIMK})\nresult = run.summary()",
        warn=["noise", "100"],
        quick=True,
    )
    api(
        "identify(noise=5) = 500 % noise",
        P13 + f"run = wo.identify(P, noise=5, {SIMK})\nresult = run.summary()",
        warn=["noise", "500"],
    )
    api("identify(noise=nan)", P13 + f"wo.identify(P, noise=float('nan'), {SIMK})", ["noise"])
    api("identify(noise=-0.01)", P13 + f"wo.identify(P, noise=-0.01, {SIMK})", ["noise"])
    api("identify(noise='1%')", P13 + f"wo.identify(P, noise='1%', {SIMK})", ["noise"])
    api("identify(noise=None)", P13 + f"wo.identify(P, noise=None, {SIMK})", ["noise"])
    api("identify(seed=1.5)", P13 + f"wo.identify(P, seed=1.5, {SIMK})", ["seed"])
    api("identify(seed='a')", P13 + f"wo.identify(P, seed='a', {SIMK})", ["seed"])
    api(
        "identify(t_end=nan)",
        P13 + "wo.identify(P, load='L1', t_end=float('nan'), nodes=(13, 7), truth_nodes=(19, 10))",
        ["t_end"],
    )
    api(
        "identify(t_end='0.2')",
        P13 + "wo.identify(P, load='L1', t_end='0.2', nodes=(13, 7), truth_nodes=(19, 10))",
        ["t_end"],
    )
    api(
        "identify(nodes='13x7')",
        "wo.identify('membrane', load='L1', t_end=0.2, nodes='13x7', truth_nodes=(19, 10))",
        ["nodes", "mesh"],
    )
    api(
        "identify(truth_nodes=(3, 3))",
        P13 + "wo.identify(P, load='L1', t_end=0.2, truth_nodes=(3, 3))",
        ["truth_nodes", "mesh"],
    )
    api("identify(data=all-NaN array)", P13 + "wo.identify(P, data=np.full((200, 5), np.nan), nodes=(13, 7))", ["data"])
    api("identify(data=empty array)", P13 + "wo.identify(P, data=np.zeros((0, 5)), nodes=(13, 7))", ["data"])
    api(
        "identify(data=list of lists)",
        P13 + "m, _ = wo.read_measurements(REC, ('S1', 'S2', 'S3', 'S4'))\n"
        "run = wo.identify(P, data=np.column_stack([m.t, m.values]).tolist(), model='linear', options=LIN)\n"
        "lift = run.lift",
        ["data"],
        truth=TRUE_LIFT,
    )
    api("identify(data=123)", P13 + "wo.identify(P, data=123, nodes=(13, 7))", ["data"])
    api(
        "identify(data=object dtype array)",
        P13 + "wo.identify(P, data=np.array([['a'] * 5] * 50, dtype=object), nodes=(13, 7))",
        ["data"],
    )
    api("identify(data=complex array)", P13 + "wo.identify(P, data=np.ones((50, 5)) * 1j, nodes=(13, 7))", ["data"])
    api("identify(load and data)", P13 + "wo.identify(P, load='L1', data=str(REC), nodes=(13, 7))", ["load", "data"])
    api("identify(neither load nor data)", P13 + "wo.identify(P, nodes=(13, 7))", ["load", "data"])
    api("identify(method='MHE')", P13 + f"wo.identify(P, method='MHE', {SIMK})", ["method"])
    api("identify(model='fvk2')", P13 + "wo.identify(P, data=str(REC), model='fvk2', nodes=(13, 7))", ["model"])
    api("identify(initial_load=nan)", P13 + f"wo.identify(P, initial_load=float('nan'), {SIMK})", ["initial_load"])
    api(
        "identify(noise_std=[1, 2]) wrong length",
        P13 + "wo.identify(P, data=str(REC), noise_std=[1.0, 2.0], nodes=(13, 7), model='linear', options=LIN)",
        ["noise_std"],
    )
    api(
        "identify(noise_std=-1)",
        P13 + "wo.identify(P, data=str(REC), noise_std=-1.0, nodes=(13, 7), model='linear', options=LIN)",
        ["noise_std"],
    )
    api("identify(settings='x')", P13 + f"wo.identify(P, settings='x', {SIMK})", ["mhe_settings", "settings"])
    api("identify(lam=-1)", P13 + f"wo.identify(P, lam=-1.0, {SIMK})", ["lam", "lambda"])
    api("identify(problem=None)", f"wo.identify(None, {SIMK})", ["problem"])
    api(
        "identify(data=array x1e-6) wrong unit",
        P13 + "m, _ = wo.read_measurements(REC, ('S1', 'S2', 'S3', 'S4'))\n"
        "arr = np.column_stack([m.t, m.values * 1e-6])\n"
        "run = wo.identify(P, data=arr, model='linear', options=LIN)\n"
        "lift = run.lift\nresult = run.summary()",
        truth=TRUE_LIFT,
    )
    api("morph(shape=None)", "wo.morph(wo.load_problem('plate'), None, 'lqr', nodes=(7, 31), t_end=0.2)", ["shape"])
    api("morph(membrane problem)", "wo.morph(wo.load_problem('membrane'), 'twist')", ["problem", "plate"])
    api(
        "morph(t_end=nan)",
        "wo.morph(wo.load_problem('plate'), 'twist', 'lqr', nodes=(7, 31), t_end=float('nan'))",
        ["t_end"],
    )
    api(
        "morph(typo option horizn=5)",
        "wo.morph(wo.load_problem('plate'), 'twist', 'qp', nodes=(7, 31), t_end=0.2, horizn=5)",
        ["horizn"],
        quick=True,
    )
    api(
        "morph(horizon=100000)",
        "wo.morph(wo.load_problem('plate'), 'twist', 'qp', nodes=(7, 31), t_end=0.2, horizon=100000)",
        ["horizon"],
        timeout=SIZE_TIMEOUT,
    )
    api(
        "morph(vmin='a')",
        "wo.morph(wo.load_problem('plate'), 'twist', 'qp', nodes=(7, 31), t_end=0.2, vmin='a')",
        ["vmin"],
    )
    api(
        "morph(nodes=(10000, 10000))",
        "wo.morph(wo.load_problem('plate'), 'twist', 'lqr', nodes=(10000, 10000))",
        ["nodes", "mesh"],
        timeout=SIZE_TIMEOUT,
    )
    api(
        "morph(seed=None)",
        "wo.morph(wo.load_problem('plate'), 'twist', 'lqr', nodes=(7, 31), t_end=0.2, sensor_noise=1e-6, seed=None)",
        ["seed"],
    )
    api("write_identify_outputs(None, 'res')", "wo.write_identify_outputs(None, 'res')", ["run"])
    api(
        "write_identify_outputs into a user's project dir",
        P13 + f"run = wo.identify(P, {SIMK})\nwo.write_identify_outputs(run, 'proj', plots=False)",
        ["proj", "out"],
    )
    api(
        "write_identify_outputs twice, notebook added between",
        P13 + f"run = wo.identify(P, {SIMK})\n"
        "wo.write_identify_outputs(run, 'res', plots=False)\n(D / 'res' / 'analysis2.ipynb').write_text('{}')\n"
        "wo.write_identify_outputs(run, 'res', plots=False)",
        keep_exists=["res/analysis2.ipynb"],
        quick=True,
    )
    api(
        "write_identify_outputs onto the input's directory",
        P13 + "run = wo.identify(P, data=str(REC), model='linear', options=LIN)\n"
        "wo.write_identify_outputs(run, D / 'proj', plots=False)",
        ["proj", "out"],
    )
    api("write_morph_outputs('x', 'res')", "wo.write_morph_outputs('x', 'res')", ["result"])
    api(
        "write_morph_outputs into a user's project dir",
        "r = wo.morph(wo.load_problem('plate'), 'twist', 'lqr', nodes=(7, 31), "
        "t_end=0.2)\nwo.write_morph_outputs(r, 'proj', plots=False)",
        ["proj", "out"],
    )
    api(
        "write_morph_outputs twice, notebook added between",
        "r = wo.morph(wo.load_problem('plate'), 'twist', 'lqr', nodes=(7, 31), "
        "t_end=0.2)\nwo.write_morph_outputs(r, 'res', plots=False)\n(D / 'res' / 'analysis2.ipynb').write_text('{}')\n"
        "wo.write_morph_outputs(r, 'res', plots=False)",
        keep_exists=["res/analysis2.ipynb"],
    )
    api(
        "read_measurements(names as one string)",
        "wo.read_measurements(REC, 'S1S2S3S4')",
        ["sensor_names", "names", "S1S2S3S4"],
    )
    api("read_measurements(None)", "wo.read_measurements(None, ('S1',))", ["path"])
    api("read_measurements(names=[])", "wo.read_measurements(REC, [])", ["sensor"])
    api(
        "read_measurements('/dev/zero')",
        "wo.read_measurements('/dev/zero', ('S1', 'S2', 'S3', 'S4'))",
        ["/dev/zero"],
        timeout=SIZE_TIMEOUT,
    )
    api(
        "read_measurements(a 40 MB line)",
        "(D / 'x.csv').write_text('t,S1,S2,S3,S4\\n' + '0.001,' * 6_700_000)\n"
        "wo.read_measurements(D / 'x.csv', ('S1', 'S2', 'S3', 'S4'))",
        ["x.csv", "line"],
        timeout=SIZE_TIMEOUT,
    )
    api("run_demo(config='quick')", "wo.run_demo('res', config='quick')", ["config"])
    api(
        "run_demo into a user's project dir",
        "from wingopt.workflows.demo import DemoConfig\nwo.run_demo('proj', config=DemoConfig.quick(), progress=False)",
        ["proj", "out"],
    )
    api(
        "MovingHorizonEstimator(None)",
        "from wingopt.estimation.mhe import MovingHorizonEstimator\nMovingHorizonEstimator(None)",
        ["model"],
    )
    api(
        "MovingHorizonEstimator(model, settings='x')",
        P13 + "from wingopt.estimation.mhe import MovingHorizonEstimator\n"
        "from wingopt.membrane import MembraneModel\nMovingHorizonEstimator(MembraneModel.from_problem(P), 'x')",
        ["settings"],
    )
    api(
        "MovingHorizonEstimator.setup('not measurements')",
        P13 + "from wingopt.estimation.mhe import MovingHorizonEstimator\n"
        "from wingopt.membrane import MembraneModel\nMovingHorizonEstimator(MembraneModel.from_problem(P)).setup('x')",
        ["measurements"],
    )
    api(
        "MovingHorizonEstimator.run() before setup",
        P13 + "from wingopt.estimation.mhe import MovingHorizonEstimator\n"
        "from wingopt.membrane import MembraneModel\nMovingHorizonEstimator(MembraneModel.from_problem(P)).run()",
        ["setup"],
    )
    api(
        "MHESettings(window_s=-1) used",
        P13 + "from wingopt.estimation.mhe import MHESettings\n"
        f"wo.identify(P, settings=MHESettings(window_s=-1.0), {SIMK})",
        ["window"],
    )
    api(
        "MHESettings(modes=10**9) used",
        P13 + "from wingopt.estimation.mhe import MHESettings\n"
        f"wo.identify(P, settings=MHESettings(modes=10**9), {SIMK})",
        ["modes"],
        timeout=SIZE_TIMEOUT,
    )
    api(
        "Measurements with mismatched shapes",
        "from wingopt.measurements import Measurements\n"
        "Measurements(np.arange(10.0), np.ones((7, 4)), ('S1', 'S2', 'S3', 'S4'))",
        ["t", "values"],
    )
    api(
        "control.lqr wrong shapes",
        "from wingopt.control import lqr\nlqr(np.eye(2), np.ones((3, 1)), np.eye(2), np.eye(1))",
        ["B"],
    )
    api(
        "control.lqr NaN in A",
        "from wingopt.control import lqr\nA = np.eye(2); A[0, 1] = np.nan\n"
        "lqr(A, np.ones((2, 1)), np.eye(2), np.eye(1))",
        ["A", "nan", "finite"],
    )
    api("control.lqr strings", "from wingopt.control import lqr\nlqr('a', 'b', 'c', 'd')", ["A"])
    api("control.lqr too few arguments", "from wingopt.control import lqr\nlqr(np.eye(2))", ["B", "Q", "R", "argument"])
    api(
        "control.lqr R not positive definite",
        "from wingopt.control import lqr\nlqr(-np.eye(2), np.eye(2), np.eye(2), -np.eye(2))",
        ["R"],
    )
    api(
        "control.lqr 1-D arrays",
        "from wingopt.control import lqr\nlqr(np.ones(3), np.ones(3), np.ones(3), np.ones(1))",
        ["A"],
    )
    api(
        "control.dlqr wrong shapes",
        "from wingopt.control import dlqr\ndlqr(np.eye(3), np.ones((2, 1)), np.eye(3), np.eye(1))",
        ["B"],
    )
    api(
        "MembraneModel.from_problem(plate)",
        "from wingopt.membrane import MembraneModel\nMembraneModel.from_problem(wo.load_problem('plate'))",
        ["problem", "membrane"],
    )
    api(
        "MembraneModel.from_problem(None)",
        "from wingopt.membrane import MembraneModel\nMembraneModel.from_problem(None)",
        ["problem"],
    )
    api(
        "MembraneModel.from_problem(nodes=(0, 0))",
        "from wingopt.membrane import MembraneModel\nMembraneModel.from_problem(wo.load_problem('membrane'), (0, 0))",
        ["nodes", "mesh"],
    )
    api(
        "MembraneModel.from_problem(nodes=10000x10000)",
        "from wingopt.membrane import MembraneModel\n"
        "MembraneModel.from_problem(wo.load_problem('membrane'), (10000, 10000))",
        ["nodes", "mesh"],
        timeout=SIZE_TIMEOUT,
    )
    api("design_sensors(count=-1)", P13 + "from wingopt.design import design_sensors\ndesign_sensors(P, -1)", ["count"])
    api(
        "design_sensors(count=2.5)",
        P13 + "from wingopt.design import design_sensors\ndesign_sensors(P, 2.5)",
        ["count"],
    )
    api(
        "design_sensors(candidates=123)",
        P13 + "from wingopt.design import design_sensors\ndesign_sensors(P, 2, 123)",
        ["candidates"],
    )
    api(
        "StreamingEstimator.push(wrong length)",
        P13 + "from wingopt.estimation.streaming import StreamingEstimator\n"
        "from wingopt.membrane import MembraneModel\n"
        "StreamingEstimator(MembraneModel.from_problem(P)).push(0.0, [1e-4, 1e-4])",
        ["y", "sensor"],
    )
    api(
        "StreamingEstimator.push(t=nan)",
        P13 + "from wingopt.estimation.streaming import StreamingEstimator\n"
        "from wingopt.membrane import MembraneModel\ne = StreamingEstimator(MembraneModel.from_problem(P))\n"
        "e.push(0.0, [1e-4] * 4)\ne.push(float('nan'), [1e-4] * 4)",
        ["t"],
    )
    api(
        "workflows.stream.follow into a user's project dir",
        P13 + "from wingopt.workflows.stream import follow\nfollow(P, 'proj', source=str(REC), idle_timeout=1.0)",
        ["proj", "out"],
    )
    api(
        "workflows.stream.follow source=/dev/zero",
        P13 + "from wingopt.workflows.stream import follow\nfollow(P, 'res', source='/dev/zero', idle_timeout=1.0)",
        ["/dev/zero", "source"],
        timeout=SIZE_TIMEOUT,
    )
    api(
        "workflows.stream.follow(linear spec) with default settings",
        P13 + "from wingopt.workflows.stream import follow\nfrom wingopt.estimation.registry import resolve\n"
        "follow(P, 'res', source=str(REC), spec=resolve('mhe', 'linear', stream=True), idle_timeout=1.0)",
    )
    return C


# -- the harness ---------------------------------------------------------------------------------

WRITER = r"""
import json, os, sys, time
spec = json.loads(open(sys.argv[1]).read())
target = spec.get("target")
count_path = sys.argv[2]
n = 0
def note():
    with open(count_path + ".tmp", "w") as f:
        f.write(str(n))
    os.replace(count_path + ".tmp", count_path)
def emit(data):
    if target is None:
        os.write(1, data)
    else:
        with open(target, "ab") as f:
            f.write(data)
note()
for act in spec["actions"]:
    op = act[0]
    if op == "lines":
        lines, per, tick = act[1], act[2], act[3]
        for i in range(0, len(lines), per):
            chunk = lines[i:i + per]
            emit(("".join(l + "\n" for l in chunk)).encode())
            n += sum(1 for l in chunk if l and l[0] not in "#t" and not l.startswith("\ufeff"))
            note()
            time.sleep(tick)
    elif op == "raw":
        emit(act[1].encode())
    elif op == "partial":
        emit(act[1].encode())
    elif op == "garbage":
        emit(os.urandom(act[1]))
    elif op == "big":
        emit(b"0.001," * (act[1] // 6))
    elif op == "sleep" or op == "hold":
        time.sleep(act[1])
    elif op == "truncate":
        open(target, "wb").close()
    elif op == "rotate":
        os.rename(target, act[1])
    elif op == "delete":
        os.remove(target)
note()
"""


def _feed_actions(feed: dict) -> list:
    """Expand named data sources into 'lines' actions (3 rows per 10 ms: the record's 300 Hz)."""
    out = []
    for act in feed["actions"]:
        if act[0] == "write":
            what = act[1]
            if what == "record":
                lines = [HEADER, *rows()]
            elif what == "first150":
                lines = [HEADER, *rows(0, 150)]
            elif what == "second150":  # the same stream after a truncation/rotation: header again, times go on
                lines = [HEADER, *rows(200, 350, k0=160)]
            elif what == "steady":
                lines = [HEADER, *steady(300)]
            elif what == "record_1e-6":
                lines = [HEADER, *rows(scale=1e-6)]
            elif what == "record_bomcrlf":
                lines = ["\ufeff" + HEADER + "\r", *[r + "\r" for r in rows()]]
            else:
                raise AssertionError(what)
            out.append(["lines", lines, 3, 0.01])
        else:
            out.append(act)
    return out


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEM_CAP, MEM_CAP))
    os.umask(0o022)


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env["WINGOPT_ROOT"] = str(ROOT)
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(k, "1")
    env.pop("COLUMNS", None)
    return env


def _seed(T: Path, files: dict) -> None:
    for rel, content in files.items():
        if rel.endswith("/"):
            (T / rel).mkdir(parents=True, exist_ok=True)
        elif rel.endswith("@"):
            p = T / rel[:-1]
            p.parent.mkdir(parents=True, exist_ok=True)
            p.symlink_to(content)
        else:
            p = T / rel
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(content if isinstance(content, bytes) else content.encode())


def _snapshot(T: Path) -> dict:
    snap = {}
    for dirpath, dirnames, filenames in os.walk(T, followlinks=False):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            rel = str(p.relative_to(T))
            if p.is_symlink():
                snap[rel] = ("link", os.readlink(p))
            elif p.is_file():
                h = hashlib.sha1()
                with open(p, "rb") as fh:
                    for block in iter(lambda: fh.read(1 << 20), b""):
                        h.update(block)
                snap[rel] = ("file", h.hexdigest())
    return snap


def _kill(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _spawn(argv, cwd, logdir, tag, stdin=subprocess.DEVNULL, stdout=None):
    out = stdout if stdout is not None else open(logdir / f"{tag}.out", "wb")
    err = open(logdir / f"{tag}.err", "wb")
    proc = subprocess.Popen(
        [sys.executable, "-m", "wingopt", *argv],
        cwd=cwd,
        env=_env(),
        stdin=stdin,
        stdout=out,
        stderr=err,
        preexec_fn=_limits,
        start_new_session=True,
    )
    return proc


def _wait(proc, timeout) -> tuple[int | None, bool]:
    try:
        return proc.wait(timeout=timeout), False
    except subprocess.TimeoutExpired:
        _kill(proc)
        proc.wait()
        return None, True


def _rc(code):
    if code is None:
        return None
    return code if code >= 0 else 128 - code


def _data_lines(text: str) -> int:
    n = 0
    for ln in text.splitlines():
        if ln and (ln[0].isdigit() or ln[0] == "-") and "," in ln:
            n += 1
    return n


def _lift_rows(path: Path) -> int:
    try:
        return max(0, len(path.read_text(errors="replace").splitlines()) - 1)
    except OSError:
        return 0


def _wait_lines(path: Path, k: int, proc, limit: float) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit:
        if proc.poll() is not None:
            return False
        try:
            if _data_lines(path.read_text(errors="replace")) >= k:
                return True
        except OSError:
            pass
        time.sleep(0.02)
    return False


def run_cli_case(case, T: Path, W: Path, logdir: Path) -> dict:
    res = {"rc": None, "timed_out": False, "notes": []}
    argv = case["argv"]
    kind = case["kind"]
    writer = None
    t_start = time.monotonic()
    close_stdout = case.get("close_stdout")
    if kind == "stream" and case.get("feed") is not None:
        feed = dict(case["feed"])
        feed["actions"] = _feed_actions(feed)
        if feed.get("target"):
            feed["target"] = str(W / feed["target"])
        (logdir / "feed.json").write_text(json.dumps(feed))
        count = logdir / "fed"
        if feed.get("target"):
            writer = subprocess.Popen(
                [sys.executable, "-c", WRITER, str(logdir / "feed.json"), str(count)],
                cwd=W,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
            stdin = subprocess.DEVNULL
        else:
            r, w = os.pipe()
            writer = subprocess.Popen(
                [sys.executable, "-c", WRITER, str(logdir / "feed.json"), str(count)],
                cwd=W,
                stdout=w,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
            os.close(w)
            stdin = r
    elif case.get("stdin_file"):
        stdin = open(case["stdin_file"], "rb")
    elif case.get("stdin_bytes") is not None:
        (logdir / "stdin.bin").write_bytes(case["stdin_bytes"])
        stdin = open(logdir / "stdin.bin", "rb")
    else:
        stdin = subprocess.DEVNULL
    stdout = subprocess.PIPE if close_stdout is not None else None
    proc = _spawn(argv, W, logdir, "main", stdin=stdin, stdout=stdout)
    if isinstance(stdin, int) and stdin >= 0:
        os.close(stdin)
    elif hasattr(stdin, "close"):
        stdin.close()
    if close_stdout is not None:
        got = []
        for _ in range(close_stdout):
            line = proc.stdout.readline()
            if not line:
                break
            got.append(line)
        (logdir / "main.out").write_bytes(b"".join(got))
        proc.stdout.close()
        res["stdout_seen"] = _data_lines(b"".join(got).decode(errors="replace"))
    sig = case.get("signal")
    if sig is not None or case.get("kill_writer_after") is not None:
        after = case.get("after", case.get("kill_writer_after"))
        if after is not None and after < 0:
            time.sleep(-after)
            ok = proc.poll() is None
        else:
            ok = _wait_lines(logdir / "main.out", after, proc, case["timeout"] * 0.6)
        if not ok:
            res["notes"].append(f"the stop was not sent: the run ended or printed fewer than {after} estimates first")
        elif case.get("kill_writer_after") is not None:
            _kill(writer)
        else:
            res["fed_at_signal"] = _read_int(logdir / "fed")
            os.kill(proc.pid, getattr(signal, "SIG" + sig))
            if case.get("twice"):
                time.sleep(0.02)
                _try_kill(proc.pid, getattr(signal, "SIG" + sig))
            if case.get("then"):
                time.sleep(0.05)
                _try_kill(proc.pid, getattr(signal, "SIG" + case["then"]))
    remaining = max(1.0, case["timeout"] - (time.monotonic() - t_start))
    code, timed_out = _wait(proc, remaining)
    res["rc"], res["timed_out"] = _rc(code), timed_out
    if writer is not None:
        _kill(writer)
        writer.wait()
        res["fed"] = _read_int(logdir / "fed")
    res["stdout"] = _read(logdir / "main.out")
    res["stderr"] = _read(logdir / "main.err")
    return res


def _read(p: Path) -> str:
    """A child's output as written: no newline translation, so a raw carriage return stays visible."""
    try:
        return p.read_bytes().decode("utf-8", "replace")
    except OSError:
        return ""


def _try_kill(pid, sig):
    try:
        os.kill(pid, sig)
    except ProcessLookupError:
        pass


def _read_int(p: Path) -> int:
    try:
        return int(p.read_text())
    except (OSError, ValueError):
        return 0


API_BOOT = r"""
import json, logging, os, sys, traceback, warnings
from pathlib import Path
res = {"ok": None, "warnings": []}
class _H(logging.Handler):
    def emit(self, record):
        if record.levelno >= logging.WARNING:
            res["warnings"].append(record.getMessage())
logging.getLogger().addHandler(_H())
logging.getLogger().setLevel(logging.WARNING)
code = open(sys.argv[1]).read()
try:
    import numpy as np
    import wingopt as wo
    from wingopt.errors import WingoptError
    ns = {"wo": wo, "np": np, "Path": Path, "D": Path.cwd(), "REC": Path.cwd() / "proj" / "rec.csv"}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            exec(compile(code, "<case>", "exec"), ns)
            res["ok"] = True
            r = ns.get("result")
            if isinstance(r, dict):
                res["summary_warnings"] = [str(w) for w in r.get("warnings", [])]
            res["value"] = repr(r)[:300]
            if ns.get("lift") is not None:
                res["lift"] = float(ns["lift"])
        except BaseException as exc:
            res["ok"] = False
            res["exc_type"] = type(exc).__module__ + "." + type(exc).__name__
            res["wingopt_error"] = isinstance(exc, WingoptError)
            res["memory"] = isinstance(exc, MemoryError)
            res["msg"] = str(exc)[:2000]
            res["tb"] = traceback.format_exc()[-3000:]
        res["warnings"] += [str(w.message) for w in caught]
finally:
    with open(sys.argv[2], "w") as fh:
        json.dump(res, fh, default=str)
"""


def run_api_case(case, T: Path, W: Path, logdir: Path) -> dict:
    (logdir / "case.py").write_text(case["code"])
    result = logdir / "api.json"
    err = open(logdir / "main.err", "wb")
    proc = subprocess.Popen(
        [sys.executable, "-c", API_BOOT, str(logdir / "case.py"), str(result)],
        cwd=W,
        env=_env(),
        stdin=subprocess.DEVNULL,
        stdout=open(logdir / "main.out", "wb"),
        stderr=err,
        preexec_fn=_limits,
        start_new_session=True,
    )
    code, timed_out = _wait(proc, case["timeout"])
    res = {"rc": _rc(code), "timed_out": timed_out, "notes": []}
    res["stderr"] = _read(logdir / "main.err")
    res["stdout"] = _read(logdir / "main.out")
    try:
        res["api"] = json.loads(result.read_text())
    except (OSError, ValueError):
        res["api"] = None
    return res


CTRL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")


def _last_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def _mentions(text: str, words) -> bool:
    low = text.lower()
    alts = set()
    for w in words:
        alts.add(w.lower())
        if w.startswith("--") and len(w) > 3:  # "--t-end" is also named as "t-end", "t_end", "t end"
            bare = w[2:].lower()
            alts.update({bare, bare.replace("-", "_"), bare.replace("-", " ")})
    return any(a in low for a in alts)


def classify(case, res, T: Path, W: Path, before: dict, package: set) -> tuple[list[str], list[str]]:
    """Counters hit and why."""
    hit, why = [], []

    def flag(counter, reason):
        if counter not in hit:
            hit.append(counter)
        why.append(f"{counter}: {reason}")

    after = _snapshot(T)
    # -- foreign files
    for rel, sig in before.items():
        if rel in package:
            continue
        now = after.get(rel)
        if now != sig:
            flag("foreign_changed", f"{rel} {'deleted or moved' if now is None else 'changed'}")
    for rel in case.get("keep_exists", []):
        if not (W / rel).exists():
            flag("foreign_changed", f"work/{rel} (a user's file) is gone")
    # -- permissions of created files (umask 022 in the child)
    for rel, sig in after.items():
        if rel in before or sig[0] != "file" or ".tmp-" in rel or ".old-" in rel:
            continue
        try:
            mode = (T / rel).stat().st_mode & 0o777
        except OSError:
            continue
        if mode & 0o044 != 0o044:
            flag("unclear", f"{rel} created mode {mode:04o} (not readable by group/other under umask 022)")
            break
    err = res.get("stderr", "")
    rc = res.get("rc")
    api = res.get("api") if case["kind"] == "api" else None
    # -- hangs
    if res.get("timed_out"):
        flag("hangs", f"still running after {case['timeout']:.0f} s (killed)")
    oom = (err + "\n" + res.get("stdout", "")[-5000:]).lower()
    if "out of memory" in oom or "memoryerror" in oom or "unable to allocate" in oom or (api and api.get("memory")):
        flag("hangs", "hit the memory cap (out of memory) instead of refusing before the work")
    # -- tracebacks
    if "Traceback" in err and not (api and not api.get("ok")):
        flag("tracebacks", "Traceback on stderr: " + _last_line(err)[:200])
    if case["kind"] != "api" and rc is not None and rc not in OK_CODES:
        flag("tracebacks", f"exit code {rc}")
    if case["kind"] == "api":
        if api is None:
            if not res.get("timed_out"):
                flag("tracebacks", f"the API child died (rc {rc}) without a result")
        elif api.get("ok") is False and not api.get("wingopt_error"):
            flag("tracebacks", f"raised {api.get('exc_type')}: {api.get('msg', '')[:200]}")
    # -- unclear: error lines
    if CTRL.search(err) or CTRL.search(res.get("stdout", "")):
        flag("unclear", "control characters printed raw: " + repr(CTRL.findall(err + res.get("stdout", ""))[:5]))
    names = case.get("names")
    if case["kind"] != "api" and rc in (2, 3) and not res.get("timed_out"):
        last = _last_line(err)
        if not last:
            flag("unclear", f"exit {rc} with nothing on stderr (the reason is only in stdout/summary.json)")
        elif not last.startswith("wingopt"):
            flag("unclear", f"error is not one 'wingopt ...' line; last stderr line: {last[:200]!r}")
        elif names and not _mentions(last, names):
            flag("unclear", f"error line does not name {names[0]!r}: {last[:200]!r}")
    if api and api.get("ok") is False and api.get("wingopt_error"):
        msg = api.get("msg", "")
        if "\n" in msg.strip():
            flag("unclear", f"error message is {msg.count(chr(10)) + 1} lines")
        elif names and not _mentions(msg, names):
            flag("unclear", f"error does not name {names[0]!r}: {msg[:200]!r}")
    # -- silent wrong answers
    ok_exit = (rc == 0 and case["kind"] != "api") or (api is not None and api.get("ok"))
    summary = None
    sp = W / "res" / "summary.json"
    if case["kind"] != "api" and rc == 0 and sp.is_file():
        try:
            summary = json.loads(sp.read_text())
        except ValueError:
            summary = None
    warn_text = err
    if summary and isinstance(summary, dict):
        warn_text += "\n" + "\n".join(map(str, summary.get("warnings", []) or []))
    if api:
        warn_text += "\n" + "\n".join(map(str, api.get("warnings", []) + api.get("summary_warnings", [])))
    truth = case.get("truth")
    if truth and ok_exit:
        lift = api.get("lift") if api else (summary or {}).get("lift_N")
        if lift is not None and not (truth / 10 <= abs(lift) <= truth * 10):
            if not _mentions(warn_text, SCALE_WORDS):
                flag("silent_wrong", f"lift {lift:.4g} N vs true {truth:.4g} N, exit 0, no warning about the scale")
    if case.get("warn") and api and api.get("ok") and not _mentions(warn_text, case["warn"][:1]):
        flag("silent_wrong", f"accepted without a warning mentioning {case['warn'][0]!r}")
    if case["cmd"] in ("sweep", "compare") and rc == 0:
        sfile = _study_summary(case, W)
        if sfile is not None and _study_empty(case["cmd"], sfile):
            flag("silent_wrong", "exit 0 with an empty study table")
    if case.get("all_rows") and rc == 0 and not res.get("timed_out"):
        got = _lift_rows(W / "res" / "lift.csv")
        fed = res.get("fed", 0)
        if got < fed - 2:
            flag(
                "silent_wrong",
                f"exit 0 after {got} estimates of {fed} rows written (the new file's rows were not read)",
            )
    # -- estimates lost (streams)
    if case["kind"] == "stream" and not res.get("timed_out"):
        printed = _data_lines(res.get("stdout", ""))
        if res.get("stdout_seen") is not None:
            printed = max(printed, res["stdout_seen"])
        got = _lift_rows(W / "res" / "lift.csv")
        res["printed"], res["lift_rows"] = printed, got
        if got < printed:
            where = "no lift.csv in --out" if not (W / "res" / "lift.csv").exists() else f"{got} rows in lift.csv"
            flag("estimates_lost", f"{printed} estimates computed (printed), {where}; exit {rc}")
    return hit, why


def _study_summary(case, W: Path):
    argv = case["argv"]
    if "--out" not in argv:
        return None
    out = W / argv[argv.index("--out") + 1]
    p = out / "summary.json"
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def _study_empty(cmd: str, s) -> bool:
    if not isinstance(s, dict) or s.get("mine"):
        return False
    if cmd == "sweep":
        return not s.get("cases") or not s.get("tasks")
    meta = {"problem", "truth_mesh", "mesh", "wall_s"}
    return not any(v for k, v in s.items() if k not in meta)


def run_case(case: dict, scratch: Path) -> dict:
    T = Path(tempfile.mkdtemp(prefix="case-", dir=scratch))
    W = T / "work"
    logdir = Path(tempfile.mkdtemp(prefix="log-", dir=scratch))
    W.mkdir()
    files = dict(BASE_FILES)
    files.update({("work/" + k if not k.startswith("../") else k[3:]): v for k, v in case["files"].items()})
    _seed(T, files)
    s0 = _snapshot(T)
    notes = []
    for i, pre in enumerate(case.get("pre", [])):
        p = _spawn(pre, W, logdir, f"pre{i}")
        code, _ = _wait(p, TIMEOUT)
        if code != 0:
            notes.append(
                f"setup run {i} exited {code}: " + _last_line((logdir / f"pre{i}.err").read_text(errors="replace"))
            )
    s1 = _snapshot(T)
    package = {k for k, v in s1.items() if s0.get(k) != v}
    added = case.get("add") or {}
    _seed(T, {("work/" + k): v for k, v in added.items()})
    package -= {("work/" + k.rstrip("@")) for k in added}
    before = _snapshot(T)
    t0 = time.perf_counter()
    if case["kind"] == "api":
        res = run_api_case(case, T, W, logdir)
    else:
        res = run_cli_case(case, T, W, logdir)
    seconds = time.perf_counter() - t0
    hit, why = classify(case, res, T, W, before, package)
    api = res.get("api") or {}
    tail = res.get("stderr", "")[-700:]
    if api.get("ok") is False:
        tail = (f"{api.get('exc_type')}: {api.get('msg', '')}")[-700:]
    rec = {
        "name": case["name"],
        "command": case["cmd"],
        "argv": case["argv"] if case["kind"] != "api" else None,
        "code": case.get("code"),
        "exit_code": res.get("rc"),
        "counters": hit,
        "why": why,
        "stderr_tail": tail,
        "stdout_tail": res.get("stdout", "")[-300:],
        "seconds": round(seconds, 2),
        "notes": notes + res.get("notes", []),
    }
    for k in ("fed", "printed", "lift_rows", "fed_at_signal"):
        if k in res:
            rec[k] = res[k]
    if api:
        rec["api_ok"] = api.get("ok")
    shutil.rmtree(T, ignore_errors=True)
    shutil.rmtree(logdir, ignore_errors=True)
    return rec


COUNTERS = ("foreign_changed", "estimates_lost", "tracebacks", "hangs", "silent_wrong", "unclear")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a subset of ~40 cases (the issue's examples)")
    ap.add_argument("--only", action="append", metavar="SUBSTRING", help="only cases whose name contains this")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--json", default="reliability_results.json", help="where to write the per-case records")
    args = ap.parse_args()
    all_cases = cases()
    names = [c["name"] for c in all_cases]
    assert len(names) == len(set(names)), [n for n in names if names.count(n) > 1]
    sel = all_cases
    if args.quick:
        sel = [c for c in sel if c.get("quick")]
    if args.only:
        sel = [c for c in sel if any(s in c["name"] for s in args.only)]
    if args.list:
        per = {}
        for c in sel:
            per[c["cmd"]] = per.get(c["cmd"], 0) + 1
            print(f"{c['cmd']:18s} {c['name']}")
        print(json.dumps(per, indent=1), len(sel))
        return 0
    scratch = Path(tempfile.mkdtemp(prefix="wingopt-reliability-"))
    counts = dict.fromkeys(COUNTERS, 0)
    records = []
    t0 = time.perf_counter()
    try:
        for i, case in enumerate(sel):
            try:
                rec = run_case(case, scratch)
            except Exception as exc:  # noqa: BLE001 - a harness problem must not end the battery
                rec = {
                    "name": case["name"],
                    "command": case["cmd"],
                    "argv": case["argv"],
                    "exit_code": None,
                    "counters": [],
                    "why": [],
                    "stderr_tail": "",
                    "seconds": 0.0,
                    "notes": [f"HARNESS ERROR {type(exc).__name__}: {exc}"],
                }
                print(f"      HARNESS ERROR {type(exc).__name__}: {exc}", flush=True)
            records.append(rec)
            for c in rec["counters"]:
                counts[c] += 1
            mark = ",".join(rec["counters"]) or "ok"
            print(
                f"[{i + 1}/{len(sel)}] {rec['seconds']:6.1f}s rc={rec['exit_code']} {mark:24s} {case['name']}",
                flush=True,
            )
            for w in rec["why"]:
                print(f"      {w}", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    wall = time.perf_counter() - t0
    per_cmd = {}
    for r in records:
        per_cmd[r["command"]] = per_cmd.get(r["command"], 0) + 1
    result = {
        "root": str(ROOT),
        "cases": len(records),
        "counters": counts,
        "wall_s": round(wall, 1),
        "per_command": per_cmd,
        "records": records,
    }
    Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({"cases": len(records), **counts, "wall_s": round(wall, 1)}))
    return 0 if not any(counts.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
