"""The description's Stribeck friction, position ripple and load-dependent friction reach the
generated tau, fd, M, Y and the derivatives (Python and C): checked against Pinocchio (rigid
bodies, its own RNEA derivatives) plus the textbook laws written out here in numpy, and the
forward dynamics against a numeric solve of tau(q, qd, qdd) = applied (no closed form taken
from the code under test)."""
from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
import yaml

from tests.harness import ROOT
from kindyngen.codegen.pipeline import generate
from kindyngen.model.robot_model import RobotDescriptionError
from kindyngen.readers.yaml_description import load_robot
from kindyngen.runtime.evaluate import load_generated
from tests.reference import pinocchio_model

FV = np.array([0.8, 0.7, 0.5, 0.5, 0.3, 0.0, 0.0])
FC = np.array([1.2, 1.1, 0.9, 0.8, 0.5, 0.4, 0.0])
F0 = np.array([0.1, -0.2, 0.0, 0.05, 0.0, 0.0, 0.0])
FS = np.array([0.5, 0.6, 0.0, 0.4, 0.3, 0.2, 0.0])
VS = np.array([0.07, 0.05, 0.1, 0.2, 0.1, 0.1, 0.1])
FL = np.array([0.05, 0.08, 0.0, 0.03, 0.02, 0.0, 0.0])
RS = np.array([0.3, 0.0, 0.2, 0.1, 0.0, 0.05, 0.0])
RC = np.array([0.1, 0.2, 0.0, 0.1, 0.0, 0.02, 0.0])
ORDER = np.array([6, 11, 3, 6, 1, 9, 1])
IA = np.array([0.3, 0.3, 0.2, 0.2, 0.1, 0.1, 0.05])


def description(smoothing=None) -> dict:
    data = yaml.safe_load((ROOT / "robots" / "lwr4.yaml").read_text())
    data["name"] = "lwr4_laws" if smoothing is None else "lwr4_laws_smooth"
    for i, joint in enumerate(data["joints"]):
        joint["friction"] = {"viscous": float(FV[i]), "coulomb": float(FC[i]), "offset": float(F0[i]),
                             "stribeck": float(FS[i]), "stribeck_velocity": float(VS[i]), "load": float(FL[i])}
        joint["armature"] = float(IA[i])
        if RS[i] or RC[i]:
            joint["ripple"] = {"sin": float(RS[i]), "cos": float(RC[i]), "order": int(ORDER[i])}
    if smoothing is not None:
        data["coulomb_smoothing"] = smoothing
    return data


def shape(qd, smoothing):
    return np.sign(qd) if smoothing is None else np.tanh(qd / smoothing)


def law(q, qd, qdd, rigid, smoothing=None):
    """tau = y + fl |y| s + fv qd + fc s + fs exp(-(qd/vs)^2) s + rs sin(k q) + rc cos(k q) + f0,
    y = rigid + Ia qdd: the textbook laws, written out here."""
    s = shape(qd, smoothing)
    y = rigid + IA * qdd
    ripple = np.where(ORDER > 0, RS * np.sin(ORDER * q) + RC * np.cos(ORDER * q), 0.0)
    mask = np.array([bool(RS[i] or RC[i]) for i in range(7)])
    return y + FL * np.abs(y) * s + FV * qd + FC * s + FS * np.exp(-(qd / VS) ** 2) * s + np.where(mask, ripple, 0) + F0


def reference_tau(model, data, q, qd, qdd, smoothing=None):
    return law(q, qd, qdd, pin.rnea(model, data, q, qd, qdd), smoothing)


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    root = tmp_path_factory.mktemp("laws")
    path = root / "lwr4_laws.yaml"
    path.write_text(yaml.safe_dump(description(), sort_keys=False))
    robot = load_robot(path)
    out = generate(robot, root / "out", languages=("python", "c"), progress=False,
                   only={"tau", "fd", "M", "Y", "tau_derivatives", "fd_derivatives"})
    return robot, out


def states(robot, count=12, seed=4):
    rng = np.random.default_rng(seed)
    q = rng.uniform(robot.lower, robot.upper, size=(count, robot.n))
    qd, qdd = rng.normal(size=(2, count, robot.n)) * 0.8
    qd[0, 3] = 0.0    # sign(0) = 0: no Coulomb, Stribeck or load-dependent friction at rest
    qd[1, 1] = 0.03   # slower than the Stribeck velocity: the static friction acts
    return q, qd, qdd


