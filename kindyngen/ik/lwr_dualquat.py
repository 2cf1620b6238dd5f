"""Closed-form inverse kinematics of the KUKA LWR (and every arm of LWR type, mapped onto it
by :func:`kindyngen.ik.lwr_common.lwr_geometry`: the target x becomes b* x f*, the product with
the conjugate dual quaternions of the constant base and tool transforms B and F, which is
bilinear, so the zero input stays zero) from a unit dual quaternion:
``ik_dq(x, theta3) -> q (8 x 7), status (8)``, with x in fk_dq's layout
(rw, rx, ry, rz, dw, dx, dy, dz), |r| = 1, d = 1/2 t (x) r; x and -x give the same result.

Solved with quaternion algebra throughout, never building a rotation matrix:

* position: t/2 = vec(d (x) r*) (12 multiplications); the position sub-problem is scale
  free, so it runs on t/2 with the lengths d3/2, d5/2 (see :func:`ik_common.solve_position`:
  law of cosines for q4, then q1 and q2 as planar rotations between known vectors);
* joint quaternions in half-angle form: q3 from cos/sin(theta3/2), q4 from
  cos(q4/2) = sqrt((1 + c4)/2), sin(q4/2) = sqrt((1 - c4)/2), q1 and q2 from their
  cosines and sines by the rotation-between-vectors formula (1 + c, s) ~ (cos th/2, sin th/2)
  (or (s, 1 - c) when c < 0), left unnormalised (every later step is scale free);
* wrist: w = r_04* (x) r = Rz(q5/2) Ry(-q6/2) Rz(q7/2) as quaternions
  = (cb cos S, -sb sin D, sb cos D, cb sin S) with S = (q5 + q7)/2, D = (q5 - q7)/2,
  b = -q6/2, so q6 = 2 atan2(|(x, y)|, |(w, z)|) (evaluated as
  atan2(2 |(x, y)| |(w, z)|, |(w, z)|^2 - |(x, y)|^2), one root) and, with complex products,
  q5 = arg((w + i z)(-y + i x)), q7 = arg((w + i z)(-y - i x)) (no wrapping, and
  q5 + q7 exact near the wrist singularity; at it, q5 = q7 = arg((w + i z) w)).

The other six branches, as in ik_hom, from the elbow and wrist twins (:mod:`ik_common`).
The paper's DQ inverse solved two quartics and was 70 % slower than the homogeneous one;
here no polynomial is solved and the cost is about that of the homogeneous form.
Method, branch order and status codes: :mod:`kindyngen.ik.lwr_common`
(0 valid, 1 outside joint limits, 2 unreachable, 3 wrist, 4 elbow, 5 shoulder singular).
"""
from __future__ import annotations

from typing import Optional

import sympy
import symengine as se

from ..algorithms.geometry import constant, joint_cos_sin
from .lwr_common import (TOLERANCES, LwrGeometry, Wrist, assemble, elbow_cosine, half_angle, indicator,
                         input_bound, lwr_geometry, quaternion, sanitize, solve_position)
from ..algorithms.dualquat.dq_kinematics import quat_add, quat_mul
from ..model.robot_model import RobotModel
from ..algorithms.symbolic import Port, SymbolicFunction, port_symbols


def conj(quat):
    w, x, y, z = quat
    return (w, -x, -y, -z)


def _constant_dq(pose) -> tuple:
    """The unit dual quaternion (r, 1/2 (0, p) (x) r) of an exact pose (R, p), symengine."""
    R, p = pose
    r = tuple(constant(v) for v in quaternion(R))
    return r, quat_mul((0,) + tuple(constant(v) / 2 for v in p), r)


def canonical_dq(geometry: LwrGeometry, xs) -> tuple:
    """The target mapped onto the canonical LWR: B^-1 x F^-1 as dual quaternions (the input
    itself when B and F are identities; the inverse of a unit dual quaternion is its
    conjugate)."""
    r, d = tuple(xs[:4]), tuple(xs[4:])
    if geometry.flange is not None:                     # x F^-1 = (r f*, r fd* + d f*)
        fr, fd = _constant_dq(geometry.flange)
        r, d = quat_mul(r, conj(fr)), quat_add(quat_mul(r, conj(fd)), quat_mul(d, conj(fr)))
    if geometry.base is not None:                       # B^-1 x = (b* r, b* d + bd* r)
        br, bd = _constant_dq(geometry.base)
        r, d = quat_mul(conj(br), r), quat_add(quat_mul(conj(br), d), quat_mul(conj(bd), r))
    return r + d


