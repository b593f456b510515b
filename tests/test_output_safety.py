"""Output safety (issue 12): wingopt replaces only what it wrote, cleans up after signals and disk errors.

* an existing directory that wingopt did not write (no marker) is refused with exit 2, untouched;
  ``--out .`` is refused; an empty directory and an earlier wingopt result are replaced;
* result directories get the usual permissions (``0777 & ~umask``), not ``mkdtemp``'s 0700;
* SIGTERM and SIGINT during a run end it with one line, exit code 143 / 130, and no hidden work
  directory; work directories of killed runs are removed by the next run;
* a full disk is exit 2 with one line and no leftovers.
"""

import errno
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from wingopt.cli import main
from wingopt.errors import OutputError
from wingopt.results.writer import MARKER, ResultDirectory, check_writable, clean_stale, write_json

LINEAR = ("--model", "linear", "--no-model-form")  # input handling is tested, not the membrane model

ROOT = Path(__file__).resolve().parents[1]
# a short shipped record (151 rows): cheap in every estimator; its own warnings are filtered below
RECORD = ROOT / "examples" / "data" / "tunnel_calibration_300Hz.csv"
FAST = ["identify", "membrane", *LINEAR, "--data", str(RECORD), "--mesh", "13x7", "--no-plots"]


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if ".tmp-" in p.name or ".old-" in p.name)


