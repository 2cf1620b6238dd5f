"""Robot descriptions: YAML file -> immutable :class:`RobotModel`.

The schema is the one fixed in the project reference (``name``, ``dh``, ``gravity``,
``joints``, ``links``).  Every problem in a file is reported as a
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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sympy
import yaml

CONVENTIONS = ("standard", "modified")


class RobotDescriptionError(ValueError):
    """A robot description that cannot be used, with the file, field and reason."""

    def __init__(self, source: str, field: str, reason: str):
        self.source, self.field, self.reason = source, field, reason
        super().__init__(f"{source}: field '{field}': {reason}")


@dataclass(frozen=True)
class Joint:
    """One DH row. ``alpha`` is kept exact (a sympy number such as pi/2) so that its
    cosine and sine are exact and zeros never reach generated code; ``a`` and ``d`` are
    exact numbers or symbols (symbolic lengths)."""

    a: sympy.Expr
    alpha: sympy.Expr
    d: sympy.Expr
    offset: sympy.Expr
    lower: float
    upper: float
    friction: "Friction | None" = None       # None: the description declares no friction
    armature: sympy.Rational | None = None   # kg m^2 (reflected rotor inertia); None: not declared


@dataclass(frozen=True)
class Friction:
    """Joint friction and torque bias, exact (``tau_f = viscous qd + coulomb sign(qd) + offset``;
    with ``coulomb_smoothing`` eps, ``tanh(qd / eps)`` replaces ``sign(qd)``)."""

    viscous: sympy.Rational = sympy.Integer(0)   # N m s/rad
    coulomb: sympy.Rational = sympy.Integer(0)   # N m
    offset: sympy.Rational = sympy.Integer(0)    # N m, constant bias of the sensor or drive


@dataclass(frozen=True)
class Link:
    """Inertial parameters of one link, in that link's DH frame (SI units).

    ``inertia`` is (ixx, iyy, izz, ixy, ixz, iyz) about the centre of mass.  Loaded values
    are exact rationals (sympy), the decimals as written, so that everything derived from
    them and baked into generated code is computed exactly, whatever the processor."""

    mass: sympy.Rational
    com: tuple[sympy.Rational, sympy.Rational, sympy.Rational]
    inertia: tuple[sympy.Rational, ...]

    def inertia_matrix(self) -> np.ndarray:
        """The inertia about the CoM as a float 3x3 array."""
        ixx, iyy, izz, ixy, ixz, iyz = (float(v) for v in self.inertia)
        return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


@dataclass(frozen=True)
class RobotModel:
    """A serial arm of revolute joints. Constant: derivations read it, never change it."""

    name: str
    convention: str  # "standard" or "modified" DH
    gravity: tuple[sympy.Rational, sympy.Rational, sympy.Rational]  # exact, m/s^2
    joints: tuple[Joint, ...]
    links: tuple[Link, ...]
    source: str = "<memory>"
    payload: Link | None = None                     # a rigid body fixed to the flange, flange frame
    coulomb_smoothing: sympy.Rational | None = None  # eps (rad/s) of tanh(qd / eps); None: sign(qd)

    @property
    def effects(self) -> tuple[str, ...]:
        """The joint effects the description declares, in a fixed order: friction (any joint
        with a ``friction`` entry gives every joint viscous, Coulomb and offset terms, zero
        where not given) and ``armature``."""
        out = []
        if any(j.friction is not None for j in self.joints):
            out += ["viscous_friction", "coulomb_friction", "torque_offset"]
        if any(j.armature is not None for j in self.joints):
            out.append("armature")
        return tuple(out)

    def friction(self, i: int) -> Friction:
        """Joint i's friction (zeros where the description gives none)."""
        return self.joints[i].friction or Friction()

    def armature(self, i: int) -> sympy.Rational:
        """Joint i's armature (zero where the description gives none)."""
        return self.joints[i].armature if self.joints[i].armature is not None else sympy.Integer(0)

    @property
    def n(self) -> int:
        return len(self.joints)

    @property
    def lower(self) -> np.ndarray:
        return np.array([j.lower for j in self.joints])

    @property
    def upper(self) -> np.ndarray:
        return np.array([j.upper for j in self.joints])

    @property
    def length_symbols(self) -> tuple:
        """Symbolic DH lengths (plain names in the YAML), in order of first appearance."""
        seen = []
        for joint in self.joints:
            for value in (joint.a, joint.d):
                if isinstance(value, sympy.Symbol) and value not in seen:
                    seen.append(value)
        return tuple(seen)

    @property
    def identifier(self) -> str:
        """The name as a C identifier (used as the prefix of generated functions)."""
        ident = "".join(ch if ch.isalnum() else "_" for ch in self.name.lower())
        return ident if not ident[0].isdigit() else "r_" + ident


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
TOP_KEYS = ("name", "dh", "gravity", "joints", "links", "payload", "coulomb_smoothing")
JOINT_KEYS = ("a", "alpha", "d", "offset", "lower", "upper", "friction", "armature")
LINK_KEYS = ("mass", "com", "inertia")
FRICTION_KEYS = ("viscous", "coulomb", "offset")


