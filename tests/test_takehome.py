"""What a lab takes home from an identification (issue 33): the field behind the reported lift and
its band (``load.csv``), the lift history with the reported lift (``lift.csv``), the field over time
(``field.nc``, xarray), pandas and xarray exports, the provenance in ``summary.json`` and a
self-contained ``report.html``.

The records are the shipped SYNTHETIC stand-in's (``examples/data``; FvK truth on a finer mesh,
prestrains off the problem file's). The calibrated problem carries the posterior ``wingopt
calibrate`` finds on the stand-in's calibration record (docs/tunnel.md), not the truth.
"""

from __future__ import annotations

import base64
import csv
import hashlib
import json
import shutil
import subprocess
import sys
from datetime import datetime
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import simpson, trapezoid

import wingopt as wo
from wingopt.errors import InputError
from wingopt.estimation.core.result import IdentificationResult
from wingopt.membrane import MembraneModel
from wingopt.results import to_jsonable
from wingopt.results.field import integral, mean_field

DATA = Path(__file__).resolve().parents[1] / "examples" / "data"
RECORD, FRAMES = DATA / "tunnel_300Hz.csv", DATA / "tunnel_dic_300Hz.npz"
CALIBRATION = DATA / "tunnel_calibration_300Hz.csv"
# wingopt calibrate's posterior on the stand-in's calibration record (docs/tunnel.md)
CALIBRATED = {
    "prestrain": (0.05733, 0.04561),
    "prestrain_std": (0.0023, 0.0017),
    "prestrain_correlation": -0.36,
    "damping": 1.035,
    "damping_std": 0.02,
    "calibration": "tunnel_calibration_300Hz.csv (the test's copy of its posterior)",
}
ROUTES = ("sensors", "calibration", "dic", "dic+calibration")
PNG = b"\x89PNG\r\n\x1a\n"


