"""URDF -> :class:`kindyngen.model.robot_model.RobotModel`: the serial chain from a base link to a tip link.

Each revolute, continuous or prismatic joint on the chain becomes a
:class:`kindyngen.model.robot_model.Joint` whose link frame is the URDF child link frame:
``before = F * T(xyz) Rz(yaw) Ry(pitch) Rx(roll) * A``, ``after = A^-1``, with F the fixed
joints met since the previous moving joint and A turning z onto the joint axis. Fixed joints
are merged: into the next moving joint's ``before``, or after the last one into the model's
``tool``. Each moving joint's :class:`kindyngen.model.robot_model.Link` is the exact combination (mass,
centre of mass, inertia about it, in the child link frame) of its child link and every link
fixed to it, the same bodies Pinocchio's ``buildModelFromUrdf`` makes; a moving joint off
the chain (a gripper's fingers) is locked at q = 0 with a note (its links join the body it
hangs from, as in Pinocchio's ``buildReducedModel``), and links above the first moving joint
are the base, which carries no dynamics.

``<mimic joint multiplier offset>`` on a moving joint makes it follow another moving joint,
``q = multiplier * q_joint + offset`` (defaults 1 and 0, exact as written;
:class:`kindyngen.model.robot_model.Mimic`): a mimic of a mimic is resolved into the joint at
the end of the chain, a cycle or a mimicked joint that is missing or fixed is an error. A chain
(no ``--tree``) keeps a mimic joint whose joint is on it; an off-chain joint locked at 0 locks
its mimics at their offsets; a mimic pair split by the chain's end is an error (read the tree).
On a fixed joint ``<mimic>`` moves nothing and is ignored (as urdfdom does).

Numbers are read as the decimals written (exact rationals); lengths below 1e-12 are 0 and
angles are cleaned by :func:`kindyngen.model.placement.clean_angle` (1.5708 read as pi/2, with a
note). An inertia entry that is not rational (rotated by an angle that is not a multiple of
pi/12) is its value to 17 significant digits, so every :class:`Link` field is rational.
A URDF states no gravity: the model's is (0, 0, -9.81) m/s^2, the base link's z axis up.
Every problem is a :class:`kindyngen.model.robot_model.RobotDescriptionError` naming the file and the
element, never a traceback.

Example: a 1-joint arm turning about y, its link a point mass 1 kg at 0.5 m along x:

>>> model = parse_urdf('''<robot name="pendulum">
...   <link name="base"/>
...   <link name="arm"><inertial><mass value="1"/><origin xyz="0.5 0 0"/>
...     <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
...   <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/>
...     <origin xyz="0 0 1" rpy="0 0 1.5708"/><axis xyz="0 1 0"/>
...     <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
... </robot>''')
>>> joint = model.joints[0]
>>> joint.name, joint.kind, joint.lower, joint.upper
('shoulder', 'revolute', -2.0, 2.0)
>>> joint.before.factors           # T(xyz) Rz(yaw), then Rx(-pi/2) turning z onto the axis y
(('trans', (0, 0, 1)), ('rot', (0, 0, 1), pi/2), ('rot', (1, 0, 0), -pi/2))
>>> joint.after.factors
(('rot', (1, 0, 0), pi/2),)
>>> model.links[0].mass, model.links[0].com, model.base_name, model.flange_name
(1, (1/2, 0, 0), 'base', 'arm')
>>> print(model.notes[0])
<memory>: joint 'shoulder' origin rpy[2]: 1.5708 read as pi/2 (off by 3.7e-06 rad; keep the value ...)
"""
from __future__ import annotations

import difflib
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np     # only to check inertias as written: nothing in the model is computed with it
import sympy

from dataclasses import replace

from ..model.robot_model import (DIRECTIONS, Frame, Joint, Link, LOOP_DIRECTIONS, LOOP_TYPES, LoopClosure, Mimic,
                                 RobotDescriptionError, RobotModel, check_inertia, check_name)
from ..model.placement import (Placement, Reading, axis_alignment, exact_length, rotation, rpy_xyz, translation,
                               unit_axis)
from .input_bounds import (MAX_URDF_BYTES, check_angle, check_number, check_quantity, degrees_hint, read_bounded,
                           shown)

GRAVITY = (sympy.Integer(0), sympy.Integer(0), sympy.Rational(-981, 100))
MOVING = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic"}
UNSUPPORTED = ("floating", "planar")          # several degrees of freedom: not a serial-arm joint
JOINT_TYPES = tuple(MOVING) + ("fixed",) + UNSUPPORTED
TINY_RESIDUE = 1e-20    # an evaluated inertia or CoM entry below this is an exact cancellation
SIGNIFICANT_DIGITS = 17  # a double's worth: non-rational entries are rounded to this
# a decimal as URDF parsers read it (float() would also accept nan, inf and 1_0)
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")

# a floating body with two pendulums, the example of the tree modules
TWO_PENDULUMS = """<robot name="two_pendulums">
  <link name="body"><inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.2" iyz="0" izz="0.3"/></inertial></link>
  <link name="left"><inertial><mass value="1"/><origin xyz="0 0 -0.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.001"/></inertial></link>
  <link name="right"><inertial><mass value="1"/><origin xyz="0 0 -0.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.001"/></inertial></link>
  <joint name="left_joint" type="revolute"><parent link="body"/><child link="left"/>
    <origin xyz="0 0.2 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="right_joint" type="revolute"><parent link="body"/><child link="right"/>
    <origin xyz="0 -0.2 0"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"""


