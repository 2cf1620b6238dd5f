"""Dynamic model by recursive Newton-Euler, derived symbolically in joint frames with exact
zeros (customised symbolic Newton-Euler in the manner of Khalil & Kleinfinger), plus the
composite-rigid-body inertia matrix and a composite-first-moment gravity vector.

Everything runs on the grouped barycentric parameters of :mod:`kindyngen.rigid_bodies`
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

>>> from kindyngen.robot import load_robot
>>> f = inverse_dynamics(load_robot("robots/lwr4.yaml"))     # doctest: +SKIP
>>> [p.name for p in f.inputs]                                # doctest: +SKIP
['q', 'qd', 'qdd']
"""
from __future__ import annotations

import symengine as se

from .joint_effects import effect_torques, with_armature
from .kinematics_homogeneous import q_port
from .rigid_bodies import (ZERO, Body, cross, dynamic_bodies, dynamics_function, flat, gravity, joint_frames,
                           qd_port, qdd_port, tau_port, vadd, vscale)
from .model import RobotModel
from .symbolic import Port, SymbolicFunction, port_symbols

NE = "Newton-Euler route (joint frames, grouped parameters): "


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


def setup(model: RobotModel, params: str):
    q = port_symbols("q", (model.n,))
    joints = joint_frames(model, q)
    bodies, ports, syms = dynamic_bodies(model, params, joints)
    return q, joints, bodies, ports, syms


def rnea(joints, bodies, qd, qdd, gam):
    """Joint torques by recursive Newton-Euler; ``qd``/``qdd`` may be None (zero) and
    ``gam`` the gravity vector in the base frame or None.

    Per link (Khalil-Kleinfinger form, all in frame j): ``U = skew(w') + skew(w)^2`` from the
    six products of w's components; ``F = m a + U h``; ``N = I w' + w x (I w) + h x a``;
    the next origin's acceleration is ``R^T (a + U t)``, plus ``qdd e_z + 2 w x (qd e_z)``
    after a prismatic joint, whose torque is the force along its axis.  (Variants with cross products for
    F, or products of w for ``w x I w``, cost more after CSE on the LWR and Panda.)"""
    return NewtonEulerPass(joints, bodies, qd, qdd, gam).tau


class NewtonEulerPass:
    """The pass of :func:`rnea`, its intermediates kept per link j (in frame j): the incoming
    velocity, angular and linear acceleration rotated into frame j (``wr``, ``wdr``, ``ar``),
    the angular velocity ``w``, ``U``, ``Iw = I w``, the wrench ``f``, ``nn`` link j passes on
    and ``tau``. :mod:`kindyngen.dynamics_derivatives` sweeps over them."""

    def __init__(self, joints, bodies, qd, qdd, gam):
        n = len(joints)
        self.joints, self.bodies, self.qd = joints, bodies, qd
        self.wr, self.wdr, self.ar, self.w, self.U, self.Iw = ([None] * n for _ in range(6))
        w, wd = [ZERO] * 3, [ZERO] * 3
        a = [-x for x in gam] if gam is not None else [ZERO] * 3
        U = None
        forces = []
        for j, (joint, body) in enumerate(zip(joints, bodies)):
            a_in = a if U is None else vadd(a, mat3(U, joint.t))
            self.ar[j] = a = joint.rot_t(a_in)
            self.wr[j] = wr = joint.rot_t(w)
            self.wdr[j] = wdr = joint.rot_t(wd)
            a, w, wd = joint_step(joint, a, wr, wdr, qd[j] if qd is not None else ZERO,
                                  qdd[j] if qdd is not None else ZERO)
            self.w[j] = w
            self.U[j] = U = u_matrix(w, wd, omega_products(w))
            h, I, m = body.h, body.I, body.m
            self.Iw[j] = Iw = mat3(I, w)
            forces.append((vadd(vscale(m, a), mat3(U, h)), vadd(mat3(I, wd), cross(w, Iw), cross(h, a))))
        self.f, self.nn, self.tau = [None] * n, [None] * n, [None] * n
        f, nn = [ZERO] * 3, [ZERO] * 3
        for j in range(n - 1, -1, -1):
            F, N = forces[j]
            if j + 1 < n:
                joint = joints[j + 1]
                fr = joint.rot(f)
                nn = vadd(N, joint.rot(nn), cross(joint.t, fr))
                f = vadd(F, fr)
            else:
                f, nn = F, N
            self.f[j], self.nn[j] = f, nn
            self.tau[j] = f[2] if joints[j].prismatic else nn[2]


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