def test_foreign_directory_is_refused_and_kept(tmp_path, capsys):
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "rec.csv").write_text(RECORD.read_text())
    argv = ["identify", "membrane", *LINEAR, "--data", str(proj / "rec.csv"), "--mesh", "13x7", "--no-plots"]
    assert main([*argv, "--out", str(proj)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(proj) in err and "holds the input" in err  # the input is inside
    assert sorted(p.name for p in proj.iterdir()) == ["rec.csv"]
    assert (proj / "rec.csv").read_text() == RECORD.read_text()


def test_morph_refuses_a_foreign_directory_before_work(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    assert main(["morph", "plate", "--shape", "twist", "--out", str(tmp_path)]) == 2
    assert "not written by wingopt" in capsys.readouterr().err
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_working_directory_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / MARKER).write_text("")  # even a marker does not make the working directory replaceable
    assert main([*FAST, "--out", "."]) == 2
    assert "working directory" in capsys.readouterr().err
    assert main([*FAST, "--out", ".."]) == 2
    assert (tmp_path / MARKER).exists()


def test_empty_directory_and_earlier_result_are_replaced_with_umask_permissions(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    old = os.umask(0o027)
    try:
        assert main([*FAST, "--out", str(out)]) == 0
    finally:
        os.umask(old)
    assert (out / MARKER).is_file() and (out / "summary.json").is_file()
    assert out.stat().st_mode & 0o777 == 0o750
    (out / "notes.txt").write_text("a user's file in the earlier result")
    assert main([*FAST, "--out", str(out)]) == 2  # refused, naming it: never deleted
    assert "notes.txt" in capsys.readouterr().err and (out / "notes.txt").is_file()
    (out / "notes.txt").unlink()
    old = os.umask(0o022)
    try:
        assert main([*FAST, "--out", str(out)]) == 0
    finally:
        os.umask(old)
    assert out.stat().st_mode & 0o777 == 0o755
    assert _leftovers(tmp_path) == []


def test_check_writable_names_the_path_for_files_and_foreign_dirs(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(OutputError, match="exists and is not a directory"):
        check_writable(f)
    with pytest.raises(OutputError, match="is a file, not a directory"):
        check_writable(f / "sub")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "x").write_text("x")
    with pytest.raises(OutputError, match=r"'.*d': exists and was not written by wingopt"):
        check_writable(tmp_path / "d")


def test_stale_work_directories_of_dead_runs_are_removed_foreign_ones_kept(tmp_path):
    dead = 2**22 + 12345  # above the default pid_max of 4194304: no such process
    ours = tmp_path / f".run.tmp-{dead}-abc"
    ours.mkdir()
    (ours / MARKER).write_text("")
    (ours / "lift.csv").write_text("half")
    old = tmp_path / f".run.old-{dead}"
    old.mkdir()
    (old / MARKER).write_text("")
    foreign = tmp_path / f".run.tmp-{dead}-user"
    foreign.mkdir()
    (foreign / "notes").write_text("not ours")
    alive = tmp_path / f".run.tmp-{os.getppid()}-xyz"
    alive.mkdir()
    (alive / MARKER).write_text("")
    removed = clean_stale(tmp_path / "run")
    assert sorted(p.name for p in removed) == sorted([ours.name, old.name])
    assert foreign.exists() and alive.exists()
    with ResultDirectory(tmp_path / "run") as tmp:
        write_json(tmp / "a.json", {})
    assert (tmp_path / "run" / "a.json").exists() and not ours.exists()


def test_disk_full_is_one_line_exit_2_and_no_leftovers(tmp_path, monkeypatch, capsys):
    import wingopt.workflows.identify as ident

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(ident, "write_csv", full)
    out = tmp_path / "run"
    assert main([*FAST, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    failure = [ln for ln in err.splitlines() if "warning:" not in ln and not _stage(ln)]  # warnings, stages first
    assert len(failure) == 1 and "disk is full" in failure[0] and str(out) in failure[0]
    assert not out.exists() and _leftovers(tmp_path) == []


def test_exception_inside_keeps_the_earlier_result(tmp_path):
    out = tmp_path / "run"
    with ResultDirectory(out) as tmp:
        write_json(tmp / "summary.json", {"v": 1})
    with pytest.raises(KeyboardInterrupt), ResultDirectory(out) as tmp:
        write_json(tmp / "summary.json", {"v": 2})
        raise KeyboardInterrupt
    assert (out / "summary.json").read_text().split() == ["{", '"v":', "1", "}"]
    assert _leftovers(tmp_path) == []


def _stage(line: str) -> bool:
    """A stage line of the run (wingopt.progress), not a failure: failures say error, failure or signal."""
    return not any(w in line for w in (": error:", "failure:", "terminated by", "interrupted", "internal error"))


# A child process that sends itself a signal in the middle of writing the outputs (deterministic).
_CHILD = textwrap.dedent(
    """
    import os, signal, sys
    import wingopt.workflows.identify as ident
    from wingopt.cli import main
    real = ident.write_csv
    def write_then_signal(path, *a, **k):
        real(path, *a, **k)
        os.kill(os.getpid(), getattr(signal, sys.argv[1]))
    ident.write_csv = write_then_signal
    sys.exit(main(sys.argv[2:]))
    """
)


@pytest.mark.parametrize(("sig", "code"), [("SIGTERM", 143), ("SIGINT", 130), ("SIGHUP", 129)])
def test_signal_during_write_is_one_line_and_leaves_nothing(tmp_path, sig, code):
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD, sig, *FAST, "--out", str(out)], capture_output=True, text=True, env=env
    )
    assert proc.returncode == code, proc.stderr
    failure = [ln for ln in proc.stderr.splitlines() if "warning:" not in ln and not _stage(ln)]
    assert len(failure) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert not out.exists() and _leftovers(tmp_path) == []


def test_sigterm_at_a_random_moment_leaves_a_result_or_nothing(tmp_path):
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = "import sys; from wingopt.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *FAST[:-1], "--out", str(out)], stderr=subprocess.PIPE, text=True, env=env
    )
    try:
        proc.wait(timeout=1.5)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (0, 143, -signal.SIGTERM), err
    assert "Traceback" not in err
    assert _leftovers(tmp_path) == []
    assert not out.exists() or (out / MARKER).is_file()


def test_signal_wrapped_by_a_c_extension_is_still_a_signal(monkeypatch, capsys):
    """SIGTERM during a module's initialisation surfaces as ``ImportError: initialization failed``."""
    import wingopt.cli.modes as modes
    from wingopt.cli import Terminated

    def wrapped(args):
        try:
            raise Terminated(signal.SIGTERM)
        except Terminated as exc:
            raise ImportError("initialization failed") from exc

    monkeypatch.setattr(modes, "run", wrapped)
    parser_func = modes.run
    assert parser_func is wrapped
    assert main(["modes", "membrane"]) == 143
    err = capsys.readouterr().err
    assert err == "wingopt modes: terminated by SIGTERM; nothing written\n"
