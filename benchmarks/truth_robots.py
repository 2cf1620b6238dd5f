"""The robots of the known-truth benchmark of ``discover`` (``benchmarks.discover_truth``), each
twice: the description ``discover`` is given (a file, as a user passes it) and a Pinocchio model
of the same arm built here without any of kindyngen's code, which the simulator runs.

- ``lwr4``, ``panda``: the repository's YAML DH tables (standard and modified DH), read with
  PyYAML and turned into a Pinocchio model joint by joint from the conventions' definitions
  (``dh_model``);
- ``ur5``, ``ur10``: example-robot-data's URDFs read by Pinocchio's own URDF reader (the chain
  ``world`` -> ``tool0``: six revolute joints, the fixed ones merged by Pinocchio).

Every robot also has a *home* pose around which the excitation moves and its joint limits.

>>> robot = ROBOTS["lwr4"]
>>> model = robot.model()
>>> model.nq, robot.n, round(float(model.gravity.linear[2]), 2)
(7, 7, -9.81)
"""
from __future__ import annotations

import importlib.metadata
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def example_robot_data() -> Path:
    """The robots folder of the installed example-robot-data wheel."""
    dist = importlib.metadata.distribution("example-robot-data")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def number(text) -> float:
    """A YAML entry as a float: a number or an expression in ``pi`` such as ``-pi/2``.

    >>> number("-pi/2") == -math.pi / 2, number(0.4)
    (True, 0.4)
    """
    if isinstance(text, (int, float)):
        return float(text)
    return float(eval(str(text), {"__builtins__": {}}, {"pi": math.pi}))  # the repository's own files only


def _rot_x(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _rot_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def dh_model(path: Path):
    """A ``pin.Model`` of a YAML DH arm (``dh: standard`` or ``modified``): revolute joints about
    their frame's z axis, each link's mass, CoM (in DH frame i) and inertia about the CoM
    (``[ixx, iyy, izz, ixy, ixz, iyz]`` in DH frame i) as the description reference defines
    them, gravity as written.

    Standard DH: frame i = frame i-1 * Rz(q_i + offset_i) Tz(d_i) Tx(a_i) Rx(alpha_i); modified
    (Craig): frame i = frame i-1 * Rx(alpha_i) Tx(a_i) Rz(q_i + offset_i) Tz(d_i).  The Pinocchio
    joint i sits at the z axis the joint turns about; the DH frame i is a fixed placement after
    it, and link i's inertia is moved there."""
    import pinocchio as pin
    import yaml
    doc = yaml.safe_load(Path(path).read_text())
    modified = doc["dh"] == "modified"
    model = pin.Model()
    model.gravity = pin.Motion(np.array([number(g) for g in doc["gravity"]]), np.zeros(3))
    parent, before = 0, pin.SE3.Identity()      # joint frame of the parent -> DH frame of the parent
    for i, (joint, link) in enumerate(zip(doc["joints"], doc["links"])):
        a, alpha, d, offset = (number(joint[k]) for k in ("a", "alpha", "d", "offset"))
        if modified:
            at_joint = before * pin.SE3(_rot_x(alpha), np.array([a, 0.0, 0.0])) * pin.SE3(_rot_z(offset), np.zeros(3))
            joint_to_frame = pin.SE3(np.eye(3), np.array([0.0, 0.0, d]))
        else:
            at_joint = before * pin.SE3(_rot_z(offset), np.zeros(3))
            joint_to_frame = pin.SE3(_rot_x(alpha), np.array([a, 0.0, d]))
        jid = model.addJoint(parent, pin.JointModelRZ(), at_joint, f"joint{i + 1}")
        ixx, iyy, izz, ixy, ixz, iyz = (number(v) for v in link["inertia"])
        inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        body = pin.Inertia(number(link["mass"]), np.array([number(c) for c in link["com"]]), inertia)
        model.appendBodyToJoint(jid, joint_to_frame.act(body), pin.SE3.Identity())
        model.lowerPositionLimit[i] = number(joint["lower"])
        model.upperPositionLimit[i] = number(joint["upper"])
        parent, before = jid, joint_to_frame
    return model


def urdf_model(path: Path):
    """A ``pin.Model`` from Pinocchio's URDF reader (gravity (0, 0, -9.81), as kindyngen assumes)."""
    import pinocchio as pin
    return pin.buildModelFromUrdf(str(path))


@dataclass(frozen=True)
class BenchRobot:
    """One arm: ``description`` is what ``discover --robot`` reads (``discover_args`` picks the
    chain of a URDF), ``source`` the file the Pinocchio model is built from, ``home`` the pose the
    excitation moves around (rad)."""

    name: str
    kind: str                        # "yaml" or "urdf"
    description_relative: str        # to the repository root (yaml) or to example-robot-data (urdf)
    home: tuple[float, ...]
    discover_args: tuple[str, ...] = ()

    @property
    def description(self) -> Path:
        if self.kind == "yaml":
            return ROOT / self.description_relative
        return example_robot_data() / self.description_relative

    @property
    def n(self) -> int:
        return len(self.home)

    def model(self):
        """A fresh ``pin.Model`` of the arm (callers may append bodies to it)."""
        return _cached_model(self.kind, str(self.description)).copy()

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        model = self.model()
        return np.array(model.lowerPositionLimit), np.array(model.upperPositionLimit)


@lru_cache(maxsize=None)
def _cached_model(kind: str, path: str):
    return dh_model(Path(path)) if kind == "yaml" else urdf_model(Path(path))


ROBOTS = {r.name: r for r in (
    BenchRobot("lwr4", "yaml", "robots/lwr4.yaml", (0.1, 0.6, -0.2, -1.2, 0.3, 1.0, -0.3)),
    BenchRobot("panda", "yaml", "robots/panda.yaml", (0.0, 0.3, 0.0, -1.8, 0.0, 1.6, 0.4)),
    BenchRobot("ur5", "urdf", "ur_description/urdf/ur5_robot.urdf", (0.0, -1.2, 1.2, -1.5, -1.5, 0.0),
               ("--tip", "tool0")),
    BenchRobot("ur10", "urdf", "ur_description/urdf/ur10_joint_limited_robot.urdf",
               (0.3, -1.4, 1.4, -1.2, 1.4, 0.2), ("--tip", "tool0")),
)}
