"""Robot description files: the shipped robots load, and every kind of bad input is reported
as a RobotDescriptionError naming the file, the field and the reason."""
from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import numpy as np
import pytest
import sympy
import yaml

from kindyngen.model.robot_model import RobotDescriptionError
from kindyngen.readers.yaml_description import load_robot

ROBOTS = Path(__file__).resolve().parents[2] / "robots"


# --------------------------------------------------------------------------- shipped robots

@pytest.mark.parametrize("name, convention", [("lwr4", "standard"), ("lwr4_hartl", "standard"),
                                              ("panda", "modified")])
def test_shipped_robot_loads(name, convention):
    robot = load_robot(ROBOTS / f"{name}.yaml")
    assert robot.name == name
    assert robot.convention == convention
    assert robot.n == 7
    assert len(robot.links) == 7
    assert robot.lower.shape == (7,) and robot.upper.shape == (7,)
    assert np.all(robot.lower < robot.upper)
    assert np.all(np.isfinite(robot.lower)) and np.all(np.isfinite(robot.upper))
    assert robot.gravity == (0, 0, sympy.Rational(-981, 100))   # exact, as written
    for link in robot.links:
        assert link.mass > 0
        assert np.all(np.linalg.eigvalsh(link.inertia_matrix()) > 0)
    # every alpha of these arms is a multiple of pi/2, so its cosine and sine are exact
    for joint in robot.joints:
        assert isinstance(joint.alpha, sympy.Expr)
        assert sympy.cos(joint.alpha) in (-1, 0, 1) and sympy.sin(joint.alpha) in (-1, 0, 1)


def test_panda_matches_published_geometry():
    """Zero configuration of the Franka table without the 0.107 m flange offset:
    flange at x = 0.088, z = 0.333 + 0.316 + 0.384, z axis pointing down."""
    robot = load_robot(ROBOTS / "panda.yaml")
    d = [float(j.d) for j in robot.joints]
    a = [float(j.a) for j in robot.joints]
    assert d == [0.333, 0, 0.316, 0, 0.384, 0, 0]
    assert a == [0, 0, 0, 0.0825, -0.0825, 0, 0.088]
    assert [j.alpha for j in robot.joints] == [0, -sympy.pi / 2, sympy.pi / 2, sympy.pi / 2,
                                               -sympy.pi / 2, sympy.pi / 2, sympy.pi / 2]
    assert sum(link.mass for link in robot.links) == pytest.approx(16.0621, abs=1e-4)


# --------------------------------------------------------------------------- exact alpha

def _good() -> dict:
    """A valid two-joint description; each test mutates a fresh copy."""
    return copy.deepcopy({
        "name": "two",
        "dh": "standard",
        "gravity": [0, 0, -9.81],
        "joints": [
            {"a": 0, "alpha": "pi/2", "d": 0.40, "offset": 0, "lower": -2.0, "upper": 2.0},
            {"a": 0.1, "alpha": "-pi/2", "d": 0, "offset": 0, "lower": -1.0, "upper": 1.5},
        ],
        "links": [
            {"mass": 2.0, "com": [0.0, 0.01, 0.1], "inertia": [0.02, 0.02, 0.01, 0.001, 0.0, 0.0]},
            {"mass": 1.0, "com": [0.05, 0.0, 0.0], "inertia": [0.01, 0.012, 0.009, 0.0, 0.0, 0.0005]},
        ],
    })


def _write(tmp_path: Path, data) -> Path:
    path = tmp_path / "robot.yaml"
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False))
    return path


def test_good_file_loads_and_alpha_is_exact(tmp_path):
    robot = load_robot(_write(tmp_path, _good()))
    assert robot.n == 2 and robot.convention == "standard"
    assert robot.joints[0].alpha == sympy.pi / 2
    assert robot.joints[1].alpha == -sympy.pi / 2
    assert sympy.cos(robot.joints[0].alpha) == 0 and sympy.sin(robot.joints[1].alpha) == -1
    assert robot.joints[0].d == sympy.Rational(2, 5)           # decimal kept exact as well
    assert robot.lower.tolist() == [-2.0, -1.0] and robot.upper.tolist() == [2.0, 1.5]
    assert robot.links[1].inertia_matrix()[1, 2] == 0.0005


