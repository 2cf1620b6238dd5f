"""Inputs for timing: K varying, plausible values per input port, the same for every
implementation of a function (so branches in IK take the same paths everywhere).

Joint angles are uniform within the joint limits; IK targets are the forward kinematics of
such angles, with theta3 the angle that produced them, so IK solves reachable poses.
"""
from __future__ import annotations

import numpy as np

# Ranges for ports that are not angles: values of the right order for a 7-DOF arm.
UNIFORM = {"qd": 1.5, "qdd": 3.0, "tau": 20.0}


def joint_angles(robot, count: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(robot.lower, robot.upper, size=(count, robot.n))


def sample(function: dict, robot, count: int, python_module=None, seed: int = 0) -> dict:
    """{port name: array (count, *shape)} for the inputs of one functions.json entry."""
    rng = np.random.default_rng(seed + 1)
    q = joint_angles(robot, count, seed)
    out = {}
    for port in function["inputs"]:
        name, shape = port["name"], tuple(port["shape"])
        if name == "q":
            value = q
        elif name in UNIFORM:
            value = rng.uniform(-UNIFORM[name], UNIFORM[name], size=(count,) + shape)
        elif name == "lengths":  # symbolic DH lengths: values of a real arm's links
            value = rng.uniform(0.3, 0.45, size=(count,) + shape)
        elif name == "theta3":
            value = q[:, 2].reshape((count,) + shape)
        elif name == "T" and python_module is not None and hasattr(python_module, "fk_hom"):
            value = np.asarray(python_module.fk_hom(q)).reshape((count,) + shape)
        elif name == "x" and python_module is not None and hasattr(python_module, "fk_dq"):
            value = np.asarray(python_module.fk_dq(q)).reshape((count,) + shape)
        else:
            # Unknown port (e.g. symbolic parameters): any finite values time the same.
            value = rng.standard_normal((count,) + shape)
        out[name] = np.ascontiguousarray(value, dtype=np.float64)
    return out


def dynamics_inputs(robot, count: int, seed: int = 0) -> dict:
    """q, qd, qdd, tau for Pinocchio, drawn exactly as :func:`sample` draws them."""
    fake = {"inputs": [{"name": k, "shape": [robot.n]} for k in ("q", "qd", "qdd", "tau")]}
    return sample(fake, robot, count, seed=seed)
