"""Dynamics in dual-quaternion form: recursive Newton-Euler with twists, accelerations and
wrenches as dual quaternions, poses as unit dual quaternions and the link inertia as the dual
inertia operator (``tau_dq``), and from the same route ``M_dq``, ``g_dq``, ``c_dq`` and the
torque regressor ``Y_dq``.

Conventions (all quantities of link j in joint frame j, whose z axis is joint j's axis, as in
:mod:`kindyngen.algorithms.rigid_bodies`):

* **Poses.** Joint j's relative pose is the unit dual quaternion ``x_j = K_j Z_j(q_j)``:
  ``K_j = B_{j-1} A_j`` the constant factors of :func:`kindyngen.algorithms.dualquat.dq_kinematics.joint_factors`
  (the previous link's ``after``, this joint's ``before`` and offset: exact half-angle
  rotations and translations multiplied out), ``Z_j = cos(q_j/2) + k sin(q_j/2)`` (revolute)
  or ``1 + e/2 q_j k`` (prismatic).
* **Twists** ``xi = w + e v`` (angular velocity, then the linear velocity of the frame
  origin, both pure quaternions); **wrenches** ``f + e n`` (force, then the moment about the
  frame origin).  With this order both transform by the same adjoint
  ``Ad(x) y = x y x*`` (``R w + e (R v + t x R w)``), and both cross products (of motions,
  and of a motion with a force) are the dual-quaternion commutator
  ``[a, b] = 1/2 (a b - b a)``.
* **Adjoint.** ``Ad(x_j) = Ad(K_j) Ad(Z_j)``; each factor's map is obtained at generation
  time by multiplying out ``x y x*`` for a placeholder ``y`` in dual-quaternion algebra (the
  unit norm ``cos^2 + sin^2 = 1`` of the half angles applied), so the constant factor's
  coefficients are exact numbers and the joint factor's are ``1 - 2 sin^2(q/2)`` and
  ``2 sin(q/2) cos(q/2)`` (shared per joint after CSE).
* **Dual inertia operator** of a body with mass m, first moment h = m c and inertia I about
  the frame origin: ``M(w + e v) = (m v + w x h) + e (I w + h x v)`` (momentum, then angular
  momentum about the origin).  The bodies are the grouped barycentric bodies of the
  homogeneous route (:func:`kindyngen.algorithms.dynamics.setup`), so the parameter
  dependence, numeric or symbolic, is the same.
* **Newton-Euler.** ``xi_j = Ad(x_j*) xi_{j-1} + s_j qd_j``, ``a_j = Ad(x_j*) a_{j-1} + s_j
  qdd_j + [xi_j, s_j qd_j]`` with ``s_j = k`` (revolute) or ``e k`` (prismatic) and the base
  acceleration ``a_0 = -e gamma`` (gravity); ``F_j = M_j(a_j) + [xi_j, M_j(xi_j)]``;
  ``f_j = F_j + Ad(x_{j+1}) f_{j+1}``; ``tau_j`` the k component of the moment (revolute)
  or of the force (prismatic).

``c_dq = tau(q, qd, 0)`` without gravity, ``g_dq = tau(q, 0, 0)``; ``M_dq`` by composite
rigid bodies in the same algebra: the composite inertia operator ``Mc_j = M_j + Ad(x_{j+1})
Mc_{j+1} Ad(x_{j+1}*)`` (read back as barycentric parameters), column j the wrench
``Mc_j(s_j)`` carried down by the adjoints (``composite=False``: column j from the pass with
qd = 0, no gravity and qdd = e_j, stopped at joint j; cheaper where constant rotations are
not signed permutations).  The description's friction, offset and
armature enter ``tau_dq`` and ``M_dq`` as in the homogeneous route; a payload is part of the
last link's parameters.  ``Y_dq`` differentiates ``tau_dq`` (symbolic parameters, rigid
bodies only) on the base parameters of ``Y`` plus the effect columns.

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> f = inverse_dynamics_dq(load_robot("robots/lwr4.yaml"))   # doctest: +SKIP
>>> [p.name for p in f.inputs]                                # doctest: +SKIP
['q', 'qd', 'qdd']
"""
from __future__ import annotations

