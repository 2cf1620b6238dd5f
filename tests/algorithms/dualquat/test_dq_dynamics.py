"""The dual-quaternion dynamics of :mod:`kindyngen.algorithms.dualquat.dq_dynamics`, straight
from the derivation (symengine, no code generation): its algebra (commutator, dual inertia
operator, joint adjoints) against Pinocchio's motion and force algebra, and ``tau_dq``,
``M_dq`` (composite and column by column), ``g_dq``, ``c_dq`` and ``Y_dq`` times the base
parameters (p_B + T p_D, numpy) against Pinocchio's rnea, crba, computeGeneralizedGravity
and nonLinearEffects at random states: the LWR (standard DH) and the Panda (modified DH) from
tests/reference.py, and a chain from a URDF with a prismatic joint on a tilted axis and
non-axis-aligned origins (Pinocchio from the same text).

Tolerance: 1e-10 relative to the largest |reference entry| (at least 1)."""
from __future__ import annotations

import numpy as np
import pytest
import symengine as se

from kindyngen.algorithms.dualquat.dq_dynamics import (commutator, coriolis_dq, gravity_dq, inertia_operator,
                                                       inverse_dynamics_dq, joint_poses, mass_matrix_dq,
                                                       regressor_dq)
from kindyngen.algorithms.regressors import base_parameters
from kindyngen.algorithms.rigid_bodies import Body
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.readers.urdf import parse_urdf
from tests.harness import robot

pin = pytest.importorskip("pinocchio")
from tests.reference import pinocchio_model, random_configurations  # noqa: E402
from tests.robot_files import SLIDER_CHAIN_URDF

TOL = 1e-10
STATES = 20

def _evaluate(f, *inputs):
    """Outputs of a SymbolicFunction at one point (Lambdify of the inlined outputs)."""
    fn = se.Lambdify([s for syms in f.input_symbols for s in syms],
                     [e for exprs in f.inlined_outputs() for e in exprs], cse=True)
    out = np.ravel(fn(np.concatenate([np.ravel(x) for x in inputs])))
    result, start = [], 0
    for port in f.outputs:
        result.append(out[start:start + port.size].reshape(port.shape))
        start += port.size
    return result


def _close(ours, reference):
    reference = np.asarray(reference, float)
    return np.abs(np.asarray(ours, float) - reference).max() <= TOL * max(1.0, np.abs(reference).max())


def _num(v, values=None):
    return np.array([float(se.sympify(x).subs(values) if values else x) for x in v])


def _se(a):
    return [se.RealDouble(float(x)) for x in a]


def _motion(y):
    """A pure dual quaternion w + e v (6-list: w, then v) as a pin.Motion (linear v, angular w)."""
    y = np.asarray(y, float)
    return pin.Motion(y[3:], y[:3])


# ----------------------------------------------------------------------------- algebra

def test_commutator_is_the_motion_and_force_cross_product():
    rng = np.random.default_rng(1)
    for _ in range(10):
        a, b = rng.normal(size=6), rng.normal(size=6)
        ours = _num(commutator(_se(a), _se(b)))
        cross = _motion(a).cross(_motion(b))                        # twist x twist
        assert np.allclose(ours, np.concatenate([cross.angular, cross.linear]), rtol=0, atol=1e-14)
        force = _motion(a).cross(pin.Force(b[:3], b[3:]))           # twist x wrench f + e n
        assert np.allclose(ours, np.concatenate([force.linear, force.angular]), rtol=0, atol=1e-14)


def test_inertia_operator_is_pinocchios_inertia_times_twist():
    rng = np.random.default_rng(2)
    for _ in range(10):
        m, c = rng.uniform(0.5, 3), rng.normal(scale=0.2, size=3)
        L = rng.normal(size=(3, 3))
        inertia = pin.Inertia(m, c, 0.01 * (L @ L.T) + 0.01 * np.eye(3))
        I = inertia.matrix()[3:, 3:]                                # about the frame origin
        body = Body(se.RealDouble(m), _se(m * c), [_se(row) for row in I])
        y = rng.normal(size=6)
        momentum = inertia * _motion(y)
        assert np.allclose(_num(inertia_operator(body, _se(y))),
                           np.concatenate([momentum.linear, momentum.angular]), rtol=0, atol=1e-14)


