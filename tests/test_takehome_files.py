"""Where wingopt writes (issue 33): caches in the user's cache directory, never in the installed
package; a killed stream's rows are kept (moved aside, with a warning) by the next run at its place."""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import wingopt
from wingopt.cache_dir import use_user_cache, user_cache_dir
from wingopt.results.writer import MARKER, ResultDirectory, write_json

PACKAGE = Path(wingopt.__file__).resolve().parent
ROOT = PACKAGE.parent
DEAD = 2**22 + 4321  # above the default pid_max: no such process

PROBE = """
import os, sys
import wingopt
assert wingopt.__file__.startswith(sys.argv[1]), wingopt.__file__
import numba
sys.path.insert(0, sys.argv[2])
import probe_kernel
assert probe_kernel.twice(2.0) == 4.0
from wingopt.cli import main
code = main(["identify", sys.argv[3], "--data", sys.argv[4], "--out", sys.argv[5], "--no-plots"])
print(numba.config.CACHE_DIR)
sys.exit(code)
"""


def _listing(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


def test_identify_writes_nothing_inside_a_read_only_package(tmp_path):
    site = tmp_path / "site"
    pkg = site / "wingopt"
    shutil.copytree(PACKAGE, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    probe = tmp_path / "probe"
    probe.mkdir()
    (probe / "probe_kernel.py").write_text(
        "from numba import njit\n\n\n@njit(cache=True)\ndef twice(x):\n    return 2.0 * x\n"
    )
    before = _listing(site)
    for p in [pkg, *pkg.rglob("*")]:
        p.chmod(p.stat().st_mode & ~0o222)
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "WINGOPT_CACHE_DIR")}
    # The interpreter's bytecode is left out (an installer compiles it at install time): wingopt's own writes count.
    env.update(PYTHONPATH=str(site), XDG_CACHE_HOME=str(tmp_path / "cache"), OPENBLAS_NUM_THREADS="1")
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    args = [
        str(site),
        str(probe),
        str(ROOT / "problems" / "membrane.toml"),
        str(ROOT / "examples" / "data" / "tunnel_300Hz.csv"),
    ]
    try:
        done = subprocess.run(
            [sys.executable, "-c", PROBE, *args, str(tmp_path / "out")],
            env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
    finally:
        for p in [pkg, *pkg.rglob("*")]:
            p.chmod(p.stat().st_mode | 0o200)
    assert done.returncode == 0, done.stderr
    cache = tmp_path / "cache" / "wingopt" / "numba"
    assert done.stdout.strip().splitlines()[-1] == str(cache)
    assert any(cache.rglob("*.nbi")) and not any(probe.rglob("*.nbi"))  # numba's index went to the user cache
    assert _listing(site) == before  # not one file added or changed in the package
    assert (tmp_path / "out" / "load.csv").is_file()


def test_the_user_cache_directory_rules(tmp_path, monkeypatch):
    monkeypatch.delenv("WINGOPT_CACHE_DIR", raising=False)
    monkeypatch.setitem(sys.modules, "platformdirs", None)  # not installed: the XDG rule
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert user_cache_dir() == tmp_path / "xdg" / "wingopt"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert user_cache_dir() == tmp_path / "home" / ".cache" / "wingopt"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    assert use_user_cache() == str(tmp_path / "mine")  # the user's setting wins
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    assert use_user_cache() == str(tmp_path / "home" / ".cache" / "wingopt" / "numba") == os.environ["NUMBA_CACHE_DIR"]


def test_a_killed_streams_rows_are_kept_moved_aside_and_said(tmp_path, caplog):
    work = tmp_path / f".run.tmp-{DEAD}-abc"
    work.mkdir()
    (work / MARKER).write_text("")
    rows = "t,lift_N\n" + "".join(f"{k / 300:.6f},1.7\n" for k in range(299)) + "0.99,1."  # a torn last row
    (work / "lift.csv").write_text(rows)
    empty = tmp_path / f".run.tmp-{DEAD + 1}-def"  # a killed run that wrote no row: removed as before
    empty.mkdir()
    (empty / MARKER).write_text("")
    (empty / "lift.csv").write_text("t,lift_N\n")
    with caplog.at_level(logging.WARNING, logger="wingopt.results.writer"):
        with ResultDirectory(tmp_path / "run") as tmp:
            write_json(tmp / "summary.json", {})
    kept = tmp_path / f"run.killed-{DEAD}"
    assert (kept / "lift.csv").read_text() == rows and not work.exists() and not empty.exists()
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(said) == 1 and "299 estimate row(s)" in said[0] and str(kept) in said[0]
    assert (tmp_path / "run" / "summary.json").is_file()
    # a second killed run of the same pid number does not overwrite the first one's rows
    work.mkdir()
    (work / MARKER).write_text("")
    (work / "lift.csv").write_text(rows)
    with ResultDirectory(tmp_path / "run") as tmp:
        write_json(tmp / "summary.json", {})
    assert (tmp_path / f"run.killed-{DEAD}.1" / "lift.csv").read_text() == rows


@pytest.mark.parametrize("torn", ["half", ""])
def test_a_work_directory_without_a_complete_row_is_removed(tmp_path, torn):
    work = tmp_path / f".run.tmp-{DEAD}-abc"
    work.mkdir()
    (work / MARKER).write_text("")
    (work / "lift.csv").write_text(torn)
    with ResultDirectory(tmp_path / "run") as tmp:
        write_json(tmp / "a.json", {})
    assert not work.exists() and not list(tmp_path.glob("run.killed-*"))
