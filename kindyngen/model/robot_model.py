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

A joint may *mimic* another (:class:`Mimic`, URDF ``<mimic>``): its position is ``multiplier *
q_k + offset`` of joint k, a linear holonomic constraint. The model's coordinates (``q``,
``qd``, ``qdd``, ``tau`` of every generated function: :attr:`RobotModel.coordinates`, sizes
:attr:`RobotModel.nq`, :attr:`RobotModel.nv`) are then the joints that mimic none; the
derivations run on :meth:`RobotModel.without_mimics` (every joint a coordinate) and
:mod:`kindyngen.algorithms.reduced_coordinates` folds the mimics in.

A tree may be closed into kinematic loops (:class:`LoopClosure`: four-bar and parallelogram
linkages, parallel robots): a loop joint holds a frame on one body to a frame on another in
the directions it constrains. The model keeps the tree and its loops as described, with the
independent joints the user named (``independent``) and the configuration the loops are
assembled near (``reference``); :mod:`kindyngen.algorithms.loop_closure` chooses the
coordinates and reduces the dynamics to them.

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
from .user_text import identifier, name_problem, one_line

CONVENTIONS = ("standard", "modified")


class RobotDescriptionError(ValueError):
    """A robot description that cannot be used, with the file, field and reason; its message is
    one line whatever the file's names hold (:func:`kindyngen.model.user_text.one_line`)."""

    def __init__(self, source: str, field: str, reason: str):
        self.source, self.field, self.reason = source, field, reason
        super().__init__(one_line(f"{source}: field '{field}': {reason}"))


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
class Mimic:
    """The joint follows joint ``joint`` (an index into ``RobotModel.joints``; that joint mimics
    none): ``q = multiplier * q_joint + offset``, exact. The multiplier's unit is the ratio of
    the two joints' units (m/rad for a prismatic joint following a revolute one); readers
    resolve a mimic of a mimic into this form. ``terms``: further ``(joint, multiplier)``
    pairs added to the sum (a linear coupling of several joints; readers never write them:
    the closed form of a parallelogram loop does,
    :func:`kindyngen.algorithms.loop_closure.coupled_model`)."""

    joint: int
    multiplier: sympy.Rational = sympy.Integer(1)
    offset: sympy.Rational = sympy.Integer(0)   # rad (m for a prismatic joint)
    terms: tuple = ()                           # ((joint, multiplier), ...) beyond the first

    @property
    def sources(self) -> tuple:
        """Every ``(joint, multiplier)`` of the sum, the first one first."""
        return ((self.joint, self.multiplier),) + tuple(self.terms)


LOOP_TYPES = ("spherical", "revolute", "fixed")
DIRECTIONS = ("x", "y", "z", "rx", "ry", "rz")
# what each loop joint constrains by default: a spherical joint the origin (3 translations),
# a revolute one also the two rotations about frame A's x and y (its axis is z), a fixed one all
LOOP_DIRECTIONS = {"spherical": DIRECTIONS[:3], "revolute": DIRECTIONS[:5], "fixed": DIRECTIONS}