from dataclasses import replace
from fractions import Fraction

import symengine as se

from ..effect_torques import joint_torques, with_armature
from .dq_kinematics import dq_conjugate, dq_mul, joint_factors
from ..kinematics_conventions import q_port
from ...model.robot_model import RobotModel
from ..regressors import base_parameters, full_regressor, regressor
from ..rigid_bodies import ZERO, Body, flat, gravity, qd_port, qdd_port, tau_port
from ..symbolic import Port, SymbolicFunction, port_symbols
from ..dynamics import dynamics_function, setup as tree_setup

DQ = "Dual-quaternion route (twists and wrenches as dual quaternions, grouped parameters): "

HALF = se.Rational(1, 2)
# placeholders of a dual quaternion w + e v (pure parts) for multiplying out adjoints
_PLACEHOLDERS = tuple(se.Symbol(f"_dq_y{k}") for k in range(6))


# ----------------------------------------------------------------------------- dual-quaternion algebra
# A pure dual quaternion (twist, acceleration, wrench) is the 6-list (real x, y, z, dual x, y, z).

def _dq(y):
    """6-list -> ((0, real), (0, dual))."""
    return (ZERO, y[0], y[1], y[2]), (ZERO, y[3], y[4], y[5])


def _pure(u) -> list:
    """((0, real), (0, dual)) -> 6-list (the scalar parts are exactly zero here)."""
    (rw, *real), (dw, *dual) = u
    assert rw == 0 and dw == 0, "not a pure dual quaternion"
    return list(real) + list(dual)


def _bilinear(product) -> list:
    """A bilinear product of pure dual quaternions, multiplied out once on placeholders: per
    component, the (coefficient, i, j) of its terms ``coefficient * a_i * b_j``."""
    a, b = _PLACEHOLDERS, tuple(se.Symbol(f"_dq_z{k}") for k in range(6))
    out = []
    for row in product(a, b):
        row = se.expand(row)
        out.append([(se.diff(row, a[i], b[j]), i, j) for i in range(6) for j in range(6)
                    if se.diff(row, a[i], b[j]) != 0])
    return out


def _commutator_of_placeholders(a, b):
    ab, ba = dq_mul(_dq(a), _dq(b)), dq_mul(_dq(b), _dq(a))
    diff = tuple(tuple(se.expand(HALF * (x - y)) for x, y in zip(p, r)) for p, r in zip(ab, ba))
    return _pure(diff)


_COMMUTATOR = _bilinear(_commutator_of_placeholders)


def commutator(a, b) -> list:
    """``[a, b] = 1/2 (a b - b a)`` of pure dual quaternions: the cross product of twists
    (``w_a x w_b + e (w_a x v_b + v_a x w_b)``) and of a twist with a wrench ``f + e n``
    (``w x f + e (w x n + v x f)``).  The dual-quaternion products are multiplied out once
    on placeholders (the scalar parts and the symmetric terms cancel there) and the result
    applied to the entries, skipping zeros."""
    return [se.Add(*(coefficient * a[i] * b[j] for coefficient, i, j in row if a[i] != 0 and b[j] != 0))
            for row in _COMMUTATOR]


def dadd(*ys) -> list:
    return [se.Add(*(y[k] for y in ys)) for k in range(6)]


ROUNDING_RESIDUE = Fraction(1, 10 ** 14)


def _rounded(coefficient: se.Basic) -> se.Basic:
    """A coefficient multiplied out from constants held as the exact values of doubles (angles
    without a closed form, such as rpy 0.3: :func:`kindyngen.algorithms.geometry.constant`):
    within 1e-14 of an exact 0 or +-1 (a rounding residue of c^2 + s^2 = 1, c s - s c) it is
    that number. The comparison is exact rational arithmetic, the same on every machine.

    >>> _rounded(1 - se.Rational(1, 10 ** 17)), _rounded(se.Rational(3, 10 ** 16)), _rounded(se.Rational(1, 3))
    (1, 0, 1/3)
    """
    if isinstance(coefficient, (se.Rational, se.RealDouble)) and not coefficient.is_Integer:
        value = Fraction(float(coefficient)) if isinstance(coefficient, se.RealDouble) else \
            Fraction(int(coefficient.p), int(coefficient.q))
        if abs(value) < ROUNDING_RESIDUE:
            return ZERO
        if abs(abs(value) - 1) < ROUNDING_RESIDUE:
            return se.Integer(1 if value > 0 else -1)
    return coefficient


