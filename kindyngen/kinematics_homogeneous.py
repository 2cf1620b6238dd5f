"""Forward kinematics as 4x4 homogeneous transforms, and the geometric Jacobian.

Conventions (stated in every generated header): frame 0 is the base frame of the DH table,
the flange frame is the last DH frame; ``T`` maps flange coordinates to base coordinates,
row-major.  ``J`` is 6 x n: rows 0-2 the linear velocity of the flange origin, rows 3-5 the
angular velocity of the flange, both expressed in the base frame (Pinocchio's
LOCAL_WORLD_ALIGNED), so that ``[v; w] = J(q) qd``.

Example:

>>> from kindyngen.robot import load_robot
>>> f = fk_hom(load_robot("robots/lwr4.yaml"))       # doctest: +SKIP
>>> f.outputs[0].shape                                 # doctest: +SKIP
(4, 4)
"""
from __future__ import annotations

import symengine as se

from .geometry import joint_axis_in_previous, joint_transform
from .robot import RobotModel
from .symbolic import Port, SymbolicFunction, flatten, port_symbols

FRAME_CONVENTION = (
    "Frames: base = DH frame 0, flange = last DH frame ({n}). T maps flange to base "
    "coordinates (row-major 4x4, last row 0 0 0 1). Lengths in m, angles in rad.")


def q_port(model: RobotModel) -> Port:
    return Port("q", (model.n,), "joint angles, DH order", "rad")


def frame_chain(model: RobotModel, q) -> list[tuple[se.Matrix, se.Matrix]]:
    """Absolute (R_0i, p_0i) for i = 0..n, built one joint at a time on shared objects.

    Each product reuses the previous frame's entries, so the expressions form a DAG whose
    size grows linearly with n."""
    rotation, position = se.eye(3), se.zeros(3, 1)
    chain = [(rotation, position)]
    for joint, qi in zip(model.joints, q):
        r, p = joint_transform(joint, model.convention, qi)
        position = position + rotation * p
        rotation = rotation * r
        chain.append((rotation, position))
    return chain


def homogeneous(rotation: se.Matrix, position: se.Matrix) -> se.Matrix:
    rows = rotation.tolist()
    return se.Matrix([rows[0] + [position[0]], rows[1] + [position[1]], rows[2] + [position[2]], [0, 0, 0, 1]])


def fk_hom(model: RobotModel) -> SymbolicFunction:
    """Flange pose as a 4x4 homogeneous transform, ``fk_hom(q) -> T``."""
    q = port_symbols("q", (model.n,))
    rotation, position = frame_chain(model, q)[-1]
    return SymbolicFunction(
        name="fk_hom",
        summary="Forward kinematics: flange pose as a 4x4 homogeneous transform.",
        inputs=(q_port(model),),
        outputs=(Port("T", (4, 4), "flange pose in the base frame (row-major)", "m (translation), 1 (rotation)"),),
        input_symbols=(q,),
        output_exprs=(flatten(homogeneous(rotation, position)),),
        conventions=FRAME_CONVENTION.format(n=model.n),
    )


def jacobian(model: RobotModel) -> SymbolicFunction:
    """Geometric Jacobian of the flange, ``jacobian(q) -> J`` (6 x n, linear rows first)."""
    q = port_symbols("q", (model.n,))
    chain = frame_chain(model, q)
    flange = chain[-1][1]
    columns = []
    for i in range(model.n):
        rotation, origin = chain[i] if joint_axis_in_previous(model.convention) else chain[i + 1]
        axis = rotation[:, 2]
        linear = axis.cross(flange - origin)
        columns.append(list(linear) + list(axis))
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
        conventions=FRAME_CONVENTION.format(n=model.n)
        + " J is expressed in base-frame axes at the flange origin (Pinocchio LOCAL_WORLD_ALIGNED).",
    )
