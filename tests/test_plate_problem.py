"""The plate problem file: the built-in loads, bad files give one line that names the field."""

import re
import tomllib

import pytest

from wingopt.errors import ProblemFileError
from wingopt.problem import PROBLEMS_DIR, load_problem, parse_problem


def plate_doc():
    return tomllib.loads((PROBLEMS_DIR / "plate.toml").read_text())


def test_builtin_plate_layout():
    p = load_problem("plate")
    assert p.kind == "plate"
    assert (p.width, p.length, p.nodes) == (0.15, 0.6, (13, 61))
    assert p.patch_names == tuple(f"PZ{i}" for i in range(1, 10))
    assert len(p.battens) == 5
    assert (p.actuators.vmin, p.actuators.vmax) == (-500.0, 1500.0)
    assert (p.targets.twist, p.targets.camber, p.targets.bending) == (0.01, 0.01, 0.1)
    # Table 5.2/5.3 values that are not calibrated
    assert p.skin.material.e1 == 1.0e9 and p.skin.thickness == 5.0e-4
    assert p.batten.material.e1 == 20.0e9 and p.batten.angles == (90.0,) * 4
    assert p.piezo.d33 == 5.0e-10 and p.piezo.thickness == 5.0e-4
    assert p.piezo.material.nu21 == pytest.approx(0.3)
    assert p.piezo.material.kelvin_voigt == (5.0e-5, 5.0e-5)
    # root pair PZ8/PZ9 the largest, at the root; pairs symmetric about mid-chord
    areas = {q.name: (q.rect[1] - q.rect[0]) * (q.rect[3] - q.rect[2]) for q in p.patches}
    assert max(areas, key=areas.get) in ("PZ8", "PZ9") and areas["PZ8"] == pytest.approx(areas["PZ9"])
    assert p.patches[7].rect[3] == p.length


def _set(doc, path, value):
    node = doc
    for k in path[:-1]:
        node = node[k]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value


BAD = [
    (("materials", "plate", "thickness"), -5e-4, r"\[materials\.plate\] thickness = -0\.0005: expected a positive"),
    (("materials", "plate", "poisson_ratio"), 0.6, r"\[materials\.plate\] poisson_ratio = 0\.6"),
    (("materials", "batten", "nu12"), 5.0, r"\[materials\.batten\] nu12 = 5\.0"),
    (("materials", "batten", "e1"), "stiff", r"\[materials\.batten\] e1 = 'stiff'"),
    (("materials", "batten", "plies"), [90.0, 400.0], r"\[materials\.batten\] plies = \[90\.0, 400\.0\]: expected"),
    (("materials", "batten", "youngs_modulus"), 1e9, r"\[materials\.batten\] e1 = .*either youngs_modulus"),
    (("materials", "piezo", "d33"), 0.0, r"\[materials\.piezo\] d33 = 0\.0: expected a positive number"),
    (("materials", "piezo", "kelvin_voigt"), [1e-4, -1.0], r"\[materials\.piezo\] kelvin_voigt = \[0\.0001, -1\.0\]"),
    (("materials", "piezo", "colour"), "blue", r"\[materials\.piezo\] unknown key 'colour'"),
    (("materials", "piezo"), KeyError, r"\[materials\] piezo is missing"),
    (("geometry", "length"), 0.0, r"\[geometry\] length = 0\.0: expected a positive number"),
    (("geometry", "span"), 0.6, r"\[geometry\] unknown key 'span'"),
    (("battens", 0, "rect"), [0.0, 0.2, 0.0, 0.6], r"\[battens\[1\]\] rect = .*inside the domain"),
    (("patches", 3, "rect"), [0.1, 0.05, 0.2, 0.225], r"\[patches\[4\]\] rect = .*x0 < x1"),
    (("patches", 0, "name"), "PZ2", r"patches = 'PZ2': expected unique patches names"),
    (("mesh", "nodes"), [3, 61], r"\[mesh\] nodes = \[3, 61\]: expected a list of 2 integers >= 4"),
    (("actuators", "vmax"), -600.0, r"\[actuators\] vmax = -600\.0: expected a voltage above vmin = -500\.0"),
    (("actuators", "vmin"), 1500.0, r"\[actuators\] vmax = 1500\.0: expected a voltage above vmin = 1500\.0"),
    (("targets", "twist"), "big", r"\[targets\] twist = 'big'"),
    (("targets", "sweep"), 0.1, r"\[targets\] unknown key 'sweep'"),
]


@pytest.mark.parametrize("path,value,pattern", BAD)
def test_bad_plate_file_names_the_field(path, value, pattern):
    doc = plate_doc()
    _set(doc, path, value)
    with pytest.raises(ProblemFileError) as exc:
        parse_problem(doc, "bad.toml")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("bad.toml: ")
    assert re.search(pattern, msg), msg


def test_overlapping_patches_are_rejected():
    doc = plate_doc()
    doc["patches"][1]["rect"] = list(doc["patches"][4]["rect"])  # PZ2 onto PZ5
    with pytest.raises(ProblemFileError, match=r"PZ2 .* and PZ5 .* overlap") as exc:
        parse_problem(doc, "bad.toml")
    assert "\n" not in str(exc.value)


def test_isotropic_and_orthotropic_forms_are_both_accepted():
    doc = plate_doc()
    doc["materials"]["plate"] = {
        "density": 1000.0,
        "e1": 1.0e9,
        "e2": 1.0e9,
        "g12": 1.0e9 / 2.66,
        "nu12": 0.33,
        "thickness": 5.0e-4,
    }
    p = parse_problem(doc, "iso.toml")
    q = load_problem("plate")
    assert p.skin.rigidity() == pytest.approx(q.skin.rigidity(), rel=1e-12)


def test_battens_and_patches_are_optional(tmp_path):
    doc = plate_doc()
    del doc["battens"], doc["patches"]
    p = parse_problem(doc, "bare.toml")
    assert p.battens == () and p.patches == ()
