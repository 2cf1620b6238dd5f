""":func:`kindyngen.readers.yaml_writer.describe` writes a model as YAML description data
(``dh: none``): the written data, read back by the reader, has the original's joints, links
and effects; and the written data, built into Pinocchio by a builder here that reads only the
dict (origins, axes, inertias; no kindyngen code), has the mass matrix and inverse dynamics
of the original (the Panda, modified DH, from tests/reference.py; an arm by origins and axes
with a prismatic joint, friction, armature, payload and tool, from its own input dict).
A standard DH table is refused (its link frames are off the joint axes).

Tolerance: 1e-12 relative (the written decimals are the shortest that give the same double).
"""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from kindyngen.readers.yaml_description import load_robot, parse_robot
from kindyngen.readers.yaml_writer import describe, origin
from tests.harness import ROOT

pin = pytest.importorskip("pinocchio")
from tests.reference import origin_matrix, pinocchio_model  # noqa: E402

TOL = 1e-12

# an arm by origins and axes: angles off the pi/12 grid, a tilted prismatic axis, effects
ARM = {
    "name": "written_arm", "dh": "none", "gravity": [0.3, -0.2, -9.81],
    "joints": [
        {"name": "turret", "origin": {"xyz": [0, 0, 0.3], "rpy": [0, 0, 0.2]}, "axis": [0, 0, 1],
         "lower": -2.5, "upper": 2.5, "friction": {"viscous": 0.8, "coulomb": 1.2, "offset": 0.1},
         "armature": 0.3},
        {"name": "slide", "type": "prismatic", "origin": {"xyz": [0.1, 0.02, 0.2], "rpy": [0.3, 0, 0]},
         "axis": [0, 0.6, 0.8], "lower": -0.2, "upper": 0.3, "armature": 2.5},
        {"name": "elbow", "origin": {"xyz": [0.3, 0, 0.05], "rpy": ["pi/2", 0.1, -0.4]}, "axis": [1, 0, 0],
         "lower": -2.0, "upper": 2.0, "friction": {"viscous": 0.3, "coulomb": 0.4, "offset": 0.05}},
    ],
    "links": [
        {"mass": 3.0, "com": [0.01, -0.005, 0.12], "inertia": [0.054, 0.052, 0.0073, 0.0003, -0.0008, 0.0019]},
        {"mass": 1.5, "com": [0.03, 0.01, 0.02], "inertia": [0.0031, 0.0042, 0.0037, -0.0004, 0.0005, -0.0003]},
        {"mass": 0.9, "com": [0.1, 0.005, -0.01], "inertia": [0.002, 0.006, 0.005, 0.0001, 0.0, 0.0002]},
    ],
    "payload": {"mass": 0.4, "com": [0.05, 0, 0.02], "inertia": [0.0005, 0.0005, 0.0004, 0, 0, 0]},
    "tool": {"xyz": [0.0, 0.0, 0.1], "rpy": [0, "pi/2", 0]},
}


def _inertia(link: dict):
    ixx, iyy, izz, ixy, ixz, iyz = (float(v) for v in link["inertia"])
    I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return pin.Inertia(float(link["mass"]), np.array(link["com"], float), I)


def pinocchio_from_data(data: dict):
    """Pinocchio's model of description data with ``dh: none`` (a chain): joint j at its
    origin in link frame j-1, turning about / sliding along its axis; link j (and the payload
    on the last) in link frame j = joint frame j; armature as Pinocchio's rotor inertia."""
    assert data["dh"] == "none"
    model = pin.Model()
    model.gravity = pin.Motion(np.array(data["gravity"], float), np.zeros(3))
    parent = 0
    for k, (joint, link) in enumerate(zip(data["joints"], data["links"])):
        T = origin_matrix(joint["origin"].get("xyz", [0, 0, 0]), joint["origin"].get("rpy", [0, 0, 0]))
        axis = np.array(joint.get("axis", [0, 0, 1]), float)
        axis /= np.linalg.norm(axis)
        kind = (pin.JointModelPrismaticUnaligned if joint.get("type") == "prismatic"
                else pin.JointModelRevoluteUnaligned)(axis)
        parent = model.addJoint(parent, kind, pin.SE3(T[:3, :3], T[:3, 3]), joint.get("name", f"j{k}"))
        model.appendBodyToJoint(parent, _inertia(link), pin.SE3.Identity())
        model.armature[k] = float(joint.get("armature", 0.0))
    if "payload" in data:
        model.appendBodyToJoint(parent, _inertia(data["payload"]), pin.SE3.Identity())
    return model, model.createData()


def _friction_torque(data: dict, qd):
    """viscous qd + coulomb sign(qd) + offset, per joint, from the description dict."""
    out = np.zeros(len(data["joints"]))
    for j, joint in enumerate(data["joints"]):
        f = joint.get("friction")
        if f:
            out[j] = float(f["viscous"]) * qd[j] + float(f["coulomb"]) * np.sign(qd[j]) + float(f["offset"])
    return out


