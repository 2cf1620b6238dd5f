"""Excitation trajectories (kindyngen.measured.excitation).

Expected values come from outside the module under test: the Fourier series and its
derivatives are re-evaluated here from the brief's formula, derivatives are checked against
finite differences, and the condition number is recomputed from Pinocchio's full torque
regressor reduced to the base parameters with the project's base map."""
import csv
import json
import math

import numpy as np
import pinocchio as pin
import pytest
import yaml

from tests.harness import robot
from tests.reference import pinocchio_model
from kindyngen.measured.excitation import (ExcitationError, ExcitationLimits, FourierTrajectory, default_limits,
                                           optimise_excitation, read_trajectory_json, write_trajectory_csv,
                                           write_trajectory_json)
from kindyngen.measured.regressor_rows import TorqueRegressor
from kindyngen.readers.yaml_description import parse_robot

# A 3-joint arm in the project's schema.  Modified DH with every d = 0: Pinocchio's joint
# frames (tests/reference.py) then coincide with the DH link frames, so its full regressor
# is on the same barycentric parameters as the base map (checked in the test below).
ARM3_YAML = """
name: arm3
dh: modified
gravity: [0, 0, -9.81]
joints:
  - {a: 0,   alpha: 0,    d: 0, lower: -2.5, upper: 2.5}
  - {a: 0,   alpha: pi/2, d: 0, lower: -1.8, upper: 1.8}
  - {a: 0.4, alpha: 0,    d: 0, lower: -2.2, upper: 2.2}
links:
  - {mass: 3.0, com: [0.01, 0.02, -0.05], inertia: [0.02, 0.025, 0.015, 0.001, -0.002, 0.0015]}
  - {mass: 2.0, com: [0.2, 0.01, 0.02],   inertia: [0.004, 0.03, 0.031, 0.0005, 0.001, -0.0007]}
  - {mass: 1.0, com: [0.15, -0.01, 0.015], inertia: [0.002, 0.012, 0.0125, -0.0003, 0.0004, 0.0002]}
"""
ARM3_SETTINGS = dict(harmonics=3, base_frequency_hz=0.2, max_iterations=25, seed=3)


def fourier(a, b, q0, f, t):
    """q, qd, qdd (N, n) of q_i = q0_i + sum_k a_ik/(w k) sin(w k t) - b_ik/(w k) cos(w k t)."""
    a, b, q0, t = (np.asarray(v, float) for v in (a, b, q0, t))
    w = 2 * math.pi * f
    q = np.tile(q0, (len(t), 1))
    qd = np.zeros_like(q)
    qdd = np.zeros_like(q)
    for i in range(a.shape[0]):
        for k in range(1, a.shape[1] + 1):
            wk = w * k
            s, c = np.sin(wk * t), np.cos(wk * t)
            q[:, i] += a[i, k - 1] / wk * s - b[i, k - 1] / wk * c
            qd[:, i] += a[i, k - 1] * c + b[i, k - 1] * s
            qdd[:, i] += -a[i, k - 1] * wk * s + b[i, k - 1] * wk * c
    return q, qd, qdd


def of(trajectory, t):
    return fourier(trajectory.a, trajectory.b, trajectory.q0, trajectory.base_frequency_hz, t)


@pytest.fixture(scope="module")
def arm3():
    return parse_robot(yaml.safe_load(ARM3_YAML), "arm3.yaml")


@pytest.fixture(scope="module")
def arm3_result(arm3):
    return optimise_excitation(arm3, default_limits(arm3), **ARM3_SETTINGS)


# ----------------------------------------------------------------------------- trajectory

