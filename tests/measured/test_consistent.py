"""Physically consistent identification (kindyngen.measured.consistent): the semidefinite
program fits the torques with full barycentric parameters that describe real bodies.

Data: Pinocchio's RNEA on the robot description's inertias at seeded random states, friction
torques written out here.  Physicality is checked by the test's own pseudo-inertia (written
from Wensing, Wensing & Kim 2017), the realisability of the OLS base values by the test's own
small cvxpy feasibility program, and the robot loader."""
import copy

import cvxpy as cp
import numpy as np
import pinocchio as pin
import pytest
import sympy
import yaml

from tests.harness import ROOT, robot
from tests.reference import pinocchio_model, random_configurations
from kindyngen.model.inertial_parameters import barycentric, parameter_vector
from kindyngen.measured.consistent import (ConsistentIdentificationError, identify_consistent,
                                           links_from_barycentric)
from kindyngen.measured.effect_columns import effect_columns, effect_names
from kindyngen.measured.estimation import IdentificationDataError, least_squares
from kindyngen.measured.regressor_rows import TorqueRegressor
from kindyngen.model.robot_model import Link, RobotDescriptionError
from kindyngen.readers.yaml_description import parse_robot

N_JOINTS = 7
FRICTION = ("viscous_friction", "coulomb_friction", "torque_offset")


def pseudo_inertia(link):
    """[[Sigma, h], [h^T, m]] with Sigma = int r r^T dm = 0.5 tr(I) 1 - I (I about the origin)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = link
    sigma = np.array([[(-ixx + iyy + izz) / 2, -ixy, -ixz],
                      [-ixy, (ixx - iyy + izz) / 2, -iyz],
                      [-ixz, -iyz, (ixx + iyy - izz) / 2]])
    h = np.array([hx, hy, hz])
    return np.block([[sigma, h[:, None]], [h[None, :], np.array([[m]])]])


def smallest_eigenvalues(p):
    return np.array([np.linalg.eigvalsh(pseudo_inertia(p[10 * i:10 * i + 10]))[0] for i in range(len(p) // 10)])


def realisability_margin(P, base):
    """min t such that some full p with P p = base has every J(p) + t 1 >= 0 (t > 0: no physical
    body has these base values).  Written independently of consistent.py."""
    n = P.shape[1] // 10
    p, t = cp.Variable(P.shape[1]), cp.Variable()
    constraints = [P @ p == base, t >= -1]
    for i in range(n):
        m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = (p[10 * i + k] for k in range(10))
        J = cp.bmat([[(-ixx + iyy + izz) / 2, -ixy, -ixz, hx], [-ixy, (ixx - iyy + izz) / 2, -iyz, hy],
                     [-ixz, -iyz, (ixx + iyy - izz) / 2, hz], [hx, hy, hz, m]])
        constraints.append(J + t * np.eye(4) >> 0)
    problem = cp.Problem(cp.Minimize(t), constraints)
    problem.solve(solver="CLARABEL")
    assert problem.status == "optimal"
    return float(t.value)


def simulate(name, count, seed, speed=1.0, noise=0.0, fv=None, fc=None, f0=None):
    rob = robot(name)
    model, data, _ = pinocchio_model(rob)
    rng = np.random.default_rng(seed)
    Q = random_configurations(rob, count, seed + 500)
    QD, QDD = speed * rng.normal(size=Q.shape), 2 * speed * rng.normal(size=Q.shape)
    tau = np.array([pin.rnea(model, data, Q[k], QD[k], QDD[k]) for k in range(count)])
    tau = tau + fv * QD + fc * np.sign(QD) + f0 + noise * rng.normal(size=tau.shape)
    return Q, QD, QDD, tau


def description_with(name, links):
    """The robot's YAML data with its links replaced."""
    data = yaml.safe_load((ROOT / "robots" / f"{name}.yaml").read_text())
    data = copy.deepcopy(data)
    data["links"] = links
    return data


FV = np.array([1.2, 0.9, 0.7, 0.5, 0.3, 0.2, 0.1])
FC = np.array([2.5, 2.0, 1.5, 1.0, 0.6, 0.4, 0.2])
F0 = np.array([0.3, -0.2, 0.1, -0.15, 0.05, 0.02, -0.04])


