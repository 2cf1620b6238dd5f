"""Reading closed loops: the YAML ``loops`` section and the URDF ``<loop_joint>`` (Isaac Sim's
extension), the independent joints (named, by ``<transmission>``, or by the rule), and every
refusal as one line naming the file, the field and the reason (exit 2 on the command line)."""
from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from kindyngen.algorithms.loop_closure import FOUR_BAR, loop_system, resolved
from kindyngen.model.robot_model import RobotDescriptionError
from kindyngen.readers.urdf import parse_urdf
from kindyngen.readers.yaml_description import parse_robot

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples" / "loops"


def four_bar(**changes) -> dict:
    data = copy.deepcopy(FOUR_BAR)
    for key, value in changes.items():
        if value is None:
            data.pop(key, None)
        else:
            data[key] = value
    return data


def loop(**changes) -> dict:
    return {**FOUR_BAR["loops"][0], **changes}


def test_the_example_file_is_the_module_example():
    """examples/loops/four_bar.yaml is the four-bar of the loop module's docstring."""
    assert yaml.safe_load((EXAMPLES / "four_bar.yaml").read_text()) == {
        **FOUR_BAR, "loops": [{**FOUR_BAR["loops"][0]}]}


def test_loops_read_and_the_rule_chooses_the_crank():
    """The loop joint's bodies, frames and directions; without 'independent' the rule takes the
    first joint whose omission leaves a regular constraint Jacobian (the crank); 'resolved' makes
    it the model's coordinate (nq = nv = 1)."""
    model = parse_robot(four_bar(), "f.yaml", tree=True)
    (closure,) = model.loops
    assert (closure.name, closure.kind, closure.body_a, closure.body_b, closure.directions) == (
        "pin", "revolute", 1, 2, ("x", "y"))
    assert model.independent is None and model.nv == 3
    assert loop_system(model).independent == (0,)
    assert resolved(model).coordinates == (0,) and resolved(model).nv == 1
    named = parse_robot(four_bar(independent=["rocker"]), "f.yaml", tree=True)
    assert loop_system(named).independent == (2,) and loop_system(named).closed is None
    assert loop_system(parse_robot(four_bar(loops=[loop(type="spherical")]), "f.yaml", tree=True)).independent == (0,)


@pytest.mark.parametrize("changes, field, reason", [
    ({"loops": [loop(link1="coupler", link2="coupler")]}, "loops[0].link2", "two different links"),
    ({"loops": [loop(link1="couplr")]}, "loops[0].link1", "closest: coupler"),
    ({"loops": [loop(type="prismatic")]}, "loops[0].type", "expected one of"),
    ({"loops": [loop(directions=["x", "rz"])]}, "loops[0].directions[1]", "a revolute loop joint constrains"),
    ({"loops": [loop(directions=["x", "x"])]}, "loops[0].directions", "named twice"),
    ({"loops": [loop(name="crank")]}, "loops[0].name", "unique"),
    ({"loops": [loop(origin1={"xyz": [0.4, 0.3]})]}, "loops[0].origin1.xyz", "3 numbers"),
    ({"loops": [loop(extra=1)]}, "loops[0].extra", "unknown key"),
    ({"loops": []}, "loops", "non-empty list"),
    ({"loops": [loop(directions=["x", "y", "z"])]}, "loops", "not independent at the reference"),
    ({"independent": ["crank", "rocker"]}, "independent", "2 joints named; the loops leave 1"),
    ({"independent": ["crankk"]}, "independent[0]", "closest: crank"),
    ({"loops": None, "independent": ["crank"]}, "independent", "no 'loops' given"),
    ({"loops": [loop(origin2={"xyz": [0, 2.0, 0]})]}, "reference", "do not close near the reference"),
    ({"reference": {"rockr": 0.1}}, "reference.rockr", "closest: rocker"),
    ({"loops": [loop(origin2={"xyz": [0, "L3", 0]})]}, "loops", "numeric lengths"),
])
def test_refused_loops(changes, field, reason):
    """Every problem is one RobotDescriptionError naming the file and the field."""
    with pytest.raises(RobotDescriptionError) as info:
        loop_system(parse_robot(four_bar(**changes), "f.yaml", tree=True))
    assert info.value.field == field and reason in info.value.reason, str(info.value)
    assert str(info.value).startswith("f.yaml: field ")


