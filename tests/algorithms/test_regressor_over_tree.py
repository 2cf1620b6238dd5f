"""The one regressor derivation (kindyngen/algorithms/regressors.py) on an arm, a branched
fixed-base tree and a floating-base tree, checked against Pinocchio: the full torque regressor
times the description's parameter values is Pinocchio's rnea (plus the joint effects by their
textbook formulas), and the number of base parameters is the numeric rank of Pinocchio's own
stacked full regressors (pin.computeJointTorqueRegressor) at random states drawn here."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from kindyngen.algorithms import regressors
from kindyngen.readers.urdf import TWO_PENDULUMS, load_urdf, parse_urdf
from kindyngen.readers.yaml_description import parse_robot
from tests.harness import robot
from tests.reference import pinocchio_model

pin = pytest.importorskip("pinocchio")

URDF = Path(__file__).resolve().parents[1] / "data" / "urdf" / "mobile_slider_tree.urdf"
COUNT = 25
TOLERANCE = 1e-9


def _tree(floating: bool):
    """(our model, Pinocchio's model of the same URDF)."""
    if floating:
        model = load_urdf(URDF, tree=True, floating_base=True)
        return model, pin.buildModelFromUrdf(str(URDF), pin.JointModelFreeFlyer())
    return parse_urdf(TWO_PENDULUMS, tree=True), pin.buildModelFromXML(TWO_PENDULUMS)


def _states(model, seed):
    """q (joints within limits, a free base anywhere within 1 m with a unit quaternion), qd, qdd."""
    rng = np.random.default_rng(seed)
    lower = np.array([max(j.lower, -np.pi) for j in model.joints])
    upper = np.array([min(j.upper, np.pi) for j in model.joints])
    q = rng.uniform(lower, upper, (COUNT, model.n))
    if model.floating_base:
        quat = rng.standard_normal((COUNT, 4))
        q = np.hstack([rng.uniform(-1, 1, (COUNT, 3)), quat / np.linalg.norm(quat, axis=1, keepdims=True), q])
    return q, rng.uniform(-2, 2, (COUNT, model.nv)), rng.uniform(-5, 5, (COUNT, model.nv))


def _pinocchio_q(pmodel, model, q):
    """Our q in Pinocchio's configuration (a continuous joint is (cos, sin))."""
    base = 7 if model.floating_base else 0
    first = 2 if model.floating_base else 1
    assert list(pmodel.names)[first:] == [j.name for j in model.joints]
    out = list(q[:base])
    for j in range(model.n):
        out += [np.cos(q[base + j]), np.sin(q[base + j])] if pmodel.joints[first + j].nq == 2 else [q[base + j]]
    return np.array(out)


def _full_times_values(model, q, qd, qdd):
    A = regressors.evaluate_full(model, "Y", {"q": q, "qd": qd, "qdd": qdd})
    values = np.array([float(v) for v in regressors.full_values(model, "Y")])
    assert A.shape == (COUNT, model.nv, len(values))
    return A, A @ values


def _scaled_error(got, expected):
    return float((np.abs(got - expected).max(axis=1) / np.maximum(1, np.abs(expected).max(axis=1))).max())


def _rank(stacked):
    sv = np.linalg.svd(stacked.reshape(-1, stacked.shape[-1]), compute_uv=False)
    return int(np.sum(sv > 1e-9 * sv[0]))


def _arm_with_effects():
    """The LWR4's DH table with friction, a torque offset and armature on some joints."""
    data = yaml.safe_load((Path(__file__).resolve().parents[2] / "robots" / "lwr4.yaml").read_text())
    data["joints"][1]["friction"] = {"viscous": 0.75, "coulomb": 0.5, "offset": -0.25}
    data["joints"][3]["friction"] = {"viscous": 0.125}
    data["joints"][5]["armature"] = 0.0625
    return parse_robot(data, "lwr4_effects.yaml")


def test_arm_full_regressor_with_effects_equals_pinocchio_rnea():
    model = _arm_with_effects()
    pmodel, data, _ = pinocchio_model(model)
    q, qd, qdd = _states(model, 1)
    A, tau = _full_times_values(model, q, qd, qdd)
    expected = np.array([pin.rnea(pmodel, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    # the effects by their textbook formulas: fv qd + fc sign(qd) + f0, Ia qdd
    expected[:, 1] += 0.75 * qd[:, 1] + 0.5 * np.sign(qd[:, 1]) - 0.25
    expected[:, 3] += 0.125 * qd[:, 3]
    expected[:, 5] += 0.0625 * qdd[:, 5]
    assert _scaled_error(tau, expected) <= TOLERANCE
    names = regressors.full_regressor(model, "Y").p
    assert [str(s) for s in names[70:]] == ["fv1", "fv2", "fv3", "fv4", "fv5", "fv6", "fv7", "fc1", "fc2", "fc3",
                                           "fc4", "fc5", "fc6", "fc7", "f01", "f02", "f03", "f04", "f05", "f06",
                                           "f07", "Ia1", "Ia2", "Ia3", "Ia4", "Ia5", "Ia6", "Ia7"]


@pytest.mark.parametrize("floating", (False, True), ids=("branched", "floating"))
def test_tree_full_regressor_equals_pinocchio_rnea(floating):
    model, pmodel = _tree(floating)
    data = pmodel.createData()
    q, qd, qdd = _states(model, 2)
    _, tau = _full_times_values(model, q, qd, qdd)
    expected = np.array([pin.rnea(pmodel, data, _pinocchio_q(pmodel, model, a), b, c) for a, b, c in zip(q, qd, qdd)])
    assert _scaled_error(tau, expected) <= TOLERANCE


def test_arm_base_parameter_counts_are_pinocchio_ranks():
    """Y's count from the tree recursion and Y_g's, Y_m's from the Lagrange route, each against
    the rank of Pinocchio's regressor of the same quantity (gravity: qd = qdd = 0; the inertia
    stack: gravity off, column j of M at qdd = e_j)."""
    model = robot("lwr4")
    pmodel, data, _ = pinocchio_model(model)
    q, qd, qdd = _states(model, 3)
    zero, n = np.zeros(model.n), model.n
    Yt = np.array([pin.computeJointTorqueRegressor(pmodel, data, a, b, c).copy() for a, b, c in zip(q, qd, qdd)])
    Yg = np.array([pin.computeJointTorqueRegressor(pmodel, data, a, zero, zero).copy() for a in q])
    pmodel.gravity = pin.Motion.Zero()
    data = pmodel.createData()
    Ym = []
    for a in q:
        cols = [pin.computeJointTorqueRegressor(pmodel, data, a, zero, np.eye(n)[j]).copy() for j in range(n)]
        Ym.append([cols[j][i] for i in range(n) for j in range(i + 1)])
    for kind, stacked in (("Y", Yt), ("Y_g", Yg), ("Y_m", np.array(Ym))):
        assert regressors.base_parameters(model, kind).rank == _rank(stacked), kind


@pytest.mark.parametrize("floating", (False, True), ids=("branched", "floating"))
def test_tree_base_parameter_count_is_pinocchio_rank(floating):
    model, pmodel = _tree(floating)
    data = pmodel.createData()
    q, qd, qdd = _states(model, 4)
    stacked = np.array([pin.computeJointTorqueRegressor(pmodel, data, _pinocchio_q(pmodel, model, a), b, c).copy()
                        for a, b, c in zip(q, qd, qdd)])
    b = regressors.base_parameters(model, "Y")
    assert b.rank == len(b.base) == _rank(stacked) < len(b.full_names)
    # and the base columns of our full regressor have that rank at these states too
    A, _ = _full_times_values(model, q, qd, qdd)
    assert _rank(A[:, :, list(b.base)]) == b.rank


def test_a_tree_has_only_the_torque_regressor():
    model, _ = _tree(True)
    assert regressors.kinds(model) == ("Y",)
    with pytest.raises(ValueError, match="kind must be one of"):
        regressors.full_regressor(model, "Y_g")
    assert list(regressors.base_params_document(model)) == ["Y"]
