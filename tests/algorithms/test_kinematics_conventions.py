"""The port and header conventions of :mod:`kindyngen.algorithms.kinematics_conventions`
against what the module text promises: units rad / m per joint kind (mixed arms name their
prismatic joints, 0-based), the q port's size and description for a fixed and a floating
base, and the frames text every kinematics header carries."""
from __future__ import annotations

from kindyngen.algorithms.kinematics_conventions import frame_convention, joint_units, q_port
from kindyngen.readers.urdf import parse_urdf
from kindyngen.readers.yaml_description import parse_robot
from tests.harness import robot

LINK = {"mass": 1.0, "com": [0.0, 0.0, 0.1], "inertia": [0.01, 0.01, 0.01, 0, 0, 0]}


def _arm(*kinds):
    return parse_robot({"name": "arm", "dh": "none", "gravity": [0, 0, -9.81],
                        "joints": [{"type": kind, "origin": {"xyz": [0, 0, 0.2]}, "lower": -1, "upper": 1}
                                   for kind in kinds],
                        "links": [LINK for _ in kinds]})


URDF = """<robot name="two"><link name="base"/><link name="a"><inertial><mass value="1"/>
  <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="j0" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j1" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""


def test_joint_units_by_kind():
    assert joint_units(_arm("revolute", "revolute"), "rad/s", "m/s") == "rad/s"
    assert joint_units(_arm("prismatic", "prismatic"), "rad/s", "m/s") == "m/s"
    assert joint_units(_arm("revolute", "prismatic", "revolute", "prismatic"), "N m", "N") == \
        "N m (N for prismatic joints 1, 3, 0-based)"


def test_q_port_of_fixed_base_arms():
    lwr = robot("lwr4")
    port = q_port(lwr)
    assert (port.name, port.shape, port.unit) == ("q", (7,), "rad")
    assert port.description == "joint angles, DH order"
    mixed = q_port(_arm("revolute", "prismatic"))
    assert mixed.shape == (2,) and mixed.unit == "rad (m for prismatic joints 1, 0-based)"
    assert mixed.description == "joint positions, chain order from the base"


def test_q_port_of_a_floating_base():
    model = parse_urdf(URDF, floating_base=True)
    port = q_port(model)
    assert port.shape == (7 + 2,)
    assert port.description.startswith("base position in the world, base orientation as a unit quaternion (x, y, z, w)")
    assert port.unit == "m, 1, rad (m for prismatic joints 1, 0-based)"


def test_frame_convention_states_frames_units_and_layout():
    lwr = robot("lwr4")
    text = frame_convention(lwr)
    assert text.startswith("Frames: base = DH frame 0, flange = last DH frame (7).")
    assert "row-major 4x4, last row 0 0 0 1" in text and "Lengths in m, angles in rad." in text
    urdf = frame_convention(parse_urdf(URDF))
    assert "the frame of link 'base'" in urdf and "the frame of link 'b'" in urdf
