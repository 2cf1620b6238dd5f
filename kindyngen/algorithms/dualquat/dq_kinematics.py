"""Forward kinematics as a unit dual quaternion, built joint by joint with dual-quaternion
products (the kinematics paper's f_dQ).

Layout of ``x`` (8 numbers): ``(rw, rx, ry, rz, dw, dx, dy, dz)``: real part r, the
rotation quaternion (scalar first), then dual part d = 1/2 t (x) r, with t the flange
position as a pure quaternion, both in the base frame. Sign: x is the product of the
joint dual quaternions, each with cos(theta_i / 2) >= 0 at theta_i = 0; it is a continuous
function of q, and -x is the same pose (no canonical sign is forced, so that x stays
smooth along trajectories).

Example:

>>> qz = (se.Symbol("c"), 0, 0, se.Symbol("s"))
>>> quat_mul(qz, (1, 0, 0, 0)) == qz
True
"""
from __future__ import annotations

from dataclasses import replace

import sympy
import symengine as se

from ..geometry import constant, exact
from ..kinematics_conventions import frame_convention, q_port
from ...model.robot_model import Joint, RobotModel
from ...model.placement import Placement
from ..symbolic import Port, SymbolicFunction, port_symbols

Quat = tuple  # (w, x, y, z)


def pose_convention(model: RobotModel) -> str:
    """The frames text of a function whose pose is the dual quaternion x, not the matrix T."""
    return f"{model.frames_text} Lengths in m, angles in rad."


def quat_mul(a: Quat, b: Quat) -> Quat:
    """Hamilton product, scalar first."""
    aw, ax, ay, az = (se.sympify(v) for v in a)
    bw, bx, by, bz = (se.sympify(v) for v in b)
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def quat_add(a: Quat, b: Quat) -> Quat:
    return tuple(x + y for x, y in zip(a, b))


def dq_mul(a: tuple[Quat, Quat], b: tuple[Quat, Quat]) -> tuple[Quat, Quat]:
    """(ra + e da)(rb + e db) = ra rb + e (ra db + da rb); zero dual parts are skipped."""
    (ra, da), (rb, db) = a, b
    dual = quat_add(quat_mul(ra, db), quat_mul(da, rb))
    return quat_mul(ra, rb), dual


def dq_conjugate(u: tuple[Quat, Quat]) -> tuple[Quat, Quat]:
    """Inverse of a unit dual quaternion: the quaternion conjugate of both parts."""
    (w, x, y, z), (dw, dx, dy, dz) = u
    return (w, -x, -y, -z), (dw, -dx, -dy, -dz)


def _rotation(angle, axis) -> tuple[Quat, Quat]:
    """Exact constant rotation by ``angle`` about a unit axis (three exact numbers)."""
    half = sympy.sympify(angle) / 2
    c, s = sympy.cos(half), sympy.sin(half)
    return (constant(c), *(constant(s * sympy.sympify(u)) for u in axis)), (0, 0, 0, 0)


def _translation(t) -> tuple[Quat, Quat]:
    """The dual quaternion of a pure translation: 1 + e/2 (0, t)."""
    half = se.Rational(1, 2)
    return (1, 0, 0, 0), (0, half * t[0], half * t[1], half * t[2])


def _product(factors):
    u = ((1, 0, 0, 0), (0, 0, 0, 0))
    for f in factors:
        u = dq_mul(u, f)
    return u


def placement_dq(placement: Placement) -> tuple[Quat, Quat]:
    """A constant placement as a dual quaternion: the product of its factors' (exact
    half-angle rotations, pure translations)."""
    return _product([_translation(tuple(exact(v) for v in factor[1])) if factor[0] == "trans"
                     else _rotation(factor[2], factor[1]) for factor in placement.factors])


def joint_factors(joint: Joint):
    """Constant dual quaternions (A, B) with link frame i in link frame i-1 = A M(q_i) B,
    M a rotation about (revolute) or translation along (prismatic) z.

    The offset is a constant rotation (translation) folded into A, so it costs nothing at
    run time."""
    if joint.prismatic:
        offset = _translation((0, 0, exact(joint.offset)))
    else:
        offset = _rotation(joint.offset, (0, 0, 1))
    return _product([placement_dq(joint.before), offset]), placement_dq(joint.after)