def _wrist(r, h1, h2, h3, h4, wrist_s6: float, tiny: float) -> Wrist:
    """Wrist angles (th6 >= 0) from w = (Qz(th1) Qy(-th2) Qz(th3) Qy(th4))* (x) r; singular
    where |sin th6| < ``wrist_s6``."""
    w = quat_mul(conj((h1[0], 0, 0, h1[1])), r)
    w = quat_mul(conj((h2[0], 0, -h2[1], 0)), w)
    w = quat_mul(conj((h3[0], 0, 0, h3[1])), w)
    W, X, Y, Z = quat_mul(conj((h4[0], 0, h4[1], 0)), w)
    sb2, cb2 = X ** 2 + Y ** 2, W ** 2 + Z ** 2
    singular = indicator(sb2 < (wrist_s6 / 2) ** 2 * (sb2 + cb2))     # th6 = 0
    regular = 1 - singular
    th6 = se.atan2(2 * regular * se.sqrt(sb2 * cb2), cb2 - sb2)        # exactly 0 there
    # (cos S, sin S) ~ (W, Z), (cos D, sin D) ~ (-Y, X); W + tiny keeps th6 = pi (W = Z = 0)
    # valid. At the singularity D := 0, split equally: q5 = q7 = S taken in [-pi/2, pi/2]
    # (from (W, 0) instead of (1, 0); + tiny for W = 0, S = pi/2)
    Wt = W + tiny
    dc, ds = singular * Wt - regular * Y, regular * X
    th5 = se.atan2(Wt * ds + Z * dc, Wt * dc - Z * ds)
    th7 = se.atan2(Z * dc - Wt * ds, Wt * dc + Z * ds)
    return Wrist(th5=th5, th6=th6, th7=th7, singular=singular)


def ik_dq(model: RobotModel, scalar: str = "double") -> Optional[SymbolicFunction]:
    """All eight IK branches of an arm of LWR type from a unit dual quaternion (None
    otherwise), with the tolerances of the C scalar type ``scalar``
    (:data:`lwr_common.TOLERANCES`; the sum of squares of x below ``bound_dq``: in double its
    entries below ~3e74, so t/2 = vec(d r*) stays below 1e150 and its squares below 1e300)."""
    geometry = lwr_geometry(model)
    if geometry is None:
        return None
    tol = TOLERANCES[scalar]
    x = port_symbols("x", (8,))
    theta3 = port_symbols("theta3", (1,))
    bound = input_bound(geometry, tol.bound_dq)
    xs = sanitize(x, bound)
    if geometry.base is not None or geometry.flange is not None:
        xs = canonical_dq(geometry, xs)                # B^-1 x F^-1
    r, d = xs[:4], xs[4:]
    half = se.Rational(1, 2)
    d3, d5 = half * geometry.d3, half * geometry.d5     # lengths at the scale of t/2
    p = quat_mul(d, conj(r))[1:]                          # t/2 = vec(d (x) r*)

    ch3, sh3 = joint_cos_sin(geometry.signs[2] * theta3[0] / 2, sympy.sympify(geometry.offsets[2]) / 2)
    c3, s3 = ch3 ** 2 - sh3 ** 2, 2 * ch3 * sh3
    c4, elbow_unreachable, elbow_singular = elbow_cosine(p, d3, d5, tol)
    ch4, sh4 = se.sqrt((1 + c4) / 2), se.sqrt((1 - c4) / 2)
    s4 = 2 * ch4 * sh4
    th4 = se.atan2(s4, c4)
    shoulders, shoulder_unreachable, shoulder_singular = solve_position(p, c3, s3, c4, s4, d3, d5, tol, scale=half)
    wrists = [_wrist(r, half_angle(sh.c1, sh.s1), half_angle(sh.c2, sh.s2), (ch3, sh3), (ch4, sh4),
                     tol.wrist_s6, tol.tiny) for sh in shoulders]
    q, status = assemble(geometry, theta3[0], th4, shoulders, wrists,
                         (elbow_unreachable, shoulder_unreachable), shoulder_singular, elbow_singular)
    return SymbolicFunction(
        name="ik_dq",
        summary="Closed-form inverse kinematics (all eight branches) from a unit dual quaternion, "
                "with theta3 = q3 as the redundancy parameter.",
        inputs=(Port("x", (8,), "target flange pose as in fk_dq: (rw, rx, ry, rz, dw, dx, dy, dz), "
                     "d = 1/2 t (x) r; either sign", "1 (real), m (dual)"),
                Port("theta3", (1,), "redundancy parameter: the angle of joint 3", "rad")),
        outputs=(Port("q", (8, 7), "joint angles, one branch per row (row 4 s + 2 e + w)", "rad"),
                 Port("status", (8,), "per branch: 0 valid, 1 outside joint limits, 2 unreachable, "
                      "3 wrist singular, 4 elbow singular, 5 shoulder singular", "", "int")),
        input_symbols=(x, theta3),
        output_exprs=(q, status),
        conventions=tol.conventions(geometry.limits_text(), bound)
        + " Input x in fk_dq's layout; x and -x give the same result." + geometry.map_text(),
    )
