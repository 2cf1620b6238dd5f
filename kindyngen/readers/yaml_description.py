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

import ast
import difflib
import math
import re
from pathlib import Path

import sympy
import yaml

from ..model.robot_model import (CONVENTIONS, DHRow, Frame, Friction, Joint, Link, RobotDescriptionError, RobotModel,
                                 Ripple, check_inertia)
from ..model.placement import (Placement, Reading, axis_alignment, dh_modified, dh_standard, exact_length, rpy_xyz,
                               unit_axis)
from .urdf import load_urdf

_SYMPY_FUNCTIONS = {"sqrt": sympy.sqrt, "sin": sympy.sin, "cos": sympy.cos, "tan": sympy.tan,
                    "asin": sympy.asin, "acos": sympy.acos, "atan": sympy.atan,
                    "atan2": sympy.atan2}
_SYMPY_NAMESPACE = {"pi": sympy.pi, **_SYMPY_FUNCTIONS}
# Only arithmetic on numbers, pi and the functions above: sympify evaluates its input as
# Python, so anything else (attributes, subscripts, other calls) is refused before it runs.
_EXPRESSION_NODES = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Add, ast.Sub, ast.Mult,
                     ast.Div, ast.Pow, ast.UAdd, ast.USub, ast.Constant, ast.Name, ast.Load,
                     ast.Call)


