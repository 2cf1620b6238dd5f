"""Poses and Jacobians of the frames of interest of a kinematic tree.

Every link frame is its parent's composed with ``before * motion(q) * after``
(:func:`kindyngen.algorithms.geometry.joint_transform`), one product per joint on shared objects; the
root link frame is the world's (fixed base) or the base pose ``(q[0:3], R(q[3:7]))``
(floating base, quaternion x, y, z, w). ``fk_hom`` returns the k requested frames' poses
(k x 4 x 4, row-major, in the order of ``--frames``), ``jacobian`` their k Jacobians (k x 6
x nv): rows 0-2 the linear velocity of the frame origin, rows 3-5 the angular velocity,
both in the world (fixed base: root) frame, Pinocchio's LOCAL_WORLD_ALIGNED. A joint off
the frame's branch has a zero column. A floating base's columns are those of its twist in
the base frame: ``[R, -[p_f - p_b]x R]`` (linear), ``[0, R]`` (angular).

Example:

>>> from kindyngen.readers.urdf import parse_urdf
>>> from kindyngen.readers.urdf import TWO_PENDULUMS
>>> f = jacobian_tree(parse_urdf(TWO_PENDULUMS, floating_base=True))
>>> f.outputs[0].shape
(2, 6, 8)
"""
from __future__ import annotations

import symengine as se

from .geometry import compose, constant_transform, motion
from .kinematics_conventions import frame_convention, q_port
from ..model.robot_model import FREE_FLYER_NV, RobotModel
from .symbolic import Port, Stages, SymbolicFunction, flatten, port_symbols
from .dynamics import quaternion_rotation


def _root_pose(model: RobotModel, q):
    if not model.floating_base:
        return se.eye(3), se.zeros(3, 1)
    return se.Matrix(quaternion_rotation(*q[3:7])), se.Matrix(list(q[0:3]))


def link_poses(model: RobotModel, q, stages: Stages | None = None):
    """(root pose, [(R, p) of each joint's link frame], [(axis, origin) of each joint]) in
    the world (root) frame; with ``stages``, each link pose is named there."""
    if model.has_mimics or model.has_loops:
        raise ValueError(f"{model.name}: mimic joints or loops: derive on model.without_mimics() and reduce "
                         f"(kindyngen.algorithms.reduced_coordinates, loop_closure)")
    joint_q = q[7:] if model.floating_base else q
    root = _root_pose(model, q)
    links, axes = [], []
    for joint, parent, qj in zip(model.joints, model.parents, joint_q):
        above = links[parent] if parent >= 0 else root
        frame = compose(above, constant_transform(joint.before))
        axes.append((frame[0][:, 2], frame[1]))
        link = compose(compose(frame, motion(joint, qj)), constant_transform(joint.after))
        if stages is not None:
            link = tuple(se.Matrix(m.rows, m.cols, stages.cut_all(list(m))) for m in link)
        links.append(link)
    return root, links, axes


def frame_poses(model: RobotModel, q, stages: Stages | None = None):
    """(R, p) of each requested frame, and the poses of :func:`link_poses`."""
    root, links, axes = link_poses(model, q, stages)
    poses = [compose(links[f.body] if f.body >= 0 else root, constant_transform(f.placement))
             for f in model.frames_of_interest]
    return poses, root, axes


def _levers(model: RobotModel, q, root, links, frame, stages: Stages) -> dict:
    """The lever arms ``p_f - o_j`` from each joint origin on the frame's branch to the frame
    origin (key -1: from the root origin), summed from the frame down: ``d_j = d_c + (o_c -
    o_j)`` with c the joint below j, where ``o_c - o_j`` is the rotated constant offsets of
    joint j's motion and after-placement and of joint c's before-placement. Each offset is a
    product the link poses share; the origins ``o_j`` and the frame position are never formed,
    so that each lever is one vector addition after the one below it."""
    joint_q = q[7:] if model.floating_base else q

    def rotated(R, t):
        return None if t is None else R * t

    def plus(a, b):
        return b if a is None else a if b is None else a + b

    def offset_in_link(j):
        """p_link_j - o_j: the rotated translations of joint j's motion and after-placement."""
        joint, parent = model.joints[j], model.parents[j]
        above = links[parent] if parent >= 0 else root
        R_frame = compose(above, constant_transform(joint.before))[0]
        R_motion, t_motion = motion(joint, joint_q[j])
        after = constant_transform(joint.after)
        out = rotated(R_frame, t_motion) if joint.prismatic else None
        return plus(out, None if after is None else (R_frame * R_motion) * after[1])

    def before_offset(j):
        """o_j - p_parent: joint j's before-translation in its parent link's axes."""
        parent = model.parents[j]
        above = links[parent] if parent >= 0 else root
        before = constant_transform(model.joints[j].before)
        return None if before is None else above[0] * before[1]

    placement = constant_transform(frame.placement)
    d = None
    if placement is not None:
        d = (links[frame.body] if frame.body >= 0 else root)[0] * placement[1]
    levers = {}
    for j in model.ancestors(frame.body):
        d = plus(d, offset_in_link(j))
        d = se.zeros(3, 1) if d is None else se.Matrix(3, 1, stages.cut_all(list(d)))
        levers[j] = d
        d = plus(d, before_offset(j))
    levers[-1] = se.zeros(3, 1) if d is None else d
    return levers


