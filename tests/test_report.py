import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from wingopt.results.browser import find_chromium, open_in_chromium  # noqa: E402
from wingopt.results.report import Report, figure_png  # noqa: E402

needs_chromium = pytest.mark.skipif(find_chromium() is None, reason="no chromium binary (apt-get install chromium)")


def small_report(tmp_path):
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot(np.linspace(0, 1, 50), np.sin(np.linspace(0, 6, 50)))
    rep = Report("test report").heading("Numbers").table(["case", "error"], [["L1", 0.0123], ["L2", 0.045]], "errors")
    rep.figure(figure_png(fig), "a sine").paragraph("done <ok> & escaped")
    return rep.write(tmp_path / "report.html")


def test_report_is_self_contained(tmp_path):
    text = small_report(tmp_path).read_text()
    assert "<script" not in text
    assert re.findall(r'(?:src|href)="(?!data:)', text) == []
    assert "&lt;ok&gt; &amp; escaped" in text and "<td>0.0123</td>" in text


@needs_chromium
def test_report_opens_in_headless_chromium_without_console_messages(tmp_path):
    check = open_in_chromium(small_report(tmp_path), tmp_path / "shot.png")
    assert check.console == ()
    assert check.screenshot.stat().st_size > 10_000


@needs_chromium
def test_the_browser_check_can_fail(tmp_path):
    bad = tmp_path / "bad.html"
    bad.write_text('<!DOCTYPE html><html><head><link rel="icon" href="data:,"></head><body>'
                   '<script>console.error("boom")</script></body></html>')  # fmt: skip
    check = open_in_chromium(bad, tmp_path / "bad.png", size=(400, 300))
    assert any("boom" in c for c in check.console)