def test_evaluate_matches_formula_finite_differences_and_period():
    rng = np.random.default_rng(11)
    n, H, f = 3, 4, 0.3
    traj = FourierTrajectory(f, rng.normal(size=(n, H)), rng.normal(size=(n, H)), rng.normal(size=n))
    assert traj.period == pytest.approx(1 / 0.3, rel=1e-15)
    t = rng.uniform(0, 10, 50)
    q, qd, qdd = traj.evaluate(t)
    assert q.shape == qd.shape == qdd.shape == (50, n)
    for mine, theirs in zip((q, qd, qdd), fourier(traj.a, traj.b, traj.q0, f, t)):
        np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-12)
    h = 1e-5
    (qp, qdp, _), (qm, qdm, _) = traj.evaluate(t + h), traj.evaluate(t - h)
    np.testing.assert_allclose((qp - qm) / (2 * h), qd, rtol=0, atol=1e-7 * np.abs(qd).max())
    np.testing.assert_allclose((qdp - qdm) / (2 * h), qdd, rtol=0, atol=1e-7 * np.abs(qdd).max())
    for now, later in zip(traj.evaluate(t), traj.evaluate(t + traj.period)):
        np.testing.assert_allclose(later, now, rtol=0, atol=1e-11)
    # not trivially periodic with another period
    assert not np.allclose(traj.evaluate(t + 0.5 * traj.period)[0], q)


def test_trajectory_is_immutable():
    traj = FourierTrajectory(0.1, [[1.0, 2.0]], [[0.5, 0.0]], [0.1])
    with pytest.raises(ValueError):
        traj.a[0, 0] = 3.0
    with pytest.raises(AttributeError):
        traj.base_frequency_hz = 1.0


# ----------------------------------------------------------------------------- optimisation

def assert_within_limits(result, model, samples=20000):
    """Independent check on a dense grid, from the coefficients with this file's formula."""
    traj, lim = result.trajectory, result.limits
    q, qd, qdd = of(traj, np.linspace(0, traj.period, samples))
    assert np.all(q >= lim.lower) and np.all(q <= lim.upper)
    assert np.all(q >= model.lower + 0.1 - 1e-12) and np.all(q <= model.upper - 0.1 + 1e-12)  # default margin
    assert np.all(np.abs(qd) <= lim.velocity) and np.all(np.abs(qdd) <= lim.acceleration)
    assert result.feasible
    assert result.max_position_violation == result.max_velocity_violation == result.max_acceleration_violation == 0
    # the excitation uses its limits (not a uselessly small motion): some limit within 15 %
    # (the start is scaled to 90 % of its tightest one)
    use = max((np.abs(qd) / lim.velocity).max(), (np.abs(qdd) / lim.acceleration).max(),
              ((q - lim.lower) / (lim.upper - lim.lower)).max())
    assert use > 0.85


def test_arm3_limits_improvement_and_rest(arm3, arm3_result):
    r = arm3_result
    assert_within_limits(r, arm3)
    assert r.trajectory.a.shape == (3, 3) and r.trajectory.base_frequency_hz == 0.2
    assert 0 < r.iterations <= 25
    # by a factor 4 at least (0.15 here; a wrong gradient still reaches only 0.39)
    assert r.condition_number < 0.25 * r.initial_condition_number
    # starts (and so, periodic, ends) at rest
    _, qd0, qdd0 = of(r.trajectory, [0.0, r.trajectory.period])
    np.testing.assert_allclose(qd0, 0, atol=1e-8)
    np.testing.assert_allclose(qdd0, 0, atol=1e-8)


def test_same_seed_same_result_other_seed_other_result(arm3, arm3_result):
    again = optimise_excitation(arm3, default_limits(arm3), **ARM3_SETTINGS)
    for name in ("a", "b", "q0"):
        assert np.array_equal(getattr(again.trajectory, name), getattr(arm3_result.trajectory, name))
    assert again.condition_number == arm3_result.condition_number
    other = optimise_excitation(arm3, default_limits(arm3), **{**ARM3_SETTINGS, "seed": 4, "max_iterations": 0})
    assert not np.allclose(other.trajectory.a, arm3_result.trajectory.a)
    assert other.iterations == 0 and other.condition_number == other.initial_condition_number


