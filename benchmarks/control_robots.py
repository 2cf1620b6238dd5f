"""The three arms of the control benchmark and tests, with their reach tasks and a Pinocchio
plant that shares no code with the controllers: the LWR and the Panda from their DH tables
(tests/reference.py's model, Pinocchio's own joints and inertias), the UR5 from
example-robot-data's URDF read by Pinocchio's URDF parser.

>>> sorted(ROBOTS)
['lwr4', 'panda', 'ur5']
"""
from __future__ import annotations

import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ERD = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
UR5_URDF = ERD / "ur_description" / "urdf" / "ur5_robot.urdf"


@dataclass(frozen=True)
class Arm:
    name: str
    description: Path
    tip: str | None
    limits_file: Path | None      # None: the URDF's <limit>
    q0: tuple
    goal_offset: tuple            # goal = flange at q0 + this (m)


ROBOTS = {
    "lwr4": Arm("lwr4", ROOT / "robots" / "lwr4.yaml", None, ROOT / "examples" / "limits" / "lwr4.yaml",
                (0.0, 0.5, 0.0, -1.0, 0.0, 0.0, 0.0), None),
    "panda": Arm("panda", ROOT / "robots" / "panda.yaml", None, ROOT / "examples" / "limits" / "panda.yaml",
                 (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785), (0.15, 0.2, -0.1)),
    "ur5": Arm("ur5", UR5_URDF, "tool0", None, (0.0, -1.2, 1.5, -1.5, -1.5, 0.0), (0.2, 0.15, 0.1)),
}
LWR_GOAL = (0.35, 0.25, 0.55)      # the reach


def available(name: str) -> bool:
    return ROBOTS[name].description.is_file()


def load(name: str):
    """(model, prepared robot, limits, reach task) of one arm."""
    from kindyngen.control.reach import ReachTask
    from kindyngen.control.robot import prepare, read_limits, urdf_limits
    from kindyngen.readers.yaml_description import load_robot
    arm = ROBOTS[name]
    model = load_robot(arm.description, tip=arm.tip) if arm.tip else load_robot(arm.description)
    robot = prepare(model)
    limits = read_limits(arm.limits_file, model) if arm.limits_file else urdf_limits(arm.description, model)
    goal = LWR_GOAL if arm.goal_offset is None else tuple(robot.flange_position(arm.q0) + np.array(arm.goal_offset))
    return model, robot, limits, ReachTask(arm.q0, goal, limits)


def pinocchio_plant_model(name: str, model):
    """(pin.Model, flange frame id): Pinocchio's own model of the arm, not ours."""
    import pinocchio as pin
    arm = ROBOTS[name]
    if arm.description.suffix == ".urdf":
        pm = pin.buildModelFromUrdf(str(arm.description))
        return pm, pm.getFrameId(arm.tip)
    sys.path.insert(0, str(ROOT / "tests"))
    from reference import pinocchio_model
    pm, _, frame = pinocchio_model(model)
    return pm, frame