def _problem(route: str):
    problem = wo.load_problem("membrane")
    return problem.with_identification(**CALIBRATED) if "calibration" in route else problem


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Each stand-in route identified once and written (figures only for the DIC route: the report's)."""
    out = {}
    for route in ROUTES:
        source = {"dic": FRAMES} if route.startswith("dic") else {"data": RECORD}
        run = wo.identify(_problem(route), **source)
        d = tmp_path_factory.mktemp("takehome") / route.replace("+", "_")
        wo.write_identify_outputs(run, d, plots=route == "dic")
        out[route] = (run, d)
    return out


def mf_ratio(run) -> float:
    """The mean field's integral over the reported lift (1 but for the frames' mean of a DIC run, 4e-4 off)."""
    mf = run.mean_field()
    return mf.field_lift_N / mf.lift_N


def _load_csv(d: Path):
    with open(d / "load.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["x", "y", "pressure_Pa", "pressure_std_Pa"]
    a = np.array(rows[1:], dtype=float)
    x, y = np.unique(a[:, 0]), np.unique(a[:, 1])
    return x, y, a[:, 2].reshape(y.size, x.size), a[:, 3].reshape(y.size, x.size)


@pytest.mark.parametrize("route", ROUTES)
def test_load_csv_integrates_to_the_reported_lift(runs, route):
    run, d = runs[route]
    summary = json.loads((d / "summary.json").read_text())
    lift, band = summary["lift_N"], summary["lift_std_N"]
    assert (lift, band) == run.result.reported_lift
    x, y, P, S = _load_csv(d)
    # The file itself, integrated as a lab would (trapezoid on its grid): within 0.1 %.
    assert trapezoid(trapezoid(P, x, axis=1), y) == pytest.approx(lift, rel=1e-3)
    assert simpson(simpson(P, x=x, axis=1), x=y) == pytest.approx(lift, rel=1e-3)
    assert summary["mean_field"]["field_lift_N"] == pytest.approx(lift, rel=1e-3)
    # The band: the lift's relative band at every point; the field keeps one sign, so it integrates to the lift's band.
    assert np.all(P > 0)
    np.testing.assert_allclose(S, P * band / lift, rtol=1e-8, atol=1e-9)
    assert simpson(simpson(S, x=x, axis=1), x=y) == pytest.approx(band * mf_ratio(runs[route][0]), rel=2e-4)
    # run.load_field() is the same field (no longer the last sample's).
    X, Y = np.meshgrid(x, y)
    np.testing.assert_allclose(run.load_field()(X, Y), P, rtol=1e-8, atol=1e-6)
    last = run.load_field(-1)(X, Y)
    assert abs(trapezoid(trapezoid(last, x, axis=1), y) - run.result.lift[-1]) < 2e-3 * abs(lift)


def test_the_steady_field_is_the_time_mean_and_lift_csv_carries_the_reported_lift(runs):
    run, d = runs["sensors"]
    mf = run.mean_field()
    assert mf.kind == "mean" and mf.samples == run.result.t.size
    np.testing.assert_allclose(mf.coefficients, run.result.load.mean(axis=0), rtol=1e-12)
    with open(d / "lift.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "lift_N", "lift_std_N", "reported_lift_N", "reported_lift_std_N"]
    a = np.array(rows[1:], dtype=float)
    np.testing.assert_allclose(a[:, 1], run.result.lift, rtol=1e-9)
    np.testing.assert_allclose(a[:, 2], run.result.lift_std, rtol=1e-9)
    assert np.all(a[:, 3] == pytest.approx(run.lift, rel=1e-9)) and np.all(a[:, 4] == pytest.approx(run.lift_std))
    assert run.lift_history is run.result.lift or np.array_equal(run.lift_history, run.result.lift)


def test_a_transient_result_reports_its_last_field():
    problem = wo.load_problem("membrane").with_mesh((13, 7))
    model = MembraneModel.from_problem(problem)
    rng = np.random.default_rng(0)
    load = 100.0 + 20.0 * rng.standard_normal((5, model.space.n))
    lifts = integral(model.space, load.T)
    result = IdentificationResult("mhe", np.arange(5.0), load, np.zeros((5, model.n)), lifts, 0.1 * lifts)
    mf = mean_field(result, model)
    assert mf.kind == "last" and mf.samples == 1
    np.testing.assert_array_equal(mf.coefficients, load[-1])
    assert mf.field_lift_N == pytest.approx(result.reported_lift[0], rel=1e-12)
    assert mf.relative_band == pytest.approx(0.1)


def test_to_xarray_to_netcdf_and_back_equals_the_field_band_and_lift(runs, tmp_path):
    xr = pytest.importorskip("xarray", reason="the data extra (make test installs it) is not installed")
    from wingopt.results.export import netcdf_engine, write_netcdf

    run, d = runs["dic"]
    ds = run.to_xarray()
    assert set(ds["pressure"].dims) == {"t", "x", "y"} and ds["x"].attrs["units"] == "m"
    assert ds["pressure"].attrs["units"] == "Pa" and ds["t"].attrs["units"] == "s" and ds["lift"].attrs["units"] == "N"
    path = write_netcdf(ds, tmp_path / "f.nc")
    with xr.open_dataset(path, engine=netcdf_engine()) as back:
        x, y, P, S = _load_csv(d)
        np.testing.assert_allclose(back["x"].values, x)
        np.testing.assert_allclose(back["pressure_mean"].values.T, P, rtol=1e-9)
        np.testing.assert_allclose(back["pressure_std"].values.T, S, rtol=1e-9)
        np.testing.assert_array_equal(back["lift"].values, run.result.lift)
        np.testing.assert_array_equal(back["lift_std"].values, run.result.lift_std)
        assert back.attrs["lift_N"] == run.lift and back.attrs["lift_std_N"] == run.lift_std
        # the field over time, in single precision: the samples' own fields and their lifts
        X, Y = np.meshgrid(x, y)
        k = len(run.result.t) // 2
        np.testing.assert_allclose(back["pressure"].values[k].T, run.load_field(k)(X, Y), rtol=1e-5, atol=1e-3)
        lifts = trapezoid(trapezoid(back["pressure"].values, y, axis=2), x, axis=1)
        np.testing.assert_allclose(lifts, run.result.lift, rtol=2e-3)
    # identify wrote the same dataset
    with xr.open_dataset(d / "field.nc", engine=netcdf_engine()) as written:
        np.testing.assert_allclose(written["pressure_mean"].values, ds["pressure_mean"].values, rtol=1e-12)


def test_to_dataframe_holds_the_lift_history_with_its_band(runs):
    pytest.importorskip("pandas", reason="the data extra (make test installs it) is not installed")
    run, _ = runs["sensors"]
    df = run.to_dataframe()
    assert df.index.name == "t" and len(df) == run.result.t.size
    np.testing.assert_array_equal(df["lift_N"].to_numpy(), run.result.lift)
    np.testing.assert_array_equal(df["lift_std_N"].to_numpy(), run.result.lift_std)
    np.testing.assert_allclose(df["lift_hi_N"] - df["lift_lo_N"], 2 * run.result.lift_std)
    assert df.attrs["lift_N"] == run.lift and df.attrs["lift_std_N"] == run.lift_std
    assert run.result.to_dataframe().equals(df)


def test_summary_json_carries_the_provenance(runs):
    run, d = runs["calibration"]
    s = json.loads((d / "summary.json").read_text())
    prov = s["provenance"]
    assert prov["version"] == wo.__version__ and prov["command_line"]
    assert datetime.fromisoformat(prov["time_utc"]).utcoffset().total_seconds() == 0
    data = next(r for r in prov["inputs"] if r["option"] == "--data")
    assert data["path"] == str(RECORD) and data["sha256"] == hashlib.sha256(RECORD.read_bytes()).hexdigest()
    assert data["bytes"] == RECORD.stat().st_size
    problem_file = Path(run.problem.source)
    assert s["problem_file"]["file_sha256"] == hashlib.sha256(problem_file.read_bytes()).hexdigest()
    plain = json.loads((runs["sensors"][1] / "summary.json").read_text())["problem_file"]
    # the calibrated problem is the same file run with another prior: the as-run hash tells them apart
    assert plain["file_sha256"] == s["problem_file"]["file_sha256"]
    assert plain["as_run_sha256"] != s["problem_file"]["as_run_sha256"]
    assert "platform" in prov and "blas_threads" in prov
    assert s["route"] == "steady" and json.loads(json.dumps(to_jsonable(run.summary()))) == s


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images, self.tags, self.text = [], [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        if tag == "img":
            self.images.append(dict(attrs)["src"])

    def handle_data(self, data):
        self.text.append(data)


def _check_report(path: Path, expect: list[str]) -> _Page:
    html = path.read_text(encoding="utf-8")
    page = _Page()
    page.feed(html)
    page.close()
    assert "script" not in page.tags and "http://" not in html and "https://" not in html  # self-contained
    assert page.images
    for src in page.images:
        head, b64 = src.split(",", 1)
        assert head == "data:image/png;base64"
        assert base64.b64decode(b64, validate=True).startswith(PNG)
    text = " ".join(page.text)
    for e in expect:
        assert e in text, e
    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if chromium:
        # the screenshot goes beside the results folder, never into it: the tests count its figures
        shot = path.parent.with_name(f"{path.parent.name}_report_screenshot.png")
        subprocess.run(
            [chromium, "--headless", "--disable-gpu", "--no-sandbox", f"--screenshot={shot}", path.as_uri()],
            check=True, timeout=60, capture_output=True,
        )  # fmt: skip
        assert shot.read_bytes().startswith(PNG)
    return page


def test_identify_report_html_is_self_contained_and_says_what_ran(runs):
    run, d = runs["dic"]
    s = json.loads((d / "summary.json").read_text())
    sha = hashlib.sha256(FRAMES.read_bytes()).hexdigest()
    page = _check_report(d / "report.html", [sha, "full field (DIC)", "tunnel_dic_300Hz.npz", f"{run.lift:.4g}"])
    assert len(page.images) == len(list(d.glob("*.png"))) == 3  # the field with its band, the lift, the fit
    assert all(w in " ".join(page.text) for w in s["warnings"])


def test_calibrate_writes_a_report_and_its_provenance(tmp_path):
    from wingopt.workflows.calibrate import write_calibration_outputs

    run = wo.calibrate_membrane("membrane", CALIBRATION, nodes=(13, 7))
    write_calibration_outputs(run, tmp_path / "cal")
    s = json.loads((tmp_path / "cal" / "summary.json").read_text())
    sha = hashlib.sha256(CALIBRATION.read_bytes()).hexdigest()
    assert [r["sha256"] for r in s["provenance"]["inputs"] if r["option"] == "--data"] == [sha]
    assert json.loads(json.dumps(to_jsonable(run.summary()))) == s  # what --json prints is on disk
    page = _check_report(
        tmp_path / "cal" / "report.html", [sha, "prestrain_x", f"{run.calibration.parameters['prestrain_x']:.4g}"]
    )
    assert len(page.images) == 2


def test_a_missing_extra_is_one_line_naming_it(runs, monkeypatch):
    for name in ("pandas", "xarray"):
        monkeypatch.setitem(sys.modules, name, None)  # imports of it raise ImportError
    run, _ = runs["sensors"]
    for call in (run.to_dataframe, run.to_xarray):
        with pytest.raises(ImportError, match=r"wingopt\[data\]") as err:
            call()
        assert isinstance(err.value, InputError) and "\n" not in str(err.value)


def test_plot_lift_and_plot_field_from_wo_return_figures(runs):
    from matplotlib.figure import Figure

    from wingopt.plots.field import field_colors

    run, _ = runs["sensors"]
    fig = wo.plot_lift(run)
    assert isinstance(fig, Figure)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert any(f"reported {run.lift:.4g} N ± {run.lift_std:.2g} N (1 sd)" == t for t in labels)
    mine = Figure().subplots()
    for which in ("mean", "std", 1.0):
        assert wo.plot_field(run, which, ax=mine) is mine.figure
    mesh = wo.plot_field(run).axes[0].collections[0]
    assert mesh.get_cmap().name == "viridis" and mesh.norm.vmin == 0.0  # one-signed: sequential from zero
    assert field_colors(np.array([-1.0, 3.0])) == {"cmap": "RdBu_r", "vmin": -3.0, "vmax": 3.0}
    with pytest.raises(InputError, match="which = 'last'"):
        wo.plot_field(run, "last")


def test_a_stream_writes_its_lift_figure_report_and_provenance(tmp_path):
    from wingopt.estimation.options import IdentifyOptions
    from wingopt.estimation.registry import resolve
    from wingopt.workflows.stream import follow

    lines = RECORD.read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#") or not ln.strip()[:1].isdigit()]
    rows = [ln for ln in lines if ln not in head][:400]
    part = tmp_path / "first_400.csv"
    part.write_text("\n".join([*head, *rows]) + "\n")
    problem = wo.load_problem("membrane")
    spec = resolve("auto", "linear", stream=True)
    out = tmp_path / "stream"
    options = IdentifyOptions(window=100, modes=20)
    summary = follow(problem, out, source=str(part), spec=spec, options=options, idle_timeout=0.5)
    on_disk = json.loads((out / "summary.json").read_text())
    sha = hashlib.sha256(part.read_bytes()).hexdigest()
    assert [r["sha256"] for r in on_disk["provenance"]["inputs"] if r["option"] == "--data"] == [sha]
    page = _check_report(out / "report.html", [sha, "stream", part.name, f"{summary['lift_N']:.4g}"])
    assert len(page.images) == len(list(out.glob("*.png"))) == 1  # the lift history with the reported lift
    assert all(w in " ".join(page.text) for w in on_disk["warnings"])
