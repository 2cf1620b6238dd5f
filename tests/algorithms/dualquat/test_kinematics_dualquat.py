"""kindyngen.algorithms.dualquat.dq_kinematics's algebra on its own: the Hamilton product against scipy's
rotation composition, dual-quaternion products against 4x4 matrix products, the conjugate as
the inverse, and each joint's constant factors A M(q) B against the DH formula written out in
numpy (the whole fk_dq is held to fk_hom, itself to Pinocchio, in tests/algorithms/test_kinematics.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy
from scipy.spatial.transform import Rotation

from kindyngen.algorithms.dualquat.dq_kinematics import dq_conjugate, dq_mul, joint_factors, placement_dq, quat_mul
from kindyngen.model.robot_model import Joint
from kindyngen.model.placement import dh_modified, dh_standard, rpy_xyz

RNG = np.random.default_rng(17)


def _num(quat):
    return np.array([float(v) for v in quat])


def _scipy(quat_wxyz):
    return Rotation.from_quat(np.roll(quat_wxyz, -1))          # scipy is scalar-last


def _hom(dq):
    """4x4 of a unit dual quaternion (r, d): R from r, t = 2 d r* (vector part)."""
    r, d = _num(dq[0]), _num(dq[1])
    T = np.eye(4)
    T[:3, :3] = _scipy(r).as_matrix()
    rc = r * np.array([1, -1, -1, -1])
    T[:3, 3] = 2 * _num(quat_mul(tuple(d), tuple(rc)))[1:]
    return T


def _dq(T):
    """A unit dual quaternion of a 4x4 (independent of the package: scipy and the formula
    d = 1/2 t r, Hamilton product written out here)."""
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    r = np.array([w, x, y, z])
    t = np.array([0.0, *T[:3, 3]])
    tw, tx, ty, tz = t
    d = 0.5 * np.array([tw * w - tx * x - ty * y - tz * z, tw * x + tx * w + ty * z - tz * y,
                        tw * y - tx * z + ty * w + tz * x, tw * z + tx * y - ty * x + tz * w])
    return tuple(r), tuple(d)


def _random_T():
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=RNG.integers(1 << 30)).as_matrix()
    T[:3, 3] = RNG.uniform(-1, 1, 3)
    return T


def test_hamilton_product_composes_rotations():
    for _ in range(5):
        a, b = Rotation.random(random_state=RNG.integers(1 << 30)), Rotation.random(random_state=RNG.integers(1 << 30))
        wa, wb = np.roll(a.as_quat(), 1), np.roll(b.as_quat(), 1)
        product = _num(quat_mul(tuple(wa), tuple(wb)))
        np.testing.assert_allclose(_scipy(product).as_matrix(), (a * b).as_matrix(), atol=1e-14)


def test_dual_quaternion_product_is_the_matrix_product_and_conjugate_the_inverse():
    for _ in range(5):
        A, B = _random_T(), _random_T()
        np.testing.assert_allclose(_hom(dq_mul(_dq(A), _dq(B))), A @ B, atol=1e-13)
        np.testing.assert_allclose(_hom(dq_conjugate(_dq(A))), np.linalg.inv(A), atol=1e-13)


def test_urdf_placement():
    xyz, rpy = (0.1, -0.25, 0.333), (0.3, -1.1, 2.0)
    placement = rpy_xyz([sympy.nsimplify(v) for v in xyz], [sympy.nsimplify(v) for v in rpy])
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()       # extrinsic x, y, z = Rz Ry Rx
    T[:3, 3] = xyz
    np.testing.assert_allclose(_hom(placement_dq(placement)), T, atol=1e-14)


def _rz(t):
    out = np.eye(4)
    out[:2, :2] = [[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]
    return out


def _rx(t):
    out = np.eye(4)
    out[1:3, 1:3] = [[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]
    return out


def _tr(x, y, z):
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


@pytest.mark.parametrize("convention", ("standard", "modified"))
@pytest.mark.parametrize("kind", ("revolute", "prismatic"))
def test_joint_factors_are_the_dh_formula(convention, kind):
    a, alpha, d, offset = sympy.Rational(2, 5), -sympy.pi / 2, sympy.Rational(1, 8), sympy.Rational(3, 10)
    place = dh_standard if convention == "standard" else dh_modified
    before, after = place(a, alpha, d)
    A, B = joint_factors(Joint(before=before, after=after, offset=offset, lower=-1, upper=1, kind=kind))
    for q in RNG.uniform(-2, 2, 3):
        motion = _tr(0, 0, q + 0.3) if kind == "prismatic" else _rz(q + 0.3)
        M = _dq(_tr(0, 0, q) if kind == "prismatic" else _rz(q))     # the offset is folded into A
        expected = (motion @ _tr(0, 0, 1 / 8) @ _tr(0.4, 0, 0) @ _rx(-math.pi / 2) if convention == "standard"
                    else _rx(-math.pi / 2) @ _tr(0.4, 0, 0) @ _tr(0, 0, 1 / 8) @ motion)
        np.testing.assert_allclose(_hom(dq_mul(dq_mul(A, M), B)), expected, atol=1e-14)


@pytest.mark.parametrize("robot", ("lwr4", "panda"))
def test_fk_dq_routes_are_one_function(robot):
    """fk_dq of an arm with a spherical triple has two routes (dq_kinematics.ROUTES): the sines and
    cosines of the triple's a +- c directly, or by the addition formulas from those of its half
    angles a and c. The same dual quaternion at random angles; the second's sin/cos arguments are
    halves of joint angles only (what lets the C kernel read q in place)."""
    import symengine as se
    from kindyngen.algorithms.dualquat.dq_kinematics import fk_dq
    from kindyngen.readers.yaml_description import load_robot
    from tests.harness import ROOT
    f = fk_dq(load_robot(ROOT / "robots" / f"{robot}.yaml"))
    routes = {g.metadata["route"]: g for g in (f, *f.alternatives)}
    assert set(routes) == {"half angles", "sum angles"} and f.metadata["route"] == "half angles"
    q = f.input_symbols[0]
    halves = {se.Rational(1, 2) * s for s in q}
    arguments = {name: {call.args[0] for e in g.output_exprs[0] for call in se.sympify(e).atoms(se.sin, se.cos)}
                 for name, g in routes.items()}
    assert arguments["half angles"] <= halves and not arguments["sum angles"] <= halves
    values = {name: se.Lambdify(list(q), list(g.output_exprs[0])) for name, g in routes.items()}
    for angles in RNG.uniform(-3, 3, (20, len(q))):
        np.testing.assert_allclose(values["half angles"](angles), values["sum angles"](angles), atol=1e-14)