def test_the_description_declares_the_laws(generated):
    robot, _ = generated
    assert robot.effects == ("viscous_friction", "coulomb_friction", "torque_offset", "armature",
                             "stribeck_friction", "position_ripple", "load_dependent_friction")
    assert robot.joints[1].ripple.order == 11 and float(robot.joints[0].friction.stribeck_velocity) == 0.07


@pytest.mark.parametrize("lang", ["python", "c"])
def test_tau_fd_M_against_pinocchio_and_the_laws(generated, lang):
    robot, out = generated
    lib = load_generated(out, lang)
    model, data, _ = pinocchio_model(robot)
    q, qd, qdd = states(robot)
    tau = lib.call("tau", {"q": q, "qd": qd, "qdd": qdd})["tau"]
    M = lib.call("M", {"q": q})["M"]
    for k in range(len(q)):
        np.testing.assert_allclose(tau[k], reference_tau(model, data, q[k], qd[k], qdd[k]), atol=1e-10)
        Mk = pin.crba(model, data, q[k])
        np.testing.assert_allclose(M[k], np.triu(Mk) + np.triu(Mk, 1).T + np.diag(IA), atol=1e-10)
    # fd inverts tau: the generated qdd put back into the reference tau gives the applied torque
    applied = np.random.default_rng(9).normal(size=q.shape) * 20
    fd = lib.call("fd", {"q": q, "qd": qd, "tau": applied})["qdd"]
    for k in range(len(q)):
        np.testing.assert_allclose(reference_tau(model, data, q[k], qd[k], fd[k]), applied[k], atol=1e-9)


def test_regressor_times_the_values_is_tau(generated):
    robot, out = generated
    lib = load_generated(out, "python")
    document = json.loads((out / "base_params.json").read_text())
    names = document["Y"]["names"]
    for prefix in ("fs", "rs", "rc", "fl"):
        assert f"{prefix}4" in names, names
    model, data, _ = pinocchio_model(robot)
    q, qd, qdd = states(robot)
    Y = lib.call("Y", {"q": q, "qd": qd, "qdd": qdd})["Y"]
    for k in range(len(q)):
        np.testing.assert_allclose(Y[k] @ document["Y"]["values"], reference_tau(model, data, q[k], qd[k], qdd[k]),
                                   atol=1e-9)


def _law_derivatives(robot, q, qd, qdd, smoothing=None, h=1e-6):
    """dtau/dq, dtau/dqd of the reference: Pinocchio's analytical RNEA derivatives for the
    rigid part, chained through the laws by central differences in y, q_i and qd_i."""
    model, data, _ = pinocchio_model(robot)
    dq, dv, _ = pin.computeRNEADerivatives(model, data, q, qd, qdd)
    rigid = pin.rnea(model, data, q, qd, qdd)
    # the law as a function of (y_i, q_i, qd_i) per joint; rigid depends on q, qd
    def per_joint(y, qq, vv):
        return law(qq, vv, np.zeros(7), y - 0 * vv, smoothing)
    y = rigid + IA * qdd
    dtau_dy = (per_joint(y + h, q, qd) - per_joint(y - h, q, qd)) / (2 * h)
    dtau_dq_own = (per_joint(y, q + h, qd) - per_joint(y, q - h, qd)) / (2 * h)
    dtau_dqd_own = (per_joint(y, q, qd + h) - per_joint(y, q, qd - h)) / (2 * h)
    return dtau_dy[:, None] * dq + np.diag(dtau_dq_own), dtau_dy[:, None] * dv + np.diag(dtau_dqd_own)


