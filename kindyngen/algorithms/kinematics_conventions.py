"""The kinematic conventions of an arm's ports and headers (the functions themselves, FK
as 4x4 homogeneous transforms and the geometric Jacobian, are derived over the tree by
:mod:`kindyngen.algorithms.kinematics`, an arm being the tree whose parent of joint j is j - 1).

Conventions (stated in every generated header, see ``RobotModel.frames_text``): the base
frame is DH frame 0 (a URDF: the root or ``--base`` link's frame), the flange frame the last
DH frame (the last moving joint's link), moved by the description's constant tool
transform; ``T`` maps flange (tool) coordinates to base coordinates, row-major.  ``J`` is 6 x
n: rows 0-2 the linear velocity of the flange origin, rows 3-5 the angular velocity of the
flange, both expressed in the base frame (Pinocchio's LOCAL_WORLD_ALIGNED), so that ``[v; w]
= J(q) qd``. A prismatic joint's column is its axis (linear) and zeros (angular).

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> q_port(load_robot("robots/lwr4.yaml")).unit
'rad'
"""
from __future__ import annotations

from ..model.robot_model import RobotModel
from .symbolic import Port

def frame_convention(model: RobotModel) -> str:
    """The frames text of every kinematics header."""
    return (f"{model.frames_text} T maps flange to base coordinates (row-major 4x4, last row "
            f"0 0 0 1). Lengths in m, angles in rad.")


def joint_units(model: RobotModel, revolute: str, prismatic: str) -> str:
    """A port's unit: the revolute one, the prismatic one, or both with the joints named (by
    their index among the coordinates: a mimic joint is no entry of a port)."""
    kinds = {j.kind for j in model.coordinate_joints}
    if kinds == {"revolute"}:
        return revolute
    if kinds == {"prismatic"}:
        return prismatic
    moving = ", ".join(str(i) for i, j in enumerate(model.coordinate_joints) if j.prismatic)
    return f"{revolute} ({prismatic} for prismatic joints {moving}, 0-based)"


def q_port(model: RobotModel) -> Port:
    """The joint positions (after a floating base's position and unit quaternion)."""
    what = "joint angles" if all(not j.prismatic for j in model.coordinate_joints) else "joint positions"
    if model.floating_base:
        return Port("q", (model.nq,), "base position in the world, base orientation as a unit quaternion "
                    f"(x, y, z, w), then {what}, {model.order_text}", "m, 1, " + joint_units(model, "rad", "m"))
    return Port("q", (model.nq,), f"{what}, {model.order_text}", joint_units(model, "rad", "m"))
