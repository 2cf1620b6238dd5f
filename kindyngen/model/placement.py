"""Constant rigid placements, exact: how a joint sits on its parent link, whatever the
description (DH row, URDF origin and axis, tool frame).

A :class:`Placement` is a product of elementary factors, kept as factors (not as a matrix)
so that each consumer builds the form it needs without rounding: the rotation matrix and
translation (:meth:`Placement.matrix`, exact sympy), or the dual quaternion (products of
half-angle rotations, in :mod:`kindyngen.algorithms.dualquat.dq_kinematics`). Factors are

* ``("trans", (x, y, z))``: a translation;
* ``("rot", (ux, uy, uz), angle)``: a rotation by ``angle`` about the unit axis u.

Every joint of a :class:`kindyngen.model.robot_model.RobotModel` is ``before * motion(q) * after``:
``before`` places the joint frame (its z axis is the joint axis) on the parent link frame,
``motion`` is ``Rz(q + offset)`` (revolute) or ``Tz(q + offset)`` (prismatic), and ``after``
places the joint's link frame on the moved joint frame. A standard DH row is
``before = 1, after = Tz(d) Tx(a) Rx(alpha)``; a modified one ``before = Rx(alpha) Tx(a) Tz(d),
after = 1``; a URDF joint ``before = T(xyz) Rz(yaw) Ry(pitch) Rx(roll) A, after = A^-1`` with A
turning z onto the joint axis.

Angles written as floats are cleaned by :func:`clean_angle`: a double within 1e-12 of a
multiple of pi/12 (pi/2, pi/4, pi/6 and their multiples) is that multiple; within 1e-5 it is
snapped with a note (URDFs write 1.5708 or 1.570796 for pi/2).

Example:

>>> import sympy
>>> R, p = Placement((("trans", (1, 0, 0)), ("rot", (0, 0, 1), sympy.pi / 2))).matrix()
>>> R.tolist(), p.T.tolist()
([[0, -1, 0], [1, 0, 0], [0, 0, 1]], [[1, 0, 0]])
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import sympy

X, Y, Z = (1, 0, 0), (0, 1, 0), (0, 0, 1)
EXACT_ANGLE_TOLERANCE = 1e-12   # a float this close to a multiple of pi/12 is that multiple
SNAP_ANGLE_TOLERANCE = 1e-5     # this close: snapped, with a note (unless the user keeps it)
ZERO_TOLERANCE = 1e-12          # |x| below this in an axis or angle (6.1e-17 = cos(pi/2)) is 0
ANGLE_STEP = 12                 # multiples of pi/12 are recognised


@dataclass(frozen=True)
class Placement:
    """A constant rigid transform as a product of exact elementary factors."""

    factors: tuple = ()

    def __mul__(self, other: "Placement") -> "Placement":
        return Placement(self.factors + other.factors)

    @property
    def is_identity(self) -> bool:
        return not self.factors

    def inverse(self) -> "Placement":
        """The inverse transform, again as factors (reversed, negated)."""
        out = []
        for factor in reversed(self.factors):
            if factor[0] == "trans":
                out.append(("trans", tuple(-v for v in factor[1])))
            else:
                out.append(("rot", factor[1], -factor[2]))
        return Placement(tuple(out))

    def matrix(self) -> tuple[sympy.Matrix, sympy.Matrix]:
        """(R, p): rotation 3x3 and translation 3x1, exact sympy."""
        R, p = sympy.eye(3), sympy.zeros(3, 1)
        for factor in self.factors:
            if factor[0] == "trans":
                p = p + R * sympy.Matrix(factor[1])
            else:
                R = R * rotation_matrix(factor[1], factor[2])
        return R.applyfunc(_tidy), p.applyfunc(_tidy)


def _tidy(value):
    """Cheap exact simplification of a constant (no general simplify: it can be slow)."""
    value = sympy.sympify(value)
    if value.is_Rational or value.is_Symbol:
        return value
    expanded = sympy.expand(value)
    return expanded if sympy.count_ops(expanded) <= sympy.count_ops(value) else value


def rotation_matrix(axis, angle) -> sympy.Matrix:
    """Exact rotation by ``angle`` about the unit ``axis`` (Rodrigues)."""
    c, s = sympy.cos(angle), sympy.sin(angle)
    if tuple(axis) == X:
        return sympy.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])
    if tuple(axis) == Y:
        return sympy.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    if tuple(axis) == Z:
        return sympy.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    u = sympy.Matrix(axis)
    K = sympy.Matrix([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return sympy.eye(3) * c + K * s + (u * u.T) * (1 - c)


def translation(x, y, z) -> Placement:
    """A pure translation (identity when zero)."""
    if all(sympy.sympify(v) == 0 for v in (x, y, z)):
        return Placement()
    return Placement((("trans", (sympy.sympify(x), sympy.sympify(y), sympy.sympify(z))),))


def rotation(axis, angle) -> Placement:
    """A rotation about a unit axis (identity for a zero angle)."""
    angle = sympy.sympify(angle)
    if angle == 0:
        return Placement()
    return Placement((("rot", tuple(sympy.sympify(v) for v in axis), angle),))


def dh_standard(a, alpha, d, theta=0) -> tuple[Placement, Placement]:
    """(before, after) of a standard DH row ``Rz(theta) Rz(q) Tz(d) Tx(a) Rx(alpha)``
    (``theta``: a prismatic joint's constant angle; a revolute joint's offset is not a
    placement but part of its motion)."""
    return rotation(Z, theta), translation(a, 0, d) * rotation(X, alpha)


def dh_modified(a, alpha, d, theta=0) -> tuple[Placement, Placement]:
    """(before, after) of a modified (Craig) DH row ``Rx(alpha) Tx(a) Rz(theta) Tz(d) Rz(q)``
    (Tz(d) commutes with Rz, so it is placed before the joint)."""
    return rotation(X, alpha) * translation(a, 0, d) * rotation(Z, theta), Placement()


def rpy_xyz(xyz, rpy) -> Placement:
    """URDF ``<origin xyz rpy>``: ``T(xyz) Rz(yaw) Ry(pitch) Rx(roll)``."""
    roll, pitch, yaw = rpy
    return translation(*xyz) * rotation(Z, yaw) * rotation(Y, pitch) * rotation(X, roll)


def axis_alignment(axis) -> Placement:
    """A rotation A with ``A e_z = axis`` (unit, exact): a signed permutation for the
    coordinate axes, else the shortest rotation.

    >>> axis_alignment((0, 1, 0)).factors
    (('rot', (1, 0, 0), -pi/2),)
    """
    axis = tuple(sympy.sympify(v) for v in axis)
    table = {Z: Placement(), (0, 0, -1): rotation(X, sympy.pi), X: rotation(Y, sympy.pi / 2),
             (-1, 0, 0): rotation(Y, -sympy.pi / 2), Y: rotation(X, -sympy.pi / 2),
             (0, -1, 0): rotation(X, sympy.pi / 2)}
    if axis in table:
        return table[axis]
    ux, uy, uz = axis
    norm = sympy.sqrt(ux ** 2 + uy ** 2)       # |e_z x u|, > 0 off the z axis
    return rotation((-uy / norm, ux / norm, 0), sympy.acos(uz))


def unit_axis(values) -> tuple:
    """A direction as an exact unit vector (exact components of the cleaned decimals).

    >>> unit_axis((0, 0, 2)), unit_axis((1, 1, 0))
    ((0, 0, 1), (sqrt(2)/2, sqrt(2)/2, 0))
    """
    exact = [sympy.Integer(0) if abs(float(v)) < ZERO_TOLERANCE else sympy.Rational(repr(float(v)))
             for v in values]
    norm = sympy.sqrt(sum(v ** 2 for v in exact))
    return tuple(v / norm for v in exact)


@dataclass(frozen=True)
class CleanAngle:
    """An angle read from a float: its exact value and, when it was snapped, a note."""

    value: sympy.Expr
    note: str | None = None


def clean_angle(value: float, field: str, snap: bool = True) -> CleanAngle:
    """A float angle as an exact value: a multiple k pi/12 when within 1e-12 of it (read as
    that multiple: the float was written for it), within 1e-5 snapped with a note (unless
    ``snap`` is False), else the decimal as written (exact rational).

    >>> clean_angle(1.5707963267948966, "alpha").value, clean_angle(6.1e-17, "rpy").value
    (pi/2, 0)
    >>> clean_angle(1.5708, "rpy").note
    'rpy: 1.5708 read as pi/2 (off by 3.7e-06 rad; keep the value as written with --keep-angles)'
    >>> clean_angle(0.3, "rpy").value
    3/10
    """
    x = float(value)
    k = round(x * ANGLE_STEP / math.pi)
    multiple = sympy.pi * sympy.Rational(k, ANGLE_STEP)
    error = abs(x - k * math.pi / ANGLE_STEP)
    if error <= EXACT_ANGLE_TOLERANCE:
        return CleanAngle(multiple)
    if snap and error <= SNAP_ANGLE_TOLERANCE:
        return CleanAngle(multiple, f"{field}: {x!r} read as {sympy.sstr(multiple)} (off by {error:.2g} rad; "
                                    f"keep the value as written with --keep-angles)")
    return CleanAngle(sympy.Rational(repr(x)))


TINY_LENGTH = 1e-12     # m: below, a rounding residue (6.1e-17 = 1 m cos(pi/2)), not a design


def exact_length(value: float) -> sympy.Rational:
    """A length written as a float, exact: the rational of its decimal, 0 below a picometre.

    >>> exact_length(0.333), exact_length(6.1e-17)
    (333/1000, 0)
    """
    return sympy.Integer(0) if abs(value) < TINY_LENGTH else sympy.Rational(repr(float(value)))


@dataclass
class Reading:
    """What reading one description file needs besides its data: its name, whether
    near-exact angles are snapped, and the notes (in order, each once) the user is shown
    about what reading changed. Shared by the YAML and the URDF reader."""

    source: str
    snap_angles: bool = True
    notes: list = field(default_factory=list)

    def note(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def angle(self, value: float, what: str) -> sympy.Expr:
        """A float angle cleaned by :func:`clean_angle`, its note (if snapped) kept.

        >>> r = Reading("f.urdf"); r.angle(1.5708, "rpy[0]"), len(r.notes)
        (pi/2, 1)
        """
        cleaned = clean_angle(value, f"{self.source}: {what}", self.snap_angles)
        if cleaned.note:
            self.note(cleaned.note)
        return cleaned.value
