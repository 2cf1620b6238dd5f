"""The robot model every derivation reads: immutable dataclasses, exact numbers.

A :class:`RobotModel` is a kinematic tree of revolute and prismatic :class:`Joint` s, each
placed on the link frame of its parent ``parents[j]`` (-1: the root body) by exact constant
placements (:mod:`kindyngen.model.placement`), with the inertial parameters of every :class:`Link`
in that link's frame. A serial arm is the tree whose parent of joint j is j - 1 (the
default when ``parents`` is not given); it carries the arm's extras (joint effects, payload,
tool, DH rows). Optionally the root moves freely (a *floating base*, Pinocchio's free-flyer
layout: ``q`` = base position, base orientation quaternion x, y, z, w, then the joints;
``qd`` = base linear and angular velocity in the base frame, then the joints). Readers
build it from a YAML description (:mod:`kindyngen.readers.yaml_description`) or a URDF (:mod:`kindyngen.readers.urdf`);
derivations read it and never change it. ``frames`` are the frames of interest of a tree
(FK and Jacobians); an arm's is its flange moved by the tool.

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> model = load_robot("robots/lwr4.yaml")            # doctest: +SKIP
>>> model.n, model.joints[0].kind                     # doctest: +SKIP
(7, 'revolute')
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import sympy

from .placement import Placement

CONVENTIONS = ("standard", "modified")


class RobotDescriptionError(ValueError):
    """A robot description that cannot be used, with the file, field and reason."""

    def __init__(self, source: str, field: str, reason: str):
        self.source, self.field, self.reason = source, field, reason
        super().__init__(f"{source}: field '{field}': {reason}")


@dataclass(frozen=True)
class DHRow:
    """A joint's DH row as written (standard or modified convention of the model); kept for
    what is defined on DH tables only (the paper's per-joint coefficients, its simulator).
    ``alpha`` is exact (pi/2, not a float); ``a`` and ``d`` are exact numbers or symbols."""

    a: sympy.Expr
    alpha: sympy.Expr
    d: sympy.Expr
    theta: sympy.Expr = sympy.Integer(0)     # constant angle of a prismatic row


@dataclass(frozen=True)
class Joint:
    """One joint: ``before * motion(q) * after`` (see :mod:`kindyngen.model.placement`).

    ``before`` places the joint frame on the parent link's frame (the joint axis is that
    frame's z axis), ``motion`` is ``Rz(q + offset)`` for a revolute joint and ``Tz(q +
    offset)`` for a prismatic one, ``after`` places this joint's link frame (where the link's
    inertial parameters are given) on the moved joint frame. Everything is exact."""

    before: Placement
    after: Placement
    offset: sympy.Expr
    lower: float
    upper: float
    kind: str = "revolute"                   # "revolute" or "prismatic"
    name: str = ""
    friction: "Friction | None" = None       # None: the description declares no friction
    armature: sympy.Rational | None = None   # kg m^2 (kg, prismatic): reflected rotor inertia
    ripple: "Ripple | None" = None           # None: no position-periodic torque
    dh: DHRow | None = None                  # the DH row, when the description is a DH table
    # how the joint is *measured* (not part of the dynamics, nor of the generated code):
    # q_logged = q + tau / stiffness + encoder_offset, tau_logged = torque_gain * tau
    stiffness: sympy.Rational | None = None       # N m/rad (N/m): elasticity seen by a motor-side encoder
    encoder_offset: sympy.Rational | None = None  # rad (m): constant offset of the position reading
    torque_gain: sympy.Rational | None = None     # gain of the torque sensor (1: exact)

    @property
    def prismatic(self) -> bool:
        return self.kind == "prismatic"

    # the DH row's entries, for code defined on DH tables only
    @property
    def a(self):
        return self._dh().a

    @property
    def alpha(self):
        return self._dh().alpha

    @property
    def d(self):
        return self._dh().d

    def _dh(self) -> DHRow:
        if self.dh is None:
            raise ValueError(f"joint {self.name or '?'} has no DH row (given by origin and axis)")
        return self.dh


@dataclass(frozen=True)
class Friction:
    """Joint friction and torque bias, exact: ``tau_f = viscous qd + coulomb s + stribeck
    exp(-(qd / stribeck_velocity)^2) s + load |y| s + offset`` with ``s = sign(qd)`` (with
    ``coulomb_smoothing`` eps, ``tanh(qd / eps)``) and ``y`` the torque the joint transmits
    apart from friction (rigid bodies plus armature, :mod:`kindyngen.algorithms.effect_torques`).
    ``stribeck_velocity`` None: no Stribeck term declared; ``load`` None: no load-dependent
    term declared."""

    viscous: sympy.Rational = sympy.Integer(0)   # N m s/rad
    coulomb: sympy.Rational = sympy.Integer(0)   # N m
    offset: sympy.Rational = sympy.Integer(0)    # N m, constant bias of the sensor or drive
    stribeck: sympy.Rational = sympy.Integer(0)  # N m, static friction in excess of Coulomb's
    stribeck_velocity: sympy.Rational | None = None   # rad/s (> 0)
    load: sympy.Rational | None = None           # dimensionless, 0 <= load < 1


@dataclass(frozen=True)
class Ripple:
    """A torque periodic in the joint position (cogging, gear ripple), exact:
    ``sin_amplitude sin(order q) + cos_amplitude cos(order q)`` (N m), ``order`` periods per
    revolution (a positive integer)."""

    sin_amplitude: sympy.Rational
    cos_amplitude: sympy.Rational
    order: int


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


FREE_FLYER_NQ, FREE_FLYER_NV = 7, 6


@dataclass(frozen=True)
class Frame:
    """A frame of interest: link ``name``'s frame, ``placement`` on the frame of the body it
    belongs to (``body`` = a joint index, -1 the root body)."""

    name: str
    body: int
    placement: Placement = Placement()


ZERO_LINK = Link(mass=sympy.Integer(0), com=(sympy.Integer(0),) * 3, inertia=(sympy.Integer(0),) * 6)


@dataclass(frozen=True)
class RobotModel:
    """A kinematic tree (see the module text); a serial arm by default. Constant:
    derivations read it, never change it."""

    name: str
    # "standard" or "modified" DH, "frames" (an arm by origin and axis) or "tree" (read as a tree)
    convention: str
    gravity: tuple[sympy.Rational, sympy.Rational, sympy.Rational]  # exact, m/s^2
    joints: tuple[Joint, ...]
    links: tuple[Link, ...]             # each joint's link (its child link and links fixed to it)
    source: str = "<memory>"
    parents: tuple[int, ...] | None = None  # parent joint of each joint, -1 the root; None: j - 1
    root: Link = ZERO_LINK              # the root body (moves only with a floating base)
    frames: tuple[Frame, ...] = ()      # a tree's frames of interest (an arm: its flange, see flange_frame)
    floating_base: bool = False
    payload: Link | None = None                     # a rigid body fixed to the flange, flange frame
    coulomb_smoothing: sympy.Rational | None = None  # eps (rad/s) of tanh(qd / eps); None: sign(qd)
    tool: Placement = Placement()                   # flange (last link frame) -> tool frame
    base_name: str = ""                             # the base frame's name (URDF root link)
    flange_name: str = ""                           # the last link's name
    notes: tuple[str, ...] = ()                     # what reading the description changed, for the user

    def __post_init__(self):
        if self.parents is None:
            object.__setattr__(self, "parents", tuple(range(-1, len(self.joints) - 1)))
        assert len(self.parents) == len(self.joints) == len(self.links)
        assert all(-1 <= p < j for j, p in enumerate(self.parents)), "parents must come first"

    @property
    def is_tree(self) -> bool:
        """Read as a tree (its functions: those of a tree, every frame of interest); else an
        arm (the arm's functions, the flange)."""
        return self.convention == "tree"

    @property
    def is_chain(self) -> bool:
        """Fixed base, each joint's parent the joint before it: what the chain-only
        derivations (closed-form IK, DH-based code) need."""
        return not self.floating_base and self.parents == tuple(range(-1, self.n - 1))

    @property
    def flange_chain(self) -> "RobotModel | None":
        """This model as the arm the flange derivations (dual-quaternion kinematics, closed-form
        IK) read: a chain (:attr:`is_chain`) with one flange. An arm is its own; a chain read
        as a tree has for flange its one frame of interest when that is on the last link (the
        frame's placement as the tool); None otherwise (a branched tree, a floating base,
        several frames of interest or one elsewhere)."""
        if not self.is_chain:
            return None
        if not self.is_tree:
            return self
        if len(self.frames) != 1 or self.frames[0].body != self.n - 1:
            return None
        return replace(self, tool=self.frames[0].placement)

    @property
    def flange_frame(self) -> Frame:
        """The arm's flange frame (the last link frame moved by the tool)."""
        return Frame(self.flange_name or "flange", self.n - 1, self.tool)

    @property
    def frames_of_interest(self) -> tuple[Frame, ...]:
        """The frames FK and Jacobians give: a tree's ``frames``, an arm's flange."""
        return self.frames if self.is_tree else (self.flange_frame,)

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
    def is_dh(self) -> bool:
        return self.convention in CONVENTIONS

    @property
    def order_text(self) -> str:
        """How the joints are ordered, for port descriptions."""
        if self.is_tree:
            return "depth-first order (Pinocchio's)"
        return "DH order" if self.is_dh else "chain order from the base"

    @property
    def frames_text(self) -> str:
        """Which frames the outputs refer to (stated in every generated header)."""
        if self.is_tree:
            world = ("the world frame (the base pose is q[0:7])" if self.floating_base
                     else f"the frame of the root link '{self.base_name}'")
            return f"Frames: poses and Jacobians in {world}."
        if self.is_dh:
            base, flange = "DH frame 0", f"last DH frame ({self.n})"
        else:
            base = f"the frame of link '{self.base_name}'" if self.base_name else "the base frame"
            flange = f"the frame of link '{self.flange_name}'" if self.flange_name else "the last link frame"
        tool = "" if self.tool.is_identity else ", moved by the constant tool transform of the description"
        return f"Frames: base = {base}, flange = {flange}{tool}."

    @property
    def effects(self) -> tuple[str, ...]:
        """The joint effects the description declares, in a fixed order: friction (any joint
        with a ``friction`` entry gives every joint viscous, Coulomb and offset terms, zero
        where not given), ``armature``, then the Stribeck term (any joint declaring a
        ``stribeck_velocity``), the position ripple (any joint with ``ripple``) and the
        load-dependent friction (any joint declaring ``load``), each zero on the other joints."""
        out = []
        if any(j.friction is not None for j in self.joints):
            out += ["viscous_friction", "coulomb_friction", "torque_offset"]
        if any(j.armature is not None for j in self.joints):
            out.append("armature")
        if any(j.friction is not None and j.friction.stribeck_velocity is not None for j in self.joints):
            out.append("stribeck_friction")
        if any(j.ripple is not None for j in self.joints):
            out.append("position_ripple")
        if any(j.friction is not None and j.friction.load is not None for j in self.joints):
            out.append("load_dependent_friction")
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
    def nq(self) -> int:
        """Configuration coordinates: the joint positions (after the base pose's 7)."""
        return self.n + (FREE_FLYER_NQ if self.floating_base else 0)

    @property
    def nv(self) -> int:
        """Velocity coordinates: the joint velocities (after the base twist's 6)."""
        return self.n + (FREE_FLYER_NV if self.floating_base else 0)

    @property
    def structure_text(self) -> str | None:
        """What a tree's generated files say it is (an arm's state n and its convention)."""
        if not self.is_tree:
            return None
        kinds = sorted({j.kind for j in self.joints})
        base = (f"floating base (nq {self.nq}, nv {self.nv})" if self.floating_base else "fixed base")
        return f"{self.n} {' and '.join(kinds)} joints in a tree of depth {self.depth}, {base}"

    @property
    def lower(self) -> np.ndarray:
        return np.array([j.lower for j in self.joints])

    @property
    def upper(self) -> np.ndarray:
        return np.array([j.upper for j in self.joints])

    @property
    def length_symbols(self) -> tuple:
        """Symbolic lengths (plain names in the YAML: DH ``a`` and ``d``, ``xyz`` of an origin
        or of the tool), in order of first appearance: each joint's (DH row, else its
        placements), then the tool's and the frames' of interest."""
        seen = []

        def add(values):
            for value in values:
                if isinstance(value, sympy.Symbol) and value not in seen:
                    seen.append(value)

        for joint in self.joints:
            if joint.dh is not None:
                add((joint.dh.a, joint.dh.d))
            else:
                add(_translations(joint.before) + _translations(joint.after))
        add(_translations(self.tool))
        for frame in self.frames:
            add(_translations(frame.placement))
        return tuple(seen)

    @property
    def identifier(self) -> str:
        """The name as a C identifier (used as the prefix of generated functions)."""
        ident = "".join(ch if ch.isalnum() else "_" for ch in self.name.lower())
        return ident if not ident[0].isdigit() else "r_" + ident


def _translations(placement: Placement) -> tuple:
    """The entries of a placement's translations, in order."""
    return tuple(v for kind, *rest in placement.factors if kind == "trans" for v in rest[0])


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