@pytest.mark.parametrize("text, value", [("pi/2", sympy.pi / 2), ("-pi/2", -sympy.pi / 2),
                                         ("pi", sympy.pi), ("2*pi/3", 2 * sympy.pi / 3),
                                         (0, 0), (1.5, sympy.Rational(3, 2))])
def test_alpha_expressions(tmp_path, text, value):
    data = _good()
    data["joints"][0]["alpha"] = text
    alpha = load_robot(_write(tmp_path, data)).joints[0].alpha
    assert isinstance(alpha, sympy.Expr)
    assert sympy.simplify(alpha - value) == 0 and alpha.free_symbols == set()
    assert not alpha.has(sympy.Float)


# --------------------------------------------------------------------------- bad input

def _expect(path: Path, field: str, reason: str):
    """Load ``path`` and check that the error names the file, the field and the reason."""
    pattern = f"^{re.escape(str(path))}: field '{re.escape(field)}': .*{reason}"
    with pytest.raises(RobotDescriptionError, match=pattern) as info:
        load_robot(path)
    assert info.value.field == field
    assert info.value.source == str(path)
    return info.value


def test_malformed_yaml_reports_line(tmp_path):
    path = _write(tmp_path, "name: bad\ndh: standard\ngravity: [0, 0, -9.81]\njoints: x: y\n")
    err = _expect(path, "<yaml>", "malformed YAML")
    assert re.search(r"\bline 4\b", err.reason)


def test_malformed_yaml_unclosed_list(tmp_path):
    path = _write(tmp_path, "name: bad\ngravity: [0, 0\ndh: standard\n")
    err = _expect(path, "<yaml>", "malformed YAML")
    assert re.search(r"\bline 3\b", err.reason)


@pytest.mark.parametrize("text", ["- 1\n- 2\n", "just a string\n", "", "42\n"])
def test_top_level_not_mapping(tmp_path, text):
    _expect(_write(tmp_path, text), "<top level>", "expected a mapping")


@pytest.mark.parametrize("field", ["name", "dh", "gravity", "joints", "links",
                                   "joints[0].a", "joints[0].alpha", "joints[0].d",
                                   "joints[0].lower", "joints[0].upper",
                                   "joints[1].upper",
                                   "links[0].mass", "links[0].com", "links[0].inertia",
                                   "links[1].inertia"])
def test_missing_field(tmp_path, field):
    data = _good()
    m = re.fullmatch(r"(\w+)(?:\[(\d+)\]\.(\w+))?", field)
    if m.group(2) is None:
        del data[m.group(1)]
    else:
        del data[m.group(1)][int(m.group(2))][m.group(3)]
    _expect(_write(tmp_path, data), field, "missing")


def _set(data, field, value):
    """Set ``gravity``, ``joints[0].a`` or ``links[1].com`` to ``value``."""
    m = re.fullmatch(r"(\w+)(?:\[(\d+)\]\.(\w+))?", field)
    if m.group(2) is None:
        data[m.group(1)] = value
    else:
        data[m.group(1)][int(m.group(2))][m.group(3)] = value
    return data


@pytest.mark.parametrize("field, value, reported, reason", [
    ("gravity", [0, -9.81], "gravity", "expected 3 numbers, got 2"),
    ("gravity", [0, 0, 0, -9.81], "gravity", "expected 3 numbers, got 4"),
    ("gravity", -9.81, "gravity", "expected a list of 3 numbers"),
    ("links[0].com", [0.0, 0.1], "links[0].com", "expected 3 numbers, got 2"),
    ("links[1].inertia", [0.01, 0.01, 0.01, 0, 0], "links[1].inertia", "expected 6 numbers, got 5"),
])
def test_wrong_length(tmp_path, field, value, reported, reason):
    _expect(_write(tmp_path, _set(_good(), field, value)), reported, reason)


def test_links_count_differs_from_joints(tmp_path):
    data = _good()
    data["links"].pop()
    _expect(_write(tmp_path, data), "links", "expected 2 entries.*got 1")
    data = _good()
    data["links"].append(copy.deepcopy(data["links"][0]))
    _expect(_write(tmp_path, data), "links", "expected 2 entries.*got 3")