def _error(reading: Reading, field: str, reason: str) -> RobotDescriptionError:
    return RobotDescriptionError(reading.source, field, reason)


@dataclass(frozen=True)
class _Origin:
    """An ``<origin>`` as written (floats), with the element path its notes name."""

    xyz: tuple
    rpy: tuple
    field: str


@dataclass(frozen=True)
class _Inertial:
    """A link's ``<inertial>`` as written: mass, origin, (ixx, ixy, ixz, iyy, iyz, izz)."""

    mass: float
    origin: _Origin
    inertia: tuple


@dataclass(frozen=True)
class _UrdfMimic:
    """A joint's ``<mimic>`` as written: the joint it follows, multiplier, offset (floats)."""

    joint: str
    multiplier: float
    offset: float


@dataclass(frozen=True)
class _UrdfJoint:
    """A ``<joint>`` as written (numbers as floats, checked but not yet made exact)."""

    name: str
    kind: str
    parent: str
    child: str
    origin: _Origin
    axis: tuple                 # as written, (1, 0, 0) when absent (the URDF default)
    limit: tuple | None         # (lower, upper) of <limit>, None without one
    mimic: _UrdfMimic | None


@dataclass(frozen=True)
class _Tree:
    """The kinematic tree: links (name -> inertial or None) in document order, the joint
    above each non-root link, the joints below each link, and the root link."""

    links: dict
    parent_joint: dict
    child_joints: dict
    root: str
    loop_joints: tuple = ()     # <loop_joint> elements (:class:`_UrdfLoop`), in document order
    actuated: tuple = ()        # joints named by <transmission> elements, in document order


@dataclass(frozen=True)
class _UrdfLoop:
    """A ``<loop_joint name type [directions]>`` with its ``<link1 link xyz rpy/>`` and
    ``<link2 .../>`` (Isaac Sim's URDF extension for closed chains), as written."""

    name: str
    kind: str
    links: tuple                # (link name, _Origin) of link1, link2
    directions: tuple | None    # as written, None: the type's


# ------------------------------------------------------------------ numbers and elements

def _floats(text: str | None, count: int, reading: Reading, field: str, quantity: str | None = None
            ) -> tuple[float, ...]:
    """``count`` whitespace-separated finite decimals, each 0 or within 1e-100..1e100 in
    magnitude, and within the plausible range of ``quantity`` (a key of
    :data:`kindyngen.readers.input_bounds.QUANTITIES`, or ``"angle"``: a full turn).

    >>> _floats("0 0.333 -1e-3", 3, Reading("f.urdf"), "xyz", "length")
    (0.0, 0.333, -0.001)
    """
    tokens = (text or "").split()
    if len(tokens) != count:
        raise _error(reading, field, f"expected {count} numbers, got {shown(text)}")
    for token in tokens:
        if not _NUMBER.fullmatch(token):
            hint = " (a xacro expression: run xacro on the file first)" if "$" in token else ""
            raise _error(reading, field, f"cannot read {shown(token)} as a number{hint}")
    values = tuple(float(token) for token in tokens)
    if not all(math.isfinite(v) for v in values):
        raise _error(reading, field, f"expected finite numbers, got {shown(text)}")
    for k, value in enumerate(values):
        where = f"{field}[{k}]" if count > 1 else field
        if quantity == "angle":
            check_angle(value, reading.source, where)
        elif quantity is not None:
            check_quantity(value, quantity, reading.source, where)
        else:
            check_number(value, reading.source, where)
    return values


def _attribute(element: ET.Element, name: str, reading: Reading, field: str, default: float | None = None,
               quantity: str | None = None) -> float:
    """One numeric attribute (``default`` when absent, an error when there is none)."""
    text = element.get(name)
    if text is None:
        if default is None:
            raise _error(reading, f"{field} {name}", "missing")
        return default
    return _floats(text, 1, reading, f"{field} {name}", quantity)[0]


def _read_origin(element: ET.Element | None, reading: Reading, field: str) -> _Origin:
    """An optional ``<origin xyz rpy>`` (absent parts zero; a loop joint's link element
    carries the same attributes)."""
    field = f"{field} origin" if element is None or element.tag == "origin" else field
    if element is None:
        return _Origin((0.0,) * 3, (0.0,) * 3, field)
    return _Origin(_floats(element.get("xyz", "0 0 0"), 3, reading, f"{field} xyz", "length"),
                   _floats(element.get("rpy", "0 0 0"), 3, reading, f"{field} rpy", "angle"), field)


def _placement(origin: _Origin, reading: Reading) -> Placement:
    """An origin as an exact placement ``T(xyz) Rz(yaw) Ry(pitch) Rx(roll)``, noting every
    snapped angle."""
    angles = [reading.angle(value, f"{origin.field} rpy[{k}]") for k, value in enumerate(origin.rpy)]
    return rpy_xyz([exact_length(v) for v in origin.xyz], angles)


