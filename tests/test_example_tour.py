"""The README's API tour (examples/tour.py) runs, and its key numbers hold."""

import importlib.util
from pathlib import Path

import pytest

TOUR = Path(__file__).resolve().parents[1] / "examples" / "tour.py"


def test_tour_quick(tmp_path):
    spec = importlib.util.spec_from_file_location("tour", TOUR)
    tour = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tour)
    n = tour.main(quick=True, out=tmp_path)
    assert n["plate_hz"][0] == pytest.approx(10.014, rel=2e-3)  # 7x31, docs/plate.md
    assert n["qp_shape_error"] < n["lqr_shape_error"]
    assert n["mhe_load_error"] < 0.02
    assert (n["csv_rows"], n["csv_missing"]) == (1381, 13)  # tunnel_300Hz.csv: 13 dropped frames
    assert (tmp_path / "twist" / "summary.json").is_file() and (tmp_path / "L1" / "load.csv").is_file()
    assert (tmp_path / "L1_load.vtu").is_file()