def _check_keys(mapping: dict, allowed: tuple[str, ...], source: str, prefix: str) -> None:
    """Refuse unknown keys (a typo such as ``ofset`` would otherwise be ignored silently).

    >>> _check_keys({"a": 0, "ofset": 1}, JOINT_KEYS, "f.yaml", "joints[0].")
    Traceback (most recent call last):
    ...
    kindyngen.robot.RobotDescriptionError: f.yaml: field 'joints[0].ofset': unknown key; did you mean 'offset'? (known: a, alpha, d, offset, lower, upper, friction, armature)
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
    return _number(value, source, field, exact=True)


def _parse_joint(row, source: str, field: str) -> Joint:
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping, got {row!r}")
    _check_keys(row, JOINT_KEYS, source, field + ".")
    exact = {k: _length(_require(row, k, source, field + "."), source, f"{field}.{k}") for k in ("a", "d")}
    exact["alpha"] = _number(_require(row, "alpha", source, field + "."), source, f"{field}.alpha", exact=True)
    offset = _number(row.get("offset", 0), source, f"{field}.offset", exact=True)
    lower = _number(_require(row, "lower", source, field + "."), source, f"{field}.lower")
    upper = _number(_require(row, "upper", source, field + "."), source, f"{field}.upper")
    if not lower < upper:
        raise RobotDescriptionError(source, f"{field}.lower", f"limits reversed or empty: lower {lower:g} >= upper {upper:g}")
    friction = _parse_friction(row["friction"], source, f"{field}.friction") if "friction" in row else None
    armature = _nonnegative(row["armature"], source, f"{field}.armature") if "armature" in row else None
    return Joint(a=exact["a"], alpha=exact["alpha"], d=exact["d"], offset=offset, lower=lower, upper=upper,
                 friction=friction, armature=armature)


def _nonnegative(value, source: str, field: str) -> sympy.Rational:
    """A coefficient that is physically non-negative (viscous and Coulomb friction, armature)."""
    value = _rational(value, source, field)
    if value < 0:
        raise RobotDescriptionError(source, field, f"must be non-negative (a physical coefficient), got {float(value):g}")
    return value


def _parse_friction(row, source: str, field: str) -> Friction:
    """``{viscous: fv, coulomb: fc, offset: f0}``, each optional (0), fv and fc >= 0."""
    if not isinstance(row, dict):
        raise RobotDescriptionError(source, field, f"expected a mapping with {', '.join(FRICTION_KEYS)}, got {row!r}")
    _check_keys(row, FRICTION_KEYS, source, field + ".")
    zero = sympy.Integer(0)
    return Friction(viscous=_nonnegative(row.get("viscous", 0), source, f"{field}.viscous"),
                    coulomb=_nonnegative(row.get("coulomb", 0), source, f"{field}.coulomb"),
                    offset=_rational(row.get("offset", 0), source, f"{field}.offset") if "offset" in row else zero)


def check_inertia(inertia: np.ndarray, source: str, field: str, point_mass_allowed: bool = False) -> None:
    """Reject a tensor that no rigid body has: not symmetric positive definite, or
    principal moments violating the triangle inequality (each at most the sum of the others).
    With ``point_mass_allowed`` an all-zero tensor (a point mass) is accepted."""
    moments = np.linalg.eigvalsh(inertia)
    if point_mass_allowed and not np.any(inertia):
        return
    scale = max(abs(moments).max(), 1e-300)
    if moments.min() <= 1e-12 * scale:
        listed = ", ".join(f"{v:.6g}" for v in moments)
        raise RobotDescriptionError(source, field, f"inertia is not positive definite (principal moments {listed})")
    a, b, c = (float(v) for v in sorted(moments))
    if c > a + b + 1e-9 * scale:
        raise RobotDescriptionError(
            source, field,
            f"principal moments {a:.6g}, {b:.6g}, {c:.6g} violate the triangle inequality ({c:.6g} > {a:.6g} + {b:.6g})")


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


def parse_robot(data, source: str = "<memory>") -> RobotModel:
    """Build a :class:`RobotModel` from already-parsed YAML data."""
    if not isinstance(data, dict):
        raise RobotDescriptionError(source, "<top level>", "expected a mapping with name, dh, gravity, joints, links")
    _check_keys(data, TOP_KEYS, source, "")
    name = _require(data, "name", source, "")
    if not isinstance(name, str) or not name.strip():
        raise RobotDescriptionError(source, "name", f"expected a non-empty string, got {name!r}")
    convention = _require(data, "dh", source, "")
    if convention not in CONVENTIONS:
        raise RobotDescriptionError(source, "dh", f"expected one of {CONVENTIONS}, got {convention!r}")
    gravity = _vector(_require(data, "gravity", source, ""), 3, source, "gravity")
    rows = _require(data, "joints", source, "")
    if not isinstance(rows, list) or not rows:
        raise RobotDescriptionError(source, "joints", "expected a non-empty list of DH rows")
    joints = tuple(_parse_joint(row, source, f"joints[{k}]") for k, row in enumerate(rows))
    links_data = _require(data, "links", source, "")
    if not isinstance(links_data, list):
        raise RobotDescriptionError(source, "links", "expected a list with one entry per joint")
    if len(links_data) != len(joints):
        raise RobotDescriptionError(source, "links", f"expected {len(joints)} entries (one per joint), got {len(links_data)}")
    links = tuple(_parse_link(row, source, f"links[{k}]") for k, row in enumerate(links_data))
    # a payload may be a point mass (zero inertia about its CoM), unlike a link
    payload = _parse_link(data["payload"], source, "payload", point_mass_allowed=True) if "payload" in data else None
    smoothing = None
    if "coulomb_smoothing" in data:
        smoothing = _rational(data["coulomb_smoothing"], source, "coulomb_smoothing")
        if smoothing <= 0:
            raise RobotDescriptionError(source, "coulomb_smoothing",
                                        f"must be a positive velocity (rad/s), got {float(smoothing):g}")
    return RobotModel(name=name.strip(), convention=convention, gravity=gravity, joints=joints,
                      links=links, source=source, payload=payload, coulomb_smoothing=smoothing)


def load_robot(path: str | Path) -> RobotModel:
    """Read and validate a robot description file."""
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise RobotDescriptionError(source, "<file>", f"cannot read: {exc.strerror}") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise RobotDescriptionError(source, "<yaml>", f"malformed YAML{where}: {problem}") from exc
    return parse_robot(data, source)
