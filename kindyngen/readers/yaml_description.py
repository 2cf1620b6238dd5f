"""Robot descriptions: a YAML file (or, through :mod:`kindyngen.readers.urdf`, a URDF) -> immutable
:class:`kindyngen.model.robot_model.RobotModel`.

The YAML schema: ``name``, ``dh`` (standard, modified, or none: joints by origin and axis),
``gravity``, ``joints``, ``links``, optional ``payload``, ``coulomb_smoothing``, ``tool``
(README, "Robot description").  Every problem in a file is reported as a
:class:`RobotDescriptionError` naming the file, the field and the reason, so a user never
sees a traceback from the YAML parser or from sympy.

Example:

>>> model = load_robot("robots/lwr4.yaml")      # doctest: +SKIP
>>> model.n, model.convention                 # doctest: +SKIP
(7, 'standard')
"""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import replace
from pathlib import Path

import sympy

from ..model.robot_model import (CONVENTIONS, DHRow, DIRECTIONS, Frame, Friction, Joint, Link, LOOP_DIRECTIONS,
                                 LOOP_TYPES, LoopClosure, Mimic, RobotDescriptionError, RobotModel, Ripple,
                                 check_inertia, check_name)
from ..model.placement import (Placement, Reading, axis_alignment, dh_modified, dh_standard, exact_length, rpy_xyz,
                               unit_axis)
from ..model.user_text import is_identifier
from .constant_expressions import NAMESPACE, parse_constant
from .input_bounds import beyond_turn, check_angle, check_number, check_quantity, degrees_hint, shown
from .urdf import load_urdf
from .yaml_loading import load_yaml


def _number(value, source: str, field: str, *, exact: bool = False):
    """Parse a number or a constant expression such as ``pi/2`` (bounded:
    :mod:`kindyngen.readers.constant_expressions`; 0 or a magnitude within 1e-100..1e100).

    >>> _number("-pi/2", "f.yaml", "alpha", exact=True)
    -pi/2
    """
    if isinstance(value, bool) or value is None or isinstance(value, (list, dict)):
        raise RobotDescriptionError(source, field, f"expected a number, got {shown(value)}")
    if isinstance(value, (int, float)):
        try:
            finite = math.isfinite(float(value))
        except OverflowError:
            finite = False
        if not finite:
            raise RobotDescriptionError(source, field, f"expected a finite number, got {shown(value)}")
        check_number(float(value), source, field)
        # the shortest decimal that gives this double (Python's repr, the same on every
        # machine): the value as written in the file, as an exact rational
        return sympy.Rational(repr(float(value))) if exact else float(value)
    if isinstance(value, str):
        expr = parse_constant(value, source, field)
        check_number(float(expr), source, field)
        return expr if exact else float(expr)
    raise RobotDescriptionError(source, field, f"expected a number, got {shown(value)}")


def _rational(value, source: str, field: str, quantity: str = "coefficient") -> sympy.Rational:
    """A number as an exact rational: decimals and fractions exactly as written; a constant
    expression with no rational value (``sqrt(2)``) as the rational of its double; within the
    plausible range of ``quantity`` (:data:`kindyngen.readers.input_bounds.QUANTITIES`).

    >>> _rational(0.0012, "f.yaml", "mass", "mass"), _rational("1/3", "f.yaml", "mass", "mass")
    (3/2500, 1/3)
    """
    value = _number(value, source, field, exact=True)
    check_quantity(float(value), quantity, source, field)
    return value if value.is_Rational else sympy.Rational(repr(float(value)))


def _vector(value, length: int, source: str, field: str, quantity: str) -> tuple[sympy.Rational, ...]:
    if not isinstance(value, (list, tuple)):
        raise RobotDescriptionError(source, field, f"expected a list of {length} numbers, got {shown(value)}")
    if len(value) != length:
        raise RobotDescriptionError(source, field, f"expected {length} numbers, got {len(value)}")
    return tuple(_rational(v, source, f"{field}[{k}]", quantity) for k, v in enumerate(value))


# every key a description may hold; anything else is refused with the closest known key
TOP_KEYS = ("name", "dh", "gravity", "joints", "links", "payload", "coulomb_smoothing", "tool", "bundles")
JOINT_TYPES = ("revolute", "prismatic")
# a DH row's keys (plus "offset" on revolute rows, "theta" on prismatic ones)
SENSING_KEYS = ("stiffness", "encoder_offset", "torque_gain")   # how a joint is measured
JOINT_KEYS = ("a", "alpha", "d", "type", "name", "lower", "upper", "friction", "armature", "ripple",
              "mimic") + SENSING_KEYS
# a joint given by origin and axis (dh: none)
FRAME_JOINT_KEYS = ("origin", "axis", "type", "name", "lower", "upper", "friction", "armature", "ripple",
                    "mimic") + SENSING_KEYS
