"""The Newton-Euler primitives of :mod:`kindyngen.algorithms.joint_frame_steps` on numbers,
against plain numpy and Pinocchio: ``rotate_body`` (the double-angle rotation, then the
constant C and t) is Pinocchio's inertia transform by ``(C Rz(q), t)``, or ``(C, t)`` for a
prismatic joint; ``joint_step`` is the textbook velocity/acceleration recursion written with
cross products; ``mat3``, ``omega_products`` and ``u_matrix = skew(w') + skew(w)^2`` equal
numpy's products (``U r = w' x r + w x (w x r)``)."""
from __future__ import annotations

import numpy as np
import pytest
import symengine as se

from kindyngen.algorithms.joint_frame_steps import joint_step, mat3, omega_products, rotate_body, u_matrix
from kindyngen.algorithms.rigid_bodies import Body, JointFrame

pin = pytest.importorskip("pinocchio")

TOL = 1e-13


def _se(a):
    return [se.RealDouble(float(x)) for x in a]


def _num(v):
    return np.array([float(x) for x in v])


def _mat(m):
    return np.array([[float(x) for x in row] for row in m])


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _rotation(rng):
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q * np.linalg.det(Q)


def _rz(q):
    return np.array([[np.cos(q), -np.sin(q), 0], [np.sin(q), np.cos(q), 0], [0, 0, 1.0]])


def _frame(C, t, q, prismatic=False):
    if prismatic:
        return JointFrame(C=[_se(r) for r in C], t=_se(t), c=se.Integer(1), s=se.Integer(0), prismatic=True)
    return JointFrame(C=[_se(r) for r in C], t=_se(t), c=se.RealDouble(np.cos(q)), s=se.RealDouble(np.sin(q)))


@pytest.mark.parametrize("prismatic", [False, True])
def test_rotate_body_is_pinocchios_inertia_transform(prismatic):
    rng = np.random.default_rng(1 + prismatic)
    for _ in range(10):
        m, c = rng.uniform(0.5, 3), rng.normal(scale=0.2, size=3)
        A = rng.normal(size=(3, 3))
        inertia = pin.Inertia(m, c, 0.01 * A @ A.T + 0.01 * np.eye(3))
        body = Body(se.RealDouble(m), _se(m * c), [_se(r) for r in inertia.matrix()[3:, 3:]])
        C, t, q = _rotation(rng), rng.normal(size=3), rng.uniform(-3, 3)
        R = C if prismatic else C @ _rz(q)
        expected = pin.SE3(R, t).act(inertia)
        ours = rotate_body(_frame(C, t, q, prismatic), body)
        assert abs(float(ours.m) - m) < TOL
        assert np.allclose(_num(ours.h), expected.mass * expected.lever, rtol=0, atol=TOL)
        assert np.allclose(_mat(ours.I), expected.matrix()[3:, 3:], rtol=0, atol=TOL)


@pytest.mark.parametrize("prismatic", [False, True])
def test_joint_step_is_the_velocity_recursion(prismatic):
    rng = np.random.default_rng(3 + prismatic)
    ez = np.array([0.0, 0.0, 1.0])
    for _ in range(10):
        a, wr, wdr = rng.normal(size=(3, 3))
        qd, qdd = rng.normal(size=2)
        frame = _frame(np.eye(3), np.zeros(3), 0.0, prismatic)
        a2, w2, wd2 = (_num(v) for v in joint_step(frame, _se(a), _se(wr), _se(wdr), se.RealDouble(qd),
                                                    se.RealDouble(qdd)))
        if prismatic:
            expected = (a + qdd * ez + 2 * np.cross(wr, qd * ez), wr, wdr)
        else:
            expected = (a, wr + qd * ez, wdr + qdd * ez + np.cross(wr, qd * ez))
        for ours, reference in zip((a2, w2, wd2), expected):
            assert np.allclose(ours, reference, rtol=0, atol=TOL)


def test_u_matrix_mat3_and_omega_products_equal_numpy():
    rng = np.random.default_rng(5)
    for _ in range(10):
        w, wd, r = rng.normal(size=(3, 3))
        A = rng.normal(size=(3, 3))
        products = omega_products(_se(w))
        assert np.allclose(_num(products), [w[0] ** 2, w[1] ** 2, w[2] ** 2, w[0] * w[1], w[0] * w[2], w[1] * w[2]],
                           rtol=0, atol=TOL)
        U = _mat(u_matrix(_se(w), _se(wd), products))
        assert np.allclose(U, _skew(wd) + _skew(w) @ _skew(w), rtol=0, atol=TOL)
        assert np.allclose(U @ r, np.cross(wd, r) + np.cross(w, np.cross(w, r)), rtol=0, atol=TOL)
        assert np.allclose(_num(mat3([_se(row) for row in A], _se(r))), A @ r, rtol=0, atol=TOL)