class Adjoint:
    """The linear map ``y -> x y x*`` of a unit dual quaternion x on pure dual quaternions,
    multiplied out once in dual-quaternion algebra (``unit``: pairs (c, s) of half-angle
    cosines and sines with ``c^2 + s^2 = 1``, applied to the coefficients)."""

    def __init__(self, x, unit=()):
        real, dual = dq_mul(dq_mul(x, _dq(_PLACEHOLDERS)), dq_conjugate(x))
        table = []
        for row in (*real, *dual):
            row = se.expand(row)
            coefficients = []
            for y in _PLACEHOLDERS:
                coefficient = se.diff(row, y)
                for c, s in unit:
                    coefficient = se.expand(coefficient.subs({c ** 2: 1 - s ** 2}))
                coefficients.append(_rounded(coefficient))
            table.append(coefficients)
        # the scalar parts vanish (exactly, or to rounding where constants are doubles)
        assert all(c == 0 for c in table[0] + table[4]), "not the adjoint of a unit dual quaternion"
        self.coefficients = table[1:4] + table[5:8]

    def __call__(self, y) -> list:
        return [se.Add(*(coefficient * v for coefficient, v in zip(row, y) if coefficient != 0 and v != 0))
                for row in self.coefficients]


class JointPose:
    """Joint j's ``x_j = K_j Z_j(q_j)`` with the adjoints of both factors and their inverses."""

    def __init__(self, constant, q, prismatic: bool):
        self.prismatic = prismatic
        if prismatic:
            z = ((1, 0, 0, 0), (0, 0, 0, HALF * q))
            unit = ()
        else:
            c, s = se.cos(HALF * q), se.sin(HALF * q)
            z = ((c, 0, 0, s), (0, 0, 0, 0))
            unit = ((c, s),)
        self.K, self.K_inv = Adjoint(constant), Adjoint(dq_conjugate(constant))
        self.Z, self.Z_inv = Adjoint(z, unit), Adjoint(dq_conjugate(z), unit)

    def to_parent(self, y) -> list:
        """``Ad(x_j) y``: frame j to frame j-1."""
        return self.K(self.Z(y))

    def to_child(self, y) -> list:
        """``Ad(x_j*) y``: frame j-1 to frame j."""
        return self.Z_inv(self.K_inv(y))


def joint_poses(model: RobotModel, q) -> list[JointPose]:
    """Every joint's pose in joint frames: ``K_j = B_{j-1} A_j`` of
    :func:`kindyngen.algorithms.dualquat.dq_kinematics.joint_factors` (multiplied out exactly)."""
    out, after = [], ((1, 0, 0, 0), (0, 0, 0, 0))
    for joint, qj in zip(model.joints, q):
        before, next_after = joint_factors(joint)
        constant = tuple(tuple(se.expand(se.sympify(v)) for v in part) for part in dq_mul(after, before))
        out.append(JointPose(constant, qj, joint.prismatic))
        after = next_after
    return out


def inertia_operator(body, y) -> list:
    """The dual inertia operator ``M(w + e v) = (m v + w x h) + e (I w + h x v)``."""
    w, v = y[:3], y[3:]
    m, h, I = body.m, body.h, body.I
    wh = commutator(list(w) + [ZERO] * 3, list(h) + [ZERO] * 3)[:3]          # w x h
    hv = commutator(list(h) + [ZERO] * 3, list(v) + [ZERO] * 3)[:3]          # h x v
    momentum = [m * v[k] + wh[k] for k in range(3)]
    angular = [se.Add(*(I[r][k] * w[k] for k in range(3)), hv[r]) for r in range(3)]
    return momentum + angular