def test_derivatives_against_pinocchio_and_the_laws(generated):
    robot, out = generated
    lib = load_generated(out, "c")
    q, qd, qdd = states(robot)
    qd[np.abs(qd) < 1e-3] = 0.2     # keep clear of the sign's jump for the differences
    d = lib.call("tau_derivatives", {"q": q, "qd": qd, "qdd": qdd})
    model, data, _ = pinocchio_model(robot)
    for k in range(len(q)):
        expected_q, expected_qd = _law_derivatives(robot, q[k], qd[k], qdd[k])
        np.testing.assert_allclose(d["dtau_dq"][k], expected_q, atol=1e-6)
        np.testing.assert_allclose(d["dtau_dqd"][k], expected_qd, atol=1e-6)
    # fd's: dqdd/dx = -(dtau/dqdd)^-1 dtau/dx at qdd = fd (implicit function theorem on the reference)
    applied = np.random.default_rng(3).normal(size=q.shape) * 20
    f = lib.call("fd_derivatives", {"q": q, "qd": qd, "tau": applied})
    qdd = lib.call("fd", {"q": q, "qd": qd, "tau": applied})["qdd"]
    h = 1e-6
    for k in range(len(q)):
        def tau_of(a):
            return reference_tau(model, data, q[k], qd[k], a)
        dtau_dqdd = np.stack([(tau_of(qdd[k] + h * e) - tau_of(qdd[k] - h * e)) / (2 * h) for e in np.eye(7)], axis=1)
        expected_q, expected_qd = _law_derivatives(robot, q[k], qd[k], qdd[k])
        np.testing.assert_allclose(f["dqdd_dq"][k], -np.linalg.solve(dtau_dqdd, expected_q), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(f["dqdd_dqd"][k], -np.linalg.solve(dtau_dqdd, expected_qd), rtol=1e-5, atol=1e-5)


def test_smooth_variant_tau_and_fd(tmp_path):
    path = tmp_path / "smooth.yaml"
    path.write_text(yaml.safe_dump(description(smoothing=0.05), sort_keys=False))
    robot = load_robot(path)
    out = generate(robot, tmp_path / "out", languages=("python",), progress=False,
                   only={"tau", "fd", "tau_derivatives"})
    lib = load_generated(out, "python")
    model, data, _ = pinocchio_model(robot)
    q, qd, qdd = states(robot, count=6)
    tau = lib.call("tau", {"q": q, "qd": qd, "qdd": qdd})["tau"]
    applied = np.random.default_rng(2).normal(size=q.shape) * 20
    fd = lib.call("fd", {"q": q, "qd": qd, "tau": applied})["qdd"]
    d = lib.call("tau_derivatives", {"q": q, "qd": qd, "qdd": qdd})
    for k in range(len(q)):
        np.testing.assert_allclose(tau[k], reference_tau(model, data, q[k], qd[k], qdd[k], 0.05), atol=1e-10)
        np.testing.assert_allclose(reference_tau(model, data, q[k], qd[k], fd[k], 0.05), applied[k], atol=1e-9)
        expected_q, expected_qd = _law_derivatives(robot, q[k], qd[k], qdd[k], 0.05)
        np.testing.assert_allclose(d["dtau_dq"][k], expected_q, atol=1e-6)
        np.testing.assert_allclose(d["dtau_dqd"][k], expected_qd, atol=1e-5)


@pytest.mark.parametrize("change, field, reason", [
    (lambda j: j["friction"].pop("stribeck_velocity"), "joints[0].friction.stribeck_velocity", "required with"),
    (lambda j: j["friction"].update(stribeck_velocity=0), "joints[0].friction.stribeck_velocity", "positive"),
    (lambda j: j["friction"].update(load=1.0), "joints[0].friction.load", "below 1"),
    (lambda j: j["ripple"].update(order=2.5), "joints[0].ripple.order", "positive whole number"),
    (lambda j: j["ripple"].pop("order"), "joints[0].ripple.order", "missing"),
    (lambda j: j["ripple"].update(phase=1), "joints[0].ripple.phase", "unknown key"),
])
def test_the_new_keys_are_checked(tmp_path, change, field, reason):
    data = description()
    change(data["joints"][0])
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(RobotDescriptionError, match=reason) as info:
        load_robot(path)
    assert info.value.field == field


def test_written_back_and_read_again_the_same(tmp_path):
    # the writer of joints by origin and axis (a modified DH table: its link frames sit on the joints)
    from kindyngen.readers.yaml_writer import describe
    data = yaml.safe_load((ROOT / "robots" / "panda.yaml").read_text())
    laws = description()
    for joint, other in zip(data["joints"], laws["joints"]):
        joint.update({k: other[k] for k in ("friction", "armature", "ripple") if k in other})
    path = tmp_path / "panda_laws.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    robot = load_robot(path)
    again = tmp_path / "again.yaml"
    again.write_text(yaml.safe_dump(describe(robot), sort_keys=False))
    other = load_robot(again)
    assert robot.effects == other.effects and "position_ripple" in other.effects
    assert [j.friction for j in other.joints] == [j.friction for j in robot.joints]
    assert [j.ripple for j in other.joints] == [j.ripple for j in robot.joints]
