"""The Newton-Euler primitives in joint frames with exact zeros (customised symbolic
Newton-Euler in the manner of Khalil & Kleinfinger) that the tree recursions of
:mod:`kindyngen.algorithms.dynamics` are written with (an arm is the tree whose parent of joint j
is j - 1): rotating a body into its parent's frame, one joint's step of velocities and
accelerations, and ``U = skew(w') + skew(w)^2``.

Everything runs on the grouped barycentric parameters of :mod:`kindyngen.algorithms.rigid_bodies`
(every link's mass, MZ and YY moved towards the base), so that the link forces of
Newton-Euler reduce to ``w' x h + w x (w x h)`` and the gravity torques to rotated first
moments.  All quantities are expressed in the joint frames, where every joint axis is e_z.

* ``tau(q, qd, qdd)``: forward pass of velocities and accelerations (gravity as a base
  acceleration ``-gamma``), backward pass of link wrenches, ``tau_j = n_j . e_z``.
* ``c(q, qd) = tau(q, qd, 0)`` without gravity; ``g(q) = tau(q, 0, 0)``, evaluated from the
  composite first moments ``h^c_j = h_j + R_{j,j+1} h^c_{j+1}`` (grouped masses are all
  zero) as ``g_j = -e_z . (h^c_j x gamma_j)``, gamma the gravity vector in frame j.
* ``M(q)``: composite rigid bodies from the tip; column j is the wrench
  ``(e_z x h^c_j, I^c_j e_z)`` carried down to each joint i < j.

Example:

>>> u_matrix([0, 0, 1], [0, 0, 0], omega_products([0, 0, 1]))
[[-1, 0, 0], [0, -1, 0], [0, 0, 0]]
"""
from __future__ import annotations

import symengine as se

from .rigid_bodies import Body


def rotate_body(joint, body: Body) -> Body:
    """Body seen from frame j-1 when given in frame j: ``Rz(q)`` by double angles
    (``I'xx = Ixx - s^2 (Ixx - Iyy) - 2 cs Ixy``, ``I'yy = Ixx + Iyy - I'xx``,
    ``I'xy = cs (Ixx - Iyy) + (1 - 2 s^2) Ixy``), then the constant C and translation t
    (a prismatic joint: no rotation, t includes the displacement)."""
    if joint.prismatic:
        return body.moved(joint.C, joint.t)
    c, s = joint.c, joint.s
    I, h = body.I, body.h
    cs, ss = c * s, s * s
    d = I[0][0] - I[1][1]
    xx = I[0][0] - ss * d - 2 * cs * I[0][1]
    yy = I[0][0] + I[1][1] - xx
    xy = cs * d + (1 - 2 * ss) * I[0][1]
    xz = c * I[0][2] - s * I[1][2]
    yz = s * I[0][2] + c * I[1][2]
    rotated = Body(body.m, [c * h[0] - s * h[1], s * h[0] + c * h[1], h[2]],
                   [[xx, xy, xz], [xy, yy, yz], [xz, yz, I[2][2]]])
    return rotated.moved(joint.C, joint.t)


def joint_step(joint, a, wr, wdr, qdj, qddj):
    """Link j's origin acceleration, angular velocity and acceleration in frame j from the
    incoming ones already turned into frame j (``a``, ``wr``, ``wdr``) and the joint's rate
    and acceleration: a revolute joint adds ``qd e_z`` to w and ``qdd e_z + wr x qd e_z`` to
    w'; a prismatic one ``qdd e_z + 2 w x qd e_z`` to a."""
    if joint.prismatic:
        return [a[0] + 2 * qdj * wr[1], a[1] - 2 * qdj * wr[0], a[2] + qddj], wr, wdr
    return a, [wr[0], wr[1], wr[2] + qdj], [wdr[0] + qdj * wr[1], wdr[1] - qdj * wr[0], wdr[2] + qddj]


def mat3(A, v):
    """``A v`` for a 3 x 3 nested list, one sum per row."""
    return [se.Add(*(A[r][k] * v[k] for k in range(3))) for r in range(3)]


def omega_products(w):
    """The six products (xx, yy, zz, xy, xz, yz) of w's components that ``skew(w)^2`` needs."""
    wx, wy, wz = w
    return wx * wx, wy * wy, wz * wz, wx * wy, wx * wz, wy * wz


def u_matrix(w, wd, products):
    """``skew(wd) + skew(w)^2`` from :func:`omega_products` of w."""
    xx, yy, zz, xy, xz, yz = products
    return [[-(yy + zz), xy - wd[2], xz + wd[1]],
            [xy + wd[2], -(xx + zz), yz - wd[0]],
            [xz - wd[1], yz + wd[0], -(xx + yy)]]