def _check_expression(text: str, source: str, field: str) -> None:
    """Refuse a string that is not an arithmetic expression in numbers, pi and a few functions."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError) as exc:
        raise RobotDescriptionError(source, field, f"cannot parse {text!r} as a number") from exc
    for node in ast.walk(tree):
        if not isinstance(node, _EXPRESSION_NODES):
            raise RobotDescriptionError(source, field, f"cannot parse {text!r} as a number")
        if isinstance(node, ast.Constant) and (isinstance(node.value, bool)
                                               or not isinstance(node.value, (int, float))):
            raise RobotDescriptionError(source, field, f"cannot parse {text!r} as a number")
        if isinstance(node, ast.Name) and node.id not in _SYMPY_NAMESPACE:
            raise RobotDescriptionError(
                source, field, f"{text!r} is not a real constant (unknown name {node.id!r}; "
                f"allowed: {', '.join(sorted(_SYMPY_NAMESPACE))})")
        if isinstance(node, ast.Call) and (node.keywords or not isinstance(node.func, ast.Name)
                                           or node.func.id not in _SYMPY_FUNCTIONS):
            raise RobotDescriptionError(source, field, f"cannot parse {text!r} as a number")


def _number(value, source: str, field: str, *, exact: bool = False):
    """Parse a number or a constant expression such as ``pi/2``.

    >>> _number("-pi/2", "f.yaml", "alpha", exact=True)
    -pi/2
    """
    if isinstance(value, bool) or value is None or isinstance(value, (list, dict)):
        raise RobotDescriptionError(source, field, f"expected a number, got {value!r}")
    if isinstance(value, (int, float)):
        try:
            finite = math.isfinite(float(value))
        except OverflowError:
            finite = False
        if not finite:
            raise RobotDescriptionError(source, field, f"expected a finite number, got {value!r}")
        # the shortest decimal that gives this double (Python's repr, the same on every
        # machine): the value as written in the file, as an exact rational
        return sympy.Rational(repr(float(value))) if exact else float(value)
    if isinstance(value, str):
        _check_expression(value, source, field)
        try:
            expr = sympy.sympify(value, locals=_SYMPY_NAMESPACE, rational=True)
        except Exception as exc:  # sympify raises many kinds (SympifyError, TypeError, ...)
            raise RobotDescriptionError(source, field, f"cannot parse {value!r} as a number") from exc
        if not isinstance(expr, sympy.Expr) or not expr.is_number or not expr.is_real:
            raise RobotDescriptionError(source, field, f"{value!r} is not a real constant")
        try:
            finite = math.isfinite(float(expr))
        except (OverflowError, TypeError, ValueError):
            finite = False
        if not finite:
            raise RobotDescriptionError(source, field, f"expected a finite number, got {value!r}")
        return expr if exact else float(expr)
    raise RobotDescriptionError(source, field, f"expected a number, got {value!r}")


def _rational(value, source: str, field: str) -> sympy.Rational:
    """A number as an exact rational: decimals and fractions exactly as written; a constant
    expression with no rational value (``sqrt(2)``) as the rational of its double.

    >>> _rational(0.0012, "f.yaml", "mass"), _rational("1/3", "f.yaml", "mass")
    (3/2500, 1/3)
    """
    value = _number(value, source, field, exact=True)
    return value if value.is_Rational else sympy.Rational(repr(float(value)))


def _vector(value, length: int, source: str, field: str) -> tuple[sympy.Rational, ...]:
    if not isinstance(value, (list, tuple)):
        raise RobotDescriptionError(source, field, f"expected a list of {length} numbers, got {value!r}")
    if len(value) != length:
        raise RobotDescriptionError(source, field, f"expected {length} numbers, got {len(value)}")
    return tuple(_rational(v, source, f"{field}[{k}]") for k, v in enumerate(value))


# every key a description may hold; anything else is refused with the closest known key
TOP_KEYS = ("name", "dh", "gravity", "joints", "links", "payload", "coulomb_smoothing", "tool")
JOINT_TYPES = ("revolute", "prismatic")
# a DH row's keys (plus "offset" on revolute rows, "theta" on prismatic ones)
SENSING_KEYS = ("stiffness", "encoder_offset", "torque_gain")   # how a joint is measured
JOINT_KEYS = ("a", "alpha", "d", "type", "name", "lower", "upper", "friction", "armature", "ripple") + SENSING_KEYS
# a joint given by origin and axis (dh: none)
FRAME_JOINT_KEYS = ("origin", "axis", "type", "name", "lower", "upper", "friction", "armature", "ripple") + SENSING_KEYS
ORIGIN_KEYS = ("xyz", "rpy")
FRAMES = "none"     # the value of ``dh`` for joints given by origin and axis
LINK_KEYS = ("mass", "com", "inertia")
FRICTION_KEYS = ("viscous", "coulomb", "offset", "stribeck", "stribeck_velocity", "load")
RIPPLE_KEYS = ("sin", "cos", "order")


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
    if isinstance(value, str) and _LENGTH_NAME.fullmatch(value.strip()) and value.strip() not in _SYMPY_NAMESPACE:
        name = value.strip()
        if _RESERVED.fullmatch(name):
            raise RobotDescriptionError(source, field, f"the name {name!r} is reserved for generated temporaries")
        return sympy.Symbol(name, real=True)
    value = _number(value, source, field, exact=True)
    return exact_length(float(value)) if value.is_Rational else value


def _angle(value, reading: Reading, field: str) -> sympy.Expr:
    """An angle: an expression (``pi/2``) exactly, a number cleaned by
    :func:`kindyngen.model.placement.clean_angle` (floats written for multiples of pi/12 read as
    them; within 1e-5 snapped with a note unless the user keeps them)."""
    value = _number(value, reading.source, field, exact=True)
    if not value.is_Rational or value.is_Integer and value == 0:
        return value
    return reading.angle(float(value), field)


def _kind(row, reading: Reading, field: str) -> str:
    kind = row.get("type", "revolute")
    if kind not in JOINT_TYPES:
        raise RobotDescriptionError(reading.source, f"{field}.type", f"expected one of {JOINT_TYPES}, got {kind!r}")
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
        raise RobotDescriptionError(reading.source, field, f"expected a mapping with xyz and rpy, got {value!r}")
    _check_keys(value, ORIGIN_KEYS, reading.source, field + ".")
    xyz = value.get("xyz", [0, 0, 0])
    rpy = value.get("rpy", [0, 0, 0])
    for key, item in (("xyz", xyz), ("rpy", rpy)):
        if not isinstance(item, (list, tuple)) or len(item) != 3:
            raise RobotDescriptionError(reading.source, f"{field}.{key}", f"expected a list of 3 numbers, got {item!r}")
    lengths = [_length(v, reading.source, f"{field}.xyz[{k}]") for k, v in enumerate(xyz)]
    angles = [_angle(v, reading, f"{field}.rpy[{k}]") for k, v in enumerate(rpy)]
    return rpy_xyz(lengths, angles)


def parse_axis(value, source: str, field: str) -> tuple:
    """A joint axis: three numbers, not all zero, as an exact unit vector."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise RobotDescriptionError(source, field, f"expected a list of 3 numbers, got {value!r}")
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
        raise RobotDescriptionError(source, field, f"expected a mapping, got {row!r}")
    kind = _kind(row, reading, field)
    if convention in CONVENTIONS:
        before, after, offset, dh = _dh_placement(row, convention, kind, reading, field)
    else:
        before, after, offset, dh = _frames_placement(row, kind, reading, field)
    lower = _number(_require(row, "lower", source, field + "."), source, f"{field}.lower")
    upper = _number(_require(row, "upper", source, field + "."), source, f"{field}.upper")
    if not lower < upper:
        raise RobotDescriptionError(source, f"{field}.lower", f"limits reversed or empty: lower {lower:g} >= upper {upper:g}")
    friction = _parse_friction(row["friction"], source, f"{field}.friction") if "friction" in row else None
    armature = _nonnegative(row["armature"], source, f"{field}.armature") if "armature" in row else None
    ripple = _parse_ripple(row["ripple"], source, f"{field}.ripple") if "ripple" in row else None
    name = row.get("name", "")
    if not isinstance(name, str):
        raise RobotDescriptionError(source, f"{field}.name", f"expected a string, got {name!r}")
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