def gravity_composite(joints, bodies, gam):
    """g from composite first moments: ``h^c_j = h_j + R h^c_{j+1} + m^c_{j+1} t_{j+1}``
    (the mass term vanishes with grouped parameters), ``g_j = -e_z . (h^c_j x gamma_j)``
    with gravity gamma carried into each joint frame (a prismatic joint: ``g_j = -m^c_j
    e_z . gamma_j``)."""
    n = len(joints)
    gams = []
    g_ = list(gam)
    for joint in joints:
        g_ = joint.rot_t(g_)
        gams.append(g_)
    out = [None] * n
    hc, mc = [ZERO] * 3, ZERO
    for j in range(n - 1, -1, -1):
        b = bodies[j]
        if j + 1 < n:
            joint = joints[j + 1]
            hc = vadd(b.h, joint.rot(hc), vscale(mc, joint.t))
            mc = b.m + mc
        else:
            hc, mc = list(b.h), b.m
        gj = gams[j]
        out[j] = -mc * gj[2] if joints[j].prismatic else -(hc[0] * gj[1] - hc[1] * gj[0])
    return out


def crba(joints, bodies):
    """Joint-space inertia matrix by composite rigid bodies (nested lists)."""
    n = len(joints)
    M = [[None] * n for _ in range(n)]
    comp = None
    for j in range(n - 1, -1, -1):
        comp = bodies[j] if comp is None else bodies[j] + rotate_body(joints[j + 1], comp)
        if joints[j].prismatic:     # the wrench of a unit acceleration along z
            f = [ZERO, ZERO, comp.m]
            nn = [comp.h[1], -comp.h[0], ZERO]
            M[j][j] = f[2]
        else:                       # ... of a unit angular acceleration about z
            f = [-comp.h[1], comp.h[0], ZERO]
            nn = [comp.I[0][2], comp.I[1][2], comp.I[2][2]]
            M[j][j] = nn[2]
        for i in range(j - 1, -1, -1):
            joint = joints[i + 1]
            fr = joint.rot(f)
            nn = vadd(joint.rot(nn), cross(joint.t, fr))
            f = fr
            M[i][j] = M[j][i] = fr[2] if joints[i].prismatic else nn[2]
    return M


def inverse_dynamics(model: RobotModel, params: str = "numeric", name: str = "tau",
                     effects: bool = True) -> SymbolicFunction:
    """``tau(q, qd, qdd) -> tau = M qdd + c + g`` plus the description's friction, offset and
    armature torques (``effects=False``: rigid bodies only, for the regressor)."""
    q, joints, bodies, ports, syms = setup(model, params)
    qd, qdd = port_symbols("qd", (model.n,)), port_symbols("qdd", (model.n,))
    tau = rnea(joints, bodies, qd, qdd, gravity(model))
    if effects:
        tau = [t + e for t, e in zip(tau, effect_torques(model, qd, qdd))]
    return dynamics_function(name, NE + "inverse dynamics tau = M qdd + c + g by recursive Newton-Euler.",
                             model, params, (q_port(model), qd_port(model), qdd_port(model)), (q, qd, qdd),
                             (tau_port(model, "joint torques"),), (tau,), ports, syms)


def coriolis_rnea(model: RobotModel, params: str = "numeric", name: str = "c") -> SymbolicFunction:
    """``c(q, qd) -> c = tau(q, qd, 0)`` without gravity."""
    q, joints, bodies, ports, syms = setup(model, params)
    qd = port_symbols("qd", (model.n,))
    c = rnea(joints, bodies, qd, None, None)
    return dynamics_function(name, NE + "Coriolis and centrifugal torques c = tau(q, qd, 0) without gravity, "
                             "by recursive Newton-Euler.", model, params, (q_port(model), qd_port(model)), (q, qd),
                             (Port("c", (model.n,), "Coriolis and centrifugal torques", "N m"),), (c,), ports, syms)


def gravity_rnea(model: RobotModel, params: str = "numeric", name: str = "g", composite: bool = True) -> SymbolicFunction:
    """``g(q) -> g = tau(q, 0, 0)`` (by composite first moments, or by plain RNEA)."""
    q, joints, bodies, ports, syms = setup(model, params)
    gam = gravity(model)
    g = gravity_composite(joints, bodies, gam) if composite else rnea(joints, bodies, None, None, gam)
    how = "by composite first moments" if composite else "by a Newton-Euler pass"
    return dynamics_function(name, NE + f"gravity torques g = tau(q, 0, 0), {how}.",
                             model, params, (q_port(model),), (q,),
                             (Port("g", (model.n,), "gravity torques", "N m"),), (g,), ports, syms)


def mass_matrix_crba(model: RobotModel, params: str = "numeric", name: str = "M",
                     effects: bool = True) -> SymbolicFunction:
    """``M(q) -> M`` by the composite-rigid-body algorithm (plus the armature)."""
    q, joints, bodies, ports, syms = setup(model, params)
    M = crba(joints, bodies)
    if effects:
        M = with_armature(model, M)
    return dynamics_function(name, NE + "inertia matrix M(q) by the composite-rigid-body algorithm.", model, params,
                             (q_port(model),), (q,),
                             (Port("M", (model.n, model.n), "joint-space inertia matrix (symmetric, row-major)",
                                   "kg m^2"),),
                             (flat(M),), ports, syms)
