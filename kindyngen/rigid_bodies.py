"""Joint frames, link bodies with grouped inertial parameters, gravity, ports and the
function assembly every dynamics route shares (:mod:`kindyngen.dynamics_lagrange`,
:mod:`kindyngen.dynamics_newton_euler`, :mod:`kindyngen.forward_dynamics`).

* **Joint frames.** Frame j is attached to link j with its z axis on joint j, so that every
  revolute joint is ``R_{j-1,j} = C_j Rz(q_j)``, ``p_{j-1,j} = t_j`` and every prismatic one
  ``R_{j-1,j} = C_j``, ``p_{j-1,j} = t_j + C_j e_z q_j``, with an exact constant rotation
  ``C_j`` and translation ``t_j``: the placement ``after_{j-1} before_j`` of
  :mod:`kindyngen.placement` (and the joint offset).  Link j's parameters are moved from its
  link frame into joint frame j by ``after_j`` (an exact parallel-axis transform).  For
  modified DH the joint frames are the DH frames; for standard DH, joint frame j is DH frame
  j-1 turned by ``q_j + offset_j``.  Joint axes are then always ``e_z`` and LWR-type tables
  (alpha = +-pi/2, a = 0) make ``C_j`` a signed permutation, so rotations cost only the
  ``Rz`` part.
* **Grouped parameters.** For a revolute joint, the part ``(m, 0, 0, MZ, XX=YY, 0, YY, 0,
  0, 0)`` of link j's barycentric parameters is invariant under rotation about the joint
  axis and its energy does not depend on ``qd_j``; it is moved to link j-1 (to nothing for
  the first link).  For a prismatic joint the whole inertia tensor moves (link j turns with
  link j-1, so ``1/2 w.I w`` is the same energy on either link); mass and first moments stay.  This is the classical base-parameter grouping (Khalil & Bennis): it
  leaves M, c, g and tau exactly unchanged and sets every link's mass, MZ and YY to zero,
  which removes most terms.  In symbolic mode the grouped parameters are expressions of
  the input ``p`` (a few dozen operations, counted in the function).

Example:

>>> from kindyngen.robot import load_robot
>>> from kindyngen.symbolic import port_symbols
>>> model = load_robot("robots/lwr4.yaml")                            # doctest: +SKIP
>>> frames = joint_frames(model, port_symbols("q", (model.n,)))       # doctest: +SKIP
>>> bodies, ports, syms = dynamic_bodies(model, "symbolic", frames)    # doctest: +SKIP
>>> [p.name for p in ports], bodies[-1].m                             # doctest: +SKIP
(['p'], 0)
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy
import symengine as se

from .placement import Placement
from .inertial_parameters import LinkInertials, numeric_inertials, parameter_symbols, symbolic_inertials
from .joint_effects import description_text
from .geometry import exact
from .kinematics_homogeneous import joint_units
from .model import RobotModel
from .symbolic import Port, SymbolicFunction

ZERO = se.Integer(0)

# ----------------------------------------------------------------------------- ports, text

PARAMS = ("numeric", "symbolic")


def p_port(model: RobotModel) -> Port:
    return Port("p", (10 * model.n,),
                "barycentric inertial parameters, per link: m, m*cx, m*cy, m*cz, Ixx, Ixy, Iyy, "
                "Ixz, Iyz, Izz about the link frame origin", "kg, kg m, kg m^2")


def qd_port(model: RobotModel) -> Port:
    return Port("qd", (model.n,), f"joint velocities, {model.order_text}", joint_units(model, "rad/s", "m/s"))


def qdd_port(model: RobotModel) -> Port:
    return Port("qdd", (model.n,), f"joint accelerations, {model.order_text}", joint_units(model, "rad/s^2", "m/s^2"))


def torque_unit(model: RobotModel) -> str:
    return joint_units(model, "N m", "N")


def tau_port(model: RobotModel, description: str = "joint torques") -> Port:
    return Port("tau", (model.n,), description, torque_unit(model))


def conventions(model: RobotModel, params: str) -> str:
    """The text every dynamics header carries."""
    gx, gy, gz = (float(v) for v in model.gravity)
    text = (
        f"Joint space in {model.order_text}: q (rad), qd (rad/s), qdd (rad/s^2), tau (N m)"
        f"{'' if all(not j.prismatic for j in model.joints) else ' (m, m/s, m/s^2, N for prismatic joints)'}. "
        f"Equation of motion: tau = M(q) qdd + c(q, qd) + g(q), with c = S(q, qd) qd. "
        f"Gravity acceleration in the base frame (DH frame 0): ({gx:g}, {gy:g}, {gz:g}) m/s^2; "
        f"g(q) is the torque that holds the arm against it. Link i's inertial parameters are "
        f"given in {'DH frame i (' + model.convention + ' DH)' if model.is_dh else 'link frame i'}. ")
    if params == "symbolic":
        text += ("Inertial parameters: input p, 10 per link in the order m, m*cx, m*cy, m*cz, "
                 "Ixx, Ixy, Iyy, Ixz, Iyz, Izz (inertia about the link frame origin, link-frame axes).")
    else:
        text += "Inertial parameters: the robot description's values, baked in."
    effects = description_text(model)
    return text + (" " + effects.strip() + " (Coefficients from the robot description, baked in.)" if effects else "")


# ----------------------------------------------------------------------------- small algebra
# Vectors are lists of three symengine expressions; exact zeros stay zeros.

def vadd(*vs):
    return [se.Add(*(v[k] for v in vs)) for k in range(3)]


def vscale(s, v):
    return [s * x for x in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def dot(a, b):
    return se.Add(*(x * y for x, y in zip(a, b)))


def matvec(C, v):
    """Exact constant 3x3 (nested lists) times a vector, skipping zero entries."""
    return [se.Add(*(C[r][k] * v[k] for k in range(3) if C[r][k] != 0)) for r in range(3)]


def matTvec(C, v):
    return matvec([[C[k][r] for k in range(3)] for r in range(3)], v)


def sym_matmat(C, I):
    """C I C^T for an exact constant C and a symmetric I given as nested lists."""
    CI = [[se.Add(*(C[r][k] * I[k][c] for k in range(3) if C[r][k] != 0)) for c in range(3)] for r in range(3)]
    out = [[None] * 3 for _ in range(3)]
    for r in range(3):
        for c in range(r, 3):
            out[r][c] = out[c][r] = se.Add(*(CI[r][k] * C[c][k] for k in range(3) if C[c][k] != 0))
    return out


# ----------------------------------------------------------------------------- joint frames

def _exact_trig(angle):
    """cos, sin of a constant angle: exact when sympy finds a closed form, else floats."""
    angle = sympy.sympify(angle)
    out = []
    for v in (sympy.cos(angle), sympy.sin(angle)):
        out.append(v if not v.has(sympy.cos, sympy.sin) else sympy.Float(float(v)))
    return out


def _rz(theta):
    c, s = _exact_trig(theta)
    return sympy.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _constant(v) -> se.Basic:
    """An exact sympy constant as symengine: exact where it is (rationals, sqrt(2)/2),
    a double where floats entered."""
    v = sympy.nsimplify(v) if isinstance(v, float) else sympy.sympify(v)
    return se.RealDouble(float(v)) if v.has(sympy.Float) else se.sympify(v)


def _to_se(matrix: sympy.Matrix):
    matrix = sympy.simplify(matrix)
    return [[_constant(matrix[r, c]) for c in range(matrix.cols)] for r in range(matrix.rows)]


@dataclass(frozen=True)
class JointFrame:
    """Joint j in joint frames: ``R_{j-1,j} = C Rz(q)``, origin of frame j at ``t`` in frame
    j-1; ``c, s`` are cos q, sin q (shared call objects). A prismatic joint has ``c = 1,
    s = 0`` and ``t`` includes its displacement ``C e_z q``."""

    C: list
    t: list
    c: se.Basic
    s: se.Basic
    prismatic: bool = False

    def rot(self, v):
        """R v: frame-j coordinates to frame j-1."""
        x, y, z = v
        return matvec(self.C, [self.c * x - self.s * y, self.s * x + self.c * y, z])

    def rot_t(self, v):
        """R^T v: frame j-1 coordinates to frame j."""
        x, y, z = matTvec(self.C, v)
        return [self.c * x + self.s * y, self.c * y - self.s * x, z]


def joint_frames(model: RobotModel, q) -> tuple[JointFrame, ...]:
    """Constant parts of every joint in joint frames (see the module text)."""
    out = []
    for j, (joint, qj) in enumerate(zip(model.joints, q)):
        placement = (model.joints[j - 1].after if j > 0 else Placement()) * joint.before
        R, p = placement.matrix()
        C, t = _to_se(R * (sympy.eye(3) if joint.prismatic else _rz(joint.offset))), [row[0] for row in _to_se(p)]
        if joint.prismatic:
            slide = qj + exact(joint.offset)
            t = [t[r] + C[r][2] * slide for r in range(3)]
            out.append(JointFrame(C=C, t=t, c=se.Integer(1), s=ZERO, prismatic=True))
        else:
            out.append(JointFrame(C=C, t=t, c=se.cos(qj), s=se.sin(qj)))
    return tuple(out)


# ----------------------------------------------------------------------------- parameters

@dataclass(frozen=True)
class Body:
    """Barycentric parameters of a rigid body in some frame: mass m, first moment h = m c
    (3), inertia I about the frame origin (3x3 nested lists, symmetric)."""

    m: se.Basic
    h: list
    I: list

    @staticmethod
    def from_inertials(li: LinkInertials) -> "Body":
        ixx, ixy, iyy, ixz, iyz, izz = li.inertia
        return Body(li.mass, list(li.first_moment), [[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])

    def __add__(self, other: "Body") -> "Body":
        return Body(self.m + other.m, vadd(self.h, other.h),
                    [[self.I[r][c] + other.I[r][c] for c in range(3)] for r in range(3)])

    def moved(self, R, p) -> "Body":
        """The same body seen from a frame in which this body's frame has the constant
        rotation R (nested lists) and origin p."""
        h = matvec(R, self.h)
        I = sym_matmat(R, self.I)
        if all(v == 0 for v in p):
            return Body(self.m, h, I)
        pp = dot(p, p)
        ph = dot(p, h)
        out = [[None] * 3 for _ in range(3)]
        for r in range(3):
            for c in range(r, 3):
                e = I[r][c] - self.m * p[r] * p[c] - p[r] * h[c] - h[r] * p[c]
                if r == c:
                    e = e + self.m * pp + ph + ph
                out[r][c] = out[c][r] = e
        return Body(self.m, vadd(h, vscale(self.m, p)), out)


def inertials(model: RobotModel, params: str):
    """(LinkInertials per link, extra input ports, extra input symbols) for a params mode."""
    if params == "numeric":
        return numeric_inertials(model), (), ()
    if params == "symbolic":
        p = parameter_symbols(model.n)
        return symbolic_inertials(model.n, p), (p_port(model),), (p,)
    raise ValueError(f"params must be one of {PARAMS}, got {params!r}")


def joint_frame_bodies(model: RobotModel, links) -> list[Body]:
    """Each link's parameters in its joint frame: moved from the link frame by ``after``
    (standard DH: from DH frame j; modified DH and URDF-style axes along z: unchanged)."""
    out = []
    for joint, li in zip(model.joints, links):
        body = Body.from_inertials(li)
        if not joint.after.is_identity:
            R, p = joint.after.matrix()
            body = body.moved(_to_se(R), [row[0] for row in _to_se(p)])
        out.append(body)
    return out


def grouped_bodies(model: RobotModel, bodies, joints) -> list[Body]:
    """Move each link's rotation-invariant part (m, MZ, YY) to the previous link, tip first
    (base-parameter grouping for revolute joints; the first link's part is dropped)."""
    bodies = list(bodies)
    for j in range(model.n - 1, -1, -1):
        b = bodies[j]
        if joints[j].prismatic:
            # the rotational inertia turns with link j-1: a pure rotation (no translation)
            bodies[j] = Body(b.m, list(b.h), [[ZERO] * 3 for _ in range(3)])
            part = Body(ZERO, [ZERO] * 3, b.I)
            if j > 0:
                bodies[j - 1] = bodies[j - 1] + part.moved(joints[j].C, [ZERO] * 3)
            else:
                bodies[j] = b
            continue
        yy, mz = b.I[1][1], b.h[2]
        rest = Body(ZERO, [b.h[0], b.h[1], ZERO],
                    [[b.I[0][0] - yy, b.I[0][1], b.I[0][2]], [b.I[1][0], ZERO, b.I[1][2]],
                     [b.I[2][0], b.I[2][1], b.I[2][2]]])
        bodies[j] = rest
        if j > 0:
            part = Body(b.m, [ZERO, ZERO, mz], [[yy, ZERO, ZERO], [ZERO, yy, ZERO], [ZERO, ZERO, ZERO]])
            bodies[j - 1] = bodies[j - 1] + part.moved(joints[j].C, joints[j].t)
    return [Body(_collect(b.m), [_collect(x) for x in b.h], [[_collect(x) for x in row] for row in b.I])
            for b in bodies]


def _collect(e: se.Basic) -> se.Basic:
    """A symbolic parameter expression (linear in p, at most 10 n terms, so expanding it is
    safe) as sum over distinct coefficients of coefficient * (sum of symbols): exact
    cancellations (XX - YY of accumulated parts) happen and each coefficient is paid once."""
    if not e.free_symbols:
        return e
    e = se.expand(e)
    groups: dict = {}
    for term in (e.args if isinstance(e, se.Add) else (e,)):
        factors = term.args if isinstance(term, se.Mul) else (term,)
        coeff = se.Mul(*(f for f in factors if f.is_Number))
        groups.setdefault(coeff, []).append(se.Mul(*(f for f in factors if not f.is_Number)))
    return se.Add(*(coeff * se.Add(*terms) for coeff, terms in groups.items()))


def dynamic_bodies(model: RobotModel, params: str, joints, group: bool = True):
    """Link bodies in joint frames, grouped, plus the extra ports and symbols of ``params``."""
    links, ports, syms = inertials(model, params)
    bodies = joint_frame_bodies(model, links)
    if group:
        bodies = grouped_bodies(model, bodies, joints)
    return bodies, ports, syms


def gravity(model: RobotModel):
    """Gravity acceleration in the base frame (exact zeros kept)."""
    return [se.sympify(v) for v in model.gravity]


# ----------------------------------------------------------------------------- function assembly

def dynamics_function(name, summary, model, params, inputs, input_symbols, outputs, output_exprs,
                      extra_ports, extra_syms) -> SymbolicFunction:
    """A dynamics SymbolicFunction: the route's inputs followed by the parameter ports of
    ``params`` (``extra_ports``/``extra_syms`` from :func:`dynamic_bodies`), the shared
    conventions text and ``metadata = {"params": params}``."""
    return SymbolicFunction(
        name=name, summary=summary,
        inputs=tuple(inputs) + tuple(extra_ports), outputs=tuple(outputs),
        input_symbols=tuple(input_symbols) + tuple(extra_syms),
        output_exprs=tuple(tuple(se.sympify(e) for e in exprs) for exprs in output_exprs),
        conventions=conventions(model, params),
        metadata={"params": params})


def flat(matrix):
    """A nested-list matrix as one row-major list."""
    return [e for row in matrix for e in row]