@pytest.mark.parametrize("field, value, reason", [
    ("joints[0].a", "2*abc", "not a real constant"),   # a plain name is a symbolic length; an expression in it is not
    ("joints[0].offset", "abc", "not a real constant"),
    ("joints[0].alpha", "pi/x", "not a real constant"),
    ("joints[1].d", "sqrt(-1)", "not a real constant"),
    ("joints[0].alpha", "pi/", "cannot parse"),
    ("joints[0].alpha", "[1, 2]", "cannot parse"),
    ("joints[0].alpha", "__import__('os').getcwd()", "cannot parse"),
    ("joints[0].lower", None, "expected a number"),
    ("joints[0].upper", True, "expected a number"),
    ("links[0].mass", "heavy", "not a real constant"),
    ("links[0].mass", [1.0], "expected a number"),
])
def test_non_numeric(tmp_path, field, value, reason):
    _expect(_write(tmp_path, _set(_good(), field, value)), field, reason)


def test_non_numeric_vector_entry(tmp_path):
    data = _good()
    data["links"][1]["com"] = [0.0, "abc", 0.0]
    _expect(_write(tmp_path, data), "links[1].com[1]", "not a real constant")
    data = _good()
    data["gravity"] = [0, 0, "g"]
    _expect(_write(tmp_path, data), "gravity[2]", "not a real constant")


@pytest.mark.parametrize("field, value", [
    ("links[0].mass", math.inf), ("joints[0].d", math.nan), ("joints[1].a", -math.inf),
    ("joints[0].upper", math.inf), ("joints[0].alpha", "1e400"), ("links[1].mass", "2**5000"),
    ("joints[0].d", 10 ** 400),
])
def test_non_finite(tmp_path, field, value):
    _expect(_write(tmp_path, _set(_good(), field, value)), field, "finite")


def test_non_finite_vector_entry(tmp_path):
    data = _good()
    data["links"][0]["inertia"][3] = math.nan
    _expect(_write(tmp_path, data), "links[0].inertia[3]", "finite")


@pytest.mark.parametrize("mass", [-1.0, 0, 0.0, "-pi"])
def test_mass_not_positive(tmp_path, mass):
    _expect(_write(tmp_path, _set(_good(), "links[1].mass", mass)), "links[1].mass",
            "mass must be positive")


@pytest.mark.parametrize("inertia", [
    [1.0, 1.0, -0.5, 0, 0, 0],          # a negative principal moment
    [1.0, 1.0, 1.0, 2.0, 0, 0],         # positive diagonal, eigenvalues -1, 1, 3
    [1.0, 1.0, 0.0, 0, 0, 0],           # singular
    [0, 0, 0, 0, 0, 0],
])
def test_inertia_not_positive_definite(tmp_path, inertia):
    _expect(_write(tmp_path, _set(_good(), "links[0].inertia", inertia)), "links[0].inertia",
            "not positive definite")


@pytest.mark.parametrize("inertia", [
    [1.0, 1.0, 3.0, 0, 0, 0],            # principal moments 1, 1, 3
    [3.0, 1.0, 1.0, 0, 0, 0],
    # the same tensor (moments 1, 1, 3) rotated by 45 deg about z: the check must use
    # principal moments, not the diagonal (2, 2, 1 here satisfies the inequality)
    [2.0, 2.0, 1.0, 1.0, 0, 0],
])
def test_inertia_triangle_inequality(tmp_path, inertia):
    _expect(_write(tmp_path, _set(_good(), "links[1].inertia", inertia)), "links[1].inertia",
            "triangle inequality")


def test_inertia_on_the_triangle_boundary_is_accepted(tmp_path):
    """A thin rod / flat plate limit: moments 1, 1, 2 is a physical (planar) body."""
    load_robot(_write(tmp_path, _set(_good(), "links[1].inertia", [1.0, 1.0, 2.0, 0, 0, 0])))


@pytest.mark.parametrize("lower, upper", [(1.0, -1.0), (0.5, 0.5), ("pi", "-pi")])
def test_limits_reversed_or_equal(tmp_path, lower, upper):
    data = _good()
    data["joints"][1]["lower"], data["joints"][1]["upper"] = lower, upper
    _expect(_write(tmp_path, data), "joints[1].lower", "limits reversed or empty")


