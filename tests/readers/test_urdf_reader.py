"""The URDF reader (kindyngen.readers.urdf): the chain's kinematics and merged link inertias equal
Pinocchio's parse of the same file, and every malformed file is an error naming the file and
the element."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sympy

from kindyngen.model.robot_model import RobotDescriptionError
from kindyngen.readers.yaml_description import load_robot
from kindyngen.readers.urdf import load_urdf
from tests.robot_files import example_robot_data_or_skip

pin = pytest.importorskip("pinocchio")


def _inertial(mass, xyz="0 0 0", rpy="0 0 0", moments=(0.01, 0.001, -0.002, 0.02, 0.003, 0.015)):
    ixx, ixy, ixz, iyy, iyz, izz = moments
    return (f'<inertial><origin xyz="{xyz}" rpy="{rpy}"/><mass value="{mass}"/>'
            f'<inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/></inertial>')


def _joint(name, kind, parent, child, xyz="0 0 0", rpy="0 0 0", axis="0 0 1", limit=(-2, 2)):
    limit_element = f'<limit lower="{limit[0]}" upper="{limit[1]}" effort="1" velocity="1"/>' if limit else ""
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>{limit_element}</joint>')


# A 3-joint arm: a mounting plate fixed to the ground (base side), an oblique axis, rotated
# inertials, a fixed link in the middle of the chain, a fixed camera branch, a prismatic
# joint, a flange and TCP fixed at the end and a finger on a moving joint off the chain.
ARM = f"""<?xml version="1.0"?>
<robot name="test-arm">
  <link name="ground"/>
  <link name="plate">{_inertial(5, "0.1 0 0")}</link>
  <link name="link1">{_inertial(2.5, "0.01 0.02 0.15", "0.1 -0.2 0.3")}</link>
  <link name="spacer">{_inertial(0.7, "0 0.03 0.05", "0.4 0 0", (0.002, 0, 0, 0.003, 0, 0.001))}</link>
  <link name="link2">{_inertial(1.8, "0.2 0 -0.01", "0 0.25 0")}</link>
  <link name="camera">{_inertial(0.3, "0.02 0 0", "0 0 0.7", (0.0004, 0, 0, 0.0005, 0, 0.0006))}</link>
  <link name="link3">{_inertial(0.9, "0.05 0.01 0", "1.5707963267948966 0 0")}</link>
  <link name="flange">{_inertial(0.2, "0 0 0.01", "0 0 0", (0.0001, 0, 0, 0.0001, 0, 0.00015))}</link>
  <link name="tcp"/>
  <link name="finger">{_inertial(0.1, "0 0 0.02")}</link>
  {_joint("mount", "fixed", "ground", "plate", "0.5 -0.2 0.1", "0.1 0.2 0.3", limit=None)}
  {_joint("j1", "revolute", "plate", "link1", "0 0 0.3", "0 0 0.4", "0 0 1", (-2.5, 2.5))}
  {_joint("middle", "fixed", "link1", "spacer", "0.1 0 0.2", "0.5 0 0", limit=None)}
  {_joint("j2", "revolute", "spacer", "link2", "0 0.05 0.1", "0.3 0.2 0.1", "0 0.6 0.8", (-1.5, 1.7))}
  {_joint("camera_mount", "fixed", "link2", "camera", "0.1 0.1 0", "0 1.5707963267948966 0", limit=None)}
  {_joint("j3", "prismatic", "link2", "link3", "0.3 0 0", "0 0 0", "1 0 0", (-0.1, 0.2))}
  {_joint("flange_joint", "fixed", "link3", "flange", "0.05 0 0", "0 -1.5707963267948966 0", limit=None)}
  {_joint("tcp_joint", "fixed", "flange", "tcp", "0 0 0.1", "0 0 0.25", limit=None)}
  {_joint("finger_joint", "revolute", "link3", "finger", "0.02 0 0", "0 0 0", "0 1 0", (0, 1))}