def test_joint_adjoints_are_pinocchios_joint_placements():
    """LWR (standard DH): joint frame j is Pinocchio's joint frame j of tests/reference.py, so
    ``to_parent`` is liMi.act on motions and ``to_child`` its inverse."""
    model = robot("lwr4")
    pm, pd, _ = pinocchio_model(model)
    q_symbols = se.symbols(f"q0:{model.n}")
    poses = joint_poses(model, q_symbols)
    rng = np.random.default_rng(3)
    for q in random_configurations(model, 5, seed=26):
        pin.forwardKinematics(pm, pd, q)
        values = dict(zip(q_symbols, q))
        for j, pose in enumerate(poses):
            y = rng.normal(size=6)
            up = pd.liMi[j + 1].act(_motion(y))
            down = pd.liMi[j + 1].actInv(_motion(y))
            assert np.allclose(_num(pose.to_parent(_se(y)), values), np.concatenate([up.angular, up.linear]),
                               rtol=0, atol=1e-12)
            assert np.allclose(_num(pose.to_child(_se(y)), values), np.concatenate([down.angular, down.linear]),
                               rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- functions

def _models():
    for name in ("lwr4", "panda"):
        model = robot(name)
        pm, pd, _ = pinocchio_model(model)
        yield name, model, pm, pd
    model = parse_urdf(SLIDER_CHAIN_URDF)
    pm = pin.buildModelFromXML(SLIDER_CHAIN_URDF)
    assert [pm.names[k] for k in range(1, pm.njoints)] == [j.name for j in model.joints]
    yield "slider_chain", model, pm, pm.createData()


MODELS = {name: (model, pm, pd) for name, model, pm, pd in _models()}


def _states(model, seed=26):
    rng = np.random.default_rng(seed)
    lower, upper = np.array(model.lower, float), np.array(model.upper, float)
    return [(rng.uniform(lower, upper), rng.normal(size=model.n), rng.normal(size=model.n)) for _ in range(STATES)]


@pytest.mark.parametrize("name", sorted(MODELS))
def test_tau_g_c_equal_pinocchio(name):
    model, pm, pd = MODELS[name]
    tau_f, g_f, c_f = inverse_dynamics_dq(model), gravity_dq(model), coriolis_dq(model)
    assert [p.name for p in tau_f.inputs] == ["q", "qd", "qdd"]
    for q, qd, qdd in _states(model):
        assert _close(_evaluate(tau_f, q, qd, qdd)[0], pin.rnea(pm, pd, q, qd, qdd))
        g = pin.computeGeneralizedGravity(pm, pd, q)
        assert _close(_evaluate(g_f, q)[0], g)
        assert _close(_evaluate(c_f, q, qd)[0], pin.nonLinearEffects(pm, pd, q, qd) - g)


@pytest.mark.parametrize("composite", [True, False])
@pytest.mark.parametrize("name", sorted(MODELS))
def test_mass_matrix_equals_pinocchio(name, composite):
    model, pm, pd = MODELS[name]
    f = mass_matrix_dq(model, composite=composite)
    for q, _, _ in _states(model):
        M = pin.crba(pm, pd, q)
        M = np.triu(M) + np.triu(M, 1).T
        ours = _evaluate(f, q)[0]
        assert np.array_equal(ours, ours.T)
        assert _close(ours, M)


def test_regressor_times_base_parameters_is_pinocchios_rnea():
    model, pm, pd = MODELS["lwr4"]
    f = regressor_dq(model)
    b = base_parameters(model, "Y")
    p = parameter_vector(model)
    T = np.array(b.T, dtype=float).reshape(len(b.base), len(b.dependent))
    base_values = p[list(b.base)] + T @ p[list(b.dependent)]
    for q, qd, qdd in _states(model)[:5]:
        Y = _evaluate(f, q, qd, qdd)[0]
        assert Y.shape == (model.n, len(b.base))
        assert _close(Y @ base_values, pin.rnea(pm, pd, q, qd, qdd))