def joint_axis(prismatic: bool, value) -> list:
    """``s_j value``: ``k value`` (revolute) or ``e k value`` (prismatic)."""
    return [ZERO, ZERO, ZERO, ZERO, ZERO, value] if prismatic else [ZERO, ZERO, value, ZERO, ZERO, ZERO]


# ----------------------------------------------------------------------------- Newton-Euler

def rnea_dq(poses, bodies, qd, qdd, gam, first: int = 0, stop: int = 0):
    """Joint torques by dual-quaternion Newton-Euler (module text); ``qd``/``qdd`` may be
    None (zero), ``gam`` the base-frame gravity or None.  ``first``: links before it have
    zero twist and acceleration (skipped); ``stop``: the backward pass ends at joint
    ``stop`` (torques of earlier joints are None)."""
    n = len(poses)
    xi = [ZERO] * 6
    acc = [ZERO] * 3 + ([-g for g in gam] if gam is not None else [ZERO] * 3)
    wrenches = [None] * n
    for j in range(first, n):
        pose = poses[j]
        qdj = qd[j] if qd is not None else ZERO
        qddj = qdd[j] if qdd is not None else ZERO
        motion = joint_axis(pose.prismatic, qdj)
        xi = dadd(pose.to_child(xi), motion)
        acc = dadd(pose.to_child(acc), joint_axis(pose.prismatic, qddj), commutator(xi, motion))
        body = bodies[j]
        wrenches[j] = dadd(inertia_operator(body, acc), commutator(xi, inertia_operator(body, xi)))
    tau = [None] * n
    f = None
    for j in range(n - 1, stop - 1, -1):
        own = wrenches[j] if wrenches[j] is not None else [ZERO] * 6
        f = own if f is None else dadd(own, poses[j + 1].to_parent(f))
        tau[j] = f[2] if poses[j].prismatic else f[5]
    return tau


def carried_body(pose: JointPose, body: Body) -> Body:
    """Body j's parameters seen from frame j-1: its inertia operator conjugated by the joint's
    adjoint, ``M'(y) = Ad(x_j) M(Ad(x_j*) y)``, read off at the three angular unit twists
    (``M'(e_k) = e_k x h' + e I' e_k``; the mass is unchanged)."""
    columns = []
    for k in range(3):
        unit = [se.Integer(1) if r == k else ZERO for r in range(3)] + [ZERO] * 3
        columns.append(pose.to_parent(inertia_operator(body, pose.to_child(unit))))
    h = [columns[2][1], columns[0][2], columns[1][0]]
    I = [[columns[max(r, c)][3 + min(r, c)] for c in range(3)] for r in range(3)]
    return Body(body.m, h, I)


def crba_dq(poses, bodies):
    """Joint-space inertia matrix by composite rigid bodies in dual-quaternion form: composite
    inertia operators carried by the adjoints (:func:`carried_body`), column j the wrench
    ``Mc_j(s_j)`` carried down by ``Ad(x_i)`` (nested lists)."""
    n = len(poses)
    M = [[None] * n for _ in range(n)]
    comp = None
    for j in range(n - 1, -1, -1):
        comp = bodies[j] if comp is None else bodies[j] + carried_body(poses[j + 1], comp)
        f = inertia_operator(comp, joint_axis(poses[j].prismatic, se.Integer(1)))
        for i in range(j, -1, -1):
            if i < j:
                f = poses[i + 1].to_parent(f)
            M[i][j] = M[j][i] = f[2] if poses[i].prismatic else f[5]
    return M


def setup(model: RobotModel, params: str):
    """Joint symbols, poses and the grouped bodies (the grouping uses the joint frames'
    constants only)."""
    ts = tree_setup(model, params)
    return ts.q, joint_poses(model, ts.q), list(ts.bodies), ts


def inverse_dynamics_dq(model: RobotModel, params: str = "numeric", name: str = "tau_dq",
                        effects: bool = True) -> SymbolicFunction:
    """``tau_dq(q, qd, qdd) -> tau`` plus the description's friction, offset and armature
    torques (``effects=False``: rigid bodies only, for the regressor)."""
    q, poses, bodies, ts = setup(model, params)
    qd, qdd = port_symbols("qd", (model.n,)), port_symbols("qdd", (model.n,))
    tau = rnea_dq(poses, bodies, qd, qdd, gravity(model))
    if effects:
        tau = joint_torques(model, tau, q, qd, qdd)
    return dynamics_function(name, DQ + "inverse dynamics tau = M qdd + c + g by dual-quaternion Newton-Euler.",
                             ts, (q_port(model), qd_port(model), qdd_port(model)), (q, qd, qdd),
                             (tau_port(model, "joint torques"),), (tau,))


