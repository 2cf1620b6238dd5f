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

import sympy
import symengine as se

from .geometry import exact, joint_cos_sin
from .kinematics_homogeneous import FRAME_CONVENTION, q_port
from .robot import Joint, RobotModel
from .symbolic import Port, SymbolicFunction, port_symbols

Quat = tuple  # (w, x, y, z)


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


def _half_angle_rotation(angle, axis: int) -> Quat:
    half = sympy.sympify(angle) / 2
    c, s = se.sympify(sympy.cos(half)), se.sympify(sympy.sin(half))
    v = [c, 0, 0, 0]
    v[1 + axis] = s
    return tuple(v)


def _translation(t) -> tuple[Quat, Quat]:
    """The dual quaternion of a pure translation: 1 + e/2 (0, t)."""
    half = se.Rational(1, 2)
    return (1, 0, 0, 0), (0, half * t[0], half * t[1], half * t[2])


def joint_dual_quaternion(joint: Joint, convention: str, q: se.Symbol) -> tuple[Quat, Quat]:
    """Frame i in frame i-1 as a unit dual quaternion."""
    ch, sh = joint_cos_sin(q / 2, sympy.sympify(joint.offset) / 2)
    rz = ((ch, 0, 0, sh), (0, 0, 0, 0))
    rx = (_half_angle_rotation(joint.alpha, 0), (0, 0, 0, 0))
    a, d = exact(joint.a), exact(joint.d)
    if convention == "standard":  # Rz(theta) Tz(d) Tx(a) Rx(alpha)
        factors = [rz, _translation((a, 0, d)), rx]
    else:                         # Rx(alpha) Tx(a) Rz(theta) Tz(d)
        factors = [rx, _translation((a, 0, 0)), rz, _translation((0, 0, d))]
    factors = [f for f in factors if not _is_identity(f)]
    u = factors[0]
    for f in factors[1:]:
        u = dq_mul(u, f)
    return u


def _is_identity(u) -> bool:
    r, d = u
    return tuple(se.sympify(v) for v in r) == (1, 0, 0, 0) and all(se.sympify(v) == 0 for v in d)


def fk_dq(model: RobotModel) -> SymbolicFunction:
    """Flange pose as a unit dual quaternion, ``fk_dq(q) -> x``."""
    q = port_symbols("q", (model.n,))
    u = None
    for joint, qi in zip(model.joints, q):
        ui = joint_dual_quaternion(joint, model.convention, qi)
        u = ui if u is None else dq_mul(u, ui)
    real, dual = u
    return SymbolicFunction(
        name="fk_dq",
        summary="Forward kinematics: flange pose as a unit dual quaternion.",
        inputs=(q_port(model),),
        outputs=(Port("x", (8,), "flange pose: rotation quaternion (w,x,y,z), then dual part "
                      "1/2 t (x) r (w,x,y,z); t = flange position in the base frame", "1 (real), m (dual)"),),
        input_symbols=(q,),
        output_exprs=(tuple(se.sympify(v) for v in real) + tuple(se.sympify(v) for v in dual),),
        conventions=FRAME_CONVENTION.format(n=model.n)
        + " x = (rw, rx, ry, rz, dw, dx, dy, dz), x and -x are the same pose; the sign is that of the "
          "product of the joint dual quaternions (continuous in q, not normalised to rw >= 0).",
    )
