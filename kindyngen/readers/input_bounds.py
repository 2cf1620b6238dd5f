"""What a robot description may hold: file sizes, the magnitude of every number, the plausible
range of each physical quantity, and angles within a full turn. Shared by the YAML and the URDF
reader; every rule is stated in docs/reference/description.md ("Limits and refused inputs").

A description from the internet is data: whatever it holds, reading it ends in a model or in
one :class:`kindyngen.model.robot_model.RobotDescriptionError` naming the file, the field and
the reason, in bounded time. The ranges are far beyond any real robot, so that a value outside
one is a mistake (a unit, a typo, a placeholder) and never a design, and so that no product
computed from the model (link parameters, regressors, the base parameters' factorisation)
leaves the range of a double.

Example:

>>> check_quantity(0.4, "length", "arm.yaml", "joints[1].a")
>>> check_quantity(400.0, "length", "arm.yaml", "joints[1].a")
>>> check_quantity(4000.0, "length", "arm.yaml", "joints[1].a")
Traceback (most recent call last):
...
kindyngen.model.robot_model.RobotDescriptionError: arm.yaml: field 'joints[1].a': 4000 m is beyond the plausible range of a length (|x| <= 1000 m; millimetres? lengths are in metres)
>>> check_angle(90.0, "arm.yaml", "joints[0].alpha")
Traceback (most recent call last):
...
kindyngen.model.robot_model.RobotDescriptionError: arm.yaml: field 'joints[0].alpha': 90 rad is beyond a full turn (|angle| <= 2*pi); angles are in radians and 90 looks like degrees: for 90 degrees write pi/2 (1.5708)
"""
from __future__ import annotations

import math
import reprlib
from pathlib import Path

import sympy

from ..model.robot_model import RobotDescriptionError

MAX_YAML_BYTES = 1 << 20     # 1 MiB: 1000 joints and links written as in docs/reference/trees.md: 0.21 MB
MAX_URDF_BYTES = 8 << 20     # 8 MiB: example-robot-data's largest URDF is 0.2 MB
SMALLEST, LARGEST = 1e-100, 1e100   # every nonzero number: products of three stay doubles
# the plausible range of each quantity, |x| <= bound (SI units), and what the messages call it
QUANTITIES = {"length": (1e3, "m", "a length"),            # a, d, xyz, com, prismatic limits
              "mass": (1e6, "kg", "a mass"),
              "inertia": (1e12, "kg m^2", "an inertia"),   # mass times length squared; armature
              "gravity": (1e3, "m/s^2", "gravity"),        # each component: about 100 g
              "coefficient": (1e12, "", "a coefficient")}  # friction, stiffness, gains, offsets
FULL_TURN = 2 * math.pi
TURN_SLACK = 1e-4            # 2*pi written with few decimals (6.2832) is still a full turn
DEGREES_UP_TO = 720.0        # beyond a full turn and up to two turns in degrees: probably degrees

# error messages show a value this much at most (a field may hold a list of a million items)
_SHOWN = reprlib.Repr()
_SHOWN.maxlist = _SHOWN.maxtuple = _SHOWN.maxdict = 6
_SHOWN.maxlevel = 3
_SHOWN.maxstring = _SHOWN.maxother = 60


def shown(value) -> str:
    """A value as an error message shows it: its repr, cut short (bounded time and length
    whatever the value, a nested or self-referencing list included).

    >>> shown([0.25, 0, 0]), shown(list(range(100)))
    ('[0.25, 0, 0]', '[0, 1, 2, 3, 4, 5, ...]')
    """
    return _SHOWN.repr(value)


def check_number(value: float, source: str, field: str) -> None:
    """Any number of a description: 0 or a magnitude between 1e-100 and 1e100.

    >>> check_number(1e-120, "f.urdf", "mass")
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.urdf: field 'mass': 1e-120 is below 1e-100 in magnitude (write 0 if zero is meant)
    """
    magnitude = abs(value)
    if not magnitude <= LARGEST:        # also NaN
        raise RobotDescriptionError(source, field, f"{value:g} is beyond +-{LARGEST:g}: no quantity of a robot "
                                                   f"is that large")
    if 0 < magnitude < SMALLEST:
        raise RobotDescriptionError(source, field, f"{value:g} is below {SMALLEST:g} in magnitude "
                                                   f"(write 0 if zero is meant)")


def check_quantity(value: float, quantity: str, source: str, field: str) -> None:
    """A number of a physical ``quantity`` (a key of :data:`QUANTITIES`): :func:`check_number`
    and within the quantity's plausible range."""
    check_number(value, source, field)
    bound, unit, noun = QUANTITIES[quantity]
    if abs(value) > bound:
        hint = "; millimetres? lengths are in metres" if quantity == "length" and abs(value) <= 1e6 else ""
        units = f" {unit}" if unit else ""
        raise RobotDescriptionError(source, field, f"{value:g}{units} is beyond the plausible range of {noun} "
                                                   f"(|x| <= {bound:g}{units}{hint})")


def beyond_turn(value: float) -> bool:
    """Whether an angle exceeds a full turn (2 pi, with :data:`TURN_SLACK`).

    >>> beyond_turn(6.2832), beyond_turn(-6.3), beyond_turn(90)
    (False, True, True)
    """
    return abs(value) > FULL_TURN + TURN_SLACK


def degrees_hint(value: float) -> str:
    """What ``value`` is if it was written in degrees, for values that look so ('' for others).

    >>> degrees_hint(-170.0)
    '-170 looks like degrees: for -170 degrees write -17*pi/18 (-2.96706)'
    >>> degrees_hint(1e16)
    ''
    """
    if not FULL_TURN < abs(value) <= DEGREES_UP_TO:
        return ""
    exact = sympy.Rational(repr(float(value))) * sympy.pi / 180
    return f"{value:g} looks like degrees: for {value:g} degrees write {sympy.sstr(exact)} ({math.radians(value):.6g})"


def check_angle(value: float, source: str, field: str) -> None:
    """A geometric angle (DH alpha, theta, offset; an origin's rpy): within a full turn. No
    placement needs more, and a larger value is almost always an angle in degrees."""
    check_number(value, source, field)
    if beyond_turn(value):
        hint = degrees_hint(value)
        raise RobotDescriptionError(source, field, f"{value:g} rad is beyond a full turn (|angle| <= 2*pi)"
                                                   + (f"; angles are in radians and {hint}" if hint else ""))


def read_bounded(path: str | Path, limit: int, what: str) -> bytes:
    """A file's bytes, refused beyond ``limit`` bytes (read no further than limit + 1, so a
    pipe or a huge file costs no more than that).

    >>> read_bounded("robots/lwr4.yaml", MAX_YAML_BYTES, "a YAML description")[:5]  # doctest: +SKIP
    b'# KUK'
    """
    try:
        with open(path, "rb") as stream:
            data = stream.read(limit + 1)
    except OSError as exc:
        raise RobotDescriptionError(str(path), "<file>", f"cannot read: {exc.strerror}") from exc
    if len(data) > limit:
        raise RobotDescriptionError(str(path), "<file>", f"larger than {limit} bytes ({limit >> 20} MiB), the limit "
                                                         f"of {what}")
    return data