def coriolis_dq(model: RobotModel, params: str = "numeric", name: str = "c_dq") -> SymbolicFunction:
    """``c_dq(q, qd) -> c = tau(q, qd, 0)`` without gravity."""
    q, poses, bodies, ts = setup(model, params)
    qd = port_symbols("qd", (model.n,))
    c = rnea_dq(poses, bodies, qd, None, None)
    return dynamics_function(name, DQ + "Coriolis and centrifugal torques c = tau(q, qd, 0) without gravity, "
                             "by dual-quaternion Newton-Euler.", ts, (q_port(model), qd_port(model)),
                             (q, qd), (Port("c", (model.n,), "Coriolis and centrifugal torques", "N m"),), (c,))


def gravity_dq(model: RobotModel, params: str = "numeric", name: str = "g_dq") -> SymbolicFunction:
    """``g_dq(q) -> g = tau(q, 0, 0)``."""
    q, poses, bodies, ts = setup(model, params)
    g = rnea_dq(poses, bodies, None, None, gravity(model))
    return dynamics_function(name, DQ + "gravity torques g = tau(q, 0, 0) by dual-quaternion Newton-Euler.",
                             ts, (q_port(model),), (q,),
                             (Port("g", (model.n,), "gravity torques", "N m"),), (g,))


def mass_matrix_dq(model: RobotModel, params: str = "numeric", name: str = "M_dq",
                   effects: bool = True, composite: bool = True) -> SymbolicFunction:
    """``M_dq(q) -> M`` by dual-quaternion composite rigid bodies (``composite=False``: column
    j from the Newton-Euler pass with qd = 0, no gravity and qdd = e_j, down to joint j), plus
    the armature."""
    q, poses, bodies, ts = setup(model, params)
    n = model.n
    if composite:
        M = crba_dq(poses, bodies)
    else:
        M = [[None] * n for _ in range(n)]
        for j in range(n):
            unit = [se.Integer(1) if k == j else ZERO for k in range(n)]
            column = rnea_dq(poses, bodies, None, unit, None, first=j, stop=j)
            for i in range(j, n):
                M[i][j] = M[j][i] = column[i]
    if effects:
        M = with_armature(model, M)
    how = ("composite inertia operators carried by the joint adjoints" if composite else
           "column j = tau(q, 0, e_j) without gravity by dual-quaternion Newton-Euler")
    return dynamics_function(name, DQ + f"inertia matrix M(q), {how}.", ts, (q_port(model),), (q,),
                             (Port("M", (n, n), "joint-space inertia matrix (symmetric, row-major)", "kg m^2"),),
                             (flat(M),))


def regressor_dq(model: RobotModel, name: str = "Y_dq") -> SymbolicFunction | None:
    """``Y_dq(q, qd, qdd) -> Y``: the torque regressor on the base parameters of ``Y`` (same
    columns, same base_params.json values), its rigid-body columns the parameter derivatives
    of ``tau_dq``; None where ``Y`` is not generated."""
    homogeneous = regressor(model, "Y", name)
    if homogeneous is None:
        return None
    source = inverse_dynamics_dq(model, "symbolic", effects=False)
    full = full_regressor(model, "Y")
    assert source.input_symbols[:3] == full.input_symbols and tuple(source.input_symbols[3]) == full.p[:10 * model.n]
    dq = replace(full, rigid_rows=tuple(source.output_exprs[0]))
    exprs = dq.columns(base_parameters(model, "Y").base)
    return replace(homogeneous, output_exprs=(exprs,), stages=(),
                   summary="Torque regressor on base parameters from the dual-quaternion route: "
                           "tau = Y_dq(q, qd, qdd) pi (the columns and values of Y).")
