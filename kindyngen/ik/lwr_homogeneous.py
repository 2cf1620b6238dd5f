"""Closed-form inverse kinematics of the KUKA LWR (and every arm of LWR type, mapped onto it
by :func:`kindyngen.ik.lwr_common.lwr_geometry`: the target T becomes B^-1 T F^-1, the canonical
angles theta the arm's q) from a 4x4 pose: ``ik_hom(T, theta3) -> q (8 x 7), status (8)``.

theta3 (= q3) is the redundancy parameter. All eight branches (shoulder, elbow, wrist) come
out of one straight-line, branch-free program (selects only), so it prints to C, numpy and
CasADi alike. Method, branch order and status codes: see :mod:`kindyngen.ik.lwr_common`.

Status codes: 0 valid, 1 outside joint limits, 2 unreachable (target outside the workspace
or not reachable with this theta3), 3 wrist singular, 4 elbow singular, 5 shoulder singular.
Row k = 4 s + 2 e + w (shoulder, elbow, wrist bits).

Homogeneous specifics: the wrist rotation is taken as M = R_04^T R* = Ry(-th4) Rz(-th3)
Ry(th2) Rz(-th1) R*, applied one elementary rotation at a time to the rows of R* (44
multiplications per shoulder solution, only the seven entries the wrist needs). The wrist
angles come from ZYZ with th6 negated: th6 = atan2(sqrt(m20^2 + m21^2), m22),
th7 = atan2(-m21, m20) and th5 from K = M Rz(th7)^T = Rz(th5) Ry(-th6) (its column 1 is
(-s5, c5, 0)), which keeps th5 + th7 accurate near the wrist singularity. At the
singularity (M = Rz(phi)) th7 = phi/2 and then th5 = phi/2 from the same K.

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> f = ik_hom(load_robot("robots/lwr4.yaml"))       # doctest: +SKIP
>>> [p.shape for p in f.outputs]                      # doctest: +SKIP
[(8, 7), (8,)]
"""
from __future__ import annotations

from typing import Optional

import symengine as se

from ..algorithms.geometry import joint_cos_sin
from .lwr_common import (TOLERANCES, Wrist, assemble, canonical_pose, elbow_cosine, half_angle, indicator,
                         input_bound, lwr_geometry, sanitize, solve_position)
from ..model.robot_model import RobotModel
from ..algorithms.symbolic import Port, SymbolicFunction, port_symbols


def _wrist(R, c1, s1, c2, s2, c3, s3, c4, s4, wrist_s6: float) -> Wrist:
    """Wrist angles (th6 >= 0) from M = R_04^T R*, R_04 = Rz(th1) Ry(-th2) Rz(th3) Ry(th4);
    aligned where |sin th6| < ``wrist_s6``."""
    R0, R1, R2 = R
    a = [c1 * x + s1 * y for x, y in zip(R0, R1)]
    b = [c1 * y - s1 * x for x, y in zip(R0, R1)]                 # Rz(-th1) R*
    n0 = [c2 * x + s2 * z for x, z in zip(a, R2)]                 # Ry(th2) ...
    n2 = [c2 * z - s2 * x for x, z in zip(a, R2)]
    n1 = b
    p = [c3 * x + s3 * y for x, y in zip(n0, n1)]                  # Rz(-th3) ...
    m1 = [c3 * y - s3 * x for x, y in zip(n0[:2], n1[:2])]
    m2 = [s4 * x + c4 * z for x, z in zip(p, n2)]                  # Ry(-th4) ...
    m0 = [c4 * x - s4 * z for x, z in zip(p[:2], n2[:2])]
    m20, m21, m22 = m2
    s6 = se.sqrt(m20 ** 2 + m21 ** 2)
    aligned = indicator(s6 < wrist_s6)          # th6 = 0 or pi: any th7 will do
    regular = 1 - aligned
    # (c7, s7) up to the positive factor s6. When aligned, M = Rz(phi) Ry(-th6) with
    # (cos phi, sin phi) = (m11, -m01): th7 = phi/2 (half-angle vector), and th5 from K
    # (= phi - th7 = th7 at th6 = 0)
    hc, hs = half_angle(m1[1], -m0[1])
    c7 = regular * m20 + aligned * hc
    s7 = aligned * hs - regular * m21
    th5 = se.atan2(-(m0[0] * s7 + m0[1] * c7), m1[0] * s7 + m1[1] * c7)
    th6 = se.atan2(regular * s6, m22)             # exactly 0 (or pi) when aligned
    # the wrist singularity proper: th6 = 0 (th6 = pi, beyond any joint limit, is not flagged)
    singular = aligned * indicator(0 < m22)
    return Wrist(th5=th5, th6=th6, th7=se.atan2(s7, c7), singular=singular)


def ik_hom(model: RobotModel, scalar: str = "double") -> Optional[SymbolicFunction]:
    """All eight IK branches of an arm of LWR type from a homogeneous pose (None otherwise),
    with the tolerances of the C scalar type ``scalar`` (:data:`lwr_common.TOLERANCES`; the
    sum of squares of the 12 used entries of T below ``bound_hom``: in double every entry
    below 1e150)."""
    geometry = lwr_geometry(model)
    if geometry is None:
        return None
    tol = TOLERANCES[scalar]
    T = port_symbols("T", (4, 4))
    theta3 = port_symbols("theta3", (1,))
    bound = input_bound(geometry, tol.bound_hom)
    entries, drop = sanitize(T[0:3] + T[4:7] + T[8:11] + (T[3], T[7], T[11]), bound, flag=True)
    R, p = (entries[0:3], entries[3:6], entries[6:9]), entries[9:12]
    R, p = canonical_pose(geometry, R, p, drop)    # B^-1 T F^-1 (unchanged for the LWR's own table)
    d3, d5 = geometry.d3, geometry.d5

    c3, s3 = joint_cos_sin(geometry.signs[2] * theta3[0], geometry.offsets[2])
    c4, elbow_unreachable, elbow_singular = elbow_cosine(p, d3, d5, tol)
    s4 = se.sqrt((1 - c4) * (1 + c4))
    th4 = se.atan2(s4, c4)
    shoulders, shoulder_unreachable, shoulder_singular = solve_position(p, c3, s3, c4, s4, d3, d5, tol)
    wrists = [_wrist(R, sh.c1, sh.s1, sh.c2, sh.s2, c3, s3, c4, s4, tol.wrist_s6) for sh in shoulders]
    q, status = assemble(geometry, theta3[0], th4, shoulders, wrists,
                         (elbow_unreachable, shoulder_unreachable), shoulder_singular, elbow_singular)
    return SymbolicFunction(
        name="ik_hom",
        summary="Closed-form inverse kinematics (all eight branches) from a 4x4 flange pose, "
                "with theta3 = q3 as the redundancy parameter.",
        inputs=(Port("T", (4, 4), "target flange pose in the base frame (row-major)", "m (translation), 1 (rotation)"),
                Port("theta3", (1,), "redundancy parameter: the angle of joint 3", "rad")),
        outputs=(Port("q", (8, 7), "joint angles, one branch per row (row 4 s + 2 e + w)", "rad"),
                 Port("status", (8,), "per branch: 0 valid, 1 outside joint limits, 2 unreachable, "
                      "3 wrist singular, 4 elbow singular, 5 shoulder singular", "", "int")),
        input_symbols=(T, theta3),
        output_exprs=(q, status),
        conventions=tol.conventions(geometry.limits_text(), bound) + geometry.map_text(),
    )