@dataclass(frozen=True)
class LoopClosure:
    """A loop joint closing the tree: frame A (``placement_a`` on the link frame of body
    ``body_a``, a joint index, -1 the root body) and frame B (``placement_b`` on body
    ``body_b``) are held together in ``directions``, each a row of the constraint, in frame A's
    axes: ``x``, ``y``, ``z`` the components of B's origin relative to A's
    (``R_A^T (p_B - p_A)``), ``rx``, ``ry``, ``rz`` the entries ``(R_A^T R_B)[2][1], [0][2],
    [1][0]`` (zero for B's axes aligned with A's; a small rotation of B about A's x, y or z
    axis). A spherical loop joint constrains x, y, z; a revolute one (axis: z of both frames)
    also rx, ry; a fixed one all six; ``directions`` may name a subset (a planar linkage:
    the two translations in its plane)."""

    name: str
    kind: str                      # one of LOOP_TYPES
    body_a: int
    placement_a: Placement
    body_b: int
    placement_b: Placement
    directions: tuple[str, ...]


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
    mimic: Mimic | None = None                    # None: the joint is a coordinate of the model

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
    loops: tuple[LoopClosure, ...] = ()             # loop joints closing the tree
    independent: tuple[int, ...] | None = None      # the joints the user chose as coordinates (loops)
    reference: tuple | None = None                  # exact joint values the loops close near (None: 0)
    # the description's bundles: (name, member function names), each generated as one function
    # (kindyngen/codegen/bundles.py checks the names against the function catalog)
    bundles: tuple[tuple[str, tuple[str, ...]], ...] = ()

    def __post_init__(self):
        if self.parents is None:
            object.__setattr__(self, "parents", tuple(range(-1, len(self.joints) - 1)))
        assert len(self.parents) == len(self.joints) == len(self.links)
        assert all(-1 <= p < j for j, p in enumerate(self.parents)), "parents must come first"
        for j, joint in enumerate(self.joints):
            if joint.mimic is not None:
                k = joint.mimic.joint
                assert 0 <= k < len(self.joints) and k != j, f"joint {j} mimics joint {k}"
                assert self.joints[k].mimic is None, f"joint {j} mimics joint {k}, itself a mimic (resolve chains)"
                assert joint.mimic.multiplier != 0, f"joint {j}: mimic multiplier 0"
                for k, _ in joint.mimic.terms:
                    assert 0 <= k < len(self.joints) and self.joints[k].mimic is None, f"joint {j} couples joint {k}"
        for loop in self.loops:
            assert loop.kind in LOOP_TYPES and set(loop.directions) <= set(LOOP_DIRECTIONS[loop.kind]), loop
            assert -1 <= loop.body_a < len(self.joints) and -1 <= loop.body_b < len(self.joints), loop
            assert loop.body_a != loop.body_b, f"loop {loop.name} closes a body on itself"
        assert self.reference is None or len(self.reference) == len(self.joints)
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
        """The joints (bodies) of the tree, mimic joints included."""
        return len(self.joints)

    @property
    def coordinates(self) -> tuple[int, ...]:
        """The joints whose positions are inputs: those that mimic none (all of them without
        mimic joints), in joint order; a tree closed by loops: its ``independent`` joints once
        known (:func:`kindyngen.algorithms.loop_closure.resolved`)."""
        if self.loops and self.independent is not None:
            return self.independent
        return tuple(j for j, joint in enumerate(self.joints) if joint.mimic is None)

    @property
    def coordinate_joints(self) -> tuple[Joint, ...]:
        return tuple(self.joints[j] for j in self.coordinates)

    @property
    def has_mimics(self) -> bool:
        return any(joint.mimic is not None for joint in self.joints)

    def without_mimics(self) -> "RobotModel":
        """The same tree with every joint a coordinate and no loop closed: what the derivations
        run on before :mod:`kindyngen.algorithms.reduced_coordinates` folds the mimics in (and
        :mod:`kindyngen.algorithms.loop_closure` the loops)."""
        if not self.has_mimics and not self.loops:
            return self
        return replace(self, joints=tuple(replace(joint, mimic=None) for joint in self.joints), loops=(),
                       independent=None, reference=None)

    @property
    def has_loops(self) -> bool:
        return bool(self.loops)

    @property
    def reference_values(self) -> tuple:
        """The reference configuration of the loops (exact joint values; 0 where not given)."""
        return self.reference if self.reference is not None else (sympy.Integer(0),) * self.n

    @property
    def mimic_text(self) -> str:
        """Which joints mimic which, and what the inputs are (headers, functions.json); empty
        without mimic joints."""
        if not self.has_mimics:
            return ""
        rules = "; ".join(f"{joint.name} = {_affine_text(joint.mimic, self.joints)}"
                          for joint in self.joints if joint.mimic is not None)
        names = ", ".join(joint.name for joint in self.coordinate_joints)
        if self.loops:
            loops = ", ".join(loop.name for loop in self.loops)
            return (f"Closed loops {loops} (parallelograms: the dependent joints are linear in the independent "
                    f"ones): {rules}. Inputs are the {len(self.coordinates)} independent joints ({names}); the "
                    f"dependent joints' motion, torques and inertia are folded in (tau = G^T tau_tree).")
        return (f"Mimic joints: {rules}. Inputs are the {len(self.coordinates)} independent joints ({names}); the "
                f"mimic joints' motion (q, qd, qdd through the multiplier), torques and inertia are folded in: "
                f"tau of a joint includes multiplier * tau of each joint mimicking it.")

    @property
    def nq(self) -> int:
        """Configuration coordinates: the independent joint positions (after the base pose's 7)."""
        return len(self.coordinates) + (FREE_FLYER_NQ if self.floating_base else 0)

    @property
    def nv(self) -> int:
        """Velocity coordinates: the independent joint velocities (after the base twist's 6)."""
        return len(self.coordinates) + (FREE_FLYER_NV if self.floating_base else 0)

    @property
    def structure_text(self) -> str | None:
        """What a tree's (or a model with mimic joints') generated files say it is (an arm's:
        its state n and its convention)."""
        if not self.is_tree and not self.has_mimics:
            return None
        kinds = sorted({j.kind for j in self.joints})
        base = (f"floating base (nq {self.nq}, nv {self.nv})" if self.floating_base else "fixed base")
        shape = f"a tree of depth {self.depth}" if self.is_tree else "a chain"
        mimics = self.n - len(self.coordinates)
        coupled = (f"; {mimics} of them mimic{'s' if mimics == 1 else ''} another, inputs the "
                   f"{len(self.coordinates)} independent joints" if mimics and not self.loops else "")
        if self.loops:
            closed = ", ".join(f"{loop.name} ({loop.kind}, {' '.join(loop.directions)})" for loop in self.loops)
            inputs = (f", inputs the {len(self.coordinates)} independent joints"
                      if self.independent is not None or self.has_mimics else "")
            coupled = f"; closed by the loop joints {closed}{inputs}"
        return f"{self.n} {' and '.join(kinds)} joints in {shape}, {base}{coupled}"

    @property
    def lower(self) -> np.ndarray:
        """The lower limits of the coordinates (the independent joints)."""
        return np.array([j.lower for j in self.coordinate_joints])

    @property
    def upper(self) -> np.ndarray:
        return np.array([j.upper for j in self.coordinate_joints])

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
        """The name as the identifier of the generated files and symbols (the output folder,
        ``<identifier>.h``, the prefix of every C function): :func:`kindyngen.model.user_text.identifier`."""
        return identifier(self.name)


