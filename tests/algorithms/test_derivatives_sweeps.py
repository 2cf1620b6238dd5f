"""The derivative functions of :mod:`kindyngen.algorithms.derivatives_sweeps` on arms (the
branched tree is tests/algorithms/test_derivatives_over_tree.py), straight from the
derivation (symengine):

* the LWR: ``tau_derivatives`` against Pinocchio's ``computeRNEADerivatives`` and central
  differences of ``rnea``; ``fd_derivatives`` against ``computeABADerivatives`` and central
  differences of ``aba``; the catalog's ``fd_derivatives_no_minv`` of the LWR and the Panda
  (this route without ``Minv``) against ``computeABADerivatives``; the Christoffel form
  ``dc/dqd`` (``coriolis_velocity_jacobian`` of ``mass_matrix_partials`` of M) against
  differences of Pinocchio's ``c = nle - g``;
* a URDF chain with a prismatic joint on a tilted axis, with viscous, smoothed Coulomb and
  offset friction and armature added: both functions and the catalog's
  ``fd_derivatives_no_minv`` against central differences of Pinocchio's rnea / aba plus those
  effects written out here with numpy;
* the helpers: ``inverse_from_ldlt`` and ``solve_columns`` against numpy's inverse and solve,
  ``additive_derivatives`` (their qd slopes) against differences of the friction torque, ``with_diagonal``;
  a floating base is refused.

Tolerances: analytic references 1e-10, central differences (step 1e-6) 1e-6, both relative to
the largest |reference entry| (at least 1)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import sympy
import symengine as se

from kindyngen.algorithms.derivatives_sweeps import (coriolis_velocity_jacobian,
                                                     fd_derivatives, inverse_from_ldlt, mass_matrix_partials,
                                                     solve_columns, tau_derivatives, with_diagonal)
from kindyngen.algorithms.dynamics import crba, setup
from kindyngen.algorithms.effect_torques import additive_derivatives
from kindyngen.algorithms.ldlt import ldlt_factor
from kindyngen.codegen.catalog import derive_all
from kindyngen.model.robot_model import Friction
from kindyngen.readers.urdf import parse_urdf
from tests.harness import evaluate_function, robot

pin = pytest.importorskip("pinocchio")
from tests.reference import pinocchio_model  # noqa: E402
from tests.robot_files import SLIDER_CHAIN_URDF

EXACT, DIFFERENCE, STEP = 1e-10, 1e-6, 1e-6

# per joint: viscous, coulomb, offset, armature; tanh(qd / EPS) for the Coulomb sign
EFFECTS = [(0.8, 1.2, 0.1, 0.3), (20.0, 5.0, -0.5, 2.5), (0.3, 0.4, 0.05, 0.1)]
EPS = 0.05


def _close(ours, reference, tol):
    reference = np.asarray(reference, float)
    return np.abs(np.asarray(ours, float) - reference).max() <= tol * max(1.0, np.abs(reference).max())


def _jacobian(fun, x):
    """Central differences of ``fun`` at x (columns: d fun / d x_j)."""
    columns = []
    for j in range(len(x)):
        e = np.zeros(len(x))
        e[j] = STEP
        columns.append((fun(x + e) - fun(x - e)) / (2 * STEP))
    return np.column_stack(columns)


def _full(M):
    return np.triu(M) + np.triu(M, 1).T


def _states(model, count, seed=26):
    rng = np.random.default_rng(seed)
    lower, upper = np.array(model.lower, float), np.array(model.upper, float)
    return [(rng.uniform(lower, upper), rng.normal(size=model.n), rng.normal(size=model.n)) for _ in range(count)]


# ----------------------------------------------------------------------------- the LWR

@pytest.fixture(scope="module")
def lwr():
    model = robot("lwr4")
    pm, pd, _ = pinocchio_model(model)
    return model, pm, pd


def test_lwr_tau_derivatives_equal_pinocchio(lwr):
    model, pm, pd = lwr
    f = tau_derivatives(model)
    assert [p.name for p in f.outputs] == ["dtau_dq", "dtau_dqd"]
    for q, qd, qdd in _states(model, 5):
        dq, dqd = evaluate_function(f, q, qd, qdd)
        ref_dq, ref_dqd, _ = (np.array(a) for a in pin.computeRNEADerivatives(pm, pd, q, qd, qdd))
        assert _close(dq, ref_dq, EXACT) and _close(dqd, ref_dqd, EXACT)
        assert _close(dq, _jacobian(lambda x: pin.rnea(pm, pd, x, qd, qdd), q), DIFFERENCE)
        assert _close(dqd, _jacobian(lambda x: pin.rnea(pm, pd, q, x, qdd), qd), DIFFERENCE)


def test_lwr_fd_derivatives_equal_pinocchio(lwr):
    model, pm, pd = lwr
    f = fd_derivatives(model)
    assert [p.name for p in f.outputs] == ["dqdd_dq", "dqdd_dqd", "Minv"]
    rng = np.random.default_rng(5)
    for q, qd, _ in _states(model, 5):
        tau = rng.normal(scale=5.0, size=model.n)
        dq, dqd, Minv = evaluate_function(f, q, qd, tau)
        ref_dq, ref_dqd, ref_Minv = (np.array(a) for a in pin.computeABADerivatives(pm, pd, q, qd, tau))
        assert _close(dq, ref_dq, EXACT) and _close(dqd, ref_dqd, EXACT)
        assert _close(Minv, _full(ref_Minv), EXACT)
        assert _close(dq, _jacobian(lambda x: pin.aba(pm, pd, x, qd, tau), q), DIFFERENCE)
        assert _close(dqd, _jacobian(lambda x: pin.aba(pm, pd, q, x, tau), qd), DIFFERENCE)


@pytest.mark.parametrize("name", ["lwr4", "panda"])
def test_arm_fd_derivatives_no_minv_equal_pinocchio(name):
    """An arm gets fd_derivatives_no_minv by these sweeps (fewer operations than the world
    frame's route on both arms), dqdd/dq and dqdd/dqd only."""
    model = robot(name)
    pm, pd, _ = pinocchio_model(model)
    (f,) = derive_all(model, only={"fd_derivatives_no_minv"})
    assert [p.name for p in f.outputs] == ["dqdd_dq", "dqdd_dqd"] and "tangent sweep" in f.summary
    rng = np.random.default_rng(15)
    for q, qd, _ in _states(model, 5):
        tau = rng.normal(scale=5.0, size=model.n)
        dq, dqd = evaluate_function(f, q, qd, tau)
        ref_dq, ref_dqd, _ = (np.array(a) for a in pin.computeABADerivatives(pm, pd, q, qd, tau))
        assert _close(dq, ref_dq, EXACT) and _close(dqd, ref_dqd, EXACT)


def test_christoffel_velocity_jacobian_is_that_of_pinocchios_coriolis(lwr):
    model, pm, pd = lwr
    ts = setup(model, "numeric")
    qd_symbols = se.symbols(f"v0:{model.n}")
    M = crba(ts)[0]
    dM = mass_matrix_partials(M, ts.q)
    D = coriolis_velocity_jacobian(dM, qd_symbols)
    fn = se.Lambdify(list(ts.q) + list(qd_symbols), [e for row in D for e in row] +
                     [e for k in range(model.n) for row in dM[k] for e in row], cse=True)

    def coriolis(q, qd):
        return pin.nonLinearEffects(pm, pd, q, qd) - pin.computeGeneralizedGravity(pm, pd, q)

    n = model.n
    for q, qd, _ in _states(model, 3):
        out = np.ravel(fn(np.concatenate([q, qd])))
        ours_D, ours_dM = out[:n * n].reshape(n, n), out[n * n:].reshape(n, n, n)
        assert _close(ours_D, _jacobian(lambda x: coriolis(q, x), qd), DIFFERENCE)
        for k in range(n):
            e = np.zeros(n)
            e[k] = STEP
            difference = (_full(pin.crba(pm, pd, q + e)) - _full(pin.crba(pm, pd, q - e))) / (2 * STEP)
            assert _close(ours_dM[k], difference, DIFFERENCE)


# ----------------------------------------------------------------------------- a chain with effects

@pytest.fixture(scope="module")
def chain():
    rigid = parse_urdf(SLIDER_CHAIN_URDF)
    joints = tuple(replace(j, friction=Friction(sympy.Rational(str(fv)), sympy.Rational(str(fc)), sympy.Rational(str(off))),
                           armature=sympy.Rational(str(arm)))
                   for j, (fv, fc, off, arm) in zip(rigid.joints, EFFECTS))
    model = replace(rigid, joints=joints, coulomb_smoothing=sympy.Rational(str(EPS)))
    pm = pin.buildModelFromXML(SLIDER_CHAIN_URDF)
    assert [pm.names[k] for k in range(1, pm.njoints)] == [j.name for j in model.joints]
    return model, pm, pm.createData()


def _friction(qd):
    fv, fc, off, _ = (np.array(c) for c in zip(*EFFECTS))
    return fv * qd + fc * np.tanh(qd / EPS) + off


ARMATURE = np.array([e[3] for e in EFFECTS])


def test_chain_with_effects_tau_derivatives_equal_differences(chain):
    model, pm, pd = chain

    def tau(q, qd, qdd):
        return pin.rnea(pm, pd, q, qd, qdd) + ARMATURE * qdd + _friction(qd)

    f = tau_derivatives(model)
    for q, qd, qdd in _states(model, 5):
        qd = qd * 0.1            # inside tanh's bend too (|qd| ~ eps)
        dq, dqd = evaluate_function(f, q, qd, qdd)
        assert _close(dq, _jacobian(lambda x: tau(x, qd, qdd), q), DIFFERENCE)
        assert _close(dqd, _jacobian(lambda x: tau(q, x, qdd), qd), DIFFERENCE)


def test_chain_with_effects_fd_derivatives_equal_differences(chain):
    model, pm, pd = chain

    def fd(q, qd, tau):
        M = _full(pin.crba(pm, pd, q)) + np.diag(ARMATURE)
        return np.linalg.solve(M, tau - pin.nonLinearEffects(pm, pd, q, qd) - _friction(qd))

    f = fd_derivatives(model)
    rng = np.random.default_rng(6)
    for q, qd, _ in _states(model, 5):
        qd, tau = qd * 0.1, rng.normal(scale=5.0, size=model.n)
        dq, dqd, Minv = evaluate_function(f, q, qd, tau)
        assert _close(dq, _jacobian(lambda x: fd(x, qd, tau), q), DIFFERENCE)
        assert _close(dqd, _jacobian(lambda x: fd(q, x, tau), qd), DIFFERENCE)
        assert _close(Minv, np.linalg.inv(_full(pin.crba(pm, pd, q)) + np.diag(ARMATURE)), EXACT)
    (no_minv,) = derive_all(model, only={"fd_derivatives_no_minv"})
    for q, qd, _ in _states(model, 3, seed=27):
        qd, tau = qd * 0.1, rng.normal(scale=5.0, size=model.n)
        dq, dqd = evaluate_function(no_minv, q, qd, tau)
        assert _close(dq, _jacobian(lambda x: fd(x, qd, tau), q), DIFFERENCE)
        assert _close(dqd, _jacobian(lambda x: fd(q, x, tau), qd), DIFFERENCE)


def test_effect_velocity_derivatives_are_the_friction_slopes(chain):
    model, _, _ = chain
    qd_symbols = se.symbols(f"v0:{model.n}")
    q_symbols = se.symbols(f"p0:{model.n}")
    slopes = se.Lambdify(list(qd_symbols), additive_derivatives(model, q_symbols, qd_symbols)[1])
    for qd in np.random.default_rng(7).normal(scale=0.1, size=(5, model.n)):
        assert _close(np.diag(_jacobian(_friction, qd)), np.ravel(slopes(qd)), DIFFERENCE)
    # the sign form (no smoothing) contributes only the viscous slope
    signed = replace(model, coulomb_smoothing=None)
    assert [float(v) for v in additive_derivatives(signed, q_symbols, qd_symbols)[1]] == [e[0] for e in EFFECTS]


# ----------------------------------------------------------------------------- helpers

def _spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def test_inverse_and_solved_columns_from_the_factors_equal_numpy():
    rng = np.random.default_rng(8)
    for n in (1, 3, 6):
        M, B = _spd(rng, n), rng.normal(size=(n, 4))
        L, inv_d = ldlt_factor([[se.RealDouble(v) for v in row] for row in M])
        inverse = np.array([[float(v) for v in row] for row in inverse_from_ldlt(L, inv_d)])
        assert np.allclose(inverse, np.linalg.inv(M), rtol=0, atol=1e-13)
        solved = solve_columns(L, inv_d, [[se.RealDouble(v) for v in row] for row in B])
        assert np.allclose(np.array([[float(v) for v in row] for row in solved]), -np.linalg.solve(M, B),
                           rtol=0, atol=1e-13)


def test_with_diagonal_adds_on_the_diagonal_only():
    A = [[se.Integer(1), se.Integer(2)], [se.Integer(3), se.Integer(4)]]
    x = se.Symbol("x")
    assert with_diagonal(A, [x, 0]) == [[1 + x, 2], [3, 4]]
    assert A == [[1, 2], [3, 4]]                            # the input is not changed


def test_floating_base_is_refused():
    floating = parse_urdf(SLIDER_CHAIN_URDF, floating_base=True)
    with pytest.raises(ValueError, match="fixed base"):
        tau_derivatives(floating)
    with pytest.raises(ValueError, match="fixed base"):
        fd_derivatives(floating)
