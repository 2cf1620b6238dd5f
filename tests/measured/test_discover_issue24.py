"""`discover` on logs a user would record, simulated outside the generator: rigid bodies by
Pinocchio's ``rnea`` on the independent model of ``tests/reference.py``, each hidden effect by
its textbook formula written here, encoder noise 2e-5 rad on the positions (the only motion
logged), torque noise 0.05 N m, 200 Hz multisines; ``discover`` sees only the nominal
description and the log files, through the default preprocessing (5 Hz, parallel filtering).

Each case checks the named set against the hidden set, the held-out RMS of model.yaml against
1.5 x the noise floor on every joint, and the fitted sizes where the effect is identifiable;
the reported noise floor itself is checked against the simulated noise through the filter
(measured here by filtering white noise with scipy, not by the code under test).
"""
from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from scipy.signal import butter, sosfiltfilt

from tests.harness import robot
from kindyngen.measured.discrepancy import DiscrepancyRequest, result_document, run_discrepancy
from tests.reference import pinocchio_model

RATE = 200.0
ENCODER = 2e-5
NOISE = 0.05
FC = np.array([0.6, 0.8, 0.5, 0.5, 0.3, 0.3, 0.2])
FV = np.array([0.8, 1.0, 0.6, 0.7, 0.3, 0.3, 0.2])
F0 = np.array([0.5, -0.7, 0.4, 0.6, -0.3, 0.3, 0.2])
FS, VS = np.array([0.5, 0.6, 0.4, 0.4, 0.3, 0.3, 0.2]), 0.07      # 0.07 rad/s: not on the grid
STIFFNESS = np.array([4000.0, 2000.0, 3000.0, 2500.0, 5000.0, 5000.0, 5000.0])
PAYLOAD = (1.5, np.array([0.01, -0.02, 0.08]), np.diag([0.004, 0.005, 0.003]))


def filtered_noise(level):
    """Std of white noise of std ``level`` after the default 5 Hz zero-phase filter at 200 Hz."""
    sos = butter(4, 5.0, fs=RATE, output="sos")
    x = np.random.default_rng(0).standard_normal(200000)
    return level * float(np.std(sosfiltfilt(sos, x)[1000:-1000]))


