"""Mimic joints as the readers take them: URDF ``<mimic joint multiplier offset>`` and YAML
``mimic: {joint, multiplier, offset}``, exact; chains of mimics composed; every bad entry an
error naming the file, the field and the reason; a chain (no --tree) with mimics on or off it;
``describe`` writing them back. (The generated functions are checked against Pinocchio in
tests/algorithms/test_mimic_generated.py.)"""
from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np
import pytest
import sympy
import yaml

from kindyngen.algorithms.regressors import evaluate_dag
from kindyngen.codegen.catalog import derive_all
from kindyngen.model.robot_model import Mimic, RobotDescriptionError
from kindyngen.readers.urdf import load_urdf, parse_urdf
from kindyngen.readers.yaml_description import parse_robot
from kindyngen.readers.yaml_writer import describe
from tests.harness import ROOT

DATA = Path(__file__).resolve().parents[1] / "data" / "urdf"
R = sympy.Rational


def test_urdf_mimics_resolved_exactly():
    """The coupled tree: j3 = 0.05 j2 + 0.02, k2 = -0.5 j1 + 0.3, k3 = 2 k2 - 0.1 = -j1 + 0.5
    (a mimic of a mimic composed), exact rationals; the inputs are the independent joints."""
    model = load_urdf(DATA / "mimic_coupled_tree.urdf", tree=True)
    names = [j.name for j in model.joints]
    mimics = {j.name: (names[j.mimic.joint], j.mimic.multiplier, j.mimic.offset) for j in model.joints if j.mimic}
    assert mimics == {"j3": ("j2", R(1, 20), R(1, 50)), "k2": ("j1", R(-1, 2), R(3, 10)), "k3": ("j1", -1, R(1, 2))}
    assert [model.joints[k].name for k in model.coordinates] == ["j1", "j2", "j4", "k1"]
    assert (model.n, model.nq, model.nv) == (7, 4, 4)
    assert "3 of them mimic another, inputs the 4 independent joints" in model.structure_text
    assert any("3 mimic joint(s) (j3, k2, k3) follow others" in note for note in model.notes)
    floating = load_urdf(DATA / "mimic_coupled_tree.urdf", floating_base=True)
    assert (floating.nq, floating.nv) == (11, 10)


def test_yaml_tree_equals_the_urdf():
    """The gripper written as a YAML tree gives the mimics of the URDF."""
    urdf = load_urdf(ROOT / "examples" / "mimic" / "gripper.urdf", tree=True)
    data = {"name": "g", "dh": "none", "gravity": [0, 0, -9.81], "joints": [], "links": []}
    for j, joint in enumerate(urdf.joints):
        row = {"name": joint.name, "lower": joint.lower, "upper": joint.upper}
        if urdf.parents[j] >= 0:
            row["parent"] = urdf.joints[urdf.parents[j]].name
        if joint.mimic is not None:
            row["mimic"] = {"joint": urdf.joints[joint.mimic.joint].name, "multiplier": int(joint.mimic.multiplier)}
        data["joints"].append(row)
        data["links"].append({"mass": 1, "com": [0, 0, 0], "inertia": [0.1, 0.1, 0.1, 0, 0, 0]})
    tree = parse_robot(data, "g.yaml", tree=True)
    assert [j.mimic for j in tree.joints] == [j.mimic for j in urdf.joints]
    assert tree.coordinates == urdf.coordinates == (0,)


YAML_ARM = {"name": "coupled_arm", "dh": "none", "gravity": [0, 0, -9.81], "joints": [
    {"name": "a", "axis": [0, 0, 1], "lower": -2, "upper": 2},
    {"name": "b", "origin": {"xyz": [0, 0, 0.3]}, "axis": [0, 1, 0], "lower": -2, "upper": 2,
     "mimic": {"joint": "c", "multiplier": 2, "offset": 0.1}},
    {"name": "c", "origin": {"xyz": [0.2, 0, 0]}, "axis": [1, 0, 0], "lower": -2, "upper": 2,
     "mimic": {"joint": "a", "multiplier": "1/3", "offset": -0.2}},
    {"name": "d", "type": "prismatic", "origin": {"xyz": [0.1, 0, 0]}, "axis": [1, 0, 0], "lower": 0, "upper": 0.1}],
    "links": [{"mass": 1, "com": [0.05, 0, 0.1], "inertia": [0.01, 0.011, 0.002, 0, 0, 0]}] * 4}