ORIGIN_KEYS = ("xyz", "rpy")
FRAMES = "none"     # the value of ``dh`` for joints given by origin and axis
LINK_KEYS = ("mass", "com", "inertia")
FRICTION_KEYS = ("viscous", "coulomb", "offset", "stribeck", "stribeck_velocity", "load")
RIPPLE_KEYS = ("sin", "cos", "order")
MIMIC_KEYS = ("joint", "multiplier", "offset")


def _check_keys(mapping: dict, allowed: tuple[str, ...], source: str, prefix: str) -> None:
    """Refuse unknown keys (a typo such as ``ofset`` would otherwise be ignored silently).

    >>> _check_keys({"a": 0, "ofset": 1}, ("a", "alpha", "d", "offset"), "f.yaml", "joints[0].")
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'joints[0].ofset': unknown key; did you mean 'offset'? (known: a, alpha, d, offset)
    """
    for key in mapping:
        if key in allowed:
            continue
        close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.5)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise RobotDescriptionError(source, f"{prefix}{key}",
                                    f"unknown key; {hint}(known: {', '.join(allowed)})")


def _require(mapping: dict, key: str, source: str, prefix: str):
    if key not in mapping:
        raise RobotDescriptionError(source, prefix + key, "missing")
    return mapping[key]


_LENGTH_NAME = re.compile(r"[A-Za-z][A-Za-z0-9]*")
_RESERVED = re.compile(r"t[0-9]+")  # names of CSE temporaries in generated code


def _length(value, source: str, field: str):
    """A DH length: a number, a constant expression, or a plain name (``l1``) that stays a
    symbol, so that one generated function serves a family of arms.

    >>> _length("l1", "f.yaml", "d"), _length(0.4, "f.yaml", "d")
    (l1, 2/5)
    """
    if isinstance(value, str) and _LENGTH_NAME.fullmatch(value.strip()) and value.strip() not in NAMESPACE:
        name = value.strip()
        if _RESERVED.fullmatch(name):
            raise RobotDescriptionError(source, field, f"the name {name!r} is reserved for generated temporaries")
        return sympy.Symbol(name, real=True)
    value = _number(value, source, field, exact=True)
    check_quantity(float(value), "length", source, field)
    return exact_length(float(value)) if value.is_Rational else value


def _angle(value, reading: Reading, field: str) -> sympy.Expr:
    """An angle: an expression (``pi/2``) exactly, a number cleaned by
    :func:`kindyngen.model.placement.clean_angle` (floats written for multiples of pi/12 read as
    them; within 1e-5 snapped with a note unless the user keeps them)."""
    value = _number(value, reading.source, field, exact=True)
    check_angle(float(value), reading.source, field)
    if not value.is_Rational or value.is_Integer and value == 0:
        return value
    return reading.angle(float(value), field)


def _kind(row, reading: Reading, field: str) -> str:
    kind = row.get("type", "revolute")
    if kind not in JOINT_TYPES:
        raise RobotDescriptionError(reading.source, f"{field}.type",
                                    f"expected one of {JOINT_TYPES}, got {shown(kind)}")
    return kind


def _dh_placement(row, convention: str, kind: str, reading: Reading, field: str):
    """(before, after, offset, DH row) of a DH row; a revolute row's angle offset is part of
    its motion, a prismatic row's displacement offset is its ``d``."""
    source = reading.source
    allowed = JOINT_KEYS + (("theta",) if kind == "prismatic" else ("offset",))
    _check_keys(row, allowed, source, field + ".")
    a, d = (_length(_require(row, k, source, field + "."), source, f"{field}.{k}") for k in ("a", "d"))
    alpha = _angle(_require(row, "alpha", source, field + "."), reading, f"{field}.alpha")
    theta = _angle(row.get("theta", 0), reading, f"{field}.theta")
    make = dh_standard if convention == "standard" else dh_modified
    if kind == "prismatic":
        before, after = make(a, alpha, 0, theta)
        return before, after, d, DHRow(a=a, alpha=alpha, d=d, theta=theta)
    before, after = make(a, alpha, d)
    return before, after, _angle(row.get("offset", 0), reading, f"{field}.offset"), DHRow(a=a, alpha=alpha, d=d)


def parse_origin(value, reading: Reading, field: str) -> Placement:
    """``{xyz: [x, y, z], rpy: [roll, pitch, yaw]}`` (both optional, zero) as a placement
    ``T(xyz) Rz(yaw) Ry(pitch) Rx(roll)`` (the URDF convention)."""
    if not isinstance(value, dict):
        raise RobotDescriptionError(reading.source, field, f"expected a mapping with xyz and rpy, got {shown(value)}")
    _check_keys(value, ORIGIN_KEYS, reading.source, field + ".")
    xyz = value.get("xyz", [0, 0, 0])
    rpy = value.get("rpy", [0, 0, 0])
    for key, item in (("xyz", xyz), ("rpy", rpy)):
        if not isinstance(item, (list, tuple)) or len(item) != 3:
            raise RobotDescriptionError(reading.source, f"{field}.{key}",
                                        f"expected a list of 3 numbers, got {shown(item)}")
    lengths = [_length(v, reading.source, f"{field}.xyz[{k}]") for k, v in enumerate(xyz)]
    angles = [_angle(v, reading, f"{field}.rpy[{k}]") for k, v in enumerate(rpy)]
    return rpy_xyz(lengths, angles)