@pytest.mark.parametrize("dh", ["craig", "Standard", "", 1, None])
def test_unknown_convention(tmp_path, dh):
    _expect(_write(tmp_path, _set(_good(), "dh", dh)), "dh", "expected one of")


@pytest.mark.parametrize("name", ["", "   ", 5, None])
def test_bad_name(tmp_path, name):
    _expect(_write(tmp_path, _set(_good(), "name", name)), "name", "non-empty string")


def test_unreadable_path(tmp_path):
    _expect(tmp_path / "does_not_exist.yaml", "<file>", "cannot read")
    _expect(tmp_path, "<file>", "cannot read")       # a directory


def test_joint_or_link_not_a_mapping(tmp_path):
    data = _good()
    data["joints"][1] = [0, 0, 0]
    _expect(_write(tmp_path, data), "joints[1]", "expected a mapping")
    data = _good()
    data["links"][0] = 3.0
    _expect(_write(tmp_path, data), "links[0]", "expected a mapping")
    data = _good()
    data["joints"] = []
    _expect(_write(tmp_path, data), "joints", "non-empty list")


# --------------------------------------------------------------------------- unknown keys

@pytest.mark.parametrize("where, typo, field, closest", [
    ("joints", "ofset", "joints[0].ofset", "offset"),
    ("joints", "alfa", "joints[0].alfa", "alpha"),
    ("links", "mas", "links[0].mas", "mass"),
    ("links", "inertial", "links[0].inertial", "inertia"),
    ("top", "gravty", "gravity", "gravity"),
    ("top", "joint", "joint", "joints"),
])
def test_unknown_key_is_refused_with_the_closest_known_key(tmp_path, where, typo, field, closest):
    """A typo used to be ignored silently (``ofset: 0.5`` gave a different arm, exit code 0)."""
    data = _good()
    if where == "top":
        data[typo] = 1
        field = typo
    else:
        data[where][0][typo] = 0.5
    err = _expect(_write(tmp_path, data), field, "unknown key")
    assert f"did you mean '{closest}'" in err.reason


def test_unknown_key_without_a_close_match_lists_the_known_ones(tmp_path):
    data = _good()
    data["links"][1]["colour"] = "red"
    err = _expect(_write(tmp_path, data), "links[1].colour", "unknown key")
    assert "did you mean" not in err.reason and "(known: mass, com, inertia)" in err.reason


@pytest.mark.parametrize("field, value, shown", [
    ("links[0].inertia", [1.0, 1.0, 5.0, 0, 0, 0], "principal moments 1, 1, 5 violate"),
    ("links[0].inertia", [1.0, -1.0, 1.0, 0, 0, 0], "principal moments -1, 1, 1"),
])
def test_messages_print_plain_numbers(tmp_path, field, value, shown):
    data = _good()
    _set(data, field, value)
    err = _expect(_write(tmp_path, data), field, "")
    assert shown in err.reason and "np." not in str(err) and "float64" not in str(err)


def test_reversed_limits_message_prints_plain_numbers(tmp_path):
    data = _good()
    data["joints"][0]["lower"], data["joints"][0]["upper"] = 2.5, -1
    err = _expect(_write(tmp_path, data), "joints[0].lower", "limits reversed")
    assert "lower 2.5 >= upper -1" in err.reason


def test_inertial_values_are_exact_rationals(tmp_path):
    """The decimals as written, exactly: what the generated code bakes in cannot depend on
    how a processor rounds (the barycentric numbers are computed from these exactly)."""
    robot = load_robot(_write(tmp_path, _good()))
    link = robot.links[1]
    assert link.mass == 1 and link.com[0] == sympy.Rational(1, 20)
    assert link.inertia[5] == sympy.Rational(1, 2000)
    from kindyngen.model.inertial_parameters import barycentric
    p = barycentric(link)
    # Iyy about the origin = 0.012 + m (cx^2 + cz^2) = 0.012 + 0.0025, exactly
    assert p[6] == sympy.Rational(29, 2000)
    assert all(isinstance(v, sympy.Rational) for v in p)