def multisine(seconds=30.0, seed=0):
    """Per joint, 4 sines of 0.1-0.5 Hz around a pose away from singularities (rad)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1 / RATE)
    q0 = np.array([0.1, 0.6, -0.2, -1.2, 0.3, 1.0, -0.3])
    amp = rng.uniform(0.15, 0.35, size=(7, 4))
    w = 2 * np.pi * rng.uniform(0.1, 0.5, size=(7, 4))
    phase = rng.uniform(0, 2 * np.pi, size=(7, 4))
    arg = w[None] * t[:, None, None] + phase[None]
    q = q0 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    return t, q, qd, qdd


def write_log(path, name, hidden, seed=0, noise=NOISE, extra=None):
    """An npz log (times, positions, torques) of ``name`` with the ``hidden`` effects."""
    t, q, qd, qdd = multisine(seed=seed)
    model, data, flange = pinocchio_model(robot(name))
    if "payload" in hidden:
        m, c, inertia = PAYLOAD
        model.appendBodyToJoint(model.frames[flange].parentJoint, pin.Inertia(m, c, inertia),
                                model.frames[flange].placement)
        data = model.createData()
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    if "coulomb_friction" in hidden:
        tau += FC * np.sign(qd)
    if "smooth_coulomb" in hidden:
        tau += FC * np.tanh(qd / 0.01)
    if "viscous_friction" in hidden:
        tau += FV * qd
    if "torque_offset" in hidden:
        tau += F0
    if "stribeck_friction" in hidden:
        tau += FS * np.exp(-(qd / VS) ** 2) * np.sign(qd)
    if extra is not None:
        tau += extra(t)
    logged_q = q + tau / STIFFNESS if "motor_side_elasticity" in hidden else q
    rng = np.random.default_rng(seed + 100)
    np.savez(path, times=t, positions=logged_q + ENCODER * rng.standard_normal(q.shape),
             torques=tau + noise * rng.standard_normal(tau.shape))
    return path


def run(tmp_path, name, logs):
    result = run_discrepancy(DiscrepancyRequest(f"robots/{name}.yaml", tuple(logs)))
    return result, json.loads(json.dumps(result_document(result)))


def check(doc, hidden, noise=NOISE):
    detail = f"named {doc['effects']}, notes {doc['notes']}, unexplained {doc['unexplained']}"
    assert set(doc["effects"]) == set(hidden), detail
    assert doc["explained"] is True, detail
    floor = np.array(doc["noise_floor"]["per_joint"])
    np.testing.assert_allclose(floor, filtered_noise(noise), rtol=0.25)
    assert np.all(np.array(doc["rms_after"]) <= 1.5 * floor), (doc["rms_after"], floor, detail)


def values(result, prefix):
    return np.array([result.discovery.values[f"{prefix}{i + 1}"] for i in range(7)])


@pytest.mark.parametrize("name, hidden", [
    ("lwr4", ("coulomb_friction",)),
    ("panda", ("coulomb_friction", "viscous_friction")),
    ("panda", ("smooth_coulomb",)),
    ("lwr4", ("smooth_coulomb", "viscous_friction"))])
def test_coulomb_sharp_and_smoothed_with_and_without_viscous(tmp_path, name, hidden):
    result, doc = run(tmp_path, name, [write_log(tmp_path / "log.npz", name, hidden)])
    named = {"coulomb_friction" if h == "smooth_coulomb" else h for h in hidden}
    check(doc, named)
    np.testing.assert_allclose(values(result, "fc"), FC, rtol=0.1)
    if "viscous_friction" in hidden:
        np.testing.assert_allclose(values(result, "fv"), FV, rtol=0.1)


def test_stribeck_off_the_grid(tmp_path):
    hidden = ("coulomb_friction", "stribeck_friction")
    result, doc = run(tmp_path, "lwr4", [write_log(tmp_path / "log.npz", "lwr4", hidden)])
    detail = f"named {doc['effects']}, notes {doc['notes']}"
    assert set(doc["effects"]) == set(hidden), detail
    assert np.all(np.abs(result.discovery.stribeck_vs - VS) < 0.1 * VS), result.discovery.stribeck_vs
    np.testing.assert_allclose(values(result, "fs"), FS, rtol=0.1)
    np.testing.assert_allclose(values(result, "fc"), FC, rtol=0.1)


def test_panda_payload_with_coulomb_is_written(tmp_path):
    hidden = ("payload", "coulomb_friction")
    result, doc = run(tmp_path, "panda", [write_log(tmp_path / "log.npz", "panda", hidden)])
    check(doc, hidden)
    assert abs(result.discovery.payload_mass - PAYLOAD[0]) < 0.05
    assert load_robot_text(result.model_yaml).payload is not None


def load_robot_text(text):
    import yaml

    from kindyngen.readers.yaml_description import parse_robot
    return parse_robot(yaml.safe_load(text), "model.yaml")


def test_two_recordings_each_from_zero_in_either_order(tmp_path):
    hidden = ("viscous_friction", "torque_offset")
    a = write_log(tmp_path / "a.npz", "lwr4", hidden, seed=1)
    b = write_log(tmp_path / "b.npz", "lwr4", hidden, seed=2)
    first, doc1 = run(tmp_path, "lwr4", [a, b])
    second, doc2 = run(tmp_path, "lwr4", [b, a])
    check(doc1, hidden)
    assert doc1["effects"] == doc2["effects"]
    assert doc1["samples"] == doc2["samples"]
    np.testing.assert_allclose(values(first, "f0"), F0, atol=0.05)


def test_motor_side_elasticity(tmp_path):
    hidden = ("motor_side_elasticity",)
    result, doc = run(tmp_path, "lwr4", [write_log(tmp_path / "log.npz", "lwr4", hidden)])
    check(doc, hidden)
    stiffness = [j.stiffness for j in load_robot_text(result.model_yaml).joints]
    # joints 1-4 carry the arm's weight: their springs are well excited and written
    written = [i for i, k in enumerate(stiffness) if k is not None]
    assert {0, 1, 2, 3} <= set(written), stiffness
    # no silent wrong number: every stiffness written is within 10 % of the hidden one
    for i in written:
        assert abs(float(stiffness[i]) - STIFFNESS[i]) < 0.1 * STIFFNESS[i], (i, stiffness)
    # joint 7 carries ~0.03 N m, below the torque noise: its fitted compliance is the noise's
    # (errors in the spring torque), reported as not determined, and the joint stays rigid
    assert stiffness[6] is None
    assert "ce7" in doc["not_determined"] and "noise" in doc["not_determined"]["ce7"]["reason"], doc["not_determined"]
    assert "ce7" not in doc["coefficients"]
    from kindyngen.measured.discrepancy import write_outputs
    report = (write_outputs(result, tmp_path / "out") / "report.md").read_text()
    assert "- ce7 (fitted" in report and "Not determined by the data" in report


def test_nothing_missing_at_a_torque_noise_of_0_3(tmp_path):
    result, doc = run(tmp_path, "lwr4", [write_log(tmp_path / "log.npz", "lwr4", (), noise=0.3)])
    check(doc, (), noise=0.3)


def test_an_effect_outside_the_library_is_not_explained(tmp_path):
    # a 3 Hz disturbance on joint 2, unrelated to the motion (a vibration of the stand)
    def hum(t):
        out = np.zeros((len(t), 7))
        out[:, 1] = 0.4 * np.sin(2 * np.pi * 3.0 * t)
        return out
    result, doc = run(tmp_path, "lwr4", [write_log(tmp_path / "log.npz", "lwr4", (), extra=hum)])
    assert doc["explained"] is False
    assert any(w.startswith("joint 2") for w in doc["unexplained"]), doc["unexplained"]


def test_identify_takes_two_recordings_each_from_zero(tmp_path):
    from kindyngen.measured.identify import IdentificationRequest, identify
    a = write_log(tmp_path / "a.npz", "lwr4", ("viscous_friction",), seed=1)
    b = write_log(tmp_path / "b.npz", "lwr4", ("viscous_friction",), seed=2)
    result = identify(IdentificationRequest("robots/lwr4.yaml", (a, b), effects=("viscous_friction",), split=0.7))
    # each file's last 30 % validates: 2 x 30 s at 200 Hz, trimmed 0.4 s at each end, each part
    # decimated by 5 on its own (one sample more per part at most)
    assert abs(result.samples_validation + result.samples_train - 2 * (6000 - 2 * 80) / 5) <= 4
    assert abs(result.samples_validation / (result.samples_train + result.samples_validation) - 0.3) < 0.01
    np.testing.assert_allclose(result.effect_values, FV, rtol=0.05)
    assert np.all(result.rms_validation < 1.5 * filtered_noise(NOISE))


def test_identify_fits_the_discovered_elasticity(tmp_path, capsys):
    # a discovered effect can be added to the model and re-identified: `identify --effects
    # motor_side_elasticity` fits the rigid bodies and one stiffness per joint together
    from kindyngen.cli.main import main
    log = write_log(tmp_path / "log.npz", "lwr4", ("motor_side_elasticity",))
    out = tmp_path / "id"
    assert main(["identify", "--robot", "robots/lwr4.yaml", "--data", str(log), "--split", "0.7",
                 "--effects", "motor_side_elasticity", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    doc = json.loads((out / "identification.json").read_text())
    values = dict(zip(doc["effects"]["names"], doc["effects"]["values"]))
    stiffness = [j.stiffness for j in load_robot_text((out / "model.yaml").read_text()).joints]
    for i in (1, 3):       # the joints carrying the arm's weight
        assert abs(1.0 / values[f"ce{i + 1}"] - STIFFNESS[i]) < 0.1 * STIFFNESS[i], values
        assert abs(float(stiffness[i]) - STIFFNESS[i]) < 0.1 * STIFFNESS[i], stiffness
    # joint 7's torque is below the noise: not determined, the joint stays rigid in model.yaml
    assert "ce7" in doc["effects_not_determined"] and stiffness[6] is None, doc["effects_not_determined"]
    assert np.all(np.array(doc["rms_validation"]) < 1.5 * filtered_noise(NOISE)), doc["rms_validation"]


def ur5_log(path, urdf, seed):
    """A UR5 log simulated from its URDF by Pinocchio's own reader (nothing of kindyngen's):
    viscous friction on every joint, a torque offset on joints 2 and 3; 30 s from t = 0."""
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    assert model.nq == 6
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 30.0, 1 / RATE)
    q0 = np.array([0.0, -1.2, 1.2, -1.5, -1.5, 0.0])
    amp = rng.uniform(0.2, 0.4, size=(6, 4))
    w = 2 * np.pi * rng.uniform(0.1, 0.5, size=(6, 4))
    phase = rng.uniform(0, 2 * np.pi, size=(6, 4))
    arg = w[None] * t[:, None, None] + phase[None]
    q = q0 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    tau += UR5_FV * qd + UR5_F0
    noise = np.random.default_rng(seed + 100)
    np.savez(path, times=t, positions=q + ENCODER * noise.standard_normal(q.shape),
             torques=tau + NOISE * noise.standard_normal(tau.shape))
    return path


UR5_FV = np.array([1.0, 1.2, 0.8, 0.4, 0.3, 0.3])
UR5_F0 = np.array([0.0, 0.8, -0.6, 0.0, 0.0, 0.0])


def test_ur5_two_recordings_name_the_same_set_in_either_order(tmp_path):
    # the case: named {viscous} in one file order and {offset} in the other
    from benchmarks.urdf_vs_yaml import example_robot_data
    try:
        urdf = example_robot_data() / "ur_description/urdf/ur5_robot.urdf"
    except Exception as exc:          # PackageNotFoundError without the test extra
        pytest.skip(f"example-robot-data is not installed ({exc})")
    a, b = ur5_log(tmp_path / "a.npz", urdf, 1), ur5_log(tmp_path / "b.npz", urdf, 2)
    docs = []
    for logs in ((a, b), (b, a)):
        result = run_discrepancy(DiscrepancyRequest(str(urdf), logs, tip="tool0"))
        docs.append(json.loads(json.dumps(result_document(result))))
    hidden = {"viscous_friction", "torque_offset"}
    for doc in docs:
        detail = f"named {doc['effects']}, notes {doc['notes']}, indistinguishable {doc['indistinguishable']}"
        assert set(doc["effects"]) == hidden, detail
        assert doc["explained"] is True, detail
        floor = np.array(doc["noise_floor"]["per_joint"])
        assert np.all(np.array(doc["rms_after"]) <= 1.5 * floor), (doc["rms_after"], floor)
        written = doc["coefficients"]
        np.testing.assert_allclose([written[f"fv{i + 1}"] for i in range(6)], UR5_FV, rtol=0.1)
        np.testing.assert_allclose([written[f"f0{i}"] for i in (2, 3)], UR5_F0[1:3], rtol=0.1)
        # the joints without an offset: their fitted ~0 is not a value, so none is written
        assert set(doc["not_determined"]) == {"f01", "f04", "f05", "f06"}, doc["not_determined"]
    assert docs[0]["effects"] == docs[1]["effects"]
    assert docs[0]["coefficients"] == pytest.approx(docs[1]["coefficients"], rel=1e-9, abs=1e-12)


def test_identify_fits_encoder_offsets_where_the_data_separates_them(tmp_path):
    from kindyngen.measured.estimation import RankDeficientError
    from kindyngen.measured.identify import IdentificationRequest, identify
    offsets = np.array([0.0, 0.01, -0.008, 0.012, 0.0, 0.0, 0.0])
    t, q, qd, qdd = multisine()
    model, data, _ = pinocchio_model(robot("lwr4"))
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    rng = np.random.default_rng(7)
    log = tmp_path / "log.npz"
    np.savez(log, times=t, positions=q + offsets + ENCODER * rng.standard_normal(q.shape),
             torques=tau + NOISE * rng.standard_normal(tau.shape))
    # joint 1 turns about gravity and joint 7's offset turns only the last link: neither can be
    # told from the rigid bodies, and plain least squares says so
    with pytest.raises(RankDeficientError, match="encoder offset turns the links"):
        identify(IdentificationRequest("robots/lwr4.yaml", (log,), effects=("encoder_offset",), split=0.7))
    result = identify(IdentificationRequest("robots/lwr4.yaml", (log,), effects=("encoder_offset",), split=0.7,
                                            consistent=True))
    values = dict(zip(result.effect_names, result.effect_values))
    joints = load_robot_text(result.model_yaml).joints
    for i in (1, 2, 3):
        assert abs(values[f"dq{i + 1}"] - offsets[i]) < 0.1 * abs(offsets[i]), values
        assert abs(float(joints[i].encoder_offset) - offsets[i]) < 0.1 * abs(offsets[i])
    for i in (0, 6):
        assert f"dq{i + 1}" in result.undetermined and joints[i].encoder_offset is None, result.undetermined


def test_identify_refuses_to_call_torque_gains_determined(tmp_path):
    # a gain common to every torque sensor is every mass scaled: with the rigid bodies unknown
    # the data fixes no gain, least squares refuses and the semidefinite program writes none
    from kindyngen.measured.estimation import RankDeficientError
    from kindyngen.measured.identify import IdentificationRequest, identify
    gains = np.array([0.0, 0.05, -0.04, 0.06, 0.0, 0.0, 0.0])
    t, q, qd, qdd = multisine()
    model, data, _ = pinocchio_model(robot("lwr4"))
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    rng = np.random.default_rng(8)
    log = tmp_path / "log.npz"
    np.savez(log, times=t, positions=q + ENCODER * rng.standard_normal(q.shape),
             torques=(1 + gains) * tau + NOISE * rng.standard_normal(tau.shape))
    with pytest.raises(RankDeficientError, match="common to every torque sensor"):
        identify(IdentificationRequest("robots/lwr4.yaml", (log,), effects=("torque_sensor_gain",), split=0.7))
    result = identify(IdentificationRequest("robots/lwr4.yaml", (log,), effects=("torque_sensor_gain",), split=0.7,
                                            consistent=True))
    assert set(result.undetermined) == {f"gt{i + 1}" for i in range(7)}, result.undetermined
    assert all(j.torque_gain is None for j in load_robot_text(result.model_yaml).joints)