def parse_axis(value, source: str, field: str) -> tuple:
    """A joint axis: three numbers, not all zero, as an exact unit vector."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise RobotDescriptionError(source, field, f"expected a list of 3 numbers, got {shown(value)}")
    numbers = [_number(v, source, f"{field}[{k}]") for k, v in enumerate(value)]
    if max(abs(v) for v in numbers) < 1e-9:
        raise RobotDescriptionError(source, field, f"the axis {numbers} has no direction (all zero)")
    return unit_axis(numbers)


def _frames_placement(row, kind: str, reading: Reading, field: str):
    """(before, after, offset, None) of a joint given by origin and axis."""
    _check_keys(row, FRAME_JOINT_KEYS, reading.source, field + ".")
    origin = parse_origin(row.get("origin", {}), reading, f"{field}.origin")
    align = axis_alignment(parse_axis(row.get("axis", [0, 0, 1]), reading.source, f"{field}.axis"))
    return origin * align, align.inverse(), sympy.Integer(0), None


def _parse_joint(row, convention: str, reading: Reading, field: str) -> Joint:
    source = reading.source
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping, got {shown(row)}")
    kind = _kind(row, reading, field)
    if convention in CONVENTIONS:
        before, after, offset, dh = _dh_placement(row, convention, kind, reading, field)
    else:
        before, after, offset, dh = _frames_placement(row, kind, reading, field)
    lower, upper = (_limit(_require(row, key, source, field + "."), kind, source, f"{field}.{key}")
                    for key in ("lower", "upper"))
    if not lower < upper:
        raise RobotDescriptionError(source, f"{field}.lower", f"limits reversed or empty: lower {lower:g} >= upper {upper:g}")
    friction = _parse_friction(row["friction"], source, f"{field}.friction") if "friction" in row else None
    armature = _nonnegative(row["armature"], source, f"{field}.armature", "inertia") if "armature" in row else None
    ripple = _parse_ripple(row["ripple"], source, f"{field}.ripple") if "ripple" in row else None
    name = row.get("name", "")
    if not isinstance(name, str):
        raise RobotDescriptionError(source, f"{field}.name", f"expected a string, got {name!r}")
    check_name(name, source, f"{field}.name")
    sensing = {}
    for key in ("stiffness", "torque_gain"):
        if key in row:
            value = _rational(row[key], source, f"{field}.{key}")
            if not value > 0:
                raise RobotDescriptionError(source, f"{field}.{key}", f"must be positive, got {float(value):g}")
            sensing[key] = value
    if "encoder_offset" in row:
        sensing["encoder_offset"] = _rational(row["encoder_offset"], source, f"{field}.encoder_offset")
    return Joint(before=before, after=after, offset=offset, lower=lower, upper=upper, kind=kind, name=name,
                 friction=friction, armature=armature, ripple=ripple, dh=dh, **sensing)


def _limit(value, kind: str, source: str, field: str) -> float:
    """A joint limit: a prismatic joint's a length; a revolute joint's within a full turn
    unless written as an expression (``4*pi``, ``'10'``: a multi-turn joint), since a plain
    number beyond it (170) is almost always degrees.

    >>> _limit("4*pi", "revolute", "f.yaml", "upper") > 12
    True
    >>> _limit(170, "revolute", "f.yaml", "joints[0].upper")
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'joints[0].upper': 170 rad is beyond a full turn (|q| <= 2*pi); 170 looks like degrees: for 170 degrees write 17*pi/18 (2.96706); a multi-turn range is written as an expression (4*pi, '12.5')
    """
    limit = _number(value, source, field)
    if kind == "prismatic":
        check_quantity(limit, "length", source, field)
    elif beyond_turn(limit) and not isinstance(value, str):
        hint = degrees_hint(limit)
        raise RobotDescriptionError(source, field, f"{limit:g} rad is beyond a full turn (|q| <= 2*pi); "
                                    + (f"{hint}; " if hint else "")
                                    + "a multi-turn range is written as an expression (4*pi, '12.5')")
    return limit


def _nonnegative(value, source: str, field: str, quantity: str = "coefficient") -> sympy.Rational:
    """A coefficient that is physically non-negative (viscous and Coulomb friction, armature)."""
    value = _rational(value, source, field, quantity)
    if value < 0:
        raise RobotDescriptionError(source, field, f"must be non-negative (a physical coefficient), got {float(value):g}")
    return value


def _parse_friction(row, source: str, field: str) -> Friction:
    """``{viscous: fv, coulomb: fc, offset: f0, stribeck: fs, stribeck_velocity: vs, load:
    fl}``, each optional (0; ``stribeck`` needs ``stribeck_velocity``), fv, fc, fs >= 0, vs > 0,
    0 <= fl < 1 (a load-dependent friction of the whole load or more would let the joint
    transmit no torque: the forward dynamics has no solution)."""
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field,
                                    f"expected a mapping with {', '.join(FRICTION_KEYS)}, got {shown(row)}")
    _check_keys(row, FRICTION_KEYS, source, field + ".")
    zero = sympy.Integer(0)
    velocity = None
    if "stribeck_velocity" in row:
        velocity = _rational(row["stribeck_velocity"], source, f"{field}.stribeck_velocity")
        if not velocity > 0:
            raise RobotDescriptionError(source, f"{field}.stribeck_velocity",
                                        f"must be a positive velocity (rad/s), got {float(velocity):g}")
    elif "stribeck" in row:
        raise RobotDescriptionError(source, f"{field}.stribeck_velocity",
                                    "required with 'stribeck' (the velocity below which the static friction acts)")
    load = None
    if "load" in row:
        load = _nonnegative(row["load"], source, f"{field}.load")
        if not load < 1:
            raise RobotDescriptionError(source, f"{field}.load", f"must be below 1 (a fraction of the transmitted "
                                        f"torque), got {float(load):g}")
    return Friction(viscous=_nonnegative(row.get("viscous", 0), source, f"{field}.viscous"),
                    coulomb=_nonnegative(row.get("coulomb", 0), source, f"{field}.coulomb"),
                    offset=_rational(row.get("offset", 0), source, f"{field}.offset") if "offset" in row else zero,
                    stribeck=_nonnegative(row.get("stribeck", 0), source, f"{field}.stribeck"),
                    stribeck_velocity=velocity, load=load)


def _parse_ripple(row, source: str, field: str) -> Ripple:
    """``{sin: rs, cos: rc, order: k}``: ``rs sin(k q) + rc cos(k q)``, k a positive integer
    (periods per revolution), the amplitudes optional (0)."""
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping with {', '.join(RIPPLE_KEYS)}, got {shown(row)}")
    _check_keys(row, RIPPLE_KEYS, source, field + ".")
    order = _require(row, "order", source, field + ".")
    if isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise RobotDescriptionError(source, f"{field}.order", f"expected a positive whole number of periods per "
                                    f"revolution, got {order!r}")
    return Ripple(sin_amplitude=_rational(row.get("sin", 0), source, f"{field}.sin"),
                  cos_amplitude=_rational(row.get("cos", 0), source, f"{field}.cos"), order=order)


def _parse_link(row, source: str, field: str, point_mass_allowed: bool = False) -> Link:
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping, got {shown(row)}")
    _check_keys(row, LINK_KEYS, source, field + ".")
    mass = _rational(_require(row, "mass", source, field + "."), source, f"{field}.mass", "mass")
    if mass <= 0:
        raise RobotDescriptionError(source, f"{field}.mass", f"mass must be positive, got {float(mass):g}")
    com = _vector(_require(row, "com", source, field + "."), 3, source, f"{field}.com", "length")
    inertia = _vector(_require(row, "inertia", source, field + "."), 6, source, f"{field}.inertia", "inertia")
    link = Link(mass=mass, com=com, inertia=inertia)
    check_inertia(link.inertia_matrix(), source, f"{field}.inertia", point_mass_allowed)
    return link


def _named_mapping(data, keys: tuple[str, ...], source: str) -> str:
    """The description's name, after checking it is a mapping with only ``keys``."""
    if not isinstance(data, dict):
        raise RobotDescriptionError(source, "<top level>", "expected a mapping with name, dh, gravity, joints, links")
    _check_keys(data, keys, source, "")
    name = _require(data, "name", source, "")
    if not isinstance(name, str) or not name.strip():
        raise RobotDescriptionError(source, "name", f"expected a non-empty string, got {name!r}")
    return check_name(name, source, "name")


