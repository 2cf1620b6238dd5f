"""The shared pieces of :mod:`kindyngen.algorithms.rigid_bodies`: its small vector algebra and
joint-frame rotations against plain numpy, ``Body.moved`` and ``Body + Body`` against
Pinocchio's inertia transform and sum, ``Body.from_inertials`` against the parallel-axis
theorem on the YAML numbers; and as assembled by :func:`kindyngen.algorithms.dynamics.setup`
for the LWR (standard DH) and the Panda (modified DH): the joint frames composed at random q
are Pinocchio's joint placements (tests/reference.py), the link bodies are Pinocchio's link
inertias, and the grouped bodies (every link's rotation-invariant part handed to its parent)
have Pinocchio's kinetic energy ``1/2 qd^T M(q) qd`` at random states (so the same M)."""
from __future__ import annotations

import numpy as np
import pytest
import symengine as se
import yaml

from kindyngen.algorithms.dynamics import frame_body, setup
from kindyngen.algorithms.rigid_bodies import (Body, JointFrame, cross, dot, flat, inertials, matTvec, matvec,
                                               sym_matmat, vadd, vscale)
from kindyngen.model.inertial_parameters import numeric_inertials, parameter_symbols, symbolic_inertials
from tests.harness import ROOT, robot

pin = pytest.importorskip("pinocchio")
from tests.reference import dh_numbers, pinocchio_model, random_configurations  # noqa: E402

TOL = 1e-12
ROBOTS = ("lwr4", "panda")


def _num(v):
    return np.array([float(x) for x in v])


def _mat(m):
    return np.array([[float(x) for x in row] for row in m])


def _rotation(rng):
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.diag(R)) * np.linalg.det(Q * np.sign(np.diag(R)))


def _se(a):
    return [se.RealDouble(float(x)) for x in a]


def _se_mat(A):
    return [_se(row) for row in A]


def _symmetric(rng):
    A = rng.normal(size=(3, 3))
    return A + A.T


def _body(rng):
    """A physical body: (m, com, inertia about the com) and its barycentric numbers about
    the frame origin (parallel axis, numpy)."""
    m, c = rng.uniform(0.5, 3.0), rng.normal(scale=0.2, size=3)
    L = rng.normal(size=(3, 3))
    Ic = L @ L.T * 0.01 + 0.01 * np.eye(3)
    I = Ic + m * (c @ c * np.eye(3) - np.outer(c, c))
    return (m, c, Ic), Body(se.RealDouble(m), _se(m * c), _se_mat(I))


def test_vector_algebra_equals_numpy():
    rng = np.random.default_rng(1)
    for _ in range(10):
        a, b, c = rng.normal(size=(3, 3))
        C, I, s = rng.normal(size=(3, 3)), _symmetric(rng), rng.normal()
        assert np.allclose(_num(vadd(_se(a), _se(b), _se(c))), a + b + c, rtol=0, atol=TOL)
        assert np.allclose(_num(vscale(se.RealDouble(s), _se(a))), s * a, rtol=0, atol=TOL)
        assert np.allclose(_num(cross(_se(a), _se(b))), np.cross(a, b), rtol=0, atol=TOL)
        assert abs(float(dot(_se(a), _se(b))) - a @ b) < TOL
        assert np.allclose(_num(matvec(_se_mat(C), _se(a))), C @ a, rtol=0, atol=TOL)
        assert np.allclose(_num(matTvec(_se_mat(C), _se(a))), C.T @ a, rtol=0, atol=TOL)
        assert np.allclose(_mat(sym_matmat(_se_mat(C), _se_mat(I))), C @ I @ C.T, rtol=0, atol=TOL)
        assert np.array_equal(_num(flat(_se_mat(C))), C.ravel())


def test_matvec_skips_exact_zeros():
    x = se.Symbol("x")
    out = matvec([[0, 1, 0], [0, 0, -1], [1, 0, 0]], [x, 2 * x, x ** 2])
    assert out == [2 * x, -x ** 2, x]


def test_joint_frame_rotations_equal_numpy():
    rng = np.random.default_rng(2)
    for _ in range(10):
        C, q, v = _rotation(rng), rng.uniform(-3, 3), rng.normal(size=3)
        frame = JointFrame(C=_se_mat(C), t=_se(rng.normal(size=3)), c=se.RealDouble(np.cos(q)),
                           s=se.RealDouble(np.sin(q)))
        Rz = np.array([[np.cos(q), -np.sin(q), 0], [np.sin(q), np.cos(q), 0], [0, 0, 1]])
        assert np.allclose(_num(frame.rot(_se(v))), C @ Rz @ v, rtol=0, atol=TOL)
        assert np.allclose(_num(frame.rot_t(_se(v))), (C @ Rz).T @ v, rtol=0, atol=TOL)


def _pin_body(inertia):
    """(m, h, I about the frame origin) of a pin.Inertia."""
    return inertia.mass, inertia.mass * inertia.lever, inertia.matrix()[3:, 3:]


def _assert_body(body: Body, m, h, I):
    assert abs(float(body.m) - m) <= TOL * max(1, abs(m))
    assert np.allclose(_num(body.h), h, rtol=0, atol=TOL)
    assert np.allclose(_mat(body.I), I, rtol=0, atol=TOL)


def test_body_moved_and_summed_as_pinocchio():
    rng = np.random.default_rng(3)
    for _ in range(10):
        (m, c, Ic), body = _body(rng)
        R, p = _rotation(rng), rng.normal(size=3)
        moved = body.moved(_se_mat(R), _se(p))
        _assert_body(moved, *_pin_body(pin.SE3(R, p).act(pin.Inertia(m, c, Ic))))
        _assert_body(body.moved(_se_mat(R), _se([0, 0, 0])), *_pin_body(pin.SE3(R, np.zeros(3)).act(
            pin.Inertia(m, c, Ic))))
        (m2, c2, Ic2), other = _body(rng)
        _assert_body(body + other, *_pin_body(pin.Inertia(m, c, Ic) + pin.Inertia(m2, c2, Ic2)))


