"""Exact per-joint DH geometry as symengine expressions.

Constants (alpha, a, d, offsets) stay exact, so cos(pi/2) is the integer 0 and the zeros and
ones of the LWR's table vanish before any code exists.  Standard DH:
``T_i = Rz(q_i + offset_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``; modified (Craig) DH:
``T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(q_i + offset_i) Tz(d_i)``.

Example:

>>> import sympy, symengine as se
>>> from kindyngen.robot import Joint
>>> j = Joint(a=0, alpha=sympy.pi / 2, d=sympy.Rational(2, 5), offset=0, lower=-1, upper=1)
>>> R, p = joint_transform(j, "standard", se.Symbol("q"))
>>> R.tolist()[2], p.tolist()
([0, 1, 0], [[0], [0], [2/5]])
"""
from __future__ import annotations

import sympy
import symengine as se

from .robot import Joint


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


def joint_transform(joint: Joint, convention: str, q: se.Symbol, cos_sin=None) -> tuple[se.Matrix, se.Matrix]:
    """Rotation (3x3) and translation (3x1) of frame i in frame i-1.

    ``cos_sin`` lets a caller pass already-built cos/sin of the joint angle so that every
    derived function shares the same call objects."""
    c, s = cos_sin if cos_sin is not None else joint_cos_sin(q, joint.offset)
    ca, sa = _cos_sin_exact(joint.alpha)
    a, d = exact(joint.a), exact(joint.d)
    if convention == "standard":
        rotation = rot_z(c, s) * rot_x(ca, sa)
        translation = se.Matrix([a * c, a * s, d])
    else:
        rotation = rot_x(ca, sa) * rot_z(c, s)
        translation = se.Matrix([a, -sa * d, ca * d])
    return rotation, translation


def joint_axis_in_previous(convention: str) -> bool:
    """Standard DH puts joint i on the z axis of frame i-1; modified DH on that of frame i."""
    return convention == "standard"
