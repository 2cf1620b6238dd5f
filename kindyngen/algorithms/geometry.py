"""Exact per-joint geometry as symengine expressions: ``before * motion(q) * after`` of
every joint (:mod:`kindyngen.model.placement`), whatever the description gave (DH row, URDF
origin and axis).

Constants stay exact, so cos(pi/2) is the integer 0 and the zeros and ones of the LWR's
table vanish before any code exists. A standard DH row gives ``Rz(q_i + offset_i) Tz(d_i)
Tx(a_i) Rx(alpha_i)``, a modified (Craig) one ``Rx(alpha_{i-1}) Tx(a_{i-1}) Tz(d_i)
Rz(q_i + offset_i)``; a prismatic joint moves along z instead (``Tz(q_i + offset_i)``).

Example:

>>> import sympy, symengine as se
>>> from kindyngen.model.robot_model import Joint
>>> from kindyngen.model.placement import dh_standard
>>> before, after = dh_standard(0, sympy.pi / 2, sympy.Rational(2, 5))
>>> j = Joint(before=before, after=after, offset=0, lower=-1, upper=1)
>>> R, p = joint_transform(j, se.Symbol("q"))
>>> R.tolist()[2], p.tolist()
([0, 1, 0], [[0], [0], [2/5]])
"""
from __future__ import annotations

from fractions import Fraction

import sympy
import symengine as se

from ..model.robot_model import Joint
from ..model.placement import Placement


def exact(value) -> se.Basic:
    """A sympy constant as an exact symengine number."""
    return se.sympify(sympy.nsimplify(value) if isinstance(value, float) else value)


def _cos_sin_exact(angle) -> tuple[se.Basic, se.Basic]:
    angle = sympy.sympify(angle)
    return se.sympify(sympy.cos(angle)), se.sympify(sympy.sin(angle))


def joint_cos_sin(q: se.Symbol, offset) -> tuple[se.Basic, se.Basic]:
    """cos and sin of ``q + offset``. A multiple of pi/4 as offset becomes exact constants
    (a sign, a swap, or sqrt(2)/2); any other offset stays inside the call (one addition
    instead of a rotation)."""
    offset = sympy.sympify(offset)
    if offset == 0:
        return se.cos(q), se.sin(q)
    if (4 * offset / sympy.pi).is_integer:
        co, so = _cos_sin_exact(offset)
        c, s = se.cos(q), se.sin(q)
        return c * co - s * so, s * co + c * so
    theta = q + exact(offset)
    return se.cos(theta), se.sin(theta)


def rot_z(c, s) -> se.Matrix:
    return se.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def rot_x(c, s) -> se.Matrix:
    return se.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def constant_transform(placement: Placement) -> tuple[se.Matrix, se.Matrix] | None:
    """A placement as symengine (R, p), or None for the identity (nothing to multiply)."""
    if placement.is_identity:
        return None
    R, p = placement.matrix()
    return (se.Matrix([[constant(R[r, c]) for c in range(3)] for r in range(3)]),
            se.Matrix([constant(p[r]) for r in range(3)]))


def constant_parts(placement: Placement) -> tuple[list, list]:
    """A placement as (R as 3x3 nested lists, p as a list) of :func:`constant` entries: the
    form the joint-frame recursions compute with."""
    R, p = placement.matrix()
    return [[constant(R[r, c]) for c in range(3)] for r in range(3)], [constant(p[r]) for r in range(3)]


def constant(value) -> se.Basic:
    """The one sympy-to-symengine conversion of constants (placements, IK geometry, joint
    frames): exact where sympy has a closed form (rationals, sqrt(2)/2, symbols), else the
    double nearest its 30-digit value (cos(3/10); evaluated by mpmath, the same on every
    machine), held as the exact rational of that double. Exact, not a symengine RealDouble,
    because everything computed from it after is then exact arithmetic too (rounded once, where
    the code is printed), and because symengine 0.15 hashes a RealDouble by the low 32 bits of
    its bits alone: 1.0, -1.0, 2.0 and 0.5 hash alike, so do x and -x, and c*X and -c*X with
    them; CSE's hash maps then fall back to structural comparisons that are not shared over the
    DAG and took exponential time (the UR5's right angles kept as 1.57079632679 never finished
    fd_derivatives' CSE; docs/measurements/trees.md).

    >>> c = constant(sympy.cos(sympy.Rational(3, 10)))
    >>> c.is_Rational, float(c) == float(sympy.cos(sympy.Rational(3, 10)).evalf(50))
    (True, True)
    """
    value = sympy.sympify(value)
    if value.free_symbols or not value.has(sympy.cos, sympy.sin, sympy.acos, sympy.asin, sympy.atan, sympy.atan2,
                                           sympy.tan):
        return se.sympify(value)
    nearest = Fraction(float(value.evalf(30)))
    return se.Integer(nearest.numerator) / se.Integer(nearest.denominator)


def motion(joint: Joint, q: se.Symbol, cos_sin=None) -> tuple[se.Matrix, se.Matrix]:
    """Rz(q + offset) of a revolute joint (``cos_sin``: already-built cos/sin of the angle,
    so that every derived function shares the same call objects), Tz(q + offset) of a
    prismatic one."""
    if joint.prismatic:
        return se.eye(3), se.Matrix([0, 0, q + exact(joint.offset)])
    c, s = cos_sin if cos_sin is not None else joint_cos_sin(q, joint.offset)
    return rot_z(c, s), se.zeros(3, 1)


def compose(first, second):
    """(R1, p1) * (R2, p2), skipping identities (None)."""
    if first is None:
        return second
    if second is None:
        return first
    (R1, p1), (R2, p2) = first, second
    return R1 * R2, p1 + R1 * p2


def joint_transform(joint: Joint, q: se.Symbol, cos_sin=None) -> tuple[se.Matrix, se.Matrix]:
    """Rotation (3x3) and translation (3x1) of the joint's link frame in its parent link's
    frame: ``before * motion(q) * after``."""
    out = compose(compose(constant_transform(joint.before), motion(joint, q, cos_sin)),
                  constant_transform(joint.after))
    return out