TREE_TOP_KEYS = ("name", "dh", "gravity", "joints", "links", "base", "loops", "independent", "reference", "bundles")
LOOP_KEYS = ("name", "type", "link1", "origin1", "link2", "origin2", "directions")
TREE_JOINT_KEYS = ("origin", "axis", "type", "name", "lower", "upper", "parent", "mimic")
BASE_NAME = "base"      # the root body's name in a YAML tree (its frame is the base frame)


def _refuse_tree_keys(data: dict, source: str) -> None:
    """A description read as an arm that holds a tree's keys: the reason is the reading, not a
    typo (an arm knows no ``base``, ``parent`` or ``loops``).

    >>> _refuse_tree_keys({"joints": [{"name": "a"}, {"name": "b", "parent": "a"}]}, "f.yaml")
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'joints[1].parent': a key of a tree description: read it as a tree (--tree)
    """
    if "loops" in data:
        raise RobotDescriptionError(source, "loops", "closed loops join the bodies of a tree: read the description "
                                    "as a tree (--tree), its joints named and placed by parent")
    for key in ("base", "independent", "reference"):
        if key in data:
            raise RobotDescriptionError(source, key, "a key of a tree description: read it as a tree (--tree)")
    rows = data.get("joints")
    for k, row in enumerate(rows if isinstance(rows, list) else ()):
        if isinstance(row, dict) and "parent" in row:
            raise RobotDescriptionError(source, f"joints[{k}].parent", "a key of a tree description: read it as a "
                                        "tree (--tree)")