def _nonnegative(value, source: str, field: str) -> sympy.Rational:
    """A coefficient that is physically non-negative (viscous and Coulomb friction, armature)."""
    value = _rational(value, source, field)
    if value < 0:
        raise RobotDescriptionError(source, field, f"must be non-negative (a physical coefficient), got {float(value):g}")
    return value


def _parse_friction(row, source: str, field: str) -> Friction:
    """``{viscous: fv, coulomb: fc, offset: f0, stribeck: fs, stribeck_velocity: vs, load:
    fl}``, each optional (0; ``stribeck`` needs ``stribeck_velocity``), fv, fc, fs >= 0, vs > 0,
    0 <= fl < 1 (a load-dependent friction of the whole load or more would let the joint
    transmit no torque: the forward dynamics has no solution)."""
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping with {', '.join(FRICTION_KEYS)}, got {row!r}")
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
        raise RobotDescriptionError(source, field, f"expected a mapping with {', '.join(RIPPLE_KEYS)}, got {row!r}")
    _check_keys(row, RIPPLE_KEYS, source, field + ".")
    order = _require(row, "order", source, field + ".")
    if isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise RobotDescriptionError(source, f"{field}.order", f"expected a positive whole number of periods per "
                                    f"revolution, got {order!r}")
    return Ripple(sin_amplitude=_rational(row.get("sin", 0), source, f"{field}.sin"),
                  cos_amplitude=_rational(row.get("cos", 0), source, f"{field}.cos"), order=order)


def _parse_link(row, source: str, field: str, point_mass_allowed: bool = False) -> Link:
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping, got {row!r}")
    _check_keys(row, LINK_KEYS, source, field + ".")
    mass = _rational(_require(row, "mass", source, field + "."), source, f"{field}.mass")
    if mass <= 0:
        raise RobotDescriptionError(source, f"{field}.mass", f"mass must be positive, got {float(mass):g}")
    com = _vector(_require(row, "com", source, field + "."), 3, source, f"{field}.com")
    inertia = _vector(_require(row, "inertia", source, field + "."), 6, source, f"{field}.inertia")
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
    return name


TREE_TOP_KEYS = ("name", "dh", "gravity", "joints", "links", "base")
TREE_JOINT_KEYS = ("origin", "axis", "type", "name", "lower", "upper", "parent")
BASE_NAME = "base"      # the root body's name in a YAML tree (its frame is the base frame)


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
    name = _named_mapping(data, TREE_TOP_KEYS if tree else TOP_KEYS, source)
    convention = _require(data, "dh", source, "")
    if tree and convention != FRAMES:
        raise RobotDescriptionError(source, "dh", "a tree gives its joints by origin and axis: dh: none")
    if convention not in CONVENTIONS + (FRAMES,):
        raise RobotDescriptionError(source, "dh", f"expected one of {CONVENTIONS + (FRAMES,)}, got {convention!r}")
    gravity = _vector(_require(data, "gravity", source, ""), 3, source, "gravity")
    rows = _require(data, "joints", source, "")
    if not isinstance(rows, list) or not rows:
        raise RobotDescriptionError(source, "joints", "expected a non-empty list of joints")
    if tree:
        joints, parents, index = _tree_joints(rows, reading)
    else:
        joints = tuple(_parse_joint(row, convention, reading, f"joints[{k}]") for k, row in enumerate(rows))
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
                      coulomb_smoothing=smoothing, tool=tool, notes=tuple(reading.notes))


def _tree_joints(rows: list, reading: Reading) -> tuple[tuple, tuple, dict]:
    """A tree's joints, their parents (-1: the base) and the index of each joint's name."""
    source = reading.source
    joints, parents, index = [], [], {}
    for k, row in enumerate(rows):
        field = f"joints[{k}]"
        if not isinstance(row, dict):
            raise RobotDescriptionError(source, field, f"expected a mapping, got {row!r}")
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
    return RobotModel(name=name.strip(), convention="tree", joints=joints, parents=parents,
                      links=links, root=root, frames=tuple(Frame(frame, named[frame]) for frame in wanted),
                      floating_base=floating_base, gravity=gravity, source=source, base_name=BASE_NAME,
                      notes=tuple(reading.notes))


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
    return parse_robot(_read_yaml(path), source, snap_angles, tree=tree, frames=frames, floating_base=floating_base)


def _read_yaml(path: Path):
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RobotDescriptionError(source, "<file>", f"cannot read: {exc.strerror}") from exc
    except UnicodeDecodeError as exc:
        raise RobotDescriptionError(source, "<file>", f"not a text file (byte {exc.start}: {exc.reason}): a robot "
                                                      f"description is YAML or URDF text") from None
    if "\0" in text:
        raise RobotDescriptionError(source, "<file>", "contains NUL bytes: a binary file, not a YAML description")
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise RobotDescriptionError(source, "<yaml>", f"malformed YAML{where}: {problem}") from exc