def _name(element: ET.Element, what: str, index: int, reading: Reading) -> str:
    name = element.get("name")
    if not name:
        raise _error(reading, f"{what}[{index}] name", f"<{what}> number {index + 1} has no name")
    return check_name(name, reading.source, f"{what}[{index}] name")


def _read_inertial(element: ET.Element, link: str, reading: Reading) -> _Inertial | None:
    """A link's ``<inertial>`` (None without one); mass, origin and all six moments as
    urdfdom requires them."""
    inertial = element.find("inertial")
    if inertial is None:
        return None
    field = f"link '{link}' inertial"
    mass_element, inertia_element = inertial.find("mass"), inertial.find("inertia")
    if mass_element is None:
        raise _error(reading, f"{field} mass", "missing")
    if inertia_element is None:
        raise _error(reading, f"{field} inertia", "missing")
    mass = _attribute(mass_element, "value", reading, f"{field} mass", quantity="mass")
    if mass < 0:
        raise _error(reading, f"{field} mass value", f"mass must not be negative, got {mass:g}")
    moments = tuple(_attribute(inertia_element, key, reading, f"{field} inertia", quantity="inertia")
                    for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))
    return _Inertial(mass, _read_origin(inertial.find("origin"), reading, field), moments)


def _read_joint(element: ET.Element, index: int, reading: Reading) -> _UrdfJoint:
    name = _name(element, "joint", index, reading)
    field = f"joint '{name}'"
    kind = element.get("type")
    if kind not in JOINT_TYPES:
        raise _error(reading, f"{field} type", f"expected one of {', '.join(JOINT_TYPES)}, got {kind!r}")
    ends = []
    for end in ("parent", "child"):
        link = element.find(end)
        if link is None or not link.get("link"):
            raise _error(reading, f"{field} {end}", f"missing (<{end} link=\"...\"/>)")
        ends.append(link.get("link"))
    axis = element.find("axis")
    axis = (1.0, 0.0, 0.0) if axis is None else _floats(axis.get("xyz", "1 0 0"), 3, reading, f"{field} axis xyz")
    limit = element.find("limit")
    if limit is not None:
        # a prismatic joint's limits are lengths; a revolute one's may exceed a full turn
        # (multi-turn joints, placeholders such as 1e16: a note, _turn_notes)
        quantity = "length" if kind == "prismatic" else None
        limit = tuple(_attribute(limit, key, reading, f"{field} limit", default=0.0, quantity=quantity)
                      for key in ("lower", "upper"))
    mimic = element.find("mimic")
    if mimic is not None and kind in MOVING:
        mimic = _read_mimic(mimic, kind, reading, f"{field} mimic")
    else:
        mimic = None            # on a fixed joint <mimic> moves nothing (urdfdom keeps it unused)
    return _UrdfJoint(name, kind, ends[0], ends[1], _read_origin(element.find("origin"), reading, field),
                      axis, limit, mimic)


def _read_mimic(element: ET.Element, kind: str, reading: Reading, field: str) -> _UrdfMimic:
    """``<mimic joint multiplier offset>``: the joint named, multiplier (default 1, not 0) and
    offset (default 0; an angle within a full turn, a prismatic joint's a length)."""
    joint = element.get("joint")
    if not joint:
        raise _error(reading, f"{field} joint", "missing (the name of the joint this one follows)")
    multiplier = _attribute(element, "multiplier", reading, field, default=1.0, quantity="coefficient")
    if multiplier == 0:
        raise _error(reading, f"{field} multiplier", "0 would hold the joint at its offset: write a fixed joint")
    offset = _attribute(element, "offset", reading, field, default=0.0,
                        quantity="length" if kind == "prismatic" else "angle")
    return _UrdfMimic(joint, multiplier, offset)


class _DocumentType(Exception):
    """A ``<!DOCTYPE>`` met while parsing (see :class:`_NoDocumentType`)."""


class _NoDocumentType(ET.TreeBuilder):
    """A tree builder that stops at a document type declaration: a URDF needs no DTD, and the
    entities one declares can expand without bound ("billion laughs") or name other files.
    The parser calls ``doctype`` at the declaration's start, before any entity is read."""

    def doctype(self, name, pubid, system):
        raise _DocumentType(name)


def _read_xml(text: str | bytes, reading: Reading) -> ET.Element:
    """The ``<robot>`` element of a URDF text (refused with a document type declaration).

    >>> _read_xml('<!DOCTYPE r [<!ENTITY a "1">]><robot name="&a;"/>', Reading("f.urdf"))
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.urdf: field '<!DOCTYPE>': a document type declaration (DTD) is refused: a URDF needs none, and its entities could expand without bound or read other files
    """
    parser = ET.XMLParser(target=_NoDocumentType())
    try:
        parser.feed(text)
        root = parser.close()
    except _DocumentType:
        raise _error(reading, "<!DOCTYPE>", "a document type declaration (DTD) is refused: a URDF needs none, and "
                                            "its entities could expand without bound or read other files") from None
    except ET.ParseError as exc:
        line, column = exc.position
        raise _error(reading, "<xml>", f"malformed XML at line {line}, column {column + 1}: {exc}") from exc
    if root.tag != "robot":
        raise _error(reading, "<robot>", f"the top element is <{root.tag}>, expected <robot>")
    return root