def _states(lower, upper, count=20, seed=26):
    rng = np.random.default_rng(seed)
    n = len(lower)
    return [(rng.uniform(lower, upper), rng.normal(size=n), rng.normal(size=n)) for _ in range(count)]


def _close(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.abs(a - b).max() <= TOL * max(1.0, np.abs(b).max())


@pytest.fixture(scope="module")
def panda():
    return load_robot(ROOT / "robots" / "panda.yaml")


def test_panda_written_reads_back_with_its_joints_and_links(panda):
    # through YAML text, as a user saves and reloads it
    data = yaml.safe_load(yaml.safe_dump(describe(panda), sort_keys=False))
    assert data["dh"] == "none" and data["name"] == panda.name
    back = parse_robot(data)
    assert back.n == panda.n and not back.is_dh
    assert [float(g) for g in back.gravity] == [float(g) for g in panda.gravity]
    for a, b in zip(back.joints, panda.joints):
        assert (float(a.lower), float(a.upper), a.prismatic) == (float(b.lower), float(b.upper), b.prismatic)
    for a, b in zip(back.links, panda.links):
        assert float(a.mass) == float(b.mass)
        assert [float(v) for v in a.com] == [float(v) for v in b.com]
        assert np.array_equal(a.inertia_matrix(), b.inertia_matrix())


def test_panda_written_has_the_dh_tables_dynamics_in_pinocchio(panda):
    dh_model, dh_data, _ = pinocchio_model(panda)
    model, data = pinocchio_from_data(describe(panda))
    for q, qd, qdd in _states(panda.lower, panda.upper):
        M_ref = pin.crba(dh_model, dh_data, q)
        M = pin.crba(model, data, q)
        assert _close(np.triu(M), np.triu(M_ref))
        assert _close(pin.rnea(model, data, q, qd, qdd), pin.rnea(dh_model, dh_data, q, qd, qdd))


def test_arm_with_effects_written_keeps_every_field():
    written = describe(parse_robot(ARM))
    assert [j.get("type", "revolute") for j in written["joints"]] == [j.get("type", "revolute") for j in ARM["joints"]]
    assert [j["name"] for j in written["joints"]] == [j["name"] for j in ARM["joints"]]
    for w, given in zip(written["joints"], ARM["joints"]):
        assert (w["lower"], w["upper"]) == (given["lower"], given["upper"])
        assert w.get("friction") == given.get("friction")
        assert w.get("armature") == given.get("armature")
    for w, given in zip(written["links"] + [written["payload"]], ARM["links"] + [ARM["payload"]]):
        assert w["mass"] == given["mass"] and w["com"] == [float(v) for v in given["com"]]
        assert w["inertia"] == [float(v) for v in given["inertia"]]
    assert written["gravity"] == ARM["gravity"]
    # the tool: the same pose, read independently from both
    assert np.allclose(origin_matrix(written["tool"]["xyz"], written["tool"]["rpy"]),
                       origin_matrix(ARM["tool"]["xyz"], ARM["tool"]["rpy"]), rtol=0, atol=1e-15)


def test_arm_with_effects_written_has_the_inputs_dynamics_in_pinocchio():
    """The written arm's joints differ from the input's (the axis turned into z, origins
    multiplied out): M(q) and the torques must not."""
    written = describe(parse_robot(ARM))
    given_model, given_data = pinocchio_from_data(ARM)
    model, data = pinocchio_from_data(written)
    lower = [j["lower"] for j in ARM["joints"]]
    upper = [j["upper"] for j in ARM["joints"]]
    for q, qd, qdd in _states(lower, upper):
        M_ref = pin.crba(given_model, given_data, q)
        assert _close(np.triu(pin.crba(model, data, q)), np.triu(M_ref))
        tau_ref = pin.rnea(given_model, given_data, q, qd, qdd) + _friction_torque(ARM, qd)
        tau_ref += given_model.armature * qdd       # rnea leaves the rotor inertia out
        tau = pin.rnea(model, data, q, qd, qdd) + _friction_torque(written, qd) + model.armature * qdd
        assert _close(tau, tau_ref)


def test_origin_angles_on_the_pi_over_12_grid_are_expressions():
    from kindyngen.model.placement import rpy_xyz
    import sympy
    written = origin(rpy_xyz((0.1, -0.2, 0.3), (sympy.pi / 6, 0, -sympy.pi / 4)))
    assert written["rpy"] == ["pi/6", 0, "-pi/4"]
    assert written["xyz"] == [0.1, -0.2, 0.3]
    off = origin(rpy_xyz((0, 0, 0), (0.3, 0, 0)))["rpy"]
    # off the grid: a float, recovered from the rotation matrix (atan2) to a few ulps
    assert isinstance(off[0], float) and abs(off[0] - 0.3) < 1e-15


def test_standard_dh_table_is_refused():
    lwr = load_robot(ROOT / "robots" / "lwr4.yaml")
    with pytest.raises(ValueError, match="off the joint axis"):
        describe(lwr)
