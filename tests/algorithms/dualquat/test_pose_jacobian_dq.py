"""The pose Jacobian of the flange dual quaternion (``pose_jacobian_dq``) and the geometric
Jacobian obtained from it (``jacobian_dq``), generated in every language, for the LWR, the
Panda and a small arm with a prismatic joint and a tool:

- Jx equals central finite differences of the generated ``fk_dq``;
- Jx equals 1/2 L_i x column by column, with L_i = (w_i, v_i + t x w_i) the joint's line
  read off an independent geometric Jacobian (Pinocchio for the DH arms, a plain numpy
  frame chain for the prismatic arm) and x the generated ``fk_dq``;
- ``jacobian_dq`` equals the homogeneous ``jacobian`` to 1e-12;
- for the LWR, x and Jx equal DQ Robotics' ``DQ_SerialManipulatorDH`` (fkm, pose_jacobian),
  sign included, when the ``dqrobotics`` package is installed.
"""
import json
import math

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import LANGS, ROOT
from kindyngen.runtime.evaluate import load_generated
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot, parse_robot
from tests.reference import dh_numbers, origin_matrix, pinocchio_model, random_configurations

N = 1000
FUNCTIONS = {"fk_dq", "jacobian", "pose_jacobian_dq", "jacobian_dq"}

LINK = {"mass": 1.0, "com": [0.01, 0.02, 0.03], "inertia": [0.01, 0.012, 0.014, 0, 0, 0]}
# revolute z, revolute about a tilted y, prismatic along a skew axis, revolute x, and a tool
SLIDER = {
    "name": "slider4",
    "dh": "none",
    "gravity": [0, 0, -9.81],
    "joints": [
        {"origin": {"xyz": [0, 0, 0.3]}, "axis": [0, 0, 1], "lower": -2.5, "upper": 2.5},
        {"origin": {"xyz": [0.05, 0, 0.1], "rpy": [0.3, 0, 0]}, "axis": [0, 1, 0], "lower": -1.5, "upper": 1.5},
        {"type": "prismatic", "origin": {"xyz": [0.2, 0.01, 0], "rpy": [0, 0.2, -0.4]}, "axis": [1, 0, 1],
         "lower": -0.1, "upper": 0.25},
        {"origin": {"xyz": [0.1, 0, -0.02]}, "axis": [1, 0, 0], "lower": -3, "upper": 3},
    ],
    "links": [LINK] * 4,
    "tool": {"xyz": [0.03, -0.02, 0.11], "rpy": [0.1, -0.25, 0.7]},
}
ROBOTS = ("lwr4", "panda", "slider4")


def model_of(name):
    if name == "slider4":
        return parse_robot(SLIDER, "slider4")
    return load_robot(ROOT / "robots" / f"{name}.yaml")


@pytest.fixture(scope="module", params=ROBOTS)
def case(request, tmp_path_factory):
    name = request.param
    model = model_of(name)
    folder = generate(model, tmp_path_factory.mktemp(name), only=FUNCTIONS, progress=False)
    return name, model, folder, random_configurations(model, N, seed=7)


def call(folder, lang, function, Q):
    out = load_generated(folder, lang).call(function, {"q": Q})
    return next(iter(out.values()))