@pytest.mark.parametrize("name", ["panda", "lwr4"])
def test_noise_free_data_with_a_perturbed_prior(name):
    """Status optimal, every pseudo-inertia positive definite, base values within 1e-3 of the
    truth relative to its norm (the regulariser's bias with a prior 20 % off and the default
    weight; 1e-5 with a weight of 1e-9), friction recovered and >= 0."""
    rob = robot(name)
    R = TorqueRegressor(rob)
    Q, QD, QDD, tau = simulate(name, 300, 31, fv=FV, fc=FC, f0=F0)
    truth = parameter_vector(rob)
    prior = truth * (1 + 0.2 * np.random.default_rng(32).normal(size=truth.shape))
    names = effect_names(FRICTION, N_JOINTS)
    fit = identify_consistent(R(Q, QD, QDD) @ R.base_map, effect_columns(FRICTION, QD, QDD), tau, N_JOINTS,
                              names, prior=prior, base_map=R.base_map)
    assert fit.status == "optimal"
    eig = smallest_eigenvalues(fit.full_values)
    assert eig.min() > 0.99 * fit.epsilon
    np.testing.assert_allclose(eig, fit.min_pseudo_inertia_eigenvalue, rtol=1e-9, atol=1e-12)
    base_truth = R.base_map @ truth
    np.testing.assert_allclose(fit.base_values, R.base_map @ fit.full_values, rtol=1e-12, atol=1e-12)
    assert np.linalg.norm(fit.base_values - base_truth) < 1e-3 * np.linalg.norm(base_truth)
    np.testing.assert_allclose(fit.effect_values, np.concatenate([FV, FC, F0]), rtol=0, atol=2e-3)
    assert (fit.effect_values[:14] >= 0).all()
    assert fit.rms.max() < 1e-2 and fit.data_term < 1e-6
    # the full parameters are not identifiable: the one chosen is nearer the prior than the truth is
    assert np.linalg.norm(fit.full_values - prior) < np.linalg.norm(truth - prior)
    assert fit.full_names == R.full_names
    # the bias is the regulariser's: a weaker weight shrinks it
    weak = identify_consistent(R(Q, QD, QDD) @ R.base_map, effect_columns(FRICTION, QD, QDD), tau, N_JOINTS,
                               names, prior=prior, base_map=R.base_map, regularization=1e-9)
    assert weak.status == "optimal" and smallest_eigenvalues(weak.full_values).min() > 0
    assert np.linalg.norm(weak.base_values - base_truth) < 1e-5 * np.linalg.norm(base_truth)
    np.testing.assert_allclose(weak.effect_values, np.concatenate([FV, FC, F0]), rtol=0, atol=1e-5)


def test_prior_equal_to_the_truth_gives_the_truth():
    """With noise-free data and the truth as prior, the truth is feasible with zero error and
    zero regularisation, so it is the unique optimum."""
    rob = robot("lwr4")
    R = TorqueRegressor(rob)
    Q, QD, QDD, tau = simulate("lwr4", 200, 33, fv=FV, fc=FC, f0=F0)
    truth = parameter_vector(rob)
    fit = identify_consistent(R(Q, QD, QDD) @ R.base_map, effect_columns(FRICTION, QD, QDD), tau, N_JOINTS,
                              effect_names(FRICTION, N_JOINTS), prior=truth, base_map=R.base_map)
    assert np.abs(fit.full_values - truth).max() < 1e-4
    assert np.linalg.norm(fit.base_values - R.base_map @ truth) < 1e-6 * np.linalg.norm(R.base_map @ truth)


def test_poor_excitation_ols_is_not_physical_the_sdp_is():
    """60 samples at low speed with 0.5 N m noise, three friction coefficients truly zero:
    the OLS base values belong to no physical body (the test's own feasibility program proves
    it: margin t > 0) and OLS reports negative friction; the SDP's result is physical and the
    robot loader accepts it."""
    name = "lwr4"
    rob = robot(name)
    R = TorqueRegressor(rob)
    fv = FV * (np.arange(N_JOINTS) < 4)                      # fv5 = fv6 = fv7 = 0
    Q, QD, QDD, tau = simulate(name, 60, 34, speed=0.3, noise=0.5, fv=fv, fc=FC, f0=F0)
    names = effect_names(FRICTION, N_JOINTS)
    Y, E = R(Q, QD, QDD), effect_columns(FRICTION, QD, QDD)
    ols = least_squares(np.concatenate([Y, E], axis=2), tau, R.names + names)
    p = len(R.names)
    ols_base = ols.values[:p]
    assert realisability_margin(R.base_map, ols_base) > 0.05
    assert realisability_margin(R.base_map, R.base_map @ parameter_vector(rob)) < 0   # the check can pass
    # the OLS full parameters nearest the description (minimum-norm correction) are not physical either
    truth = parameter_vector(rob)
    nearest = truth + np.linalg.pinv(R.base_map) @ (ols_base - R.base_map @ truth)
    assert smallest_eigenvalues(nearest).min() < -0.01
    with pytest.raises(RobotDescriptionError):
        parse_robot(description_with(name, links_from_barycentric(nearest, N_JOINTS)))
    assert (ols.values[p:p + 2 * N_JOINTS] < 0).any()        # some friction came out negative

    fit = identify_consistent(Y @ R.base_map, E, tau, N_JOINTS, names, prior=truth, base_map=R.base_map)
    assert fit.status == "optimal"
    assert smallest_eigenvalues(fit.full_values).min() > 0.99 * fit.epsilon
    assert (fit.full_values[::10] >= fit.min_mass * (1 - 1e-6)).all()
    assert (fit.effect_values[:2 * N_JOINTS] >= -1e-9).all()
    model = parse_robot(description_with(name, fit.links()))
    assert model.n == N_JOINTS
    # the SDP fits (almost) as well as OLS on its training data
    assert fit.rms.mean() < 1.1 * ols.rms.mean()