def _vector_part(quat) -> tuple:
    return tuple(se.expand(v) for v in quat[1:])


def joint_lines(model: RobotModel):
    """Each joint's line in the zero configuration, and the constant flange offset.

    Returns ``(lines, C)`` with ``lines[i] = (u, m)``: direction u and moment m (Plücker
    coordinates, exact constants) such that frame n in frame 0 is
    ``S_1(q_1) ... S_n(q_n) C`` with ``S_i = cos(q_i/2) + sin(q_i/2) (u_i + e m_i)``.

    This is the product of the DH dual quaternions A_1 Rz_1 B_1 A_2 Rz_2 ... regrouped
    exactly: each joint rotation is conjugated by the constant product to its left and the
    constants collect in C, so it is the same dual quaternion, sign included."""
    constant = ((1, 0, 0, 0), (0, 0, 0, 0))
    lines = []
    for joint in model.joints:
        before, after = joint_factors(joint)
        constant = dq_mul(constant, before)
        # C (0 + k) C^-1: the joint axis k = (0, 0, 1) carried to the zero configuration
        real, dual = dq_mul(dq_mul(constant, ((0, 0, 0, 1), (0, 0, 0, 0))), dq_conjugate(constant))
        lines.append((_vector_part(real), _vector_part(dual)))
        constant = dq_mul(constant, after)
    return lines, dq_mul(constant, placement_dq(model.tool))


def _slide(u, q) -> tuple[Quat, Quat]:
    """A prismatic joint: translation by q along the unit direction u, 1 + e/2 (0, q u)."""
    half = se.Rational(1, 2) * q
    return (1, 0, 0, 0), (0, half * u[0], half * u[1], half * u[2])


def _screw(u, m, angle) -> tuple[Quat, Quat]:
    c, s = se.cos(angle / 2), se.sin(angle / 2)
    return (c, s * u[0], s * u[1], s * u[2]), (0, s * m[0], s * m[1], s * m[2])


def _common_point(lines):
    """The point p shared by lines (u, m) (moment m = p x u), exactly, or None."""
    rows, rhs = [], []
    for u, m in lines:
        ux, uy, uz = (sympy.sympify(str(x)) for x in u)
        # p x u = m  <=>  [[0, uz, -uy], [-uz, 0, ux], [uy, -ux, 0]] p = m
        rows += [[0, uz, -uy], [-uz, 0, ux], [uy, -ux, 0]]
        rhs += [sympy.sympify(str(x)) for x in m]
    try:
        solution, free = sympy.Matrix(rows).gauss_jordan_solve(sympy.Matrix(rhs))
    except ValueError:
        return None
    solution = solution.subs({t: 0 for t in free})
    return tuple(se.sympify(x) for x in solution)


def _spherical_triple(lines, q, i, revolute, half_angles: bool = False):
    """Joints i, i+1, i+2 about axes u, v, +-u through one point p (a spherical shoulder or
    wrist, as the LWR's), as the factors T(p), r, T(-p) with r in closed form:
    cos(b) cos(a+c) + cos(b) sin(a+c) u + sin(b) cos(a-c) v + sin(b) sin(a-c) (u x v),
    for half angles a, b, c: two sums and four products instead of two quaternion products.

    ``half_angles``: the sines and cosines of a +- c by the addition formulas from those of a
    and c (four products and four sums more, two sums fewer), so that every sin/cos argument is
    half a joint angle, which the C sincos kernel reads in place from q; with the sums a + c and
    a - c as arguments it needs them computed into an array first (:func:`fk_dq` keeps both
    routes; kindyngen.codegen.optimize chooses)."""
    if i + 2 >= len(lines) or not all(revolute[i:i + 3]):
        return None
    (u, _), (v, _), (w, _) = lines[i:i + 3]
    if tuple(w) == tuple(u):
        sign_c = 1
    elif tuple(w) == tuple(-x for x in u):
        sign_c = -1
    else:
        return None
    if sum(a * b for a, b in zip(u, v)) != 0:
        return None
    point = _common_point(lines[i:i + 3])
    if point is None:
        return None
    cb, sb = se.cos(q[i + 1] / 2), se.sin(q[i + 1] / 2)
    if half_angles:
        ca, sa, cc, sc = se.cos(q[i] / 2), se.sin(q[i] / 2), se.cos(q[i + 2] / 2), se.sin(q[i + 2] / 2)
        sa_cc, ca_sc, ca_cc, sa_sc = sa * cc, ca * sc, ca * cc, sa * sc
        cp, sp = ca_cc - sign_c * sa_sc, sa_cc + sign_c * ca_sc
        cm, sm = ca_cc + sign_c * sa_sc, sa_cc - sign_c * ca_sc
    else:
        half = se.Rational(1, 2)
        plus, minus = half * (q[i] + sign_c * q[i + 2]), half * (q[i] - sign_c * q[i + 2])
        cp, sp, cm, sm = se.cos(plus), se.sin(plus), se.cos(minus), se.sin(minus)
    uxv = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
    vector = [cb * sp * u[k] + sb * cm * v[k] + sb * sm * uxv[k] for k in range(3)]
    rotation = ((cb * cp, *vector), (0, 0, 0, 0))
    return [_translation(point), rotation, _translation(tuple(-x for x in point))]


