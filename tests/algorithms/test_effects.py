"""Joint effects and a payload in the robot description reach every generated function they
touch, in C, Python and CasADi: checked against Pinocchio (rigid bodies, the payload appended
as a body of its own) plus the effect formulas written out here."""
from __future__ import annotations

import copy
import json

import numpy as np
import pinocchio as pin
import pytest
import yaml

from tests.harness import ROOT
from kindyngen.runtime.evaluate import load_generated
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.codegen.pipeline import generate
from kindyngen.model.robot_model import RobotDescriptionError
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

FRICTION = [(0.8, 1.2, 0.1), (0.7, 1.1, -0.2), (0.5, 0.9, 0.0), (0.5, 0.8, 0.05), (0.3, 0.5, 0.0), (0.0, 0.4, 0.0),
            None]
ARMATURE = [0.3, 0.3, 0.2, 0.2, 0.1, 0.1, 0.05]
PAYLOAD = {"mass": 0.25, "com": [0.01, -0.02, 0.05], "inertia": [0.0002, 0.0003, 0.0001, 0, 0, 0]}


def _description(smoothing=None) -> dict:
    data = yaml.safe_load((ROOT / "robots" / "lwr4.yaml").read_text())
    data["name"] = "lwr4_effects" if smoothing is None else "lwr4_smooth"
    for joint, friction, armature in zip(data["joints"], FRICTION, ARMATURE):
        if friction is not None:
            joint["friction"] = dict(zip(("viscous", "coulomb", "offset"), friction))
        joint["armature"] = armature
    data["payload"] = copy.deepcopy(PAYLOAD)
    if smoothing is not None:
        data["coulomb_smoothing"] = smoothing
    return data


def _effects(qd, qdd, smoothing=None):
    """fv qd + fc sign(qd) (or tanh(qd / eps)) + f0 + Ia qdd, from the tables above."""
    fv, fc, f0 = (np.array([f[k] if f else 0.0 for f in FRICTION]) for k in range(3))
    shape = np.sign(qd) if smoothing is None else np.tanh(qd / smoothing)
    return fv * qd + fc * shape + f0 + np.array(ARMATURE) * qdd


def _pinocchio(robot):
    """Pinocchio model of the rigid bodies with the payload as a body fixed to the flange."""
    model, data, flange = pinocchio_model(robot)
    joint = model.frames[flange].parentJoint
    placement = model.frames[flange].placement
    body = pin.Inertia(PAYLOAD["mass"], np.array(PAYLOAD["com"]), np.diag(PAYLOAD["inertia"][:3]))
    model.appendBodyToJoint(joint, placement.act(body), pin.SE3.Identity())
    return model, model.createData()


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    root = tmp_path_factory.mktemp("effects")
    path = root / "lwr4_effects.yaml"
    path.write_text(yaml.safe_dump(_description(), sort_keys=False))
    robot = load_robot(path)
    out = generate(robot, root / "out", progress=False)
    return robot, out


def _states(robot, count=25, seed=4):
    rng = np.random.default_rng(seed)
    q = rng.uniform(robot.lower, robot.upper, size=(count, robot.n))
    qd, qdd = rng.normal(size=(2, count, robot.n)) * 1.5
    qd[0, 3] = 0.0    # sign(0) = 0: no Coulomb torque at rest
    return q, qd, qdd


@pytest.mark.parametrize("lang", ["python", "c", "casadi"])
def test_tau_M_fd_g_c_with_effects(generated, lang):
    robot, out = generated
    lib = load_generated(out, lang)
    model, data = _pinocchio(robot)
    q, qd, qdd = _states(robot)
    tau = lib.call("tau", {"q": q, "qd": qd, "qdd": qdd})["tau"]
    M = lib.call("M", {"q": q})["M"]
    g = lib.call("g", {"q": q})["g"]
    c = lib.call("c", {"q": q, "qd": qd})["c"]
    applied = np.random.default_rng(9).normal(size=q.shape) * 20
    fd = lib.call("fd", {"q": q, "qd": qd, "tau": applied})["qdd"]
    for k in range(len(q)):
        rigid = pin.rnea(model, data, q[k], qd[k], qdd[k])
        np.testing.assert_allclose(tau[k], rigid + _effects(qd[k], qdd[k]), atol=1e-10)
        Mk = pin.crba(model, data, q[k])
        Mk = np.triu(Mk) + np.triu(Mk, 1).T
        np.testing.assert_allclose(M[k], Mk + np.diag(ARMATURE), atol=1e-10)
        gk = pin.computeGeneralizedGravity(model, data, q[k])
        np.testing.assert_allclose(g[k], gk, atol=1e-10)                     # payload included
        np.testing.assert_allclose(c[k], pin.nonLinearEffects(model, data, q[k], qd[k]) - gk, atol=1e-10)
        bias = pin.nonLinearEffects(model, data, q[k], qd[k]) + _effects(qd[k], np.zeros(robot.n))
        np.testing.assert_allclose(fd[k], np.linalg.solve(Mk + np.diag(ARMATURE), applied[k] - bias), atol=1e-9)


