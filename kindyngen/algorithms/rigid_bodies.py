"""Joint frames, link bodies, gravity and ports every dynamics route shares (the function
assembly is :func:`kindyngen.algorithms.dynamics.dynamics_function`);
:func:`kindyngen.algorithms.dynamics.setup` builds the frames and the grouped bodies of a
model (an arm being the tree whose parent of joint j is j - 1).

* **Joint frames.** Frame j is attached to link j with its z axis on joint j, so that every
  revolute joint is ``R_{j-1,j} = C_j Rz(q_j)``, ``p_{j-1,j} = t_j`` and every prismatic one
  ``R_{j-1,j} = C_j``, ``p_{j-1,j} = t_j + C_j e_z q_j``, with an exact constant rotation
  ``C_j`` and translation ``t_j``: the placement ``after_{j-1} before_j`` of
  :mod:`kindyngen.model.placement` (and the joint offset).  Link j's parameters are moved from its
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

>>> from kindyngen.readers.yaml_description import load_robot
>>> from kindyngen.algorithms.dynamics import setup
>>> ts = setup(load_robot("robots/lwr4.yaml"), "symbolic")
>>> [p.name for p in ts.param_ports], ts.bodies[-1].m
(['p'], 0)
"""
from __future__ import annotations

from dataclasses import dataclass

import symengine as se

from ..model.inertial_parameters import (LinkInertials, barycentric, numeric_inertials, parameter_symbols,
                                        symbolic_inertials)
from .effect_torques import description_text
from .kinematics_conventions import joint_units
from ..model.robot_model import RobotModel
from .symbolic import Port

ZERO = se.Integer(0)

# ----------------------------------------------------------------------------- ports, text

PARAMS = ("numeric", "symbolic")


def p_port(model: RobotModel) -> Port:
    """The input p of symbolic mode: 10 per body, a floating base's root body first (the
    order of the tree regressor's columns and of Pinocchio's ``model.inertias[1:]``)."""
    root = "the floating base's root body (base frame), then " if model.floating_base else ""
    return Port("p", (10 * (model.n + model.floating_base),),
                f"barycentric inertial parameters, {root}per link: m, m*cx, m*cy, m*cz, Ixx, Ixy, Iyy, "
                "Ixz, Iyz, Izz about the link frame origin", "kg, kg m, kg m^2")


def _velocity_text(model: RobotModel, what: str, base: str) -> str:
    """``what``: the plural noun ("velocities")."""
    joints = f"joint {what}, {model.order_text}"
    return f"base {base} in the base frame, then {joints}" if model.floating_base else joints


def qd_port(model: RobotModel) -> Port:
    return Port("qd", (model.nv,), _velocity_text(model, "velocities", "linear and angular velocity"),
                ("m/s, rad/s, " if model.floating_base else "") + joint_units(model, "rad/s", "m/s"))


def qdd_port(model: RobotModel, name: str = "qdd") -> Port:
    return Port(name, (model.nv,), _velocity_text(model, "accelerations", "linear and angular acceleration "
                                                  "(the derivative of its twist)"),
                ("m/s^2, rad/s^2, " if model.floating_base else "") + joint_units(model, "rad/s^2", "m/s^2"))


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

    def collected(self) -> "Body":
        """The body with every entry :func:`_collect` ed (symbolic parameters: exact
        cancellations happen, each coefficient is paid once)."""
        return Body(_collect(self.m), [_collect(x) for x in self.h], [[_collect(x) for x in row] for row in self.I])

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
    """(LinkInertials per link, extra input ports, extra input symbols) for a params mode;
    in symbolic mode a floating base's root body has the first 10 symbols (``m0 .. Izz0``),
    see :func:`root_inertials`."""
    if params == "numeric":
        return numeric_inertials(model), (), ()
    if params == "symbolic":
        p = parameter_symbols(model.n, first=0 if model.floating_base else 1)
        return symbolic_inertials(model.n, p[10 * model.floating_base:]), (p_port(model),), (p,)
    raise ValueError(f"params must be one of {PARAMS}, got {params!r}")


def root_inertials(model: RobotModel, param_symbols: tuple) -> tuple:
    """The 10 barycentric parameters of a floating base's root body: the description's
    (numeric mode, no parameter symbols) or the first 10 of p."""
    return tuple(param_symbols[0][:10]) if param_symbols else barycentric(model.root)


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


def gravity(model: RobotModel):
    """Gravity acceleration in the base frame (exact zeros kept)."""
    return [se.sympify(v) for v in model.gravity]


def flat(matrix):
    """A nested-list matrix as one row-major list."""
    return [e for row in matrix for e in row]
