import json

import pytest

from wingopt.cli import main
from wingopt.problem import PROBLEMS_DIR


def test_modes_json_reproduces_table_6_2(capsys):
    assert main(["modes", "membrane", "--mesh", "25x13", "--count", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["frequencies_hz"] == pytest.approx([82.14063341, 103.90059613, 132.44779727, 151.45989864], rel=1e-8)
    assert len(out["eigenvalues"]) == 4
    assert out["eigenvalues"][0] == pytest.approx([-31.919399, 515.116819], abs=2e-6)
    ims = [e[1] for e in out["eigenvalues"]]
    assert ims == sorted(ims) and min(ims) > 0


def test_modes_any_problem_path(capsys, tmp_path):
    src = (PROBLEMS_DIR / "membrane.toml").read_text().replace("nodes = [25, 13]", "nodes = [13, 7]")
    path = tmp_path / "small.toml"
    path.write_text(src)
    assert main(["modes", str(path), "--count", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mesh"] == [13, 7]
    assert out["frequencies_hz"][0] == pytest.approx(82.140658289, rel=1e-8)


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["modes", "membrane", "--mesh", "25by13"], "mesh = '25by13'"),
        (["modes", "membrane", "--count", "0"], "count = 0"),
        (["modes", "nowhere.toml"], "no such file"),
    ],
)
def test_modes_bad_input_exit_code_2(capsys, argv, needle):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
