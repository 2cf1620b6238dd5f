"""Robot descriptions the tests (and the benchmarks that measure the same pairs) read from
outside the repository: example-robot-data's URDFs, and the Panda as a URDF/YAML pair.

The Panda pair describes one arm in the same frames: example-robot-data's ``panda.urdf``
without the hand (joints and links named ``*hand*``, ``*finger*`` removed), chain from
``panda_link0`` to ``panda_link8``; and the modified-DH table of ``robots/panda.yaml`` with the
URDF's 0.107 m flange offset as its ``tool``. The Franka URDF's link frames are the DH frames
and both use the same identified inertial parameters (Gaz et al. 2019), so the two models must
give the same kinematics and dynamics (tests/readers/test_urdf_panda.py)."""
from __future__ import annotations

import importlib.metadata
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PANDA_TOOL = {"xyz": [0, 0, 0.107]}      # panda_joint8: link7 -> link8 (the flange)


def example_robot_data() -> Path:
    """The robots folder of the installed example-robot-data wheel (a test extra); raises
    importlib.metadata.PackageNotFoundError without it."""
    dist = importlib.metadata.distribution("example-robot-data")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def example_robot_data_or_skip() -> Path:
    """:func:`example_robot_data` inside a test: the test is skipped without the wheel."""
    import pytest
    try:
        return example_robot_data()
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (a test extra)")


def panda_arm_urdf(folder: Path) -> Path:
    """example-robot-data's panda.urdf without the hand, written to ``folder``."""
    tree = ET.parse(example_robot_data() / "panda_description" / "urdf" / "panda.urdf")
    robot = tree.getroot()
    for element in list(robot):
        if element.tag in ("link", "joint") and any(k in element.get("name", "") for k in ("hand", "finger")):
            robot.remove(element)
    path = folder / "panda_arm.urdf"
    tree.write(path)
    return path


def panda_yaml_with_tool() -> dict:
    """robots/panda.yaml as data, with the URDF's flange offset as its tool."""
    data = yaml.safe_load((ROOT / "robots" / "panda.yaml").read_text())
    data["tool"] = PANDA_TOOL
    return data


def panda_pair(folder: Path):
    """(model from the URDF, model from the YAML with the flange tool)."""
    from kindyngen.readers.yaml_description import load_robot, parse_robot
    urdf = load_robot(panda_arm_urdf(folder), tip="panda_link8")
    return urdf, parse_robot(panda_yaml_with_tool(), "robots/panda.yaml + tool")


# a three-joint chain with a tilted prismatic joint between two revolute ones and off-axis,
# rotated inertias: what a DH table cannot write and a URDF can (module-level tests of the
# dual-quaternion dynamics and the derivative sweeps)
SLIDER_CHAIN_URDF = """<robot name="slider_chain">
  <link name="base"/>
  <link name="l1"><inertial><mass value="3"/><origin xyz="0.01 -0.005 0.12" rpy="0.1 0 0.2"/>
    <inertia ixx="0.054" ixy="0.0003" ixz="-0.0008" iyy="0.052" iyz="0.0019" izz="0.0073"/></inertial></link>
  <link name="l2"><inertial><mass value="1.5"/><origin xyz="0.03 0.01 0.02"/>
    <inertia ixx="0.0031" ixy="-0.0004" ixz="0.0005" iyy="0.0042" iyz="-0.0003" izz="0.0037"/></inertial></link>
  <link name="l3"><inertial><mass value="0.9"/><origin xyz="0.1 0.005 -0.01" rpy="0 0.3 0"/>
    <inertia ixx="0.002" ixy="0.0001" ixz="0" iyy="0.006" iyz="0.0002" izz="0.005"/></inertial></link>
  <joint name="turret" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0 0 0.2"/><axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="1" velocity="1"/></joint>
  <joint name="slide" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0.02 0.2" rpy="0.3 0 0"/><axis xyz="0 0.6 0.8"/><limit lower="-0.2" upper="0.3" effort="1" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0 0.05" rpy="1.2 0.1 -0.4"/><axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>"""
