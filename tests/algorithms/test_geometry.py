"""kindyngen.algorithms.geometry: each joint's exact transform ``before * motion(q) * after`` against the
DH formulas written out in plain numpy (standard and modified rows, revolute and prismatic,
offsets that are multiples of pi/4 and offsets that are not), and the exactness it promises:
cos(pi/2) is the integer 0, a pi/4 offset costs no call, a constant without a closed form is
the double nearest its value."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import sympy
import symengine as se

from kindyngen.algorithms.geometry import compose, constant, joint_cos_sin, joint_transform
from kindyngen.model.robot_model import Joint
from kindyngen.model.placement import dh_modified, dh_standard, rpy_xyz

Q = se.Symbol("q")


def _rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])


def _t(x, y, z):
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


def _numeric(joint, q):
    R, p = joint_transform(joint, Q)
    T = np.eye(4)
    T[:3, :3] = np.array(R.subs({Q: q}).tolist(), dtype=float)
    T[:3, 3] = np.array(p.subs({Q: q}).tolist(), dtype=float)[:, 0]
    return T


ROWS = [  # a, alpha, d, offset (exact)
    (0, sympy.pi / 2, sympy.Rational(31, 100), 0),
    (sympy.Rational(2, 5), -sympy.pi / 2, 0, sympy.pi / 4),
    (sympy.Rational(-7, 100), sympy.pi, sympy.Rational(1, 8), -3 * sympy.pi / 4),
    (sympy.Rational(1, 3), sympy.Rational(3, 10), sympy.Rational(-1, 5), sympy.Rational(3, 10)),
]


@pytest.mark.parametrize("row", ROWS, ids=range(len(ROWS)))
@pytest.mark.parametrize("convention", ("standard", "modified"))
@pytest.mark.parametrize("kind", ("revolute", "prismatic"))
def test_joint_transform_is_the_dh_formula(row, convention, kind):
    a, alpha, d, offset = row
    af, alf, df, of = (float(v) for v in row)
    theta = offset if kind == "prismatic" else 0          # a prismatic joint's constant angle
    place = dh_standard if convention == "standard" else dh_modified
    before, after = place(a, alpha, d, theta)
    joint = Joint(before=before, after=after, offset=0 if kind == "prismatic" else offset, lower=-1, upper=1,
                  kind=kind)
    for q in np.random.default_rng(5).uniform(-3, 3, 4):
        rz = _rz(of) @ _t(0, 0, q) if kind == "prismatic" else _rz(q + of)
        if convention == "standard":
            expected = rz @ _t(0, 0, df) @ _t(af, 0, 0) @ _rx(alf)
        else:
            expected = _rx(alf) @ _t(af, 0, 0) @ _t(0, 0, df) @ rz
        np.testing.assert_allclose(_numeric(joint, q), expected, rtol=0, atol=1e-14)


def test_urdf_origin_joint_is_translation_then_rpy_then_motion():
    """T(xyz) Rz(yaw) Ry(pitch) Rx(roll) Rz(q), pitch 0 here."""
    xyz, rpy = (sympy.Rational(1, 10), 0, sympy.Rational(1, 3)), (sympy.pi / 2, 0, sympy.Rational(1, 5))
    joint = Joint(before=rpy_xyz(xyz, rpy), after=rpy_xyz((0, 0, 0), (0, 0, 0)), offset=0, lower=-1, upper=1)
    for q in (-1.2, 0.4, 2.9):
        expected = _t(0.1, 0, 1 / 3) @ _rz(0.2) @ _rx(math.pi / 2) @ _rz(q)
        np.testing.assert_allclose(_numeric(joint, q), expected, rtol=0, atol=1e-14)


def test_right_angles_give_exact_zeros_and_ones():
    before, after = dh_standard(0, sympy.pi / 2, sympy.Rational(31, 100))
    R, p = joint_transform(Joint(before=before, after=after, offset=0, lower=-1, upper=1), Q)
    assert R[2, :].tolist() == [[0, 1, 0]] and all(isinstance(v, se.Integer) for v in R[2, :].tolist()[0])
    assert p.tolist() == [[0], [0], [se.Rational(31, 100)]]


def test_offsets_on_the_pi_over_4_grid_cost_no_call():
    for offset in (sympy.pi / 2, -sympy.pi, sympy.pi / 4):
        c, s = joint_cos_sin(Q, offset)
        calls = c.atoms(se.cos, se.sin) | s.atoms(se.cos, se.sin)
        assert calls <= {se.cos(Q), se.sin(Q)}, (offset, c, s)
        for q in (-0.7, 1.9):
            assert abs(float(c.subs({Q: q})) - math.cos(q + float(offset))) < 1e-15
            assert abs(float(s.subs({Q: q})) - math.sin(q + float(offset))) < 1e-15
    c, _ = joint_cos_sin(Q, sympy.Rational(3, 10))            # off the grid: inside the call
    assert c == se.cos(Q + se.Rational(3, 10))


def test_constants_are_exact_or_the_nearest_double():
    assert constant(sympy.sqrt(2) / 2) == se.sqrt(2) / 2
    assert constant(sympy.Rational(2, 5)) == se.Rational(2, 5)
    value = constant(sympy.cos(sympy.Rational(3, 10)))
    assert value.is_Rational                  # the double held exactly: no se.RealDouble in a DAG
    nearest = Fraction(float(sympy.cos(sympy.Rational(3, 10)).evalf(50)))     # correctly rounded
    assert (int(value.p), int(value.q)) == (nearest.numerator, nearest.denominator)
    assert abs(float(value) - math.cos(0.3)) <= math.ulp(math.cos(0.3))


def test_compose_skips_identities():
    T = (se.eye(3), se.Matrix([1, 2, 3]))
    assert compose(None, T) is T and compose(T, None) is T and compose(None, None) is None
    R = se.Matrix([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    Rc, pc = compose((R, se.Matrix([1, 0, 0])), (se.eye(3), se.Matrix([1, 0, 0])))
    assert Rc == R and pc == se.Matrix([1, 1, 0])            # p1 + R1 p2