def _closest(name: str, names) -> str:
    close = difflib.get_close_matches(name, list(names), n=3, cutoff=0.4)
    return f"; closest: {', '.join(close)}" if close else ""


def _read_tree(robot: ET.Element, reading: Reading) -> _Tree:
    """Links and joints (direct children of ``<robot>``: a ``<transmission>`` names joints
    too), checked to form one tree."""
    links, link_index = {}, {}
    for index, element in enumerate(robot.findall("link")):
        name = _name(element, "link", index, reading)
        if name in links:
            raise _error(reading, f"link '{name}'", f"defined twice: <link> number {link_index[name] + 1} and "
                                                    f"number {index + 1}")
        links[name] = _read_inertial(element, name, reading)
        link_index[name] = index
    if not links:
        raise _error(reading, "<robot>", "no <link> elements")
    parent_joint, child_joints, joint_index = {}, {name: [] for name in links}, {}
    for index, element in enumerate(robot.findall("joint")):
        joint = _read_joint(element, index, reading)
        if joint.name in joint_index:
            raise _error(reading, f"joint '{joint.name}'", f"defined twice: <joint> number "
                                                           f"{joint_index[joint.name] + 1} and number {index + 1}")
        joint_index[joint.name] = index
        for end, link in (("parent", joint.parent), ("child", joint.child)):
            if link not in links:
                raise _error(reading, f"joint '{joint.name}' {end}",
                                    f"link '{link}' is not defined{_closest(link, links)}")
        if joint.child in parent_joint:
            raise _error(reading, f"joint '{joint.name}' child", f"link '{joint.child}' already has a parent "
                                f"(joint '{parent_joint[joint.child].name}'): not a tree")
        parent_joint[joint.child] = joint
        child_joints[joint.parent].append(joint)
    loops = tuple(_read_loop(element, index, links, reading) for index, element in enumerate(robot.findall("loop_joint")))
    actuated = tuple(joint.get("name") for element in robot.findall("transmission")
                     for joint in element.findall("joint") if joint.get("name"))
    roots = [name for name in links if name not in parent_joint]
    if len(roots) > 1:
        raise _error(reading, "<robot>", f"several root links, not connected by joints: {', '.join(roots)}")
    reached = _descendants(child_joints, roots[0]) if roots else []
    if len(reached) < len(links):
        cycle = [name for name in links if name not in reached]
        raise _error(reading, "<robot>", f"the joints between links {', '.join(cycle)} form a cycle")
    return _Tree(links, parent_joint, child_joints, roots[0], loops, actuated)


def _read_loop(element: ET.Element, index: int, links: dict, reading: Reading) -> _UrdfLoop:
    """A ``<loop_joint>``: its type (``spherical``, as Isaac Sim's importer reads; ``revolute``
    and ``fixed`` too), the two links with the loop frame's origin on each (``xyz``, ``rpy``;
    the second element may be written ``<link2>`` or, as Isaac Sim's documentation does, a
    second ``<link1>``), and optionally ``directions="x y"`` (a planar linkage's two in-plane
    translations)."""
    name = _name(element, "loop_joint", index, reading)
    field = f"loop_joint '{name}'"
    kind = element.get("type")
    if kind not in LOOP_TYPES:
        raise _error(reading, f"{field} type", f"expected one of {', '.join(LOOP_TYPES)}, got {kind!r}")
    ends = element.findall("link1") + element.findall("link2")
    if len(ends) != 2:
        raise _error(reading, field, f"expected two links (<link1 link=\"...\"/> and <link2 .../>), got {len(ends)}")
    placed = []
    for k, end in enumerate(ends):
        where = f"{field} link{k + 1}"
        link = end.get("link")
        if not link or link not in links:
            raise _error(reading, f"{where} link", f"link {shown(link)} is not defined{_closest(link or '', links)}")
        placed.append((link, _read_origin(end, reading, where)))
    if placed[0][0] == placed[1][0]:
        raise _error(reading, f"{field} link2", "a loop joint joins two different links")
    directions = element.get("directions")
    if directions is not None:
        directions = tuple(directions.split())
        allowed = LOOP_DIRECTIONS[kind]
        wrong = [d for d in directions if d not in allowed]
        if wrong or not directions or len(set(directions)) != len(directions):
            raise _error(reading, f"{field} directions", f"expected distinct directions among "
                         f"{', '.join(allowed)} (a {kind} loop joint), got {shown(element.get('directions'))}")
    return _UrdfLoop(name, kind, tuple(placed), directions)


def _read_robot(text: str | bytes, reading: Reading) -> tuple[str, _Tree]:
    """The robot's name and its tree of links and joints."""
    robot = _read_xml(text, reading)
    name = (robot.get("name") or "").strip()
    if not name:
        raise _error(reading, "<robot> name", "missing (the model's name)")
    return check_name(name, reading.source, "<robot> name"), _read_tree(robot, reading)


def _descendants(child_joints: dict, link: str, follow=lambda joint: True) -> list:
    """``link`` and the links below it (through joints accepted by ``follow``), depth first."""
    out, stack = [], [link]
    while stack:
        name = stack.pop()
        out.append(name)
        stack.extend(joint.child for joint in reversed(child_joints[name]) if follow(joint))
    return out