</robot>
"""


def _write(tmp_path: Path, text: str, name: str = "arm.urdf") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _homogeneous(placement) -> np.ndarray:
    R, p = placement.matrix()
    out = np.eye(4)
    out[:3, :3] = np.array(R.evalf(), dtype=float)
    out[:3, 3] = np.array(p.evalf(), dtype=float).ravel()
    return out


def _forward(model, q) -> np.ndarray:
    """Base -> tool transform of the model: before * motion(q) * after per joint, then the tool."""
    T = np.eye(4)
    for joint, qi in zip(model.joints, q):
        motion = np.eye(4)
        if joint.kind == "revolute":
            motion[:2, :2] = [[math.cos(qi), -math.sin(qi)], [math.sin(qi), math.cos(qi)]]
        else:
            motion[2, 3] = qi
        T = T @ _homogeneous(joint.before) @ motion @ _homogeneous(joint.after)
    return T @ _homogeneous(model.tool)


def _pinocchio_forward(pmodel, model, q, tip: str) -> np.ndarray:
    """Pinocchio's base -> tip transform with the chain's joints at q (the others at rest)."""
    data = pmodel.createData()
    config = pin.neutral(pmodel)
    for joint, qi in zip(model.joints, q):
        pjoint = pmodel.joints[pmodel.getJointId(joint.name)]
        if pjoint.nq == 1:
            config[pjoint.idx_q] = qi
        else:                       # a continuous joint: (cos, sin)
            config[pjoint.idx_q:pjoint.idx_q + 2] = (math.cos(qi), math.sin(qi))
    pin.framesForwardKinematics(pmodel, data, config)
    base = data.oMf[pmodel.getFrameId(model.base_name, pin.BODY)]
    return (base.inverse() * data.oMf[pmodel.getFrameId(tip, pin.BODY)]).homogeneous


def reduced(pmodel, model):
    """Pinocchio's model with every joint that is not on our chain locked at its neutral
    position (what the reader does with a gripper's fingers)."""
    chain = {joint.name for joint in model.joints}
    lock = [i for i in range(1, pmodel.njoints) if pmodel.names[i] not in chain]
    return pin.buildReducedModel(pmodel, lock, pin.neutral(pmodel)) if lock else pmodel


def _check_against_pinocchio(model, pmodel, tip: str, tolerance: float) -> None:
    pmodel = reduced(pmodel, model)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = rng.uniform(model.lower, model.upper)
        np.testing.assert_allclose(_forward(model, q), _pinocchio_forward(pmodel, model, q, tip), atol=tolerance)
    for joint, link in zip(model.joints, model.links):
        expected = pmodel.inertias[pmodel.getJointId(joint.name)]
        assert abs(float(link.mass) - expected.mass) < tolerance, joint.name
        np.testing.assert_allclose([float(v) for v in link.com], expected.lever, atol=tolerance, err_msg=joint.name)
        np.testing.assert_allclose(link.inertia_matrix(), expected.inertia, atol=tolerance, err_msg=joint.name)


# ------------------------------------------------------------------ the chain and its bodies

def test_arm_matches_pinocchio(tmp_path):
    model = load_urdf(_write(tmp_path, ARM), tip="tcp")
    _check_against_pinocchio(model, pin.buildModelFromXML(ARM), "tcp", 1e-12)


def test_arm_structure(tmp_path):
    path = _write(tmp_path, ARM)
    model = load_urdf(path, tip="tcp")
    assert model.name == "test-arm" and model.identifier == "test_arm"
    assert model.convention == "frames" and model.source == str(path)
    assert [(j.name, j.kind) for j in model.joints] == [("j1", "revolute"), ("j2", "revolute"), ("j3", "prismatic")]
    assert [(j.lower, j.upper) for j in model.joints] == [(-2.5, 2.5), (-1.5, 1.7), (-0.1, 0.2)]
    assert (model.base_name, model.flange_name) == ("ground", "link3")
    assert model.gravity == (0, 0, sympy.Rational(-981, 100))
    assert not model.tool.is_identity
    # every inertial parameter is an exact rational
    for link in model.links:
        assert all(isinstance(v, sympy.Rational) for v in (link.mass, *link.com, *link.inertia))
    # merged bodies: link1 + spacer; link2 + camera; link3 + flange (+ massless tcp) + the
    # finger, locked at 0
    masses = [sympy.Rational(32, 10), sympy.Rational(21, 10), sympy.Rational(12, 10)]
    assert [link.mass for link in model.links] == masses
    notes = "\n".join(model.notes)
    assert "joint 'finger_joint' (revolute) is not on the chain: locked at 0, its links part of link 'link3'" in notes
    assert "link 'tcp' has no <inertial>: massless" in notes


def test_exact_rotations_keep_inertias_exact(tmp_path):
    """link3's inertial is turned by pi/2 and the flange by -pi/2: its body needs no rounding,
    the CoM is the exact mass-weighted mean."""
    model = load_urdf(_write(tmp_path, ARM), tip="tcp")
    link3 = model.links[2]
    # flange CoM: T(0.05, 0, 0) Ry(-pi/2) (0, 0, 0.01) = (0.04, 0, 0)
    # finger (locked at 0): T(0.02, 0, 0) (0, 0, 0.02) = (0.02, 0, 0.02)
    expected = (sympy.Rational(9, 10) * sympy.Matrix([sympy.Rational(5, 100), sympy.Rational(1, 100), 0])
                + sympy.Rational(2, 10) * sympy.Matrix([sympy.Rational(4, 100), 0, 0])
                + sympy.Rational(1, 10) * sympy.Matrix([sympy.Rational(2, 100), 0, sympy.Rational(2, 100)])
                ) / sympy.Rational(12, 10)
    assert link3.com == tuple(expected)


def test_tip_is_the_last_moving_link(tmp_path):
    model = load_urdf(_write(tmp_path, ARM), tip="link3")
    assert model.tool.is_identity and model.flange_name == "link3"
    _check_against_pinocchio(model, pin.buildModelFromXML(ARM), "link3", 1e-12)


def test_base_below_the_root(tmp_path):
    """With base link1 the chain starts at j2 and spacer's placement goes into its ``before``."""
    model = load_urdf(_write(tmp_path, ARM), base="link1", tip="tcp")
    assert [j.name for j in model.joints] == ["j2", "j3"] and model.base_name == "link1"
    _check_against_pinocchio(model, pin.buildModelFromXML(ARM), "tcp", 1e-12)


def test_single_leaf_is_the_default_tip(tmp_path):
    """A leaf fixed to the base (UR's ``base`` frame) is not a candidate tip."""
    text = f"""<robot name="two">
      <link name="a"/><link name="a_marker"/><link name="b">{_inertial(1)}</link>
      <link name="c">{_inertial(1)}</link>
      {_joint("marker", "fixed", "a", "a_marker", limit=None)}
      {_joint("q1", "revolute", "a", "b", "0 0 1", axis="1 0 0")}
      {_joint("q2", "continuous", "b", "c", "0 0 1", limit=None)}
    </robot>"""
    model = load_urdf(_write(tmp_path, text))
    assert [j.name for j in model.joints] == ["q1", "q2"] and model.flange_name == "c"
    assert (model.joints[1].lower, model.joints[1].upper) == (-math.pi, math.pi)
    assert any("joint 'q2' is continuous: range -pi..pi assumed" in note for note in model.notes)
    _check_against_pinocchio(model, pin.buildModelFromXML(text), "c", 1e-12)


def test_default_axis_is_x_and_unlimited_revolute(tmp_path):
    text = f"""<robot name="r"><link name="a"/><link name="b">{_inertial(1)}</link>
      <joint name="q" type="revolute"><parent link="a"/><child link="b"/>
        <limit lower="0" upper="0" effort="1" velocity="1"/></joint></robot>"""
    model = load_urdf(_write(tmp_path, text))
    assert (model.joints[0].lower, model.joints[0].upper) == (-math.pi, math.pi)
    assert any("joint 'q' limit is 0..0" in note for note in model.notes)
    _check_against_pinocchio(model, pin.buildModelFromXML(text), "b", 1e-12)


def test_massless_link(tmp_path):
    text = f"""<robot name="r"><link name="a"/><link name="b"/>{_joint("q", "prismatic", "a", "b")}</robot>"""
    model = load_urdf(_write(tmp_path, text))
    assert model.links[0].mass == 0 and model.links[0].com == (0, 0, 0) and model.links[0].inertia == (0,) * 6
    assert any("link 'b' has no <inertial>: massless" in note for note in model.notes)


def test_load_robot_reads_urdf(tmp_path):
    model = load_robot(_write(tmp_path, ARM), tip="tcp")
    assert model.n == 3 and model.flange_name == "link3"


# ------------------------------------------------------------------ angles

def _one_joint(rpy: str) -> str:
    return f"""<robot name="r"><link name="a"/><link name="b">{_inertial(1)}</link>
      {_joint("q", "revolute", "a", "b", rpy=rpy)}</robot>"""


def test_near_right_angle_is_snapped_with_a_note(tmp_path):
    path = _write(tmp_path, _one_joint("1.5708 0 0"))
    model = load_urdf(path)
    assert model.joints[0].before.factors[0] == ("rot", (1, 0, 0), sympy.pi / 2)
    assert model.notes[0].startswith(f"{path}: joint 'q' origin rpy[0]: 1.5708 read as pi/2")


def test_angle_kept_as_written(tmp_path):
    model = load_urdf(_write(tmp_path, _one_joint("1.5708 0 0")), snap_angles=False)
    assert model.joints[0].before.factors[0] == ("rot", (1, 0, 0), sympy.Rational(19635, 12500))
    assert not any("rpy" in note for note in model.notes)


# ------------------------------------------------------------------ errors

def _arm_with(old: str, new: str) -> str:
    assert old in ARM
    return ARM.replace(old, new, 1)


ERRORS = {
    "malformed XML": (ARM.replace("</robot>", "</robt>"), "<xml>", "malformed XML at line"),
    "not a robot": ("<model name='x'/>", "<robot>", "the top element is <model>"),
    "no name": (ARM.replace('name="test-arm"', ""), "<robot> name", "missing"),
    "joint without child": (_arm_with('<child link="link1"/>', ""), "joint 'j1' child", "missing"),
    "undefined link": (_arm_with('<child link="link1"/>', '<child link="lnk1"/>'), "joint 'j1' child",
                       "link 'lnk1' is not defined; closest: link1"),
    "two parents": (_arm_with("</robot>", _joint("again", "fixed", "ground", "link2", limit=None) + "</robot>"),
                    "joint 'again' child", "already has a parent (joint 'j2')"),
    "cycle": (_arm_with("</robot>", _joint("loop", "fixed", "tcp", "ground", limit=None) + "</robot>"),
              "<robot>", "form a cycle"),
    "two xyz numbers": (_arm_with('xyz="0 0 0.3"', 'xyz="1 2"'), "joint 'j1' origin xyz", "expected 3 numbers"),
    "nan": (_arm_with('rpy="0 0 0.4"', 'rpy="0 nan 0.4"'), "joint 'j1' origin rpy", "cannot read 'nan'"),
    "xacro": (_arm_with('xyz="0 0 0.3"', 'xyz="0 0 ${d1}"'), "joint 'j1' origin xyz", "run xacro"),
    "bad mass": (_arm_with('<mass value="2.5"/>', '<mass value="heavy"/>'), "link 'link1' inertial mass value",
                 "cannot read 'heavy'"),
    "negative mass": (_arm_with('<mass value="2.5"/>', '<mass value="-2.5"/>'), "link 'link1' inertial mass value",
                      "must not be negative"),
    "impossible inertia": (_arm_with('<mass value="0.7"/><inertia ixx="0.002"',
                                     '<mass value="0.7"/><inertia ixx="0.02"'),
                           "link 'spacer' inertial inertia", "triangle inequality"),
    "missing moment": (_arm_with(' iyz="0.003"', ""), "link 'plate' inertial inertia iyz", "missing"),
    "floating joint": (_arm_with('name="j2" type="revolute"', 'name="j2" type="floating"'), "joint 'j2' type",
                       "a floating joint is not supported (only revolute, continuous, prismatic and fixed joints; "
                       "a free root body is --floating-base)"),
    "unknown type": (_arm_with('name="j2" type="revolute"', 'name="j2" type="hinge"'), "joint 'j2' type",
                     "expected one of"),
    "zero axis": (_arm_with('axis xyz="0 0.6 0.8"', 'axis xyz="0 0 0"'), "joint 'j2' axis xyz", "no direction"),
    "missing limit": (_arm_with('<limit lower="-1.5" upper="1.7" effort="1" velocity="1"/>', ""),
                      "joint 'j2' limit", "missing"),
    "reversed limits": (_arm_with('lower="-1.5" upper="1.7"', 'lower="1.7" upper="-1.5"'), "joint 'j2' limit",
                        "limits reversed"),
    "prismatic without range": (_arm_with('lower="-0.1" upper="0.2"', 'lower="0" upper="0"'), "joint 'j3' limit",
                                "needs a range"),
    "duplicate link": (_arm_with('<link name="tcp"/>', '<link name="tcp"/><link name="tcp"/>'), "link 'tcp'",
                       "defined twice"),
}


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_error_names_file_and_element(tmp_path, case):
    text, field, reason = ERRORS[case]
    path = _write(tmp_path, text)
    with pytest.raises(RobotDescriptionError) as caught:
        load_urdf(path, tip="tcp")
    assert caught.value.source == str(path) and caught.value.field == field
    assert reason in caught.value.reason
    assert str(path) in str(caught.value) and field in str(caught.value)


def test_malformed_xml_gives_line_and_column(tmp_path):
    with pytest.raises(RobotDescriptionError, match=r"line 3, column 7"):
        load_urdf(_write(tmp_path, '<robot name="r">\n<link name="a"/>\n<link <>\n</robot>'))


def test_several_leaves_need_a_tip(tmp_path):
    with pytest.raises(RobotDescriptionError) as caught:
        load_urdf(_write(tmp_path, ARM))
    assert caught.value.field == "--tip"
    assert "3 leaves" in caught.value.reason and "camera, tcp, finger" in caught.value.reason


@pytest.mark.parametrize("option, kwargs, closest", [("--tip", {"tip": "tpc"}, "tcp"),
                                                      ("--base", {"base": "Ground", "tip": "tcp"}, "ground")])
def test_unknown_link_suggests_closest(tmp_path, option, kwargs, closest):
    with pytest.raises(RobotDescriptionError) as caught:
        load_urdf(_write(tmp_path, ARM), **kwargs)
    assert caught.value.field == option and f"closest: {closest}" in caught.value.reason


def test_tip_must_be_below_base(tmp_path):
    with pytest.raises(RobotDescriptionError, match="link 'camera' is not below the base link 'link3'"):
        load_urdf(_write(tmp_path, ARM), base="link3", tip="camera")


def test_chain_without_moving_joint(tmp_path):
    with pytest.raises(RobotDescriptionError, match="no moving joint between links 'link3' and 'tcp'"):
        load_urdf(_write(tmp_path, ARM), base="link3", tip="tcp")


def test_unreadable_file(tmp_path):
    with pytest.raises(RobotDescriptionError, match="cannot read"):
        load_urdf(tmp_path / "missing.urdf")


# ------------------------------------------------------------------ real robots

REAL_ROBOTS = [("panda_description/urdf/panda.urdf", "panda_link8", 7),
               ("panda_description/urdf/panda.urdf", "panda_hand", 7),
               ("ur_description/urdf/ur5_robot.urdf", "tool0", 6),
               ("xarm_description/urdf/xarm7.urdf", None, 7),
               ("z1_description/urdf/z1.urdf", None, 7),
               ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector", 6)]


@pytest.mark.parametrize("file, tip, n", REAL_ROBOTS)
def test_real_robot_matches_pinocchio(file, tip, n):
    path = example_robot_data_or_skip() / file
    model = load_urdf(path, tip=tip, snap_angles=False)      # the angles as written: Pinocchio's
    assert model.n == n
    _check_against_pinocchio(model, pin.buildModelFromUrdf(str(path)), tip or model.flange_name, 1e-9)
    assert load_urdf(path, tip=tip).n == n                   # and with right angles snapped