def test_loops_need_a_tree_with_a_fixed_base_and_no_mimics():
    with pytest.raises(RobotDescriptionError, match="--tree"):
        parse_robot({**four_bar(), "dh": "none"}, "f.yaml")
    with pytest.raises(RobotDescriptionError, match="floating base"):
        parse_robot(four_bar(), "f.yaml", floating_base=True)
    joints = copy.deepcopy(FOUR_BAR["joints"])
    joints[2]["mimic"] = {"joint": "crank"}
    with pytest.raises(RobotDescriptionError, match="mimic joints and closed loops"):
        parse_robot(four_bar(joints=joints), "f.yaml", tree=True)


def test_a_singular_choice_of_independent_joints_is_refused():
    """A four-bar assembled with crank and coupler in line (a dead point): driven at the rocker,
    its dependent joints' block of K is singular at the reference, refused naming 'independent';
    the rule takes the crank, whose dependent block is regular there."""
    data = four_bar(loops=[loop(origin1={"xyz": [0, 0.5, 0]}, origin2={"xyz": [-0.4, 0.7, 0]})])
    assert loop_system(parse_robot(data, "f.yaml", tree=True)).independent == (0,)
    with pytest.raises(RobotDescriptionError) as info:
        loop_system(parse_robot({**data, "independent": ["rocker"]}, "f.yaml", tree=True))
    assert info.value.field == "independent" and "singular" in info.value.reason, str(info.value)


URDF = """<robot name="bar">
  <link name="ground"/>
  <link name="crank"><inertial><mass value="0.4"/><origin xyz="0 0.1 0"/>
    <inertia ixx="0.0014" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0014"/></inertial></link>
  <link name="coupler"><inertial><mass value="1"/><origin xyz="0.2 0.15 0"/>
    <inertia ixx="0.008" ixy="-0.0096" ixz="0" iyy="0.014" iyz="0" izz="0.021"/></inertial></link>
  <link name="rocker"><inertial><mass value="0.8"/><origin xyz="0 0.25 0"/>
    <inertia ixx="0.017" ixy="0" ixz="0" iyy="0.0002" iyz="0" izz="0.017"/></inertial></link>
  <link name="pin_block"/>
  <joint name="a_crank" type="revolute"><parent link="ground"/><child link="crank"/><axis xyz="0 0 1"/>
    <limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
  <joint name="b_coupler" type="revolute"><parent link="crank"/><child link="coupler"/><origin xyz="0 0.2 0"/>
    <axis xyz="0 0 1"/><limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
  <joint name="c_rocker" type="revolute"><parent link="ground"/><child link="rocker"/><origin xyz="0.4 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3.14" upper="3.14" effort="1" velocity="1"/></joint>
  <joint name="block" type="fixed"><parent link="rocker"/><child link="pin_block"/><origin xyz="0 0.5 0"/></joint>
  LOOP
  TRANSMISSION
</robot>"""
LOOP = """<loop_joint name="pin" type="revolute" directions="x y">
    <link1 link="coupler" xyz="0.4 0.3 0" rpy="0 0 0"/><link2 link="pin_block" xyz="0 0 0"/></loop_joint>"""
TRANSMISSION = """<transmission name="t"><type>transmission_interface/SimpleTransmission</type>
    <joint name="c_rocker"><hardwareInterface>EffortJointInterface</hardwareInterface></joint></transmission>"""


def urdf(loop=LOOP, transmission="") -> str:
    return URDF.replace("LOOP", loop).replace("TRANSMISSION", transmission)