# ------------------------------------------------------------------ the chain

def _link_name(tree: _Tree, name: str, option: str, reading: Reading) -> str:
    if name not in tree.links:
        raise _error(reading, option, f"no link named '{name}' in the URDF{_closest(name, tree.links)}")
    return name


def _path(tree: _Tree, base: str, tip: str, reading: Reading) -> list:
    """The joints from ``base`` down to ``tip``."""
    path, link = [], tip
    while link != base:
        if link == tree.root:
            raise _error(reading, "--tip", f"link '{tip}' is not below the base link '{base}'")
        path.append(tree.parent_joint[link])
        link = path[-1].parent
    return path[::-1]


def _default_tip(tree: _Tree, base: str, reading: Reading) -> str:
    """The single leaf below ``base`` reached through a moving joint (a leaf fixed to the
    base, such as UR's ``base`` frame, belongs to the base and cannot end an arm)."""
    static = set(_descendants(tree.child_joints, base, lambda joint: joint.kind == "fixed"))
    leaves = [link for link in _descendants(tree.child_joints, base)
              if not tree.child_joints[link] and link not in static]
    if len(leaves) == 1:
        return leaves[0]
    if not leaves:
        raise _error(reading, "--base", f"no moving joint below link '{base}'")
    raise _error(reading, "--tip", f"the tree below '{base}' has {len(leaves)} leaves; name the last link "
                        f"of the arm with --tip (one of: {', '.join(leaves)})")


def _limits(joint: _UrdfJoint, reading: Reading) -> tuple[float, float]:
    """The joint's range; a continuous joint (and a revolute one with limits 0, 0, which
    some exporters write for unlimited) gets -pi..pi, for samplers, with a note."""
    field = f"joint '{joint.name}' limit"
    if joint.kind == "continuous":
        reading.note(f"{reading.source}: joint '{joint.name}' is continuous: range -pi..pi assumed")
        return -math.pi, math.pi
    if joint.limit is None:
        raise _error(reading, field, f"missing (URDF requires <limit lower upper> on {joint.kind} joints)")
    lower, upper = joint.limit
    if lower == upper == 0:
        if joint.kind == "prismatic":
            raise _error(reading, field, "a prismatic joint needs a range (lower and upper are 0)")
        reading.note(f"{reading.source}: {field} is 0..0: range -pi..pi assumed")
        return -math.pi, math.pi
    if not lower < upper:
        raise _error(reading, field, f"limits reversed or empty: lower {lower:g} >= upper {upper:g}")
    return lower, upper


def _note_turns(joints: list, reading: Reading) -> None:
    """One note for the revolute joints with a limit beyond a full turn that could be degrees
    (up to 720): URDF states radians, and real URDFs write multi-turn ranges and placeholders
    (Solo's -10..10, a drone rotor's 1e16), so limits are read as written; the note is there
    for a URDF written in degrees by mistake.

    >>> reading = Reading("f.urdf")
    >>> _note_turns([Joint(Placement(), Placement(), 0, -170.0, 170.0, name="q1")], reading)
    >>> print(reading.notes[0])
    f.urdf: revolute joint limits beyond a full turn, read as radians (URDF's unit; a multi-turn or unlimited joint): 'q1' -170..170; if degrees were meant, convert them
    """
    wide = [j for j in joints if not j.prismatic and (degrees_hint(j.lower) or degrees_hint(j.upper))]
    if not wide:
        return
    listed = ", ".join(f"'{j.name}' {j.lower:g}..{j.upper:g}" for j in wide[:3])
    more = f" and {len(wide) - 3} more" if len(wide) > 3 else ""
    reading.note(f"{reading.source}: revolute joint limits beyond a full turn, read as radians (URDF's unit; a "
                 f"multi-turn or unlimited joint): {listed}{more}; if degrees were meant, convert them")


def _axis(joint: _UrdfJoint, reading: Reading) -> tuple:
    """The joint axis as an exact unit vector."""
    if max(abs(v) for v in joint.axis) < 1e-9:
        raise _error(reading, f"joint '{joint.name}' axis xyz",
                            f"the axis {list(joint.axis)} has no direction (all zero)")
    return unit_axis(joint.axis)


def _moving_joint(joint: _UrdfJoint, fixed: Placement, reading: Reading) -> Joint:
    """A revolute or prismatic joint whose link frame is the URDF child link frame, placed
    after the fixed placement ``fixed`` on the previous link frame."""
    if joint.kind in UNSUPPORTED:
        raise _error(reading, f"joint '{joint.name}' type",
                            f"a {joint.kind} joint is not supported (only revolute, continuous, "
                            f"prismatic and fixed joints; a free root body is --floating-base)")
    align = axis_alignment(_axis(joint, reading))
    lower, upper = _limits(joint, reading)
    return Joint(before=fixed * _placement(joint.origin, reading) * align, after=align.inverse(),
                 offset=sympy.Integer(0), lower=lower, upper=upper, kind=MOVING[joint.kind], name=joint.name)


# ------------------------------------------------------------------ rigid bodies

