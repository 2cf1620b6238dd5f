"""Independent implementations the tests compare against: Pinocchio (built from the DH
table with its own joint and inertia machinery) and a plain-numpy DH product.

Nothing here imports the symbolic pipeline; only the YAML loader is shared.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from kindyngen.model.robot_model import RobotModel


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def origin_matrix(xyz, rpy) -> np.ndarray:
    """4x4 of a URDF ``<origin>``: ``T(xyz) Rz(yaw) Ry(pitch) Rx(roll)``; entries may be
    numbers or expression strings such as ``"pi/2"``."""
    import sympy
    r, p, y = (float(sympy.sympify(v)) for v in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    T = np.eye(4)
    T[:3, :3] = (np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
                 @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]))
    T[:3, 3] = [float(v) for v in xyz]
    return T


def _se3(R=np.eye(3), p=np.zeros(3)):
    return pin.SE3(np.asarray(R, float), np.asarray(p, float))


def dh_numbers(robot: RobotModel):
    """(a, alpha, d, offset) as float arrays."""
    return tuple(np.array([float(getattr(j, k)) for j in robot.joints]) for k in ("a", "alpha", "d", "offset"))


def dh_transform_numpy(robot: RobotModel, i: int, qi: float) -> np.ndarray:
    """4x4 transform of frame i+1 in frame i, straight from the convention's definition."""
    a, alpha, d, off = (v[i] for v in dh_numbers(robot))
    T = np.eye(4)
    th = qi + off
    if robot.convention == "standard":
        T[:3, :3] = _rz(th) @ _rx(alpha)
        T[:3, 3] = [a * np.cos(th), a * np.sin(th), d]
    else:
        T[:3, :3] = _rx(alpha) @ _rz(th)
        T[:3, 3] = _rx(alpha) @ np.array([0, 0, d]) + np.array([a, 0, 0])
    return T


def fk_numpy(robot: RobotModel, q) -> np.ndarray:
    """Flange pose by a plain product of DH matrices."""
    T = np.eye(4)
    for i, qi in enumerate(q):
        T = T @ dh_transform_numpy(robot, i, qi)
    return T


def pinocchio_model(robot: RobotModel):
    """A pin.Model of the arm with revolute-z joints, link inertias and a 'flange' frame.

    Returns (model, data, flange_frame_id)."""
    model = pin.Model()
    model.gravity = pin.Motion(np.array(robot.gravity, float), np.zeros(3))
    a, alpha, d, off = dh_numbers(robot)
    parent = 0
    placement = pin.SE3.Identity()   # parent joint frame -> this joint frame
    for i in range(robot.n):
        if robot.convention == "standard":
            joint_placement = placement * _se3(_rz(off[i]))
            # DH frame i = joint frame * Rz(q) * Tz(d) Tx(a) Rx(alpha)
            body_to_link = _se3(_rx(alpha[i]), [a[i], 0, d[i]])
        else:
            joint_placement = placement * _se3(_rx(alpha[i]), [a[i], 0, 0]) * _se3(_rz(off[i]))
            body_to_link = _se3(np.eye(3), [0, 0, d[i]])
        jid = model.addJoint(parent, pin.JointModelRZ(), joint_placement, f"joint{i + 1}")
        link = robot.links[i]
        inertia = pin.Inertia(float(link.mass), np.array(link.com, float), link.inertia_matrix())
        model.appendBodyToJoint(jid, body_to_link.act(inertia), pin.SE3.Identity())
        model.lowerPositionLimit[i] = robot.joints[i].lower
        model.upperPositionLimit[i] = robot.joints[i].upper
        parent = jid
        placement = body_to_link
    frame = model.addFrame(pin.Frame("flange", parent, 0, placement, pin.FrameType.OP_FRAME))
    return model, model.createData(), frame


def random_configurations(robot: RobotModel, count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(robot.lower, robot.upper, size=(count, robot.n))


def random_tree_state(tree: RobotModel, rng: np.random.Generator, spread: float = 3.0):
    """(q, qd, qdd, tau) at random for a tree: joint angles uniform within the joint limits
    clipped to +-pi; for a floating base, a position in [-1, 1]^3 and a uniformly random unit
    quaternion (x, y, z, w) first, as Pinocchio orders q; speeds, accelerations and torques
    uniform in +-``spread``."""
    qj = rng.uniform([max(j.lower, -np.pi) for j in tree.joints], [min(j.upper, np.pi) for j in tree.joints])
    if tree.floating_base:
        quat = rng.standard_normal(4)
        q = np.r_[rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat), qj]
    else:
        q = qj
    return (q,) + tuple(rng.uniform(-spread, spread, tree.nv) for _ in range(3))