def joint_screw_factors(model: RobotModel, q, half_angles: bool = False) -> list[tuple[Quat, Quat]]:
    """The factors whose product is the flange dual quaternion: one screw per joint, or
    closed-form factors per spherical triple (``half_angles``: see :func:`_spherical_triple`),
    with runs of constants multiplied out."""
    lines, constant = joint_lines(model)
    revolute = [not joint.prismatic for joint in model.joints]
    factors, i = [], 0
    while i < len(lines):
        triple = _spherical_triple(lines, q, i, revolute, half_angles)
        if triple is not None:
            factors += triple
            i += 3
        else:
            factors.append(_screw(*lines[i], q[i]) if revolute[i] else _slide(lines[i][0], q[i]))
            i += 1
    merged = []
    for factor in factors + [constant]:
        if merged and _is_constant(factor) and _is_constant(merged[-1]):
            merged[-1] = tuple(tuple(se.expand(v) for v in part) for part in dq_mul(merged[-1], factor))
        else:
            merged.append(factor)
    return [f for f in merged if not _is_identity(f)]


def _is_constant(u) -> bool:
    return all(not se.sympify(v).free_symbols for part in u for v in part)


def _is_identity(u) -> bool:
    return tuple(se.sympify(v) for v in u[0]) == (1, 0, 0, 0) and all(se.sympify(v) == 0 for v in u[1])


ROUTES = {"half angles": True, "sum angles": False}
"""fk_dq's routes where the arm has a spherical triple, by their spherical triples' sin/cos
arguments (:func:`_spherical_triple`): halves of joint angles only, or the sums a +- c."""


def fk_dq(model: RobotModel) -> SymbolicFunction:
    """Flange pose as a unit dual quaternion, ``fk_dq(q) -> x``. An arm with a spherical triple
    gets both routes of :data:`ROUTES` (the first with the second as its alternative)."""
    q = port_symbols("q", (model.n,))
    routes = []
    for route, half_angles in ROUTES.items():
        factors = joint_screw_factors(model, q, half_angles)
        if routes and factors == routes[0][1]:
            break                        # no spherical triple: one route
        routes.append((route, factors))
    functions = [_fk_dq_function(model, q, factors, route if len(routes) > 1 else None)
                 for route, factors in routes]
    return replace(functions[0], alternatives=tuple(functions[1:]))


def _fk_dq_function(model: RobotModel, q, factors, route) -> SymbolicFunction:
    u = factors[0]
    for factor in factors[1:]:
        u = dq_mul(u, factor)
    real, dual = u
    return SymbolicFunction(
        name="fk_dq",
        summary="Forward kinematics: flange pose as a unit dual quaternion.",
        inputs=(q_port(model),),
        outputs=(Port("x", (8,), "flange pose: rotation quaternion (w,x,y,z), then dual part "
                      "1/2 t (x) r (w,x,y,z); t = flange position in the base frame", "1 (real), m (dual)"),),
        input_symbols=(q,),
        output_exprs=(tuple(se.sympify(v) for v in real) + tuple(se.sympify(v) for v in dual),),
        conventions=pose_convention(model)
        + " x = (rw, rx, ry, rz, dw, dx, dy, dz), x and -x are the same pose; the sign is that of the "
          "product of the joint dual quaternions (continuous in q, not normalised to rw >= 0).",
        metadata={"route": route} if route else {},
    )