# --- independent numpy helpers -------------------------------------------------------------
def qmul(a, b):
    """Hamilton products of (..., 4) arrays, scalar first."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def pure(v):
    return np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], axis=-1)


def line_times(u, m, x):
    """(u + e m) x for pure u, m (..., 3) and dual quaternions x (..., 8)."""
    r, d = x[..., :4], x[..., 4:]
    return np.concatenate([qmul(pure(u), r), qmul(pure(u), d) + qmul(pure(m), r)], axis=-1)


def frames_pose_and_jacobian(spec, q):
    """Tool pose (4x4) and geometric Jacobian [v; w] (base axes) of a ``dh: none`` arm by a
    plain product of 4x4 matrices."""
    T = np.eye(4)
    axes = []
    for joint, qi in zip(spec["joints"], q):
        origin = joint.get("origin", {})
        T = T @ origin_matrix(origin.get("xyz", (0, 0, 0)), origin.get("rpy", (0, 0, 0)))
        a = np.asarray(joint["axis"], float) / np.linalg.norm(joint["axis"])
        prismatic = joint.get("type") == "prismatic"
        axes.append((T[:3, :3] @ a, T[:3, 3].copy(), prismatic))
        motion = np.eye(4)
        if prismatic:
            motion[:3, 3] = qi * a
        else:
            K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
            motion[:3, :3] = np.eye(3) + math.sin(qi) * K + (1 - math.cos(qi)) * K @ K
        T = T @ motion
    T = T @ origin_matrix(spec["tool"]["xyz"], spec["tool"]["rpy"])
    J = np.zeros((6, len(q)))
    for i, (u, p, prismatic) in enumerate(axes):
        J[:, i] = np.r_[u, 0, 0, 0] if prismatic else np.r_[np.cross(u, T[:3, 3] - p), u]
    return T, J


def reference_pose_and_jacobian(name, model, Q):
    """(N, 4, 4) poses and (N, 6, n) geometric Jacobians, independently of the generator."""
    if name == "slider4":
        pairs = [frames_pose_and_jacobian(SLIDER, q) for q in Q]
    else:
        pmodel, data, frame = pinocchio_model(model)
        pairs = []
        for q in Q:
            pin.computeJointJacobians(pmodel, data, q)
            pin.framesForwardKinematics(pmodel, data, q)
            J = pin.getFrameJacobian(pmodel, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            pairs.append((data.oMf[frame].homogeneous.copy(), J.copy()))
    return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])


def dq_to_matrix(x):
    """(N, 8) unit dual quaternions -> (N, 4, 4)."""
    w, a, b, c = np.moveaxis(x[:, :4], -1, 0)
    T = np.tile(np.eye(4), (len(x), 1, 1))
    T[:, :3, :3] = np.stack([
        np.stack([1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b)], -1),
        np.stack([2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a)], -1),
        np.stack([2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)], -1)], axis=1)
    r_conj = x[:, :4] * np.array([1, -1, -1, -1])
    T[:, :3, 3] = 2 * qmul(x[:, 4:], r_conj)[:, 1:]
    return T


# --- tests ------------------------------------------------------------------------------------
@pytest.mark.parametrize("lang", LANGS)
def test_pose_jacobian_matches_finite_differences(case, lang):
    _, model, folder, Q = case
    Jx = call(folder, lang, "pose_jacobian_dq", Q)
    assert Jx.shape == (N, 8, model.n)
    h = 1e-6
    for i in range(model.n):
        step = np.zeros(model.n)
        step[i] = h
        fd = (call(folder, lang, "fk_dq", Q + step) - call(folder, lang, "fk_dq", Q - step)) / (2 * h)
        np.testing.assert_allclose(Jx[:, :, i], fd, rtol=0, atol=1e-8)


@pytest.mark.parametrize("lang", LANGS)
def test_pose_jacobian_is_half_line_times_x(case, lang):
    """Column i = 1/2 L_i x, the line L_i = (w_i, v_i + t x w_i) from a reference Jacobian."""
    name, model, folder, Q = case
    T_ref, J_ref = reference_pose_and_jacobian(name, model, Q)
    x = call(folder, lang, "fk_dq", Q)
    np.testing.assert_allclose(dq_to_matrix(x), T_ref, rtol=0, atol=1e-12)
    Jx = call(folder, lang, "pose_jacobian_dq", Q)
    t = T_ref[:, :3, 3]
    for i in range(model.n):
        v, w = J_ref[:, :3, i], J_ref[:, 3:, i]
        expected = 0.5 * line_times(w, v + np.cross(t, w), x)
        np.testing.assert_allclose(Jx[:, :, i], expected, rtol=0, atol=1e-12)


@pytest.mark.parametrize("lang", LANGS)
def test_jacobian_dq_equals_jacobian(case, lang):
    _, model, folder, Q = case
    J_dq = call(folder, lang, "jacobian_dq", Q)
    assert J_dq.shape == (N, 6, model.n)
    np.testing.assert_allclose(J_dq, call(folder, lang, "jacobian", Q), rtol=0, atol=1e-12)


def test_manifest_entries(case):
    _, model, folder, _ = case
    functions = {f["name"]: f for f in json.loads((folder / "functions.json").read_text())["functions"]}
    Jx = functions["pose_jacobian_dq"]
    assert Jx["outputs"][0]["name"] == "Jx" and Jx["outputs"][0]["shape"] == [8, model.n]
    assert "vec8(xdot) = Jx qd" in Jx["conventions"]
    J = functions["jacobian_dq"]
    assert J["outputs"][0]["shape"] == [6, model.n] and "(dual-quaternion route)" in J["summary"]


@pytest.mark.parametrize("lang", LANGS)
def test_lwr_matches_dqrobotics(tmp_path_factory, lang):
    """DQ Robotics' standard-DH serial manipulator (its own dual-quaternion DH factors and
    pose Jacobian) gives the same x and Jx, sign included."""
    dqrobotics = pytest.importorskip("dqrobotics")
    from dqrobotics.robot_modeling import DQ_SerialManipulatorDH
    model = model_of("lwr4")
    folder = tmp_path_factory.getbasetemp() / "dqrobotics_lwr4"
    if not (folder / "lwr4" / "functions.json").is_file():
        generate(model, folder, only=FUNCTIONS, progress=False)
    folder = folder / "lwr4"
    a, alpha, d, offset = dh_numbers(model)
    # rows theta, d, a, alpha, joint type (0: revolute)
    robot = DQ_SerialManipulatorDH(np.array([offset, d, a, alpha, np.zeros(model.n)], float))
    Q = random_configurations(model, N, seed=11)
    x = call(folder, lang, "fk_dq", Q)
    Jx = call(folder, lang, "pose_jacobian_dq", Q)
    for k, q in enumerate(Q):
        np.testing.assert_allclose(x[k], dqrobotics.vec8(robot.fkm(q)), rtol=0, atol=1e-12)
        np.testing.assert_allclose(Jx[k], robot.pose_jacobian(q), rtol=0, atol=1e-12)
