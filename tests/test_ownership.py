"""One ownership rule for every file the package writes (issue 25, wingopt.results.ownership).

* a result directory carries the manifest of the files wingopt wrote (names, sizes, hashes); it is
  replaced only if it holds nothing else and nothing changed: a user's notebook, sub-directory or
  edited file is named in a one-line refusal and never deleted;
* an input file is never inside what is replaced;
* a single output file (--write-problem, --doc) onto an existing file is refused without --force,
  and kept as NAME.bak (NAME.bak.1, ...) with it;
* a study's records.jsonl is appended to or trimmed only where wingopt wrote it; a cache holds only
  what wingopt wrote there;
* outputs get the usual umask permissions.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from wingopt.cli import main
from wingopt.errors import InputError, OutputError
from wingopt.results import OwnedDirectory, ResultDirectory, check_writable, write_json, write_text_atomic
from wingopt.results.ownership import MARKER, first_foreign, read_manifest
from wingopt.workflows.sweep.records import RecordLog, read_records

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "examples" / "data" / "tunnel_calibration_300Hz.csv"  # a short shipped record (151 rows)
FAST = ["identify", "membrane", "--model", "linear", "--no-model-form", "--mesh", "13x7", "--no-plots"]


def _write(out: Path, value: int = 1) -> None:
    with ResultDirectory(out) as tmp:
        write_json(tmp / "summary.json", {"v": value})
        (tmp / "sub").mkdir()
        (tmp / "sub" / "table.csv").write_text("a\n1\n")


def test_the_marker_is_a_manifest_of_the_files_written(tmp_path):
    out = tmp_path / "res"
    _write(out)
    files = read_manifest(out)["files"]
    assert sorted(files) == ["sub/table.csv", "summary.json"]
    assert files["summary.json"]["size"] == (out / "summary.json").stat().st_size
    assert first_foreign(out) is None
    _write(out, 2)  # ours, unchanged: replaced
    assert json.loads((out / "summary.json").read_text()) == {"v": 2}


@pytest.mark.parametrize(
    "change, named",
    [
        (lambda o: (o / "analysis.ipynb").write_text("{}"), "analysis.ipynb"),
        (lambda o: (o / "mine").mkdir(), "mine/"),
        (lambda o: (o / "summary.json").write_text('{"edited": true}'), "summary.json"),
        (lambda o: (o / "sub" / "notes.txt").write_text("x"), "sub/notes.txt"),
        (lambda o: (o / "link").symlink_to(o / "summary.json"), "link"),
    ],
    ids=["notebook", "empty dir", "edited file", "file in a sub-directory", "symlink"],
)
def test_a_foreign_or_changed_entry_is_named_and_kept(tmp_path, change, named):
    out = tmp_path / "res"
    _write(out)
    change(out)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and not p.is_symlink()}
    with pytest.raises(OutputError) as info:
        _write(out, 3)
    msg = str(info.value)
    assert "\n" not in msg and repr(named) in msg
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and not p.is_symlink()} == before
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name or ".old-" in p.name]


def test_a_marker_without_a_manifest_is_refused(tmp_path):
    out = tmp_path / "old"
    out.mkdir()
    (out / MARKER).write_text("written by wingopt; this directory may be replaced by a later run\n")
    (out / "summary.json").write_text("{}")
    with pytest.raises(OutputError, match="no list of the files"):
        check_writable(out)


def test_a_file_that_appears_during_the_run_is_kept_and_so_are_the_results(tmp_path):
    out = tmp_path / "res"
    _write(out)
    with pytest.raises(OutputError, match=r"now holds 'late.txt'.*the results are in") as info:
        with ResultDirectory(out) as tmp:
            write_json(tmp / "summary.json", {"v": 9})
            (out / "late.txt").write_text("the user's")
    assert (out / "late.txt").read_text() == "the user's"
    kept = Path(str(info.value).rsplit("'", 2)[-2])
    assert json.loads((kept / "summary.json").read_text()) == {"v": 9}


def test_an_input_inside_the_output_is_refused(tmp_path, capsys):
    out = tmp_path / "res"
    assert main([*FAST, "--data", str(RECORD), "--out", str(out), "-q"]) == 0
    (out / "raw").mkdir()
    data = out / "raw" / "daq.csv"
    data.write_text(RECORD.read_text())
    assert main([*FAST, "--data", str(data), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds the input" in err and "--data" in err
    assert data.read_text() == RECORD.read_text()


def test_a_symlinked_out_is_checked_where_it_points(tmp_path, capsys):
    out = tmp_path / "res"
    assert main([*FAST, "--data", str(RECORD), "--out", str(out), "-q"]) == 0
    (out / "analysis.ipynb").write_text("{}")
    (tmp_path / "link").symlink_to(out)
    assert main([*FAST, "--data", str(RECORD), "--out", str(tmp_path / "link")]) == 2
    assert "analysis.ipynb" in capsys.readouterr().err and (out / "analysis.ipynb").exists()


def test_outputs_get_the_umask_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        out = tmp_path / "res"
        _write(out)
        owned = OwnedDirectory(tmp_path / "study")
        owned.write_json("summary.json", {})
        log = owned.open_log("records.jsonl", fresh=True)
        log.append(b'{"key": "a"}\n')
    finally:
        os.umask(old)
    for p in [out / "summary.json", out / MARKER, owned.path / "summary.json", owned.path / "records.jsonl"]:
        assert p.stat().st_mode & 0o777 == 0o644, p
    assert out.stat().st_mode & 0o777 == 0o755 and owned.path.stat().st_mode & 0o777 == 0o755


# -- single files --------------------------------------------------------------------------------


def test_a_single_file_onto_an_existing_one_is_refused_unless_forced(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("mine")
    with pytest.raises(OutputError, match="exists; give a new file name, or --force"):
        write_text_atomic(target, "new", what="doc")
    assert target.read_text() == "mine"
    (tmp_path / "keep.txt.bak").write_text("an older backup of mine")
    _, kept = write_text_atomic(target, "new", what="doc", force=True)
    assert kept.name == "keep.txt.bak.1" and kept.read_text() == "mine"
    assert (tmp_path / "keep.txt.bak").read_text() == "an older backup of mine" and target.read_text() == "new"
    link = tmp_path / "lnk.toml"
    link.symlink_to(target)
    with pytest.raises(OutputError, match="exists"):
        write_text_atomic(link, "x", what="write-problem")


def test_design_write_problem_onto_the_input_is_refused_before_the_design(tmp_path, capsys):
    src = (ROOT / "problems" / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]")
    problem = tmp_path / "m.toml"
    problem.write_text(src)
    argv = ["design-sensors", str(problem), "--count", "2", "--criterion", "a", "--nominal", "1", "--no-plots"]
    assert main([*argv, "--out", str(tmp_path / "d"), "--write-problem", str(problem)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "write-problem" in err and "--force" in err
    assert problem.read_text() == src and not (tmp_path / "d").exists()


# -- studies and caches --------------------------------------------------------------------------


def test_a_users_records_file_is_never_appended_to_or_cut(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('problem = "membrane"\nt_end = 0.2\ntruth_mesh = "19x10"\n[grid]\nload = ["L1"]\n')
    out = tmp_path / "res"
    out.mkdir()
    mine = '{"run": 1, "value": 3.5}\n{"run": 2, "value": 4.25}'
    (out / "records.jsonl").write_text(mine)
    assert main(["sweep", str(spec), "--serial", "--resume", "--out", str(out)]) == 2
    assert "not written by wingopt" in capsys.readouterr().err
    assert (out / "records.jsonl").read_text() == mine


def test_a_study_log_is_continued_only_where_wingopt_wrote_it(tmp_path):
    owned = OwnedDirectory(tmp_path / "study")
    log = RecordLog(owned.path / "records.jsonl", fresh=True, owner=owned)
    log.append({"key": "a", "status": "ok"})
    log.append({"key": "b", "status": "ok"})
    path = owned.path / "records.jsonl"
    # a run killed mid-append: a complete record after the listed part, then a torn line
    with open(path, "a") as fh:
        fh.write('{"key": "c", "status": "ok"}\n{"key": "d", "sta')
    again = OwnedDirectory(tmp_path / "study")  # the whole directory is still wingopt's
    log = RecordLog(path, owner=again)
    assert [r["key"] for r in read_records(path)] == ["a", "b", "c"]  # the torn line was cut
    log.append({"key": "d", "status": "ok"})
    assert [r["key"] for r in log.read()] == ["a", "b", "c", "d"]
    # a change inside the part wingopt listed: the file is no longer its own
    path.write_text(path.read_text().replace('"a"', '"z"'))
    with pytest.raises(OutputError, match="records.jsonl.*changed"):
        OwnedDirectory(tmp_path / "study")


def test_a_cache_holds_only_gains_wingopt_wrote(tmp_path):
    from wingopt.problem import load_problem
    from wingopt.workflows.gains import plate_gains

    cache = tmp_path / "cache"
    cache.mkdir()
    np.savez(cache / "gains_7x31.npz", K=np.zeros((9, 10)), r=1e-3, weight_modes=20, info="{}")
    before = (cache / "gains_7x31.npz").read_bytes()
    with pytest.raises(InputError, match="cache.*not written by wingopt"):
        plate_gains(load_problem("plate"), [(7, 31)], cache=cache)
    assert (cache / "gains_7x31.npz").read_bytes() == before


def test_an_output_file_inside_the_output_directory_is_refused(tmp_path, capsys):
    argv = ["design-sensors", "membrane", "--count", "2", "--criterion", "a", "--nominal", "1", "--no-plots"]
    out = tmp_path / "d"
    assert main([*argv, "--out", str(out), "--write-problem", str(out / "new.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds the file" in err and "--write-problem" in err
    assert not out.exists()