def test_yaml_mimics_resolved_and_written_back():
    """b follows c, c follows a: b = 2 (a/3 - 0.2) + 0.1 = 2/3 a - 3/10, exact; describe
    writes each mimic (a fraction where no decimal is exact) and the result reads back equal."""
    model = parse_robot(YAML_ARM, "arm.yaml")
    assert [j.mimic for j in model.joints] == [None, Mimic(0, R(2, 3), R(-3, 10)), Mimic(0, R(1, 3), R(-1, 5)), None]
    assert (model.nq, model.nv, model.coordinates) == (2, 2, (0, 3))
    written = describe(model)
    assert written["joints"][1]["mimic"] == {"joint": "a", "multiplier": "2/3", "offset": -0.3}
    again = parse_robot(yaml.safe_load(yaml.safe_dump(written)), "again.yaml")
    assert [j.mimic for j in again.joints] == [j.mimic for j in model.joints]


@pytest.mark.parametrize("mimic, field, reason", [
    ({"joint": "zz"}, "joints[2].mimic.joint", "no joint named 'zz'"),
    ({"joint": "b"}, "joints[1].mimic.joint", "the mimic joints form a cycle: b -> c -> b"),
    ({"joint": "c"}, "joints[1].mimic.joint", "the mimic joints form a cycle: b -> c -> c"),
    ({"joint": "a", "multiplier": 0}, "joints[2].mimic.multiplier", "0 would hold the joint at its offset"),
    ({"joint": "a", "offset": 7}, "joints[2].mimic.offset", "7 rad is beyond a full turn"),
    ({"joint": "a", "ofset": 1}, "joints[2].mimic.ofset", "unknown key; did you mean 'offset'?"),
    ({"multiplier": 1}, "joints[2].mimic.joint", "missing"),
    ("a", "joints[2].mimic", "expected a mapping with joint, multiplier, offset"),
])
def test_yaml_mimic_errors(mimic, field, reason):
    data = copy.deepcopy(YAML_ARM)
    data["joints"][2]["mimic"] = mimic
    with pytest.raises(RobotDescriptionError) as error:
        parse_robot(data, "arm.yaml")
    assert error.value.source == "arm.yaml" and error.value.field == field and reason in error.value.reason


def _urdf(joints: str) -> str:
    link = ('<inertial><mass value="1"/><origin xyz="0.1 0 0.05"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.003"/></inertial>')
    names = dict.fromkeys(re.findall(r'link="(\w+)"', joints))
    links = "".join(f'<link name="{name}">{link}</link>' for name in names)
    return f'<robot name="r">{links}{joints}</robot>'


def _j(name, parent, child, kind="revolute", mimic="", axis="0 1 0", xyz="0 0 0.2"):
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}"/><axis xyz="{axis}"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
            f'{mimic}</joint>')


# a chain a -> b (b follows a) to l2, and a branch c -> d (d follows c, offset 0.2) off it
CHAIN = _urdf(_j("a", "base", "l1") + _j("b", "l1", "l2", mimic='<mimic joint="a" multiplier="2" offset="0.1"/>')
              + _j("c", "l1", "l3", axis="1 0 0") + _j("d", "l3", "l4", mimic='<mimic joint="c" offset="0.2"/>')
              + _j("f", "l2", "l5", kind="fixed", mimic='<mimic joint="a"/>'))