def _frame_text(model: RobotModel) -> str:
    names = ", ".join(f.name for f in model.frames_of_interest)
    where = "world" if model.floating_base else f"root link '{model.base_name}'"
    return f"frames {names} (links of the description), in the {where} frame"


def fk_hom_tree(model: RobotModel, name: str = "fk_hom") -> SymbolicFunction:
    """``fk_hom(q) -> T``: the requested frames' poses (an arm: its flange's, 4 x 4)."""
    q = port_symbols("q", (model.nq,))
    poses, _, _ = frame_poses(model, q)
    out = []
    for R, p in poses:
        out.extend(flatten(R.row_join(p).col_join(se.Matrix([[0, 0, 0, 1]]))))
    k = len(poses)
    if model.is_tree:
        summary = f"Forward kinematics of the {k} requested frames as homogeneous transforms."
        port = Port("T", (k, 4, 4), f"poses of {_frame_text(model)}: frame to world coordinates, row-major, "
                    "last row 0 0 0 1", "m")
        conventions = f"{model.frames_text} Lengths in m, angles in rad."
    else:
        summary = "Forward kinematics: flange pose as a 4x4 homogeneous transform."
        port = Port("T", (4, 4), "flange pose in the base frame (row-major)", "m (translation), 1 (rotation)")
        conventions = frame_convention(model)
    return SymbolicFunction(name, summary, (q_port(model),), (port,), (q,), (tuple(out),), conventions=conventions)


def jacobian_tree(model: RobotModel, name: str = "jacobian") -> SymbolicFunction:
    """``jacobian(q) -> J``: the requested frames' geometric Jacobians (module text; an arm:
    its flange's, 6 x n)."""
    q = port_symbols("q", (model.nq,))
    stages = Stages()
    root, links, axes = link_poses(model, q, stages)
    base = FREE_FLYER_NV if model.floating_base else 0
    out = []
    for frame in model.frames_of_interest:
        J = se.zeros(6, model.nv)
        levers = _levers(model, q, root, links, frame, stages)
        if model.floating_base:
            R = root[0]
            d = levers[-1]
            dx = se.Matrix([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
            J[0:3, 0:3] = R
            J[0:3, 3:6] = -dx * R
            J[3:6, 3:6] = R
        for j in model.ancestors(frame.body):
            z, _ = axes[j]
            if model.joints[j].prismatic:
                J[0:3, base + j] = z
            else:
                d = levers[j]
                J[0:3, base + j] = se.Matrix([z[1] * d[2] - z[2] * d[1], z[2] * d[0] - z[0] * d[2],
                                              z[0] * d[1] - z[1] * d[0]])
                J[3:6, base + j] = z
        out.extend(flatten(J))
    k = len(model.frames_of_interest)
    if model.is_tree:
        summary = f"Geometric Jacobians of the {k} requested frames."
        port = Port("J", (k, 6, model.nv), f"Jacobians of {_frame_text(model)}: rows linear velocity of the frame "
                    "origin, then angular velocity, world-aligned (Pinocchio's LOCAL_WORLD_ALIGNED); [v; w] = J qd",
                    "m or 1 per unit of qd")
        conventions = f"{model.frames_text} Lengths in m, angles in rad."
    else:
        summary = "Geometric Jacobian of the flange: [v; w] = J(q) qd."
        port = Port("J", (6, model.n), "rows 0-2: linear velocity of the flange origin, rows 3-5: angular velocity; "
                    "both in base-frame axes (row-major)", "m/rad (rows 0-2), 1 (rows 3-5)")
        conventions = (frame_convention(model) + " J is expressed in base-frame axes at the flange origin "
                       "(Pinocchio LOCAL_WORLD_ALIGNED).")
    return SymbolicFunction(name, summary, (q_port(model),), (port,), (q,), (tuple(out),), conventions=conventions,
                            stages=stages.definitions)