def _scaled(u, factor) -> tuple[Quat, Quat]:
    return tuple(tuple(se.expand(factor * se.sympify(v)) for v in part) for part in u)


def pose_jacobian_columns(model: RobotModel, q, scale=se.Rational(1, 2)):
    """``2 scale dx/dq_i`` for every joint (dx/dq_i by default), and ``scale x``, as dual
    quaternions.

    With x = S_1 ... S_n C (``joint_lines``), P_i = S_1 ... S_{i-1} and R_i = S_i ... S_n C:
    a revolute screw S_i = cos(q_i/2) + sin(q_i/2) l_i, l_i = u_i + e m_i, has
    dS_i/dq_i = 1/2 l_i S_i; a slide (``_slide``) S_i = 1 + e/2 q_i u_i has dS_i/dq_i =
    1/2 (e u_i) S_i = 1/2 l_i S_i with l_i = e u_i. So

        dx/dq_i = 1/2 P_i l_i R_i = 1/2 (P_i l_i P_i^*) x = 1/2 L_i(q) x,

    L_i(q) the joint's current line (its current axis direction, for a slide), a pure
    dual quaternion in the base frame. The columns are built as P_i (l_i R_i): one prefix
    chain P_i and one suffix chain R_i shared by all columns, l_i R_i a product by exact
    constants, and the factor ``scale`` folded into the constant C (so it costs nothing
    at run time): the columns are scale P_i l_i R_i, and the last product of the suffix
    chain is scale x."""
    lines, flange_offset = joint_lines(model)
    screws = [_slide(u, qi) if joint.prismatic else _screw(u, m, qi)
              for joint, (u, m), qi in zip(model.joints, lines, q)]
    prefixes, _ = _prefix_products(screws)   # prefixes[i] = S_1 ... S_{i-1}, None for the identity
    suffix = _scaled(flange_offset, scale)
    suffixes = [None] * len(screws)
    for i in reversed(range(len(screws))):
        suffix = dq_mul(screws[i], suffix)
        suffixes[i] = suffix
    columns = []
    for joint, (u, m), prefix, rest in zip(model.joints, lines, prefixes, suffixes):
        line = ((0, 0, 0, 0), (0, *u)) if joint.prismatic else ((0, *u), (0, *m))
        column = dq_mul(line, rest)
        if prefix is not None:
            column = dq_mul(prefix, column)
        columns.append(tuple(se.sympify(v) for v in column[0] + column[1]))
    return columns, suffixes[0]


def pose_jacobian_dq(model: RobotModel) -> SymbolicFunction:
    """Pose Jacobian of the flange dual quaternion, ``pose_jacobian_dq(q) -> Jx`` (8 x n):
    ``vec8(xdot) = Jx qd`` with x as ``fk_dq`` gives it (DQ Robotics' pose Jacobian)."""
    q = port_symbols("q", (model.n,))
    columns, _ = pose_jacobian_columns(model, q)
    return SymbolicFunction(
        name="pose_jacobian_dq",
        summary="Pose Jacobian of the flange dual quaternion: vec8(xdot) = Jx(q) qd.",
        inputs=(q_port(model),),
        outputs=(Port("Jx", (8, model.n),
                      "dx/dq: column i = 1/2 L_i(q) x, L_i = joint i's current line (u_i + e m_i; e u_i "
                      "for a prismatic joint) in the base frame; rows in fk_dq's layout "
                      "(rw, rx, ry, rz, dw, dx, dy, dz) (row-major)",
                      "1 (rows 0-3), m (rows 4-7) per rad (per m for prismatic joints)"),),
        input_symbols=(q,),
        output_exprs=(tuple(column[k] for k in range(8) for column in columns),),
        conventions=pose_convention(model)
        + " x = (rw, rx, ry, rz, dw, dx, dy, dz) as fk_dq (real part r, dual part d = 1/2 t r), with "
          "fk_dq's sign (the product of the joint dual quaternions, not normalised to rw >= 0); "
          "vec8(xdot) = Jx qd.",
    )


