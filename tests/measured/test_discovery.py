"""Effect discovery (kindyngen.measured.discovery) on data simulated by Pinocchio.

The simulator shares no code with the code under test: torques come from ``pin.rnea`` on the
independent Pinocchio model of ``tests/reference.py``; each hidden effect is added by its own
formula written here (a payload is a body appended to Pinocchio's last joint at the flange, a
tilted base is a tilted ``model.gravity``); ``discover`` sees only the nominal description.

Matrix (kept small for time; 20 s at 200 Hz per log, analytic qd and qdd, Gaussian noise on
the torques only): every library effect alone at noise 0.02 N m on a multisine; payload,
base tilt, offset and Coulomb friction alone at 0.1 N m on slow point-to-point moves; six
pairs at 0.1 N m; no effect at 0, 0.02 and 0.1 N m; one effect on clean data; a tilted base
on a slow, small motion around one pose (offsets fit it as well there, with more coefficients:
the tilt is named).
"""
from __future__ import annotations


import numpy as np
import pinocchio as pin
import pytest

from tests.harness import robot
from tests.reference import pinocchio_model

from kindyngen.measured.discovery import CANDIDATES, discover, effective_samples, noise_floor
from kindyngen.measured.log_preparing import Segment

RATE = 200.0
NOMINAL = robot("lwr4")
# effects on what is measured rather than joint torques: simulated in tests/measured/test_discover_issue24.py
MEASUREMENT_EFFECTS = ("motor_side_elasticity", "encoder_offset", "torque_sensor_gain")


# ---------------------------------------------------------------------------------------------
# motions, written here with analytic derivatives