def parse_robot(data, source: str = "<memory>", snap_angles: bool = True, *, tree: bool = False,
                frames=None, floating_base: bool = False) -> RobotModel:
    """Build a :class:`RobotModel` from already-parsed YAML data (``snap_angles``: see
    :func:`kindyngen.model.placement.clean_angle`; what was snapped is in ``model.notes``).

    An arm is the tree whose parent of joint j is j - 1. With ``tree`` (implied by ``frames``
    or ``floating_base``) the description is read as a kinematic tree: joints by origin and
    axis (``dh: none``), each with a unique ``name`` and an optional ``parent`` (an earlier
    joint's name; absent: the base), and an optional ``base`` body (mass, com, inertia; the
    root body of a floating base, massless if absent). A link's frame is named after its
    joint; ``frames`` names joints (or ``base``), default the joints without children. Joint
    effects, payload and tool are arm features and refused in a tree.

    >>> tree = parse_robot({"name": "two", "dh": "none", "gravity": [0, 0, -9.81],
    ...     "joints": [{"name": "a", "lower": -1, "upper": 1},
    ...                {"name": "b", "parent": "a", "origin": {"xyz": [0, 0, 0.5]}, "lower": -1, "upper": 1}],
    ...     "links": [{"mass": 1, "com": [0, 0, 0.2], "inertia": [0.01, 0.01, 0.001, 0, 0, 0]}] * 2}, tree=True)
    >>> tree.parents, [f.name for f in tree.frames]
    ((-1, 0), ['b'])
    """
    tree = tree or frames is not None or floating_base
    reading = Reading(source, snap_angles)
    if not tree and isinstance(data, dict):
        _refuse_tree_keys(data, source)
    name = _named_mapping(data, TREE_TOP_KEYS if tree else TOP_KEYS, source)
    convention = _require(data, "dh", source, "")
    if tree and convention != FRAMES:
        raise RobotDescriptionError(source, "dh", "a tree gives its joints by origin and axis: dh: none")
    if convention not in CONVENTIONS + (FRAMES,):
        raise RobotDescriptionError(source, "dh", f"expected one of {CONVENTIONS + (FRAMES,)}, got {shown(convention)}")
    gravity = _vector(_require(data, "gravity", source, ""), 3, source, "gravity", "gravity")
    rows = _require(data, "joints", source, "")
    if not isinstance(rows, list) or not rows:
        raise RobotDescriptionError(source, "joints", "expected a non-empty list of joints")
    _check_unique_names(rows, source)
    if tree:
        joints, parents, index = _tree_joints(rows, reading)
    else:
        joints = tuple(_parse_joint(row, convention, reading, f"joints[{k}]") for k, row in enumerate(rows))
    joints = _with_mimics(rows, joints, reading)
    _refuse_load_friction_with_mimics(joints, source)
    links_data = _require(data, "links", source, "")
    if not isinstance(links_data, list):
        raise RobotDescriptionError(source, "links", "expected a list with one entry per joint")
    if len(links_data) != len(joints):
        raise RobotDescriptionError(source, "links", f"expected {len(joints)} entries (one per joint), got {len(links_data)}")
    links = tuple(_parse_link(row, source, f"links[{k}]") for k, row in enumerate(links_data))
    if tree:
        return _tree_model(data, name, gravity, joints, parents, index, links, frames, floating_base, reading)
    # a payload may be a point mass (zero inertia about its CoM), unlike a link
    payload = _parse_link(data["payload"], source, "payload", point_mass_allowed=True) if "payload" in data else None
    smoothing = None
    if "coulomb_smoothing" in data:
        smoothing = _rational(data["coulomb_smoothing"], source, "coulomb_smoothing")
        if smoothing <= 0:
            raise RobotDescriptionError(source, "coulomb_smoothing",
                                        f"must be a positive velocity (rad/s), got {float(smoothing):g}")
    tool = parse_origin(data["tool"], reading, "tool") if "tool" in data else Placement()
    return RobotModel(name=name.strip(), convention=convention if convention in CONVENTIONS else "frames",
                      gravity=gravity, joints=joints, links=links, source=source, payload=payload,
                      coulomb_smoothing=smoothing, tool=tool, notes=tuple(reading.notes),
                      bundles=_parse_bundles(data.get("bundles"), source))