def test_regressors_gain_the_effect_columns(generated):
    robot, out = generated
    lib = load_generated(out, "python")
    document = json.loads((out / "base_params.json").read_text())
    model, data = _pinocchio(robot)
    q, qd, qdd = _states(robot)
    Y = lib.call("Y", {"q": q, "qd": qd, "qdd": qdd})["Y"]
    Ym = lib.call("Y_m", {"q": q})["Y"]
    names = document["Y"]["names"]
    # friction and offset of every joint are columns of their own; the armature of joints 1
    # and 2 coincides with link inertia (their columns are qdd_1 and, grouped, qdd_2 terms)
    for name in [f"{e}{i}" for e in ("fv", "fc", "f0") for i in range(1, 8)] + [f"Ia{i}" for i in range(3, 8)]:
        assert name in names
    assert "Ia1" not in names and any("Ia1" in e for e in document["Y"]["expressions"])
    for k in range(len(q)):
        expected = pin.rnea(model, data, q[k], qd[k], qdd[k]) + _effects(qd[k], qdd[k])
        np.testing.assert_allclose(Y[k] @ document["Y"]["values"], expected, atol=1e-9)
        Mk = pin.crba(model, data, q[k])
        Mk = np.triu(Mk) + np.triu(Mk, 1).T + np.diag(ARMATURE)
        stack = [Mk[i, j] for i in range(robot.n) for j in range(i + 1)]
        np.testing.assert_allclose(Ym[k] @ document["Y_m"]["values"], stack, atol=1e-10)


def test_symbolic_parameters_equal_numeric_with_effects_and_payload(generated, tmp_path):
    robot, _ = generated
    out = generate(robot, tmp_path, languages=("python",), params="symbolic", progress=False)
    lib = load_generated(out, "python")
    q, qd, qdd = _states(robot, count=5)
    p = np.tile(parameter_vector(robot), (len(q), 1))     # payload merged into the last link
    model, data = _pinocchio(robot)
    tau = lib.call("tau", {"q": q, "qd": qd, "qdd": qdd, "p": p})["tau"]
    for k in range(len(q)):
        np.testing.assert_allclose(tau[k], pin.rnea(model, data, q[k], qd[k], qdd[k]) + _effects(qd[k], qdd[k]),
                                   atol=1e-10)


def test_smooth_coulomb_variant(tmp_path):
    path = tmp_path / "smooth.yaml"
    path.write_text(yaml.safe_dump(_description(smoothing=0.05), sort_keys=False))
    robot = load_robot(path)
    out = generate(robot, tmp_path / "out", languages=("python", "c"), progress=False)
    model, data = _pinocchio(robot)
    q, qd, qdd = _states(robot, count=8)
    for lang in ("python", "c"):
        tau = load_generated(out, lang).call("tau", {"q": q, "qd": qd, "qdd": qdd})["tau"]
        for k in range(len(q)):
            np.testing.assert_allclose(tau[k], pin.rnea(model, data, q[k], qd[k], qdd[k])
                                       + _effects(qd[k], qdd[k], smoothing=0.05), atol=1e-10)
    header = (out / "c" / "lwr4_smooth.h").read_text()
    assert "tanh(qd / 0.05)" in header


def _expect_error(tmp_path, data, field, reason):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(RobotDescriptionError, match=reason) as info:
        load_robot(path)
    assert info.value.field == field


def test_effect_fields_are_validated(tmp_path):
    data = _description()
    data["joints"][0]["friction"]["viscus"] = 0.1
    _expect_error(tmp_path, data, "joints[0].friction.viscus", "did you mean 'viscous'")
    data = _description()
    data["joints"][1]["friction"]["coulomb"] = -0.5
    _expect_error(tmp_path, data, "joints[1].friction.coulomb", "must be non-negative")
    data = _description()
    data["joints"][2]["armature"] = -0.1
    _expect_error(tmp_path, data, "joints[2].armature", "must be non-negative")
    data = _description()
    data["payload"]["inertia"] = [0.001, 0.001, 0.01, 0, 0, 0]
    _expect_error(tmp_path, data, "payload.inertia", "triangle inequality")
    data = _description(smoothing=0)
    _expect_error(tmp_path, data, "coulomb_smoothing", "must be a positive velocity")
    data = _description()
    data["payload"]["mas"] = 1
    _expect_error(tmp_path, data, "payload.mas", "did you mean 'mass'")


def test_a_point_mass_payload_is_accepted(tmp_path):
    data = _description()
    data["payload"] = {"mass": 0.25, "com": [0, 0, 0.1], "inertia": [0, 0, 0, 0, 0, 0]}
    path = tmp_path / "point.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    assert float(load_robot(path).payload.mass) == 0.25