def pinocchio_stacked(model, trajectory, samples, friction, eps=None):
    """Stacked base regressor (+ viscous, Coulomb, offset per joint) from Pinocchio's full one;
    ``eps``: Coulomb column tanh(qd / eps) instead of sign(qd)."""
    pmodel, pdata, _ = pinocchio_model(model)
    t = np.arange(samples) * (trajectory.period / samples)
    Q, QD, QDD = of(trajectory, t)
    Yf = np.vstack([pin.computeJointTorqueRegressor(pmodel, pdata, q, qd, qdd).copy()
                    for q, qd, qdd in zip(Q, QD, QDD)])
    P = TorqueRegressor(model).base_map
    # the full regressor lies in the row space of P (Yf = Yb P), so pinv recovers Yb; this
    # also confirms that Pinocchio's parameters are the DH-frame ones here
    Yb = Yf @ np.linalg.pinv(P)
    np.testing.assert_allclose(Yb @ P, Yf, rtol=0, atol=1e-9 * np.abs(Yf).max())
    if not friction:
        return Yb
    n = model.n
    F = np.zeros((samples * n, 3 * n))
    for s in range(samples):
        for i in range(n):
            F[s * n + i, i] = QD[s, i]
            F[s * n + i, n + i] = np.sign(QD[s, i]) if eps is None else np.tanh(QD[s, i] / eps)
            F[s * n + i, 2 * n + i] = 1.0
    return np.hstack([Yb, F])


def test_condition_number_against_pinocchio(arm3, arm3_result):
    r = arm3_result
    W = pinocchio_stacked(arm3, r.trajectory, r.samples_per_period, friction=True)
    base = len(TorqueRegressor(arm3).names)
    assert W.shape == (r.samples_per_period * 3, base + 9) and len(r.columns) == base + 9
    assert np.linalg.matrix_rank(W) == base + 9
    assert r.condition_number == pytest.approx(np.linalg.cond(W), rel=1e-8)
    # the initial one is the same quantity at the start point (not reported: recompute the
    # start's value through a zero-iteration run, which returns the start itself)
    start = optimise_excitation(arm3, default_limits(arm3), **{**ARM3_SETTINGS, "max_iterations": 0})
    W0 = pinocchio_stacked(arm3, start.trajectory, r.samples_per_period, friction=True)
    assert r.initial_condition_number == pytest.approx(np.linalg.cond(W0), rel=1e-8)
    assert_within_limits(start, arm3)


def test_condition_number_without_friction(arm3):
    r = optimise_excitation(arm3, default_limits(arm3), **{**ARM3_SETTINGS, "friction": False, "max_iterations": 10})
    W = pinocchio_stacked(arm3, r.trajectory, r.samples_per_period, friction=False)
    assert W.shape[1] == len(TorqueRegressor(arm3).names) == len(r.columns)
    assert r.condition_number == pytest.approx(np.linalg.cond(W), rel=1e-8)
    assert r.condition_number < r.initial_condition_number
    assert_within_limits(r, arm3)


def test_coulomb_smoothing_of_the_description_is_used():
    data = yaml.safe_load(ARM3_YAML)
    data["coulomb_smoothing"] = 0.05
    model = parse_robot(data, "arm3_smooth.yaml")
    r = optimise_excitation(model, default_limits(model), **{**ARM3_SETTINGS, "max_iterations": 5})
    assert r.coulomb_smoothing == 0.05
    smooth = pinocchio_stacked(model, r.trajectory, r.samples_per_period, friction=True, eps=0.05)
    assert r.condition_number == pytest.approx(np.linalg.cond(smooth), rel=1e-8)
    sign = pinocchio_stacked(model, r.trajectory, r.samples_per_period, friction=True)
    assert np.linalg.cond(sign) != pytest.approx(r.condition_number, rel=1e-3)
    assert r.condition_number < r.initial_condition_number
    assert_within_limits(r, model)


def test_lwr4_small_run_with_own_limits():
    model = robot("lwr4")
    limits = default_limits(model, velocity=[0.8, 0.8, 1.0, 1.0, 1.2, 1.2, 1.5], acceleration=2.0, margin=0.2)
    lines = []
    r = optimise_excitation(model, limits, harmonics=3, max_iterations=6, progress=lines.append)
    assert_within_limits(r, model)
    q, _, _ = of(r.trajectory, np.linspace(0, r.trajectory.period, 5000))
    assert np.all(q >= model.lower + 0.2) and np.all(q <= model.upper - 0.2)
    assert r.condition_number < r.initial_condition_number
    assert len(r.columns) == 43 + 21
    assert 1 <= r.iterations <= 6 and len(lines) >= r.iterations
    assert all(isinstance(line, str) and "\n" not in line for line in lines)


# ----------------------------------------------------------------------------- files

