"""Problem files: the built-ins load, bad files give one line that names the field."""

import re
import tomllib

import pytest

from wingopt.errors import InputError, ProblemFileError
from wingopt.problem import PROBLEMS_DIR, load_problem, parse_mesh, parse_problem


def membrane_doc():
    return tomllib.loads((PROBLEMS_DIR / "membrane.toml").read_text())


def test_builtin_membrane_matches_the_spec(membrane_problem):
    p = membrane_problem
    assert (p.width, p.height, p.nodes) == (0.14, 0.07, (25, 13))
    assert p.sensor_names == ("S1", "S2", "S3", "S4")
    assert p.sensors[3].rect == (0.088, 0.128, 0.046, 0.058)
    assert p.identification.initial_load == 200.0


BAD = [
    (("material", "thickness"), -1e-4, r"\[material\] thickness = -0\.0001: expected a positive number"),
    (("material", "poisson_ratio"), 0.7, r"\[material\] poisson_ratio = 0\.7"),
    (("material", "density"), "heavy", r"\[material\] density = 'heavy'"),
    (("mesh", "nodes"), [3, 13], r"\[mesh\] nodes = \[3, 13\]: expected a list of 2 integers >= 4"),
    (("mesh", "nodes"), [25], r"\[mesh\] nodes"),
    (
        ("sensors", 0, "rect"),
        [0.01, 0.2, 0.01, 0.02],
        r"\[sensors\[1\]\] rect = .*outside the domain|inside the domain",
    ),
    (("sensors", 1, "rect"), [0.05, 0.04, 0.01, 0.02], r"\[sensors\[2\]\] rect = .*x0 < x1"),
    (("geometry", "chord"), 0.1, r"\[geometry\] unknown key 'chord'"),
    (("geometry", "width"), KeyError, r"\[geometry\] width is missing"),
    (("identification", "initial_load"), 0.0, r"\[identification\] initial_load = 0\.0"),
    (("kind",), "balloon", r"kind = 'balloon': expected one of membrane, plate"),
]


@pytest.mark.parametrize("path,value,pattern", BAD)
def test_bad_problem_file_names_the_field(path, value, pattern):
    doc = membrane_doc()
    node = doc
    for k in path[:-1]:
        node = node[k]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    with pytest.raises(ProblemFileError) as exc:
        parse_problem(doc, "bad.toml")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("bad.toml: ")
    assert re.search(pattern, msg), msg


def test_duplicate_sensor_names():
    doc = membrane_doc()
    doc["sensors"][1]["name"] = "S1"
    with pytest.raises(ProblemFileError, match="unique sensor names"):
        parse_problem(doc, "bad.toml")


def test_invalid_toml_and_missing_file(tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text("kind = membrane\n[geometry\n")
    with pytest.raises(ProblemFileError, match="not valid TOML"):
        load_problem(bad)
    with pytest.raises(ProblemFileError, match="no such file"):
        load_problem(tmp_path / "absent.toml")
    with pytest.raises(ProblemFileError, match="built-in name"):
        load_problem("no-such-problem")


def test_any_sensor_list_is_accepted():
    doc = membrane_doc()
    doc["sensors"] = [{"name": f"T{i}", "rect": [0.01 * i, 0.01 * i + 0.005, 0.01, 0.03]} for i in range(1, 13)]
    p = parse_problem(doc, "many.toml")
    assert len(p.sensors) == 12


@pytest.mark.parametrize("text,expected", [("25x13", (25, 13)), (" 49X25 ", (49, 25))])
def test_parse_mesh(text, expected):
    assert parse_mesh(text) == expected


@pytest.mark.parametrize("text", ["25", "25x", "x13", "25*13", "3x13", "25x13x2"])
def test_parse_mesh_rejects(text):
    with pytest.raises(InputError, match="mesh ="):
        parse_mesh(text)