def test_chain_keeps_its_mimics_and_locks_the_branch_at_its_offsets():
    """Read as a chain to l2: b stays a mimic of a; the branch c, d is locked (c at 0, d at its
    offset 0.2, d following the locked c), its bodies part of l1: the chain's M and g equal
    the tree's at c = 0 (rows and columns of a); a <mimic> on a fixed joint is ignored."""
    chain = parse_urdf(CHAIN, tip="l2")
    assert [j.name for j in chain.joints] == ["a", "b"] and chain.joints[1].mimic == Mimic(0, 2, R(1, 10))
    assert any("joint 'd' (revolute) is not on the chain: locked at 0.2, its offset" in n for n in chain.notes)
    tree = parse_urdf(CHAIN, tree=True)
    assert [j.name for j in tree.joints] == ["a", "b", "c", "d"] and tree.coordinates == (0, 2)
    q = np.array([0.4])
    values = {}
    for key, model, x in (("chain", chain, q), ("tree", tree, np.array([0.4, 0.0]))):
        functions = {f.name: f for f in derive_all(model, only={"M", "g"})}
        values[key] = [np.array(evaluate_dag(list(functions[name].inlined_outputs()[0]),
                                             dict(zip(functions[name].input_symbols[0], x)))).ravel()
                       for name in ("M", "g")]
    assert np.allclose(values["chain"][0], values["tree"][0][0], rtol=1e-14, atol=0)
    assert np.allclose(values["chain"][1], values["tree"][1][0], rtol=1e-14, atol=0)


@pytest.mark.parametrize("text, kwargs, field, reason", [
    (CHAIN, {"tip": "l4"}, "joint 'b' mimic joint", "'b' is not on the chain but follows 'a', which is"),
    (_urdf(_j("a", "base", "l1") + _j("b", "base", "l2", mimic='<mimic joint="a"/>')), {"tip": "l2"},
     "joint 'b' mimic joint", "follows 'a', which is not on the chain: read the URDF as a tree"),
    (_urdf(_j("a", "base", "l1") + _j("b", "l1", "l2", mimic='<mimic joint="nope"/>')), {"tree": True},
     "joint 'b' mimic joint", "no joint named 'nope'"),
    (_urdf(_j("a", "base", "l1", kind="fixed") + _j("b", "l1", "l2", mimic='<mimic joint="a"/>')), {"tree": True},
     "joint 'b' mimic joint", "'a' is a fixed joint"),
    (_urdf(_j("a", "base", "l1", mimic='<mimic joint="b"/>') + _j("b", "l1", "l2", mimic='<mimic joint="a"/>')),
     {"tree": True}, "joint 'a' mimic joint", "the mimic joints form a cycle: a -> b -> a"),
    (_urdf(_j("a", "base", "l1") + _j("b", "l1", "l2", mimic='<mimic joint="a" multiplier="0"/>')), {"tree": True},
     "joint 'b' mimic multiplier", "0 would hold the joint at its offset"),
    (_urdf(_j("a", "base", "l1") + _j("b", "l1", "l2", mimic='<mimic joint="a" offset="90"/>')), {"tree": True},
     "joint 'b' mimic offset", "beyond a full turn"),
    (_urdf(_j("a", "base", "l1") + _j("b", "l1", "l2", mimic='<mimic multiplier="2"/>')), {"tree": True},
     "joint 'b' mimic joint", "missing"),
    (_urdf(_j("a", "base", "l1") + _j("b", "l1", "l2", mimic='<mimic joint="a" multiplier="x"/>')), {"tree": True},
     "joint 'b' mimic multiplier", "cannot read 'x' as a number"),
])
def test_urdf_mimic_errors(text, kwargs, field, reason):
    with pytest.raises(RobotDescriptionError) as error:
        parse_urdf(text, "r.urdf", **kwargs)
    assert error.value.source == "r.urdf" and error.value.field == field and reason in error.value.reason, \
        str(error.value)


def test_load_dependent_friction_beside_mimic_joints_is_refused():
    """Load-dependent friction acts on a joint's own transmitted torque, which the reduced
    functions of a mimic robot do not have: refused naming the field."""
    data = copy.deepcopy(YAML_ARM)
    data["joints"][0]["friction"] = {"coulomb": 0.1, "load": 0.1}
    with pytest.raises(RobotDescriptionError) as error:
        parse_robot(data, "arm.yaml")
    assert error.value.field == "joints[0].friction.load" and "mimic joints" in error.value.reason
