"""Forward kinematics as 4x4 homogeneous transforms, and the geometric Jacobian.

Conventions (stated in every generated header, see ``RobotModel.frames_text``): the base
frame is DH frame 0 (a URDF: the root or ``--base`` link's frame), the flange frame the last
DH frame (the last moving joint's link), moved by the description's constant tool
transform; ``T`` maps flange (tool) coordinates to base coordinates, row-major.  ``J`` is 6 x
n: rows 0-2 the linear velocity of the flange origin, rows 3-5 the angular velocity of the
flange, both expressed in the base frame (Pinocchio's LOCAL_WORLD_ALIGNED), so that ``[v; w]
= J(q) qd``. A prismatic joint's column is its axis (linear) and zeros (angular).

Example:

>>> from kindyngen.robot import load_robot
>>> f = fk_hom(load_robot("robots/lwr4.yaml"))       # doctest: +SKIP
>>> f.outputs[0].shape                                 # doctest: +SKIP
(4, 4)
"""
from __future__ import annotations

import symengine as se

from .geometry import compose, constant_transform, joint_transform
from .model import RobotModel
from .symbolic import Port, SymbolicFunction, flatten, port_symbols

def frame_convention(model: RobotModel) -> str:
    """The frames text of every kinematics header."""
    return (f"{model.frames_text} T maps flange to base coordinates (row-major 4x4, last row "
            f"0 0 0 1). Lengths in m, angles in rad.")


def joint_units(model: RobotModel, revolute: str, prismatic: str) -> str:
    """A port's unit: the revolute one, the prismatic one, or both with the joints named."""
    kinds = {j.kind for j in model.joints}
    if kinds == {"revolute"}:
        return revolute
    if kinds == {"prismatic"}:
        return prismatic
    moving = ", ".join(str(i) for i, j in enumerate(model.joints) if j.prismatic)
    return f"{revolute} ({prismatic} for prismatic joints {moving}, 0-based)"


def q_port(model: RobotModel) -> Port:
    what = "joint angles" if all(not j.prismatic for j in model.joints) else "joint positions"
    return Port("q", (model.n,), f"{what}, {model.order_text}", joint_units(model, "rad", "m"))


def frame_chain(model: RobotModel, q) -> list[tuple[se.Matrix, se.Matrix]]:
    """Absolute (R_0i, p_0i) for i = 0..n, built one joint at a time on shared objects.

    Each product reuses the previous frame's entries, so the expressions form a DAG whose
    size grows linearly with n."""
    rotation, position = se.eye(3), se.zeros(3, 1)
    chain = [(rotation, position)]
    for joint, qi in zip(model.joints, q):
        r, p = joint_transform(joint, qi)
        position = position + rotation * p
        rotation = rotation * r
        chain.append((rotation, position))
    return chain


def flange(model: RobotModel, chain) -> tuple[se.Matrix, se.Matrix]:
    """The flange (tool) frame: the last link frame moved by the description's tool."""
    return compose(chain[-1], constant_transform(model.tool))


def joint_axes(model: RobotModel, chain) -> list[tuple[se.Matrix, se.Matrix]]:
    """Every joint's axis (unit direction, a point on it) in the base frame: the z axis and
    origin of ``chain[i] * before_i``."""
    axes = []
    for joint, (rotation, position) in zip(model.joints, chain):
        before = constant_transform(joint.before)
        if before is not None:
            rotation, position = compose((rotation, position), before)
        axes.append((rotation[:, 2], position))
    return axes


def homogeneous(rotation: se.Matrix, position: se.Matrix) -> se.Matrix:
    rows = rotation.tolist()
    return se.Matrix([rows[0] + [position[0]], rows[1] + [position[1]], rows[2] + [position[2]], [0, 0, 0, 1]])


def fk_hom(model: RobotModel) -> SymbolicFunction:
    """Flange pose as a 4x4 homogeneous transform, ``fk_hom(q) -> T``."""
    q = port_symbols("q", (model.n,))
    rotation, position = flange(model, frame_chain(model, q))
    return SymbolicFunction(
        name="fk_hom",
        summary="Forward kinematics: flange pose as a 4x4 homogeneous transform.",
        inputs=(q_port(model),),
        outputs=(Port("T", (4, 4), "flange pose in the base frame (row-major)", "m (translation), 1 (rotation)"),),
        input_symbols=(q,),
        output_exprs=(flatten(homogeneous(rotation, position)),),
        conventions=frame_convention(model),
    )


def jacobian(model: RobotModel) -> SymbolicFunction:
    """Geometric Jacobian of the flange, ``jacobian(q) -> J`` (6 x n, linear rows first)."""
    q = port_symbols("q", (model.n,))
    chain = frame_chain(model, q)
    point = flange(model, chain)[1]
    columns = []
    for joint, (axis, origin) in zip(model.joints, joint_axes(model, chain)):
        if joint.prismatic:
            columns.append(list(axis) + [0, 0, 0])
        else:
            columns.append(list(axis.cross(point - origin)) + list(axis))
    J = se.Matrix(columns).T
    return SymbolicFunction(
        name="jacobian",
        summary="Geometric Jacobian of the flange: [v; w] = J(q) qd.",
        inputs=(q_port(model),),
        outputs=(Port("J", (6, model.n),
                      "rows 0-2: linear velocity of the flange origin, rows 3-5: angular velocity; "
                      "both in base-frame axes (row-major)", "m/rad (rows 0-2), 1 (rows 3-5)"),),
        input_symbols=(q,),
        output_exprs=(flatten(J),),
        conventions=frame_convention(model)
        + " J is expressed in base-frame axes at the flange origin (Pinocchio LOCAL_WORLD_ALIGNED).",
    )