def test_without_prior_the_bodies_are_still_valid():
    rob = robot("panda")
    R = TorqueRegressor(rob)
    Q, QD, QDD, tau = simulate("panda", 200, 35, noise=0.1, fv=FV, fc=FC, f0=F0)
    fit = identify_consistent(R(Q, QD, QDD) @ R.base_map, effect_columns(FRICTION, QD, QDD), tau, N_JOINTS,
                              effect_names(FRICTION, N_JOINTS), base_map=R.base_map)
    assert fit.status == "optimal" and smallest_eigenvalues(fit.full_values).min() > 0
    parse_robot(description_with("panda", fit.links()))
    truth = R.base_map @ parameter_vector(rob)
    assert np.linalg.norm(fit.base_values - truth) < 0.05 * np.linalg.norm(truth)


def test_bad_input_is_refused():
    R = TorqueRegressor(robot("lwr4"))
    Yf = np.zeros((20, N_JOINTS, 70))
    with pytest.raises(IdentificationDataError, match="shape"):
        identify_consistent(Yf[:, :, :60], None, np.zeros((20, N_JOINTS)), N_JOINTS)
    tau = np.ones((20, N_JOINTS))
    tau[3, 2] = np.nan
    with pytest.raises(IdentificationDataError, match="NaN"):
        identify_consistent(Yf, None, tau, N_JOINTS)
    with pytest.raises(IdentificationDataError, match="effect"):
        identify_consistent(Yf, np.zeros((20, N_JOINTS, 3)), np.ones((20, N_JOINTS)), N_JOINTS, ("fv1",))
    with pytest.raises(ValueError, match="not an effect parameter"):
        identify_consistent(Yf, np.zeros((20, N_JOINTS, 1)), np.ones((20, N_JOINTS)), N_JOINTS, ("mass1",))
    assert issubclass(ConsistentIdentificationError, RuntimeError) and R.n == N_JOINTS


@pytest.mark.parametrize("name", ["lwr4", "panda"])
def test_links_from_barycentric_round_trip(name):
    rob = robot(name)
    p = parameter_vector(rob)
    links = links_from_barycentric(p, rob.n)
    for link, got in zip(rob.links, links):
        # back to the description's numbers (mass, CoM, inertia about the CoM as ixx iyy izz ixy ixz iyz)
        assert got["mass"] == pytest.approx(float(link.mass), rel=1e-14)
        np.testing.assert_allclose(got["com"], [float(v) for v in link.com], rtol=0, atol=1e-14)
        np.testing.assert_allclose(got["inertia"], [float(v) for v in link.inertia], rtol=0, atol=1e-13)
        # and forward again by the project's parallel-axis map
        again = Link(mass=sympy.Rational(repr(got["mass"])), com=tuple(sympy.Rational(repr(v)) for v in got["com"]),
                     inertia=tuple(sympy.Rational(repr(v)) for v in got["inertia"]))
        np.testing.assert_allclose([float(v) for v in barycentric(again)], [float(v) for v in barycentric(link)],
                                   rtol=1e-12, atol=1e-14)
    model = parse_robot(description_with(name, links))
    np.testing.assert_allclose(parameter_vector(model), p, rtol=1e-12, atol=1e-14)
    bad = p.copy()
    bad[10] = -1.0
    with pytest.raises(ValueError, match="link 2: mass"):
        links_from_barycentric(bad, rob.n)
    with pytest.raises(ValueError, match="70"):
        links_from_barycentric(p[:-1], rob.n)


def test_the_description_order_is_not_the_barycentric_order():
    """One link, CoM at the origin, inertia with distinct entries: Ixx Ixy Iyy Ixz Iyz Izz in
    the vector become ixx iyy izz ixy ixz iyz in the description."""
    p = np.array([2.0, 0, 0, 0, 0.5, 0.01, 0.4, 0.02, 0.03, 0.3])
    assert links_from_barycentric(p, 1) == [{"mass": 2.0, "com": [0.0, 0.0, 0.0],
                                             "inertia": [0.5, 0.4, 0.3, 0.01, 0.02, 0.03]}]