def _rigid_body(tree: _Tree, link: str, chain: set, reading: Reading) -> list:
    """(placement in ``link``'s frame, inertial, name) of ``link`` and every link fixed to it;
    a moving joint not in ``chain`` (a gripper's fingers) is locked at q = 0, with a note, so
    its links count (the bodies of Pinocchio's ``buildReducedModel`` locking it at 0); one that
    mimics a locked joint is locked at its offset (:func:`_mimic_chains`)."""
    parts, stack = [], [(link, Placement())]
    while stack:
        name, placement = stack.pop()
        parts.append((placement, tree.links[name], name))
        fixed = []
        for joint in tree.child_joints[name]:
            if joint.kind == "fixed":
                fixed.append((joint.child, placement * _placement(joint.origin, reading)))
            elif joint.name not in chain:
                # at q = 0 a joint's transform is its origin (rotation and slide are zero)
                value = _mimic_chains(tree, reading)[joint.name][2] if joint.mimic is not None else 0
                fixed.append((joint.child, placement * _placement(joint.origin, reading)
                              * _locked_motion(joint, value, reading)))
                at = "0" if value == 0 else f"{float(value):g}, its offset (it mimics a locked joint)"
                reading.note(f"{reading.source}: joint '{joint.name}' ({joint.kind}) is not on the chain: "
                             f"locked at {at}, its links part of link '{link}'")
        stack.extend(reversed(fixed))       # depth first, in document order
    return parts


def _locked_motion(joint: _UrdfJoint, value, reading: Reading) -> Placement:
    """The joint's motion held at ``value`` (exact), about or along its axis."""
    value = sympy.sympify(value)
    if value == 0:
        return Placement()
    axis = _axis(joint, reading)
    return translation(*(a * value for a in axis)) if joint.kind == "prismatic" else rotation(axis, value)


def _mimic_chains(tree: _Tree, reading: Reading) -> dict:
    """Every mimic joint's name -> (the name of the joint at the end of its chain of mimics,
    multiplier, offset), composed exactly: ``q_a = m_a (m_b q_c + o_b) + o_a``. Errors: a
    mimicked joint missing or fixed, a cycle.

    >>> tree = _read_robot(TWO_PENDULUMS.replace('<axis xyz="1 0 0"/>', '<axis xyz="1 0 0"/><mimic joint="left_joint" '
    ...                    'multiplier="-0.5" offset="0.1"/>'), Reading("f.urdf"))[1]
    >>> _mimic_chains(tree, Reading("f.urdf"))
    {'right_joint': ('left_joint', -1/2, 1/10)}
    """
    joints = {joint.name: joint for joint in tree.parent_joint.values()}
    out = {}
    for joint in joints.values():
        if joint.mimic is None:
            continue
        multiplier, offset, path, current = sympy.Integer(1), sympy.Integer(0), [joint.name], joint
        while current.mimic is not None:
            field = f"joint '{current.name}' mimic joint"
            target = current.mimic.joint
            if target not in joints:
                raise _error(reading, field, f"no joint named '{target}'{_closest(target, joints)}")
            if joints[target].kind == "fixed":
                raise _error(reading, field, f"'{target}' is a fixed joint: a mimic follows a moving one")
            m, o = sympy.Rational(repr(current.mimic.multiplier)), sympy.Rational(repr(current.mimic.offset))
            multiplier, offset = multiplier * m, offset + multiplier * o
            if target in path:
                raise _error(reading, f"joint '{joint.name}' mimic joint", "the mimic joints form a cycle: "
                             + " -> ".join(path + [target]))
            path.append(target)
            current = joints[target]
        out[joint.name] = (path[-1], multiplier, offset)
    return out


def _with_mimics(joints: list, tree: _Tree, reading: Reading, scope: str) -> list:
    """``joints`` (of the model, in order) with their resolved mimics (:func:`_mimic_chains`),
    each naming the joint it follows by index; a joint followed from outside the model
    (``scope``: the chain, for the error) is an error, and so is a joint of the model that
    follows one outside it. One note names the mimic joints."""
    chains = _mimic_chains(tree, reading)
    index = {joint.name: k for k, joint in enumerate(joints)}
    out = []
    for joint in joints:
        if joint.name not in chains:
            out.append(joint)
            continue
        target, multiplier, offset = chains[joint.name]
        if target not in index:
            raise _error(reading, f"joint '{joint.name}' mimic joint", f"follows '{target}', which is not on "
                         f"{scope}: read the URDF as a tree (--tree) to have both")
        out.append(replace(joint, mimic=Mimic(index[target], multiplier, offset)))
    for name, (target, _, _) in chains.items():
        if name not in index and target in index:
            raise _error(reading, f"joint '{name}' mimic joint", f"'{name}' is not on {scope} but follows "
                         f"'{target}', which is: its links would move; read the URDF as a tree (--tree)")
    mimics = [joint.name for joint in out if joint.mimic is not None]
    if mimics:
        reading.note(f"{reading.source}: {len(mimics)} mimic joint(s) ({', '.join(mimics[:3])}"
                     f"{', ...' if len(mimics) > 3 else ''}) follow others: the generated functions take the "
                     f"{len(out) - len(mimics)} independent joints")
    return out


