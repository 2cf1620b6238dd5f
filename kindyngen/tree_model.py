"""The model of a kinematic tree: immutable, exact, read by :mod:`kindyngen.tree_dynamics`.

A :class:`TreeModel` is a tree of revolute and prismatic :class:`kindyngen.model.Joint` s
hanging from a root body, optionally a *floating base*: the root body moves freely, with
Pinocchio's free-flyer layout (``q`` = base position, base orientation quaternion x, y, z,
w, then the joints; ``qd`` = base linear and angular velocity in the base frame, then the
joints). Joint j is placed on the link frame of its parent ``parents[j]`` (-1: the root
body's frame) exactly as in a serial :class:`kindyngen.model.RobotModel` (``before *
motion(q) * after``); joints are in depth-first order, parents before children. Links fixed
to a body are lumped into it (:mod:`kindyngen.urdf`). ``frames`` are the frames of interest
(FK and Jacobians), each a link of the description placed on the body that carries it.

Example: a body with two pendulums (built by :func:`kindyngen.urdf.parse_urdf_tree`):

>>> from kindyngen.urdf import parse_urdf_tree
>>> tree = parse_urdf_tree(TWO_PENDULUMS, floating_base=True)
>>> tree.parents, tree.nq, tree.nv, [f.name for f in tree.frames]
((-1, -1), 9, 8, ['left', 'right'])
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy

from .model import Joint, Link
from .placement import Placement

FREE_FLYER_NQ, FREE_FLYER_NV = 7, 6

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


@dataclass(frozen=True)
class Frame:
    """A frame of interest: link ``name``'s frame, ``placement`` on the frame of the body it
    belongs to (``body`` = a joint index, -1 the root body)."""

    name: str
    body: int
    placement: Placement = Placement()


@dataclass(frozen=True)
class TreeModel:
    """A kinematic tree (see the module text). Constant: derivations read it, never change it."""

    name: str
    joints: tuple[Joint, ...]
    parents: tuple[int, ...]            # parent joint of each joint, -1 for the root body
    links: tuple[Link, ...]             # each joint's link (its child link and links fixed to it)
    root: Link                          # the root body (root link and links fixed to it)
    frames: tuple[Frame, ...]
    floating_base: bool = False
    gravity: tuple = (sympy.Integer(0), sympy.Integer(0), sympy.Rational(-981, 100))
    source: str = "<memory>"
    base_name: str = ""                 # the root link's name
    notes: tuple[str, ...] = ()
    convention: str = "tree"

    def __post_init__(self):
        assert len(self.parents) == len(self.joints) == len(self.links)
        assert all(-1 <= p < j for j, p in enumerate(self.parents)), "parents must come first"

    @property
    def n(self) -> int:
        """Number of joints (without the floating base)."""
        return len(self.joints)

    @property
    def nq(self) -> int:
        return self.n + (FREE_FLYER_NQ if self.floating_base else 0)

    @property
    def nv(self) -> int:
        return self.n + (FREE_FLYER_NV if self.floating_base else 0)

    def ancestors(self, j: int) -> tuple[int, ...]:
        """Joint j and the joints above it, from j up (frame bodies: -1 gives ())."""
        out = []
        while j >= 0:
            out.append(j)
            j = self.parents[j]
        return tuple(out)

    @property
    def depth(self) -> int:
        """The most joints on a path from the root (d of the O(n d^2) costs)."""
        return max((len(self.ancestors(j)) for j in range(self.n)), default=0)

    @property
    def identifier(self) -> str:
        """The name as a C identifier (the prefix of generated functions)."""
        ident = "".join(ch if ch.isalnum() else "_" for ch in self.name.lower())
        return ident if not ident[0].isdigit() else "r_" + ident

    @property
    def structure_text(self) -> str:
        """What the generated files say the robot is."""
        kinds = sorted({j.kind for j in self.joints})
        base = (f"floating base (nq {self.nq}, nv {self.nv})" if self.floating_base else "fixed base")
        return f"{self.n} {' and '.join(kinds)} joints in a tree of depth {self.depth}, {base}"

    @property
    def order_text(self) -> str:
        return "depth-first order (Pinocchio's)"

    @property
    def frames_text(self) -> str:
        world = ("the world frame (the base pose is q[0:7])" if self.floating_base
                 else f"the frame of the root link '{self.base_name}'")
        return f"Frames: poses and Jacobians in {world}."
