"""Prismatic joints in DH tables (standard and modified rows) and a tool frame in the YAML:
generated FK, Jacobian, M, g, c, tau and fd in C, Python and CasADi equal a Pinocchio model
built here from the DH numbers with Pinocchio's own prismatic joints (nothing of the
pipeline used but the YAML reader)."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from kindyngen.runtime.evaluate import load_generated
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import parse_robot
from tests.reference import _rx, _rz

pin = pytest.importorskip("pinocchio")

LINKS = [{"mass": 2.0, "com": [0.01, -0.02, 0.1], "inertia": [0.02, 0.018, 0.01, 0.001, -0.002, 0.0015]},
         {"mass": 1.5, "com": [0.02, 0.03, -0.05], "inertia": [0.015, 0.012, 0.009, -0.001, 0.0005, 0.001]},
         {"mass": 1.2, "com": [-0.01, 0.04, 0.02], "inertia": [0.01, 0.011, 0.006, 0.0007, 0.0004, -0.0008]},
         {"mass": 0.6, "com": [0.005, 0.0, 0.03], "inertia": [0.004, 0.005, 0.003, 0.0002, 0.0001, -0.0003]}]
# revolute, prismatic (constant angle theta, stroke along z), revolute, revolute
ROWS = [{"a": 0.05, "alpha": "pi/2", "d": 0.3, "lower": -2.5, "upper": 2.5},
        {"type": "prismatic", "a": 0.02, "alpha": "-pi/2", "d": 0.1, "theta": "pi/6", "lower": 0.0, "upper": 0.4},
        {"a": 0.25, "alpha": 0.4, "d": 0.0, "offset": 0.3, "lower": -2.0, "upper": 2.0},
        {"a": 0.0, "alpha": "pi/2", "d": 0.08, "lower": -3.0, "upper": 3.0}]
TOOL = {"xyz": [0.01, 0.02, 0.12], "rpy": [0.1, -0.2, 0.3]}
FUNCTIONS = ("fk_hom", "jacobian", "M", "g", "c", "tau", "fd")


def _ry(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _se3(R=np.eye(3), p=(0, 0, 0)):
    return pin.SE3(np.asarray(R, float), np.asarray(p, float))


def _pinocchio(convention):
    """The arm of ROWS in Pinocchio: standard rows ``Rz(theta) Tz(d) Tx(a) Rx(alpha)`` with the
    joint's motion inside, modified rows ``Rx(alpha) Tx(a) Rz(theta) Tz(d)``, tool last."""
    model = pin.Model()
    model.gravity = pin.Motion(np.array([0, 0, -9.81]), np.zeros(3))
    parent, placement = 0, pin.SE3.Identity()
    for i, row in enumerate(ROWS):
        a, d = row["a"], row["d"]
        alpha = {"pi/2": np.pi / 2, "-pi/2": -np.pi / 2}.get(row["alpha"], row["alpha"])
        prismatic = row.get("type") == "prismatic"
        angle = np.pi / 6 if prismatic else row.get("offset", 0.0)
        if convention == "standard":
            joint_placement = placement * _se3(_rz(angle)) * (_se3(p=(0, 0, d)) if prismatic else pin.SE3.Identity())
            body_to_link = _se3(_rx(alpha), (a, 0, 0 if prismatic else d))
        else:
            joint_placement = placement * _se3(_rx(alpha), (a, 0, 0)) * _se3(_rz(angle)) * _se3(p=(0, 0, d))
            body_to_link = pin.SE3.Identity()
        joint = pin.JointModelPZ() if prismatic else pin.JointModelRZ()
        jid = model.addJoint(parent, joint, joint_placement, f"joint{i + 1}")
        link = LINKS[i]
        ixx, iyy, izz, ixy, ixz, iyz = link["inertia"]
        inertia = pin.Inertia(link["mass"], np.array(link["com"]),
                              np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]))
        model.appendBodyToJoint(jid, body_to_link.act(inertia), pin.SE3.Identity())
        parent, placement = jid, body_to_link
    roll, pitch, yaw = TOOL["rpy"]
    tool = _se3(_rz(yaw) @ _ry(pitch) @ _rx(roll), TOOL["xyz"])
    frame = model.addFrame(pin.Frame("tool", parent, 0, placement * tool, pin.FrameType.OP_FRAME))
    return model, model.createData(), frame


@pytest.fixture(scope="module", params=("standard", "modified"))
def arm(request, tmp_path_factory):
    data = {"name": f"slider_{request.param}", "dh": request.param, "gravity": [0, 0, -9.81],
            "joints": ROWS, "links": LINKS, "tool": TOOL}
    model = parse_robot(yaml.safe_load(yaml.safe_dump(data)), "slider.yaml")
    assert [j.kind for j in model.joints] == ["revolute", "prismatic", "revolute", "revolute"]
    folder = generate(model, tmp_path_factory.mktemp(request.param), progress=False, only=set(FUNCTIONS))
    return request.param, model, folder


@pytest.mark.parametrize("lang", ("c", "python", "casadi"))
def test_prismatic_dh_rows_equal_pinocchio(arm, lang):
    convention, model, folder = arm
    pmodel, pdata, frame = _pinocchio(convention)
    rng = np.random.default_rng(11)
    N = 300
    Q = rng.uniform(model.lower, model.upper, size=(N, 4))
    QD, QDD, TAU = rng.uniform(-1.5, 1.5, (N, 4)), rng.uniform(-4, 4, (N, 4)), rng.uniform(-10, 10, (N, 4))
    lib = load_generated(folder, lang)
    got = {"fk_hom": lib.call("fk_hom", {"q": Q})["T"], "jacobian": lib.call("jacobian", {"q": Q})["J"],
           "M": lib.call("M", {"q": Q})["M"], "g": lib.call("g", {"q": Q})["g"],
           "c": lib.call("c", {"q": Q, "qd": QD})["c"], "tau": lib.call("tau", {"q": Q, "qd": QD, "qdd": QDD})["tau"],
           "fd": lib.call("fd", {"q": Q, "qd": QD, "tau": TAU})["qdd"]}
    for k, (q, qd, qdd, tau) in enumerate(zip(Q, QD, QDD, TAU)):
        pin.computeJointJacobians(pmodel, pdata, q)
        pin.framesForwardKinematics(pmodel, pdata, q)
        g = pin.computeGeneralizedGravity(pmodel, pdata, q)
        expected = {"fk_hom": pdata.oMf[frame].homogeneous,
                    "jacobian": pin.getFrameJacobian(pmodel, pdata, frame, pin.LOCAL_WORLD_ALIGNED),
                    "M": np.triu(pin.crba(pmodel, pdata, q)) + np.triu(pin.crba(pmodel, pdata, q), 1).T,
                    "g": g, "c": pin.nonLinearEffects(pmodel, pdata, q, qd) - g,
                    "tau": pin.rnea(pmodel, pdata, q, qd, qdd), "fd": pin.aba(pmodel, pdata, q, qd, tau)}
        for name, value in expected.items():
            scale = max(1.0, np.abs(value).max())
            np.testing.assert_allclose(got[name][k], value, rtol=0, atol=1e-9 * scale, err_msg=f"{lang} {name}")