def _rational(value) -> sympy.Rational:
    """An exact constant as a rational: itself if rational, else its value to 17 significant
    digits (a decimal, the same on every machine); a cancellation residue is 0.

    >>> _rational(sympy.Rational(1, 3)), _rational(sympy.cos(sympy.Rational(3, 10)))
    (1/3, 47766824456280301/50000000000000000)
    """
    value = sympy.sympify(value)
    if value.is_Rational:
        return value
    approx = value.evalf(30)
    if abs(approx) < TINY_RESIDUE:
        return sympy.Integer(0)
    return sympy.Rational(str(sympy.Float(approx, SIGNIFICANT_DIGITS)))


def _combine(parts: list, reading: Reading) -> Link:
    """One body from rigid parts (placement, inertial, name): total mass, mass-weighted CoM
    and the inertia about it (each part's ``R I R^T`` moved by the parallel axis theorem),
    exact, in the frame the placements refer to. A part without ``<inertial>`` is massless."""
    masses, coms, inertias = [], [], []
    for placement, inertial, name in parts:
        if inertial is None:
            reading.note(f"{reading.source}: link '{name}' has no <inertial>: massless")
            continue
        check_inertia(_float_tensor(inertial.inertia), reading.source, f"link '{name}' inertial inertia",
                      point_mass_allowed=True)
        R, p = (placement * _placement(inertial.origin, reading)).matrix()
        ixx, ixy, ixz, iyy, iyz, izz = (sympy.Rational(repr(v)) for v in inertial.inertia)
        tensor = sympy.Matrix([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        masses.append(sympy.Rational(repr(inertial.mass)))
        coms.append(p)
        inertias.append(R * tensor * R.T)
    mass = sum(masses, sympy.Integer(0))
    com = sympy.zeros(3, 1)
    if mass != 0:
        com = sum((m * c for m, c in zip(masses, coms)), sympy.zeros(3, 1)) / mass
    total = sympy.zeros(3, 3)
    for m, c, tensor in zip(masses, coms, inertias):
        d = c - com
        total += tensor + m * ((d.T * d)[0] * sympy.eye(3) - d * d.T)
    return Link(mass=mass, com=tuple(_rational(v) for v in com),
                inertia=tuple(_rational(total[i, j]) for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))))


def _float_tensor(moments: tuple) -> np.ndarray:
    """The tensor as written, in floats, for :func:`kindyngen.model.robot_model.check_inertia` only."""
    ixx, ixy, ixz, iyy, iyz, izz = moments
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


# ------------------------------------------------------------------ entry points

def parse_urdf(text: str | bytes, source: str = "<memory>", base: str | None = None, tip: str | None = None,
               snap_angles: bool = True, *, tree: bool = False, frames=None, floating_base: bool = False) -> RobotModel:
    """The serial chain from link ``base`` (default: the root) to link ``tip`` (default: the
    only leaf reached through a moving joint) of a URDF text (see the module docstring); with
    ``tree`` (implied by ``frames`` or ``floating_base``) every moving joint, as a tree
    (:func:`_whole_tree`; ``base`` and ``tip`` do not apply)."""
    reading = Reading(source, snap_angles)
    name, graph = _read_robot(text, reading)
    if tree or frames is not None or floating_base:
        return _whole_tree(name, graph, frames, floating_base, reading)
    return _chain(name, graph, base, tip, reading)


def _chain(name: str, tree: _Tree, base: str | None, tip: str | None, reading: Reading) -> RobotModel:
    """The serial chain from ``base`` to ``tip``: fixed joints merged into the next moving
    joint or, after the last one, into the tool; moving joints off the chain locked at 0."""
    source = reading.source
    if tree.loop_joints:
        raise _error(reading, f"loop_joint '{tree.loop_joints[0].name}'", "loop joints close the tree: read the URDF "
                     "as a tree (--tree)")
    base = tree.root if base is None else _link_name(tree, base, "--base", reading)
    tip = _default_tip(tree, base, reading) if tip is None else _link_name(tree, tip, "--tip", reading)
    path = _path(tree, base, tip, reading)
    chain = {joint.name for joint in path}
    joints, links, fixed, flange = [], [], Placement(), None
    for joint in path:
        if joint.kind == "fixed":
            fixed = fixed * _placement(joint.origin, reading)
            continue
        joints.append(_moving_joint(joint, fixed, reading))
        links.append(_combine(_rigid_body(tree, joint.child, chain, reading), reading))
        fixed, flange = Placement(), joint.child
    if not joints:
        raise _error(reading, "--tip", f"no moving joint between links '{base}' and '{tip}'")
    joints = _with_mimics(joints, tree, reading, "the chain")
    _note_turns(joints, reading)
    return RobotModel(name=name, convention="frames", gravity=GRAVITY, joints=tuple(joints), links=tuple(links),
                      source=source, tool=fixed, base_name=base, flange_name=flange, notes=tuple(reading.notes))