def _parse_bundles(data, source: str) -> tuple:
    """The ``bundles:`` section: a mapping of bundle names to lists of function names (or one
    comma-separated string), each generated as one function (kindyngen/codegen/bundles.py,
    which checks the names against the function catalog when generating).

    >>> _parse_bundles({"step": ["fk_hom", "M"], "row": "Y, tau"}, "f.yaml")
    (('step', ('fk_hom', 'M')), ('row', ('Y', 'tau')))
    >>> _parse_bundles({"step": [1, 2]}, "f.yaml")
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'bundles.step': expected function names, got [1, 2]
    """
    if data is None:
        return ()
    if not isinstance(data, dict) or not data:
        raise RobotDescriptionError(source, "bundles", f"expected a mapping of bundle names to lists of function "
                                                       f"names, e.g. step: [fk_hom, jacobian, M, g, tau]; got {shown(data)}")
    out = []
    for name, members in data.items():
        if not isinstance(name, str) or not is_identifier(name):
            raise RobotDescriptionError(source, "bundles", f"a bundle's name must be ASCII letters, digits and _ "
                                                           f"with a letter first, got {shown(name)}")
        field = f"bundles.{name}"
        if isinstance(members, str):
            members = [m.strip() for m in members.split(",") if m.strip()]
        if not isinstance(members, list) or not members or not all(isinstance(m, str) and m for m in members):
            raise RobotDescriptionError(source, field, f"expected function names, got {shown(members)}")
        out.append((name, tuple(members)))
    return tuple(out)


def _check_unique_names(rows: list, source: str) -> None:
    """Refuse two joints of one name (a name selects a joint: --frames, parents, logs),
    naming both.

    >>> _check_unique_names([{"name": "a"}, {}, {}, {"name": "a"}], "f.yaml")
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'joints[3].name': 'a' is also the name of joints[0]: joint names are unique
    """
    first = {}
    for k, row in enumerate(rows):
        name = row.get("name") if isinstance(row, dict) else None
        if not isinstance(name, str) or not name:
            continue
        if name in first:
            raise RobotDescriptionError(source, f"joints[{k}].name", f"{shown(name)} is also the name of "
                                                                     f"joints[{first[name]}]: joint names are unique")
        first[name] = k


def _mimic_entry(row: dict, kind: str, source: str, field: str) -> tuple:
    """A joint's ``mimic: {joint: NAME, multiplier: 1, offset: 0}`` as (name, multiplier,
    offset), exact; the multiplier not 0, the offset an angle within a full turn (a prismatic
    joint's a length).

    >>> _mimic_entry({"joint": "a", "multiplier": -1, "offset": 0.1}, "revolute", "f.yaml", "joints[1].mimic")
    ('a', -1, 1/10)
    """
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping with {', '.join(MIMIC_KEYS)}, got {shown(row)}")
    _check_keys(row, MIMIC_KEYS, source, field + ".")
    name = _require(row, "joint", source, field + ".")
    if not isinstance(name, str) or not name:
        raise RobotDescriptionError(source, f"{field}.joint", f"expected a joint's name, got {shown(name)}")
    multiplier = _rational(row.get("multiplier", 1), source, f"{field}.multiplier")
    if multiplier == 0:
        raise RobotDescriptionError(source, f"{field}.multiplier", "0 would hold the joint at its offset")
    quantity = "length" if kind == "prismatic" else "coefficient"
    offset = _rational(row.get("offset", 0), source, f"{field}.offset", quantity)
    if kind != "prismatic":
        check_angle(float(offset), source, f"{field}.offset")
    return name, multiplier, offset


def _refuse_load_friction_with_mimics(joints: tuple, source: str) -> None:
    """Load-dependent friction acts on a joint's own transmitted torque, which a robot with
    mimic joints does not have per joint (its functions are reduced to the independent joints
    through G^T): refused, naming the first joint that declares it."""
    if not any(joint.mimic is not None for joint in joints):
        return
    for k, joint in enumerate(joints):
        if joint.friction is not None and joint.friction.load not in (None, 0):
            raise RobotDescriptionError(source, f"joints[{k}].friction.load",
                                        "load-dependent friction is not supported on a robot with mimic joints (it "
                                        "acts on each joint's own transmitted torque; the functions of this robot are "
                                        "reduced to its independent joints)")


def _with_mimics(rows: list, joints: tuple, reading: Reading) -> tuple:
    """``joints`` with the ``mimic`` entries of their ``rows`` resolved: the joint named must
    exist (by ``name``), a mimic of a mimic is composed into the joint at the end of the chain
    (``q_a = m_a (m_b q_c + o_b) + o_a``), a cycle is an error. Joints of any kinds may be
    coupled: the multiplier's unit is the ratio of theirs (m/rad: a rack on a pinion)."""
    source = reading.source
    entries = {k: _mimic_entry(row["mimic"], joints[k].kind, source, f"joints[{k}].mimic")
               for k, row in enumerate(rows) if isinstance(row, dict) and "mimic" in row}
    if not entries:
        return joints
    index = {joint.name: k for k, joint in enumerate(joints) if joint.name}
    out = list(joints)
    for k in entries:
        multiplier, offset, path, current = sympy.Integer(1), sympy.Integer(0), [k], k
        while current in entries:
            target, m, o = entries[current]
            field = f"joints[{current}].mimic.joint"
            if target not in index:
                close = difflib.get_close_matches(target, list(index), n=1)
                raise RobotDescriptionError(source, field, f"no joint named {shown(target)}"
                                            + (f"; closest: {close[0]}" if close else ""))
            multiplier, offset = multiplier * m, offset + multiplier * o
            if index[target] in path:
                cycle = " -> ".join(joints[j].name or f"joints[{j}]" for j in path + [index[target]])
                raise RobotDescriptionError(source, f"joints[{k}].mimic.joint", f"the mimic joints form a cycle: {cycle}")
            path.append(index[target])
            current = index[target]
        out[k] = replace(joints[k], mimic=Mimic(current, multiplier, offset))
    return tuple(out)