def _prefix_products(screws):
    """[S_1 ... S_{i-1} for every i] (None for the identity) and the product of all."""
    prefixes, product = [], None
    for screw in screws:
        prefixes.append(product)
        product = screw if product is None else dq_mul(product, screw)
    return prefixes, product


def current_lines(model: RobotModel, q):
    """Every joint's line now, ``L_i(q) = P_i l_i P_i^*`` as (direction w, moment m about the
    base origin) in the base frame (a slide: (0, direction)), and x = P_{n+1} C.

    ``Jx_i = 1/2 L_i(q) x`` (:func:`pose_jacobian_columns`): these are the lines the pose
    Jacobian is made of. The sandwich of a pure line ``u + e m`` by ``P = r + e d`` is
    ``r u r* + e (r m r* + d u r* + r u d*)``."""
    lines, flange_offset = joint_lines(model)
    screws = [_slide(u, qi) if joint.prismatic else _screw(u, m, qi)
              for joint, (u, m), qi in zip(model.joints, lines, q)]
    prefixes, product = _prefix_products(screws)
    out = []
    for joint, (u, m), prefix in zip(model.joints, lines, prefixes):
        if prefix is None:
            direction, moment = list(u), list(m)
        else:
            r, d = prefix
            rc, dc = (r[0], -r[1], -r[2], -r[3]), (d[0], -d[1], -d[2], -d[3])
            pure_u, pure_m = (0, *u), (0, *m)
            ru = quat_mul(r, pure_u)
            direction = list(quat_mul(ru, rc)[1:])
            moment = [a + b + c for a, b, c in zip(quat_mul(quat_mul(r, pure_m), rc)[1:],
                                                   quat_mul(quat_mul(d, pure_u), rc)[1:], quat_mul(ru, dc)[1:])]
        out.append(((0, 0, 0), direction) if joint.prismatic else (direction, moment))
    return out, dq_mul(product, flange_offset)


def jacobian_dq(model: RobotModel) -> SymbolicFunction:
    """The geometric Jacobian by the dual-quaternion route, ``jacobian_dq(q) -> J`` (6 x n),
    from the joints' current lines L_i(q) = u_i + e m_i that make the pose Jacobian
    (``Jx_i = 1/2 L_i x``) and the flange position t = 2 vec(d r^*) of x: a revolute
    column is ``[m_i + u_i x t; u_i]`` (the velocity of the point t turning about the line),
    a prismatic one ``[u_i; 0]``. Same convention as ``jacobian``: rows 0-2 linear velocity
    of the flange origin, rows 3-5 angular velocity, base-frame axes."""
    q = port_symbols("q", (model.n,))
    lines, (r, d) = current_lines(model, q)
    t = [2 * v for v in quat_mul(d, (r[0], -r[1], -r[2], -r[3]))[1:]]
    columns = []
    for (w, m), joint in zip(lines, model.joints):
        if joint.prismatic:
            columns.append(tuple(m) + (0, 0, 0))
            continue
        w_cross_t = (w[1] * t[2] - w[2] * t[1], w[2] * t[0] - w[0] * t[2], w[0] * t[1] - w[1] * t[0])
        columns.append(tuple(a + b for a, b in zip(m, w_cross_t)) + tuple(w))
    return SymbolicFunction(
        name="jacobian_dq",
        summary="Geometric Jacobian of the flange: [v; w] = J(q) qd (dual-quaternion route).",
        inputs=(q_port(model),),
        outputs=(Port("J", (6, model.n),
                      "rows 0-2: linear velocity of the flange origin, rows 3-5: angular velocity; "
                      "both in base-frame axes (row-major)", "m/rad (rows 0-2), 1 (rows 3-5)"),),
        input_symbols=(q,),
        output_exprs=(tuple(se.sympify(column[k]) for k in range(6) for column in columns),),
        conventions=frame_convention(model)
        + " J is expressed in base-frame axes at the flange origin (Pinocchio LOCAL_WORLD_ALIGNED); "
          "computed from the joints' current lines L_i = u_i + e m_i of the pose Jacobian (Jx_i = 1/2 L_i x) "
          "and t = 2 vec(d r^*): revolute columns [m_i + u_i x t; u_i], prismatic [u_i; 0].",
    )