def _affine_text(mimic: Mimic, joints) -> str:
    """``multiplier * source + offset`` as text (each term of a coupling), exact numbers as
    decimals.

    >>> a = [Joint(Placement(), Placement(), 0, -1, 1, name=n) for n in "ab"]
    >>> _affine_text(Mimic(0, sympy.Integer(-1), sympy.Rational(1, 10)), a), _affine_text(Mimic(0), a)
    ('-1 * a + 0.1', '1 * a')
    >>> _affine_text(Mimic(0, sympy.Integer(1), terms=((1, sympy.Integer(-1)),)), a)
    '1 * a - 1 * b'
    """
    text = ""
    for joint, multiplier in mimic.sources:
        term = f"{abs(float(multiplier)):g} * {joints[joint].name}"
        text = (f"{'-' if multiplier < 0 else ''}{term}" if not text
                else f"{text} {'-' if multiplier < 0 else '+'} {term}")
    return text if mimic.offset == 0 else f"{text} {'+' if mimic.offset > 0 else '-'} {abs(float(mimic.offset)):g}"


def _translations(placement: Placement) -> tuple:
    """The entries of a placement's translations, in order."""
    return tuple(v for kind, *rest in placement.factors if kind == "trans" for v in rest[0])


def check_name(name: str, source: str, field: str) -> str:
    """``name`` itself when it may name a robot, joint, link or frame (no control character:
    :func:`kindyngen.model.user_text.name_problem`), else a RobotDescriptionError saying why.

    >>> check_name('arm "7" */', "f.yaml", "name")
    'arm "7" */'
    >>> check_name("a\\x00b", "f.yaml", "joints[1].name")
    Traceback (most recent call last):
    ...
    kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'joints[1].name': holds the control character U+0000 (NULL) at position 2: a name is one line of printable text
    """
    problem = name_problem(name)
    if problem:
        raise RobotDescriptionError(source, field, problem)
    return name


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