@pytest.mark.parametrize("name", ROBOTS)
def test_from_inertials_is_the_parallel_axis_of_the_description(name):
    data = yaml.safe_load((ROOT / "robots" / f"{name}.yaml").read_text())
    for li, link in zip(numeric_inertials(robot(name)), data["links"]):
        m, c = float(link["mass"]), np.array(link["com"], float)
        ixx, iyy, izz, ixy, ixz, iyz = (float(v) for v in link["inertia"])
        Ic = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        _assert_body(Body.from_inertials(li), m, m * c, Ic + m * (c @ c * np.eye(3) - np.outer(c, c)))


def _frames_at(ts, q):
    """The joint frames' (R, p) in the base at q, composed from setup's JointFrames."""
    values = dict(zip(ts.q, q))
    R, p, out = np.eye(3), np.zeros(3), []
    for frame in ts.joints:
        c, s = float(frame.c.subs(values)), float(frame.s.subs(values))
        t = np.array([float(se.sympify(x).subs(values)) for x in frame.t])
        R_rel = _mat(frame.C) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        p, R = p + R @ t, R @ R_rel
        out.append((R, p))
    return out


def _joint_frame_in_pinocchios(model, j):
    """Joint frame j in Pinocchio's joint frame j of tests/reference.py: the same for standard
    DH (DH frame j-1 turned by q_j); for modified DH Pinocchio's joint sits d_j below the DH
    frame j on the joint axis (the link's d is its body placement there)."""
    d = dh_numbers(model)[2][j] if model.convention == "modified" else 0.0
    return pin.SE3(np.eye(3), np.array([0.0, 0.0, d]))


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_frames_and_link_bodies_are_pinocchios(name):
    model = robot(name)
    ts = setup(model, "numeric")
    pm, pd, _ = pinocchio_model(model)
    for q in random_configurations(model, 10, seed=26):
        pin.forwardKinematics(pm, pd, q)
        for j, (R, p) in enumerate(_frames_at(ts, q)):
            expected = pd.oMi[j + 1] * _joint_frame_in_pinocchios(model, j)
            assert np.allclose(R, expected.rotation, rtol=0, atol=TOL)
            assert np.allclose(p, expected.translation, rtol=0, atol=TOL)
    for j, (li, joint) in enumerate(zip(numeric_inertials(model), model.joints)):
        expected = _joint_frame_in_pinocchios(model, j).actInv(pm.inertias[j + 1])
        _assert_body(frame_body(li.as_vector(), joint.after), *_pin_body(expected))


def _kinetic_energy(body: Body, v, w) -> float:
    """1/2 m v.v + v.(w x h) + 1/2 w.I w (v: velocity of the frame origin, w: angular)."""
    m, h, I = float(body.m), _num(body.h), _mat(body.I)
    return 0.5 * m * v @ v + v @ np.cross(w, h) + 0.5 * w @ I @ w


@pytest.mark.parametrize("name", ROBOTS)
def test_grouped_bodies_keep_pinocchios_kinetic_energy(name):
    model = robot(name)
    ts = setup(model, "numeric")
    assert all(float(b.m) == 0 for b in ts.bodies)          # the grouping removed every mass
    pm, pd, _ = pinocchio_model(model)
    rng = np.random.default_rng(26)
    for q in random_configurations(model, 10, seed=27):
        qd = rng.normal(size=model.n)
        pin.forwardKinematics(pm, pd, q, qd)
        twists = [_joint_frame_in_pinocchios(model, j).actInv(pd.v[j + 1]) for j in range(model.n)]
        energy = sum(_kinetic_energy(b, v.linear, v.angular) for b, v in zip(ts.bodies, twists))
        M = pin.crba(pm, pd, q)
        M = np.triu(M) + np.triu(M, 1).T
        assert abs(energy - 0.5 * qd @ M @ qd) <= TOL * max(1.0, abs(qd @ M @ qd))


def test_collected_body_cancels_exactly():
    p = parameter_symbols(1)
    body = Body.from_inertials(symbolic_inertials(1, p)[0])
    assert body.m == p[0] and body.h == list(p[1:4]) and body.I[0] == [p[4], p[5], p[7]]
    # parts accumulated as in the grouping (XX - YY + YY): the difference vanishes once collected,
    # a common coefficient is paid once
    a = Body(p[0], [p[1], 2 * p[2] - p[2], se.Rational(1, 2) * p[3] + se.Rational(1, 2) * p[1]],
             [[p[4] - p[6] + p[6], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
    collected = a.collected()
    assert collected.h[1] == p[2] and collected.I[0][0] == p[4]
    assert collected.h[2] == se.Rational(1, 2) * (p[1] + p[3])
    assert Body(se.Integer(3), [se.Integer(1)] * 3, [[se.Integer(0)] * 3] * 3).collected().m == 3


def test_inertials_modes_and_refusal():
    model = robot("lwr4")
    links, ports, symbols = inertials(model, "numeric")
    assert ports == () and symbols == () and len(links) == model.n
    links, ports, symbols = inertials(model, "symbolic")
    assert [port.name for port in ports] == ["p"] and ports[0].shape == (70,)
    assert links[0].mass == symbols[0][0]
    with pytest.raises(ValueError, match="params must be one of"):
        inertials(model, "exact")