def test_csv_rows_header_and_values(tmp_path, arm3_result):
    traj = arm3_result.trajectory          # period 5 s
    path = tmp_path / "excitation.csv"
    write_trajectory_csv(path, traj, rate_hz=20, periods=2)
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["t", "q1", "q2", "q3", "qd1", "qd2", "qd3", "qdd1", "qdd2", "qdd3"]
    data = np.array(rows[1:], dtype=float)
    assert data.shape == (2 * 5 * 20 + 1, 10)
    np.testing.assert_allclose(data[:, 0], np.arange(201) / 20, rtol=0, atol=1e-12)
    q, qd, qdd = of(traj, data[:, 0])
    np.testing.assert_allclose(data[:, 1:], np.hstack([q, qd, qdd]), rtol=0, atol=1e-12)
    # ends where it started, at rest
    np.testing.assert_allclose(data[-1, 1:], data[0, 1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(data[0, 4:], 0, atol=1e-8)


def test_json_is_strict_and_complete(tmp_path, arm3_result):
    path = tmp_path / "excitation.json"
    write_trajectory_json(path, arm3_result)

    def refuse(constant):
        raise AssertionError(f"non-JSON constant {constant}")

    doc = json.loads(path.read_text(), parse_constant=refuse)
    traj = arm3_result.trajectory
    assert doc["base_frequency_hz"] == 0.2 and doc["harmonics"] == 3
    assert np.array_equal(np.array(doc["a"]), traj.a) and np.array_equal(np.array(doc["b"]), traj.b)
    assert np.array_equal(np.array(doc["q0"]), traj.q0)
    assert type(doc["condition_number"]) is float and doc["condition_number"] == arm3_result.condition_number
    assert doc["initial_condition_number"] == arm3_result.initial_condition_number
    assert doc["limits"]["velocity"] == [1.0, 1.0, 1.0] and doc["limits"]["margin"] == 0.1
    assert doc["limits"]["upper"] == pytest.approx([2.4, 1.7, 2.1], abs=1e-15)
    back = read_trajectory_json(path)
    assert np.array_equal(back.a, traj.a) and back.base_frequency_hz == traj.base_frequency_hz


# ----------------------------------------------------------------------------- errors

@pytest.mark.parametrize("call, message", [
    (lambda m: optimise_excitation(m, default_limits(m), harmonics=0), "harmonics must be an integer >= 1, got 0"),
    (lambda m: optimise_excitation(m, default_limits(m), base_frequency_hz=0.0), "base_frequency_hz must be a positive"),
    (lambda m: optimise_excitation(m, default_limits(m), base_frequency_hz=-1), "base_frequency_hz must be a positive"),
    (lambda m: optimise_excitation(m, default_limits(m), harmonics=1), "rest_at_start needs harmonics >= 2"),
    (lambda m: default_limits(m, velocity=0.0), "velocity limit of joint 1 must be positive, got 0 rad/s"),
    (lambda m: default_limits(m, acceleration=[3.0, -1.0, 3.0]), "acceleration limit of joint 2 must be positive"),
    (lambda m: default_limits(m, margin=1.9), r"joint 2: empty position range after the margin of 1.9 rad \(lower 0.1 >= upper -0.1"),
    (lambda m: default_limits(m, margin=-0.1), "margin must be a non-negative"),
    (lambda m: ExcitationLimits([0, 0], [1, -1], 1.0, 1.0), "joint 2: empty position range"),
    (lambda m: optimise_excitation(m, ExcitationLimits([0, 0], [1, 1], 1.0, 1.0)), "limits are for 2 joints, the robot 'arm3' has 3"),
    (lambda m: FourierTrajectory(0.0, [[1.0]], [[1.0]], [0.0]), "base_frequency_hz must be a positive"),
    (lambda m: FourierTrajectory(1.0, [[1.0]], [[1.0, 2.0]], [0.0]), r"b: expected shape \(1, 1\)"),
    (lambda m: write_trajectory_csv("unused.csv", FourierTrajectory(1.0, [[1.0]], [[1.0]], [0.0]), rate_hz=0),
     "rate_hz must be a positive"),
])
def test_bad_requests(arm3, call, message):
    assert issubclass(ExcitationError, ValueError)
    with pytest.raises(ExcitationError, match=message) as info:
        call(arm3)
    assert "\n" not in str(info.value)