def test_urdf_loop_joint_equals_the_yaml_loop():
    """The four-bar written as a URDF with a <loop_joint> (its second link a link fixed to the
    rocker) gives the YAML's loop: the same constraint rows at any configuration; Isaac Sim's
    documented typo (a second <link1>) reads the same; a <transmission> names the independent
    joint."""
    import symengine as se
    from kindyngen.algorithms.loop_closure import residual
    from kindyngen.algorithms.symbolic import port_symbols
    model = parse_urdf(urdf(), "bar.urdf", tree=True)
    typo = parse_urdf(urdf(LOOP.replace("<link2", "<link1")), "bar.urdf", tree=True)
    yaml_model = parse_robot(four_bar(), "f.yaml", tree=True)
    assert model.loops == typo.loops and model.independent is None
    q = port_symbols("q", (3,))
    rng = np.random.default_rng(3)
    for values in rng.uniform(-2, 2, (5, 3)):
        subs = dict(zip(q, values))
        got = [float(e.xreplace(subs)) for e in residual(model.without_mimics(), model.loops, q)]
        expected = [float(e.xreplace(subs)) for e in residual(yaml_model.without_mimics(), yaml_model.loops, q)]
        assert np.allclose(got, expected, atol=1e-14), (got, expected)
    assert loop_system(model).independent == (0,)
    driven = parse_urdf(urdf(transmission=TRANSMISSION), "bar.urdf", tree=True)
    assert driven.independent == (2,) and loop_system(driven).independent == (2,)
    assert isinstance(se.Symbol("x"), se.Symbol)


@pytest.mark.parametrize("loop, transmission, field, reason", [
    (LOOP.replace('type="revolute"', 'type="planar"'), "", "loop_joint 'pin' type", "expected one of"),
    (LOOP.replace('link="pin_block"', 'link="rockr"'), "", "loop_joint 'pin' link2 link", "closest: rocker"),
    (LOOP.replace('directions="x y"', 'directions="x q"'), "", "loop_joint 'pin' directions", "expected distinct"),
    (LOOP.replace('<link2 link="pin_block" xyz="0 0 0"/>', ''), "", "loop_joint 'pin'", "expected two links"),
    (LOOP.replace('link="pin_block"', 'link="rocker"').replace('name="pin"', 'name="a_crank"'), "",
     "loop_joint 'a_crank' name", "already names a joint"),
    (LOOP.replace('link="coupler"', 'link="rocker"'), "", "loop_joint 'pin'", "one rigid body"),
    (LOOP, TRANSMISSION.replace("c_rocker", "c_rockr"), "transmission joint 'c_rockr'", "names no moving joint"),
])
def test_refused_urdf_loops(loop, transmission, field, reason):
    with pytest.raises(RobotDescriptionError) as info:
        parse_urdf(urdf(loop, transmission), "bar.urdf", tree=True)
    assert info.value.field == field and reason in info.value.reason, str(info.value)


def test_urdf_loops_need_the_tree():
    with pytest.raises(RobotDescriptionError, match="read the URDF as a tree"):
        parse_urdf(urdf(), "bar.urdf", tip="rocker")


def test_command_line(tmp_path):
    """generate writes the loop functions (exit 0); describe refuses a robot with loops in one
    line, exit 2, and so do generate and identify reading the YAML without --tree, and generate
    a planar loop constraining three translations."""
    def run(*args):
        return subprocess.run([sys.executable, "-m", "kindyngen", *args], capture_output=True, text=True,
                              cwd=tmp_path, timeout=600)

    four = str(EXAMPLES / "four_bar.yaml")
    done = run("generate", four, "--tree", "--out", str(tmp_path / "out"), "--lang", "python", "--quiet")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out" / "four_bar" / "python" / "four_bar.py").exists()
    planar = tmp_path / "three_rows.yaml"
    planar.write_text((EXAMPLES / "four_bar.yaml").read_text().replace("directions: [x, y]}", "directions: [x, y, z]}"))
    for args in (("describe", four, "--tree"), ("generate", four, "--out", str(tmp_path / "o2")),
                 ("generate", str(planar), "--tree", "--out", str(tmp_path / "o3"))):
        refused = run(*args)
        assert refused.returncode == 2 and "Traceback" not in refused.stderr, refused.stderr
        assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr
    log = tmp_path / "log.csv"
    log.write_text("t,q1,qd1,tau1\n0,0,0,0\n")
    refused = run("identify", "--robot", four, "--data", str(log), "--split", "0.5", "--out", str(tmp_path / "id"))
    assert refused.returncode == 2 and "field 'loops'" in refused.stderr, refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr


def test_identify_refuses_loops_in_one_line():
    """The measured side (identify, discover, excite) refuses a robot with closed loops, naming
    the field, before reading any log."""
    from kindyngen.measured.regressor_rows import refuse_mimic_joints
    with pytest.raises(RobotDescriptionError) as info:
        refuse_mimic_joints(parse_robot(four_bar(), "f.yaml", tree=True))
    assert info.value.field == "loops" and "closed loops" in info.value.reason
