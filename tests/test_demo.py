"""The demo end to end (quick configuration): outputs, summary numbers, and the report in a browser."""

import json
import re

import pytest

from wingopt.cli import main
from wingopt.results.browser import find_chromium, open_in_chromium


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "wingopt-demo"
    assert main(["demo", "--quick", "--out", str(out), "--quiet"]) == 0
    return out


def test_demo_writes_every_run_and_the_report(demo_dir):
    for shape in ("twist", "camber", "bending"):
        assert (demo_dir / "morph" / shape / "summary.json").is_file()
        assert (demo_dir / "morph" / shape / "voltages.csv").is_file()
    for load in ("L1", "L2", "L3"):
        for method in ("mhe", "jekf-seed", "jekf-tuned"):
            assert (demo_dir / "identify" / f"{load}-{method}" / "summary.json").is_file()
    text = (demo_dir / "report.html").read_text()
    assert "<script" not in text and re.findall(r'(?:src|href)="(?!data:)', text) == []
    assert text.count("<img") >= 15


def test_demo_numbers(demo_dir):
    s = json.loads((demo_dir / "summary.json").read_text())
    for shape, runs in s["morph"].items():
        qp, sat = runs["qp"], runs["lqr_saturated"]
        lo, hi = qp["peak_voltage_V"]
        assert lo >= -500 - 1e-6 and hi <= 1500 + 1e-6, shape
        assert qp["shape_error"] < sat["shape_error"], shape
    # the quick configuration (0.5 s of data) still separates the estimators on L1/L2
    for load in ("L1", "L2"):
        runs = s["identify"][load]
        assert runs["mhe"]["load_error"] < runs["jekf-tuned"]["load_error"] < runs["jekf-seed"]["load_error"], load
    assert s["identify"]["L1"]["mhe"]["load_error"] < 0.03
    assert s["tables"]["membrane_6_2"]["ours"][0] == pytest.approx(82.14063341, rel=1e-8)


@pytest.mark.skipif(find_chromium() is None, reason="no chromium binary (apt-get install chromium)")
def test_demo_report_opens_without_console_errors(demo_dir, tmp_path):
    check = open_in_chromium(demo_dir / "report.html", tmp_path / "report.png", size=(1200, 3000))
    assert check.console == ()
    assert check.screenshot.stat().st_size > 50_000
