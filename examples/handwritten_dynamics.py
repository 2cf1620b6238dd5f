"""The peer of the generated `fd`: forward dynamics written by hand as a CasADi SX recursion.

This is what a CasADi user writes without a code generator: Featherstone's articulated-body
algorithm (ABA) with 6-D spatial vectors (angular part first), straight from the DH table of
a KinDynGen robot description, evaluated on SX symbols. No simplification beyond what SX
does by itself (x*0 -> 0, x*1 -> x) and no common-subexpression elimination beyond SX's
shared nodes.

    from kindyngen.readers.yaml_description import load_robot
    fd = handwritten_fd(load_robot("robots/lwr4.yaml"))   # casadi.Function fd(q, qd, tau) -> qdd

Frames as in tests/reference.py: body i's frame is the joint frame of joint i after the
rotation Rz(q_i); the constant placements come from the DH rows (standard:
Rz(offset) ... Tz(d) Tx(a) Rx(alpha); modified: Rx(alpha) Tx(a) Rz(offset) ... Tz(d)).
"""
from __future__ import annotations

import casadi as ca
import numpy as np


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _skew(p):
    return ca.vertcat(ca.horzcat(0, -p[2], p[1]), ca.horzcat(p[2], 0, -p[0]), ca.horzcat(-p[1], p[0], 0))


def _hom(R, p):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _crm(v):
    """Spatial motion cross product matrix v x (angular part first)."""
    w, u = v[:3], v[3:]
    Z = ca.SX.zeros(3, 3)
    return ca.vertcat(ca.horzcat(_skew(w), Z), ca.horzcat(_skew(u), _skew(w)))


def _crf(v):
    return -_crm(v).T


def _xform(R, p):
    """Plucker transform child <- parent for a child frame with rotation R and origin p in the parent."""
    E = R.T
    Z = ca.SX.zeros(3, 3)
    return ca.vertcat(ca.horzcat(E, Z), ca.horzcat(-ca.mtimes(E, _skew(p)), E))


def _spatial_inertia(m, c, Ic):
    C = np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
    top = np.hstack([Ic + m * C @ C.T, m * C])
    bottom = np.hstack([m * C.T, m * np.eye(3)])
    return np.vstack([top, bottom])


def dh_chain(robot):
    """Constant joint placements (4x4, parent body frame -> joint frame at q = 0) and link inertias
    (6x6, in the body frame) of a KinDynGen RobotModel, as numpy arrays."""
    placements, inertias = [], []
    previous = np.eye(4)   # parent body frame -> parent DH link frame
    for i, (j, link) in enumerate(zip(robot.joints, robot.links)):
        a, alpha, d, off = (float(getattr(j, k)) for k in ("a", "alpha", "d", "offset"))
        if robot.convention == "standard":
            P = _hom(_rz(off), np.zeros(3))
            B = _hom(np.eye(3), [0, 0, d]) @ _hom(np.eye(3), [a, 0, 0]) @ _hom(_rx(alpha), np.zeros(3))
        else:
            P = _hom(_rx(alpha), np.zeros(3)) @ _hom(np.eye(3), [a, 0, 0]) @ _hom(_rz(off), np.zeros(3))
            B = _hom(np.eye(3), [0, 0, d])
        placements.append(previous @ P)
        # link i's parameters are given in DH frame i = body frame * B
        R, p = B[:3, :3], B[:3, 3]
        com = R @ np.array(link.com, float) + p
        Ic = R @ np.array(link.inertia_matrix(), float) @ R.T
        inertias.append(_spatial_inertia(float(link.mass), com, Ic))
        previous = B
    return placements, inertias


def aba_sx(robot, q, qd, tau):
    """qdd as an SX expression of SX q, qd, tau (articulated-body algorithm)."""
    n = robot.n
    placements, inertias = dh_chain(robot)
    S = ca.SX([0, 0, 1, 0, 0, 0])
    X, v, c, IA, pA = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
    for i in range(n):
        Rj, pj = placements[i][:3, :3], placements[i][:3, 3]
        R = ca.mtimes(ca.SX(Rj), ca.vertcat(ca.horzcat(ca.cos(q[i]), -ca.sin(q[i]), 0),
                                            ca.horzcat(ca.sin(q[i]), ca.cos(q[i]), 0),
                                            ca.horzcat(0, 0, 1)))
        X[i] = _xform(R, ca.SX(pj))
        vJ = S * qd[i]
        v[i] = vJ if i == 0 else ca.mtimes(X[i], v[i - 1]) + vJ
        c[i] = ca.SX.zeros(6) if i == 0 else ca.mtimes(_crm(v[i]), vJ)
        I = ca.SX(inertias[i])
        IA[i] = I
        pA[i] = ca.mtimes(_crf(v[i]), ca.mtimes(I, v[i]))
    U, D, u = [None] * n, [None] * n, [None] * n
    for i in reversed(range(n)):
        U[i] = ca.mtimes(IA[i], S)
        D[i] = U[i][2]
        u[i] = tau[i] - pA[i][2]
        if i > 0:
            Ia = IA[i] - ca.mtimes(U[i], U[i].T) / D[i]
            pa = pA[i] + ca.mtimes(Ia, c[i]) + U[i] * u[i] / D[i]
            IA[i - 1] = IA[i - 1] + ca.mtimes([X[i].T, Ia, X[i]])
            pA[i - 1] = pA[i - 1] + ca.mtimes(X[i].T, pa)
    g = np.array([float(x) for x in robot.gravity])
    a_prev = ca.SX(np.concatenate([np.zeros(3), -g]))
    qdd = []
    for i in range(n):
        ap = ca.mtimes(X[i], a_prev) + c[i]
        qddi = (u[i] - ca.mtimes(U[i].T, ap)) / D[i]
        qdd.append(qddi)
        a_prev = ap + S * qddi
    return ca.vertcat(*qdd)


def handwritten_fd(robot) -> ca.Function:
    """fd(q, qd, tau) -> qdd as an SX casadi.Function, same ports as the generated one."""
    n = robot.n
    q, qd, tau = ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("tau", n)
    return ca.Function("fd_handwritten", [q, qd, tau], [aba_sx(robot, q, qd, tau)],
                       ["q", "qd", "tau"], ["qdd"])