def multisine(duration=20.0, seed=0):
    """Sum of 5 harmonics of 0.1 Hz per joint around a pose away from singularities."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1 / RATE)
    n = 7
    q0 = np.array([0.2, 0.5, -0.3, -1.0, 0.4, 0.6, -0.2])
    w = 2 * np.pi * 0.1 * np.arange(1, 6)
    amp = rng.uniform(0.08, 0.2, size=(n, 5))
    phase = rng.uniform(0, 2 * np.pi, size=(n, 5))
    arg = t[:, None, None] * w[None, None, :] + phase[None]
    q = q0 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    return t, q, qd, qdd


def near_pose(duration=20.0):
    """A slow, small motion (0.01 rad, 0.1-0.2 Hz) around one pose: gravity torques barely
    change, so an offset, a tilted base and a payload all look like a constant torque."""
    t = np.arange(0.0, duration, 1 / RATE)
    q0 = np.array([0.2, 0.5, -0.3, -1.0, 0.4, 0.6, -0.2])
    f = 0.1 + 0.015 * np.arange(7)
    a = 0.01
    w = 2 * np.pi * f
    q = q0 + a * np.sin(w * t[:, None])
    return t, q, a * w * np.cos(w * t[:, None]), -a * w ** 2 * np.sin(w * t[:, None])


def point_to_point(duration=20.0):
    """Slow quintic moves (2.5 s each, 0.5 s rest) between poses far apart: large changes of
    the gravity torques, small velocities and accelerations, the joints at rest in between."""
    poses = np.array([[0.2, 0.5, -0.3, -1.0, 0.4, 0.6, -0.2],
                      [-0.8, 1.1, 0.5, -0.4, -0.9, -0.5, 1.0],
                      [0.9, -0.3, -0.9, -1.5, 1.2, 1.0, -1.1],
                      [0.0, 0.9, 0.8, 0.6, 0.0, -1.2, 0.5]])
    move, rest = 2.5, 0.5
    t = np.arange(0.0, duration, 1 / RATE)
    k = (t // (move + rest)).astype(int)
    tau = np.clip((t - k * (move + rest)) / move, 0, 1)
    start, goal = poses[k % len(poses)], poses[(k + 1) % len(poses)]
    s = 10 * tau ** 3 - 15 * tau ** 4 + 6 * tau ** 5
    sd = (30 * tau ** 2 - 60 * tau ** 3 + 30 * tau ** 4) / move
    sdd = (60 * tau - 180 * tau ** 2 + 120 * tau ** 3) / move ** 2
    delta = goal - start
    return t, start + s[:, None] * delta, sd[:, None] * delta, sdd[:, None] * delta


# ---------------------------------------------------------------------------------------------
# hidden effects, each with its own formula

FV = np.array([0.8, 1.0, 0.6, 0.7, 0.3, 0.3, 0.2])
FC = np.array([0.6, 0.8, 0.5, 0.5, 0.3, 0.3, 0.2])
F0 = np.array([0.5, -0.7, 0.4, 0.6, -0.3, 0.3, 0.2])
IA = np.array([0.3, 0.3, 0.2, 0.2, 0.1, 0.1, 0.05])
FS, VS = np.array([0.6, 0.8, 0.5, 0.5, 0.3, 0.3, 0.2]), 0.05
RS, RC, K = np.array([0.3, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1]), np.array([0.1, 0.2, 0.1, 0.1, 0.1, 0.05, 0.05]), 6.0
FL = np.array([0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05])
PAYLOAD = (1.5, np.array([0.01, -0.02, 0.08]), np.diag([0.004, 0.005, 0.003]))
TILT_DEG = (1.5, -1.0)          # about base x, about base y


def simulate(motion, hidden=(), noise=0.0, seed=1):
    t, q, qd, qdd = motion
    model, data, flange = pinocchio_model(NOMINAL)
    if "payload" in hidden:
        m, c, inertia = PAYLOAD
        model.appendBodyToJoint(model.frames[flange].parentJoint, pin.Inertia(m, c, inertia),
                                model.frames[flange].placement)
    if "base_tilt" in hidden:
        rx, ry = np.radians(TILT_DEG)
        Rx = pin.utils.rotate("x", rx)
        Ry = pin.utils.rotate("y", ry)
        model.gravity = pin.Motion((Rx @ Ry).T @ np.array([0, 0, -9.81]), np.zeros(3))
    data = model.createData()
    tau = np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]) for k in range(len(t))])
    nominal_model, nominal_data, _ = pinocchio_model(NOMINAL)
    tau_rigid = np.array([pin.rnea(nominal_model, nominal_data, q[k], qd[k], qdd[k]) for k in range(len(t))])
    if "viscous_friction" in hidden:
        tau += FV * qd
    if "coulomb_friction" in hidden:
        tau += FC * np.sign(qd)
    if "torque_offset" in hidden:
        tau += F0
    if "armature" in hidden:
        tau += IA * qdd
    if "stribeck_friction" in hidden:
        tau += FS * np.exp(-(qd / VS) ** 2) * np.sign(qd)
    if "position_ripple" in hidden:
        tau += RS * np.sin(K * q) + RC * np.cos(K * q)
    if "load_dependent_friction" in hidden:
        tau += FL * np.abs(tau_rigid) * np.sign(qd)
    tau = tau + noise * np.random.default_rng(seed).standard_normal(tau.shape)
    return (Segment("sim", t, 1 / RATE, q, qd, qdd, tau),)


_MOTIONS = {}


def motion(name):
    if name not in _MOTIONS:
        _MOTIONS[name] = {"multisine": multisine, "near_pose": near_pose, "point_to_point": point_to_point}[name]()
    return _MOTIONS[name]


def check_named(hidden, noise, kind="multisine"):
    segments = simulate(motion(kind), hidden, noise)
    d = discover(NOMINAL, segments)
    detail = f"effects {d.effects}, groups {d.indistinguishable}, notes {d.notes}"
    assert set(d.effects) == set(hidden), detail
    assert d.indistinguishable == (), detail
    level = max(noise, 1e-6)
    assert np.all(d.rms_after <= 1.5 * level), (d.rms_after, detail)
    return d


# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("noise, kind", [(0.0, "multisine"), (0.02, "multisine"), (0.1, "multisine"),
                                         (0.1, "point_to_point")])
def test_nothing_missing_names_nothing(noise, kind):
    d = discover(NOMINAL, simulate(motion(kind), (), noise))
    assert d.effects == () and d.fitted == () and d.steps == ()
    assert np.all(d.rms_after <= 1.5 * max(noise, 1e-9))


@pytest.mark.parametrize("noise", [0.0, 0.02, 0.1])
@pytest.mark.parametrize("effect", [c for c in CANDIDATES if c not in MEASUREMENT_EFFECTS + ("rigid_bodies",)])
def test_each_effect_alone_is_named(effect, noise):
    d = check_named((effect,), noise)
    step = d.steps[0]
    # joints the effect barely touches may gain nothing; the total must fall.  The first step may
    # be a larger candidate that holds the effect (the rigid bodies hold a payload): the smallest
    # set then replaces it (its fit is as good with fewer coefficients)
    assert step.effect in (effect, "rigid_bodies") and np.sum(step.rms_after ** 2) < np.sum(step.rms_before ** 2)
    assert np.all(step.rms_after <= 1.05 * step.rms_before)
    if effect == "viscous_friction":
        assert np.allclose([d.values[f"fv{i + 1}"] for i in range(7)], FV, atol=0.02)
    if effect == "torque_offset":
        assert np.allclose([d.values[f"f0{i + 1}"] for i in range(7)], F0, atol=0.02)
    if effect == "base_tilt":
        roll, pitch, _ = d.tilt_deg
        assert abs(roll - TILT_DEG[0]) < 0.05 and abs(pitch - TILT_DEG[1]) < 0.05, d.tilt_deg
        # a tilt turns gravity; its magnitude stays the description's (a free gravity vector once
        # let the magnitude stand in for a gain or a payload: 8.95 m/s^2 on the real LWR4+ log)
        assert abs(np.linalg.norm(d.gravity) / 9.81 - 1) < 1e-12, d.gravity
        assert abs(np.linalg.norm([float(g) for g in d.model.gravity]) / 9.81 - 1) < 1e-12, d.model.gravity
    if effect == "payload":
        assert d.payload is not None
        if d.payload_mass is not None:
            assert abs(d.payload_mass - PAYLOAD[0]) < 0.05


@pytest.mark.parametrize("effect", ["payload", "base_tilt", "torque_offset", "coulomb_friction"])
def test_slow_point_to_point_motion_separates_gravity_like_effects(effect):
    d = check_named((effect,), 0.1, "point_to_point")
    if effect == "payload":
        assert d.payload_mass is not None and abs(d.payload_mass - PAYLOAD[0]) < 0.05


@pytest.mark.parametrize("pair", [("viscous_friction", "coulomb_friction"),
                                  ("payload", "torque_offset"),
                                  ("armature", "base_tilt"),
                                  ("coulomb_friction", "stribeck_friction"),
                                  ("viscous_friction", "position_ripple"),
                                  ("payload", "base_tilt")])
def test_pairs_are_named(pair):
    d = check_named(pair, 0.1)
    assert d.fitted == d.effects and len(d.effects) == 2, (d.fitted, [(s.effect, s.kept) for s in d.steps])


def test_unknown_candidate_is_refused():
    with pytest.raises(ValueError, match="unknown candidate"):
        discover(NOMINAL, simulate(motion("multisine"), (), 0.0), candidates=("viscous",))


def test_clean_effect_is_fitted_to_rounding():
    d = check_named(("coulomb_friction",), 0.0)
    assert np.allclose([d.values[f"fc{i + 1}"] for i in range(7)], FC, atol=1e-6)


def test_tilt_near_one_pose_is_named_over_offsets_that_fit_as_well():
    # near one pose seven offsets fit a tilted base as well as its two tilt angles do:
    # the smaller set is named, and the report says the offsets fit as well with more coefficients
    d = discover(NOMINAL, simulate(motion("near_pose"), ("base_tilt",), 0.1))
    assert d.effects == ("base_tilt",), (d.effects, d.indistinguishable, d.notes)
    assert any("torque_offset" in note and "more coefficients" in note for note in d.notes), d.notes


def test_statistics_helpers_can_fail():
    rng = np.random.default_rng(3)
    x = 0.05 * rng.standard_normal((5000, 2))
    assert np.allclose(noise_floor(x, [2500, 2500]), 0.05, rtol=0.1)
    smooth = np.cumsum(x, axis=0)
    assert np.all(effective_samples(smooth) < 0.05 * len(x))


def test_a_40s_log_at_200Hz():
    """The issue's yardstick log (its time is measured by benchmarks/discovery_timing.py)."""
    t, q, qd, qdd = multisine(duration=40.0, seed=4)
    d = discover(NOMINAL, simulate((t, q, qd, qdd), ("viscous_friction",), 0.02))
    assert d.effects == ("viscous_friction",)


def test_module_examples():
    import doctest

    import kindyngen.measured.discovery as discovery
    import kindyngen.measured.discovery_data as data
    import kindyngen.measured.measurement_model as measurement
    attempted = 0
    for module in (discovery, data, measurement):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
        assert result.failed == 0, module.__name__
        attempted += result.attempted
    assert attempted >= 8