def _tree_joints(rows: list, reading: Reading) -> tuple[tuple, tuple, dict]:
    """A tree's joints, their parents (-1: the base) and the index of each joint's name."""
    source = reading.source
    joints, parents, index = [], [], {}
    for k, row in enumerate(rows):
        field = f"joints[{k}]"
        if not isinstance(row, dict):
            raise RobotDescriptionError(source, field, f"expected a mapping, got {shown(row)}")
        _check_keys(row, TREE_JOINT_KEYS, source, field + ".")
        joint = _parse_joint({key: v for key, v in row.items() if key != "parent"}, FRAMES, reading, field)
        if not joint.name or joint.name in index or joint.name == BASE_NAME:
            raise RobotDescriptionError(source, f"{field}.name", "a tree's joints need unique names (not "
                                        f"'{BASE_NAME}'), got {joint.name!r}")
        parent = row.get("parent", BASE_NAME)
        if parent != BASE_NAME and parent not in index:
            close = difflib.get_close_matches(str(parent), list(index), n=1)
            hint = f"; closest: {close[0]}" if close else ""
            raise RobotDescriptionError(source, f"{field}.parent", f"{parent!r} is not an earlier joint{hint}")
        index[joint.name] = k
        joints.append(joint)
        parents.append(-1 if parent == BASE_NAME else index[parent])
    return tuple(joints), tuple(parents), index


def _tree_model(data, name, gravity, joints, parents, index, links, frames, floating_base, reading) -> RobotModel:
    """The tree's model: its root body and the frames asked for, checked by name."""
    source = reading.source
    zero = sympy.Integer(0)
    root = (_parse_link(data["base"], source, "base") if "base" in data
            else Link(mass=zero, com=(zero,) * 3, inertia=(zero,) * 6))
    named = {BASE_NAME: -1, **index}
    wanted = frames if frames is not None else [j.name for k, j in enumerate(joints) if k not in parents]
    for frame in wanted:
        if frame not in named:
            close = difflib.get_close_matches(str(frame), list(named), n=1)
            raise RobotDescriptionError(source, "--frames", f"no joint named '{frame}'"
                                        + (f"; closest: {close[0]}" if close else ""))
    loops, independent, reference = _loops(data, joints, named, floating_base, reading)
    return RobotModel(name=name.strip(), convention="tree", joints=joints, parents=parents,
                      links=links, root=root, frames=tuple(Frame(frame, named[frame]) for frame in wanted),
                      floating_base=floating_base, gravity=gravity, source=source, base_name=BASE_NAME,
                      notes=tuple(reading.notes), loops=loops, independent=independent, reference=reference,
                      bundles=_parse_bundles(data.get("bundles"), source))


def _loops(data: dict, joints: tuple, named: dict, floating_base: bool, reading: Reading) -> tuple:
    """``(loops, independent, reference)`` of a tree: its ``loops`` entries as
    :class:`LoopClosure` s (each body named by its joint, or ``base``), the joints named in
    ``independent`` (indices, in joint order) and the ``reference`` configuration (exact, per
    joint; None: all zero). Without ``loops`` the other two keys are refused."""
    source = reading.source
    if "loops" not in data:
        for key in ("independent", "reference"):
            if key in data:
                raise RobotDescriptionError(source, key, "applies to a tree closed by loops (no 'loops' given)")
        return (), None, None
    if floating_base:
        raise RobotDescriptionError(source, "loops", "closed loops on a floating base are not supported (yet): "
                                    "read the tree with a fixed base")
    if any(joint.mimic is not None for joint in joints):
        first = next(k for k, joint in enumerate(joints) if joint.mimic is not None)
        raise RobotDescriptionError(source, f"joints[{first}].mimic", "mimic joints and closed loops in one tree are "
                                    "not supported (yet): write the coupling as a loop or drop the loops")
    rows = data["loops"]
    if not isinstance(rows, list) or not rows:
        raise RobotDescriptionError(source, "loops", f"expected a non-empty list of loop joints, got {shown(rows)}")
    loops, names = [], set()
    for k, row in enumerate(rows):
        loop = _loop(row, named, reading, f"loops[{k}]")
        if loop.name in names or loop.name in named:
            raise RobotDescriptionError(source, f"loops[{k}].name", f"{shown(loop.name)} already names a joint or "
                                        "another loop: names are unique")
        names.add(loop.name)
        loops.append(loop)
    independent = None
    if "independent" in data:
        value = data["independent"]
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise RobotDescriptionError(source, "independent", f"expected a list of joint names, got {shown(value)}")
        for k, joint_name in enumerate(value):
            if joint_name not in named or joint_name == BASE_NAME:
                close = difflib.get_close_matches(joint_name, [n for n in named if n != BASE_NAME], n=1)
                raise RobotDescriptionError(source, f"independent[{k}]", f"no joint named {shown(joint_name)}"
                                            + (f"; closest: {close[0]}" if close else ""))
        if len(set(value)) != len(value):
            raise RobotDescriptionError(source, "independent", "a joint is named twice")
        independent = tuple(sorted(named[v] for v in value))
    reference = None
    if "reference" in data:
        value = data["reference"]
        if not isinstance(value, dict):
            raise RobotDescriptionError(source, "reference", f"expected a mapping of joint names to positions, got "
                                        f"{shown(value)}")
        values = [sympy.Integer(0)] * len(joints)
        for joint_name, position in value.items():
            field = f"reference.{joint_name}"
            if joint_name not in named or joint_name == BASE_NAME:
                close = difflib.get_close_matches(str(joint_name), [n for n in named if n != BASE_NAME], n=1)
                raise RobotDescriptionError(source, field, "no joint of that name"
                                            + (f"; closest: {close[0]}" if close else ""))
            j = named[joint_name]
            quantity = "length" if joints[j].prismatic else "coefficient"
            values[j] = _rational(position, source, field, quantity)
            if not joints[j].prismatic:
                check_angle(float(values[j]), source, field)
        reference = tuple(values)
    return tuple(loops), independent, reference