def _whole_tree(name: str, tree: _Tree, frames, floating_base: bool, reading: Reading) -> RobotModel:
    """Every moving joint of a URDF text as a tree :class:`kindyngen.model.robot_model.RobotModel`.

    Joints are numbered depth first from the root link, children in the order Pinocchio's
    ``buildModelFromUrdf`` takes them (urdfdom's: by joint name), so that q, qd and tau line
    up with Pinocchio's (after its free-flyer part). Links fixed to a body are lumped into
    it; ``frames`` names the links whose poses and Jacobians are wanted (default: the link
    of every joint without children, the tips).

    >>> tree = parse_urdf(TWO_PENDULUMS, frames=["right", "body"])
    >>> [j.name for j in tree.joints], [(f.name, f.body) for f in tree.frames]
    (['left_joint', 'right_joint'], [('right', 1), ('body', -1)])
    """
    source = reading.source
    moving = {joint.name for joint in tree.parent_joint.values() if joint.kind != "fixed"}
    joints, parents, bodies, placed = [], [], [], {}

    def visit(link: str, body: int, placement: Placement) -> None:
        """Place ``link`` (on ``body`` by ``placement``) and everything below it, depth first."""
        placed[link] = Frame(link, body, placement)
        for joint in sorted(tree.child_joints[link], key=lambda joint: joint.name):
            if joint.kind == "fixed":
                visit(joint.child, body, placement * _placement(joint.origin, reading))
                continue
            joints.append(_moving_joint(joint, placement, reading))
            parents.append(body)
            bodies.append(joint.child)
            visit(joint.child, len(joints) - 1, Placement())

    visit(tree.root, -1, Placement())
    if not joints:
        raise _error(reading, "<robot>", "no moving joint (revolute, continuous or prismatic)")
    joints = _with_mimics(joints, tree, reading, "the tree")
    _note_turns(joints, reading)
    links = tuple(_combine(_rigid_body(tree, child, moving, reading), reading) for child in bodies)
    root = _combine(_rigid_body(tree, tree.root, moving, reading), reading)
    if frames is None:
        leaves = [j for j in range(len(joints)) if j not in parents]
        frames = [bodies[j] for j in leaves]
    chosen = []
    for frame in frames:
        if frame not in placed:
            raise _error(reading, "--frames", f"no link named '{frame}' in the URDF{_closest(frame, placed)}")
        chosen.append(placed[frame])
    loops, independent = _loops(tree, joints, placed, floating_base, reading)
    return RobotModel(name=name, convention="tree", joints=tuple(joints), parents=tuple(parents), links=links,
                      root=root, frames=tuple(chosen), floating_base=floating_base, gravity=GRAVITY, source=source,
                      base_name=tree.root, notes=tuple(reading.notes), loops=loops, independent=independent)


def _loops(tree: _Tree, joints: list, placed: dict, floating_base: bool, reading: Reading) -> tuple:
    """The tree's ``<loop_joint>`` s as :class:`LoopClosure` s (each frame on the body its
    link is lumped into) and the independent joints: those a ``<transmission>`` drives (the
    actuated ones), None without transmissions (the loops' rule decides). The model is
    assembled at q = 0 (as Isaac Sim's and SDFormat's closed chains are written)."""
    if not tree.loop_joints:
        return (), None
    first = f"loop_joint '{tree.loop_joints[0].name}'"
    if floating_base:
        raise _error(reading, first, "closed loops on a floating base are not supported (yet): read the tree with a "
                     "fixed base")
    if any(joint.mimic is not None for joint in joints):
        raise _error(reading, first, "mimic joints and closed loops in one tree are not supported (yet)")
    names = {joint.name for joint in joints}
    loops = []
    for loop in tree.loop_joints:
        if loop.name in names or loop.name in {other.name for other in loops}:
            raise _error(reading, f"loop_joint '{loop.name}' name", "already names a joint or another loop joint")
        frames = [placed[link] for link, _ in loop.links]
        if frames[0].body == frames[1].body:
            raise _error(reading, f"loop_joint '{loop.name}'", f"links '{loop.links[0][0]}' and '{loop.links[1][0]}' "
                         "are one rigid body (fixed to each other): the loop joint closes nothing")
        placements = [frame.placement * _placement(origin, reading) for frame, (_, origin) in zip(frames, loop.links)]
        directions = loop.directions or LOOP_DIRECTIONS[loop.kind]
        loops.append(LoopClosure(loop.name, loop.kind, frames[0].body, placements[0], frames[1].body, placements[1],
                                 tuple(d for d in DIRECTIONS if d in directions)))
    independent = None
    if tree.actuated:
        index = {joint.name: k for k, joint in enumerate(joints)}
        for name in tree.actuated:
            if name not in index:
                raise _error(reading, f"transmission joint '{name}'", "names no moving joint of the tree "
                             "(the transmissions' joints are the loops' independent coordinates)")
        independent = tuple(sorted({index[name] for name in tree.actuated}))
    return tuple(loops), independent


def load_urdf(path: str | Path, base: str | None = None, tip: str | None = None, snap_angles: bool = True, *,
              tree: bool = False, frames=None, floating_base: bool = False) -> RobotModel:
    """Read a URDF file: :func:`parse_urdf` of its text, errors naming the file."""
    return parse_urdf(_file_text(path), str(path), base=base, tip=tip, snap_angles=snap_angles, tree=tree,
                      frames=frames, floating_base=floating_base)


def _file_text(path: str | Path) -> bytes:
    """The file's bytes (the XML declaration names the encoding), at most
    :data:`kindyngen.readers.input_bounds.MAX_URDF_BYTES`."""
    return read_bounded(path, MAX_URDF_BYTES, "a URDF")