def _loop(row, named: dict, reading: Reading, field: str) -> LoopClosure:
    """One ``loops`` entry: ``{name, type, link1, origin1, link2, origin2, directions}``."""
    source = reading.source
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping with {', '.join(LOOP_KEYS)}, got {shown(row)}")
    _check_keys(row, LOOP_KEYS, source, field + ".")
    name = _require(row, "name", source, field + ".")
    if not isinstance(name, str) or not name:
        raise RobotDescriptionError(source, f"{field}.name", f"expected a non-empty string, got {shown(name)}")
    check_name(name, source, f"{field}.name")
    kind = _require(row, "type", source, field + ".")
    if kind not in LOOP_TYPES:
        raise RobotDescriptionError(source, f"{field}.type", f"expected one of {LOOP_TYPES}, got {shown(kind)}")
    bodies = []
    for key in ("link1", "link2"):
        body = _require(row, key, source, field + ".")
        if not isinstance(body, str) or body not in named:
            close = difflib.get_close_matches(str(body), list(named), n=1)
            raise RobotDescriptionError(source, f"{field}.{key}", f"no link named {shown(body)} (a joint's link, or "
                                        f"'{BASE_NAME}')" + (f"; closest: {close[0]}" if close else ""))
        bodies.append(named[body])
    if bodies[0] == bodies[1]:
        raise RobotDescriptionError(source, f"{field}.link2", "a loop joint joins two different links")
    placements = [parse_origin(row.get(key, {}), reading, f"{field}.{key}") for key in ("origin1", "origin2")]
    allowed = LOOP_DIRECTIONS[kind]
    directions = row.get("directions", list(allowed))
    if not isinstance(directions, list) or not directions or not all(isinstance(d, str) for d in directions):
        raise RobotDescriptionError(source, f"{field}.directions", f"expected a non-empty list of {', '.join(allowed)}, "
                                    f"got {shown(directions)}")
    for k, direction in enumerate(directions):
        if direction not in allowed:
            reason = (f"a {kind} loop joint constrains {', '.join(allowed)}" if direction in DIRECTIONS
                      else f"expected one of {', '.join(DIRECTIONS)}")
            raise RobotDescriptionError(source, f"{field}.directions[{k}]", f"{shown(direction)}: {reason}")
    if len(set(directions)) != len(directions):
        raise RobotDescriptionError(source, f"{field}.directions", "a direction is named twice")
    return LoopClosure(name=name, kind=kind, body_a=bodies[0], placement_a=placements[0], body_b=bodies[1],
                       placement_b=placements[1], directions=tuple(d for d in DIRECTIONS if d in directions))


def load_robot(path: str | Path, snap_angles: bool = True, base: str | None = None,
               tip: str | None = None, tree: bool = False, frames=None, floating_base: bool = False) -> RobotModel:
    """Read and validate a robot description file, the one entry point of both formats: YAML,
    or URDF (``.urdf``; ``base`` and ``tip`` name the chain's first and last link, see
    :mod:`kindyngen.readers.urdf`). With ``tree`` (implied by ``frames`` or ``floating_base``) every
    branch is read (:func:`parse_robot`, :func:`kindyngen.readers.urdf.parse_urdf` with ``tree``)."""
    path = Path(path)
    source = str(path)
    tree = tree or frames is not None or floating_base
    if path.suffix.lower() == ".urdf":
        return load_urdf(path, base=base, tip=tip, snap_angles=snap_angles, tree=tree, frames=frames,
                         floating_base=floating_base)
    if not tree and (base is not None or tip is not None):
        raise RobotDescriptionError(source, "<file>", "--base and --tip apply to URDF files only")
    return parse_robot(load_yaml(path), source, snap_angles, tree=tree, frames=frames, floating_base=floating_base)
