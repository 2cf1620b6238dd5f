"""Forward dynamics of a kinematic tree by the articulated-body algorithm, derived
symbolically in the joint frames of :mod:`kindyngen.algorithms.dynamics` (Featherstone, *Rigid
Body Dynamics Algorithms*, Table 7.1; floating base, Table 9.6).

Spatial vectors are pairs of 3-vectors in joint frame j about its origin: motion ``(w, v)``
(angular, then the origin's linear velocity), force ``(n, f)`` (moment, then force). An
articulated inertia is ``[[A, B], [B^T, C]]`` (A, C symmetric 3 x 3), mapping motion to
force; a body's is ``[[I, [h]x], [-[h]x, m 1]]``.

1. Root to tips: velocities, the velocity-product accelerations ``c = v x S qd`` and the bias
   forces ``p = v x* I v``.
2. Tips to root: ``U = I^A S``, ``D = S^T U``, ``u = tau - S^T p^A``; the parent receives
   ``X^T (I^A - U U^T / D) X`` and ``X^T (p^A + I^a c + U u / D)`` (X the motion transform
   parent -> child: rotation ``C Rz(q)``, then the shift by t).
3. Root to tips: ``a = X a_parent + c``, ``qdd = (u - U^T a) / D``, ``a += S qdd``.

Every per-body quantity (velocity, bias force, articulated inertia, acceleration) is a named
intermediate (:class:`kindyngen.algorithms.symbolic.Stages`); symmetric 3 x 3 blocks are named by their
upper triangle. CSE then works on small expressions and stays near-linear in the size of
the tree: on the whole DAG, where every articulated inertia is shared by all the bodies
below, symengine's cse does not finish on a humanoid.

Gravity: with a fixed base the root accelerates at ``-gamma`` (as in Newton-Euler); with a
floating base everything is computed relative to free fall (``a' = a - (0, R^T gamma)``):
``a'_0 = -(I^A_0)^-1 p^A_0`` (a 6 x 6 L D L^T solve) and the base's output is ``a'_0 + (0,
R^T gamma)``, the derivative of its twist in the base frame (Pinocchio's ``aba``).

Example:

>>> from kindyngen.readers.urdf import parse_urdf
>>> from kindyngen.readers.urdf import TWO_PENDULUMS
>>> f = forward_dynamics_aba(parse_urdf(TWO_PENDULUMS, floating_base=True))
>>> [(p.name, p.shape) for p in f.outputs]
[('qdd', (8,))]
"""
from __future__ import annotations

import symengine as se

from .ldlt import ldlt_solve
from .kinematics_conventions import q_port
from ..model.robot_model import FREE_FLYER_NV, RobotModel
from .rigid_bodies import ZERO, cross, dot, matTvec, matvec, qd_port, qdd_port, vadd, vscale
from .symbolic import Stages, SymbolicFunction, port_symbols
from .dynamics import ROUTE, TreeSetup, carry, force_port, transmitted, dynamics_function, setup


def _skew(v):
    return [[ZERO, -v[2], v[1]], [v[2], ZERO, -v[0]], [-v[1], v[0], ZERO]]


def _matmul(P, Q):
    return [[se.Add(*(P[r][k] * Q[k][c] for k in range(3))) for c in range(3)] for r in range(3)]


def _transpose(M):
    return [[M[c][r] for c in range(3)] for r in range(3)]


def _madd(*Ms):
    return [[se.Add(*(M[r][c] for M in Ms)) for c in range(3)] for r in range(3)]


class Inertia6:
    """An articulated inertia ``[[A, B], [B^T, C]]`` (nested 3 x 3 lists)."""

    def __init__(self, A, B, C):
        self.A, self.B, self.C = A, B, C

    def named(self, stages: Stages) -> "Inertia6":
        """The same inertia with every entry named (A, C by their upper triangles)."""
        return Inertia6(_named_symmetric(stages, self.A), [stages.cut_all(row) for row in self.B],
                        _named_symmetric(stages, self.C))

    @staticmethod
    def of_body(body) -> "Inertia6":
        m = body.m
        return Inertia6([row[:] for row in body.I], _skew(body.h),
                        [[m if r == c else ZERO for c in range(3)] for r in range(3)])

    def times(self, w, v):
        """The force of motion (w, v)."""
        return vadd(matvec(self.A, w), matvec(self.B, v)), vadd(matTvec(self.B, w), matvec(self.C, v))

    def column(self, k):
        """Column k (0-2: angular, 3-5: linear) as a force (n, f)."""
        if k < 3:
            return [self.A[r][k] for r in range(3)], [self.B[k][r] for r in range(3)]
        return [self.B[r][k - 3] for r in range(3)], [self.C[r][k - 3] for r in range(3)]

    def minus_outer(self, U, inv_d) -> "Inertia6":
        """``self - U U^T / D``."""
        n, f = U
        sn, sf = vscale(inv_d, n), vscale(inv_d, f)
        return Inertia6([[self.A[r][c] - n[r] * sn[c] for c in range(3)] for r in range(3)],
                        [[self.B[r][c] - n[r] * sf[c] for c in range(3)] for r in range(3)],
                        [[self.C[r][c] - f[r] * sf[c] for c in range(3)] for r in range(3)])

    def to_parent(self, joint) -> "Inertia6":
        """``X^T self X`` for the joint's motion transform X (parent -> child)."""
        A, B, C = (_rotate(joint, M) for M in (self.A, self.B, self.C))
        T = _skew(joint.t)
        BT = _matmul(B, T)
        TC = _matmul(T, C)
        return Inertia6(_madd(A, [[-x for x in row] for row in BT], [[-x for x in row] for row in _transpose(BT)],
                              [[-x for x in row] for row in _matmul(TC, T)]),
                        _madd(B, TC), C)

    @staticmethod
    def total(items) -> "Inertia6":
        return Inertia6(_madd(*(i.A for i in items)), _madd(*(i.B for i in items)), _madd(*(i.C for i in items)))


def _named_symmetric(stages: Stages, M):
    upper = {(r, c): stages.cut(M[r][c]) for r in range(3) for c in range(r, 3)}
    return [[upper[min(r, c), max(r, c)] for c in range(3)] for r in range(3)]


def _named_pair(stages: Stages, pair):
    return tuple(stages.cut_all(v) for v in pair)


def _rotate(joint, M):
    """``R M R^T`` for the joint's rotation R (child -> parent coordinates)."""
    RM = _transpose([joint.rot([M[r][c] for r in range(3)]) for c in range(3)])       # R M, by columns
    return [joint.rot(RM[r]) for r in range(3)]          # row r of (R M) R^T is R times row r of R M


def _motion_to_child(joint, w, v):
    """A motion vector of the parent's frame in the child's frame."""
    return joint.rot_t(w), joint.rot_t(vadd(v, [-x for x in cross(joint.t, w)]))


def aba(ts: TreeSetup, qd, tau, stages: Stages, armature=None) -> list:
    """qdd (size nv) by the articulated-body algorithm (module text), its intermediates named
    in ``stages``; ``armature`` (per joint, or None) adds each joint's rotor inertia to its
    ``D`` (the motor turns with the joint only)."""
    model = ts.model
    n, base = model.n, FREE_FLYER_NV if model.floating_base else 0
    ez = [ZERO, ZERO, se.Integer(1)]
    # 1. velocities, velocity-product accelerations, bias forces
    root_w, root_v = (list(qd[3:6]), list(qd[0:3])) if model.floating_base else ([ZERO] * 3, [ZERO] * 3)
    vel, acc_c, IA, pA = [None] * n, [None] * n, [None] * n, [None] * n

    def bias(inertia, w, v):
        mn, mf = inertia.times(w, v)
        return vadd(cross(w, mn), cross(v, mf)), cross(w, mf)

    for j, (joint, parent) in enumerate(zip(ts.joints, model.parents)):
        w, v = vel[parent] if parent >= 0 else (root_w, root_v)
        w, v = _motion_to_child(joint, w, v)
        qdj = qd[base + j]
        if joint.prismatic:
            v = vadd(v, vscale(qdj, ez))
            acc_c[j] = ([ZERO] * 3, vscale(qdj, cross(w, ez)))
        else:
            w = vadd(w, vscale(qdj, ez))
            acc_c[j] = (vscale(qdj, cross(w, ez)), vscale(qdj, cross(v, ez)))
        w, v = vel[j] = _named_pair(stages, (w, v))
        acc_c[j] = _named_pair(stages, acc_c[j])
        IA[j] = [Inertia6.of_body(ts.bodies[j])]
        pA[j] = [_named_pair(stages, bias(IA[j][0], w, v))]
    root_I = [Inertia6.of_body(ts.root)]
    root_p = [bias(root_I[0], root_w, root_v)]
    # 2. articulated inertias and bias forces, tips first
    U, inv_d, u = [None] * n, [None] * n, [None] * n
    for j in range(n - 1, -1, -1):
        joint, parent = ts.joints[j], model.parents[j]
        inertia = Inertia6.total(IA[j]).named(stages)
        pn, pf = _named_pair(stages, (vadd(*(p[0] for p in pA[j])), vadd(*(p[1] for p in pA[j]))))
        k = 5 if joint.prismatic else 2
        U[j] = inertia.column(k)
        d = U[j][1][2] if joint.prismatic else U[j][0][2]
        if armature is not None and armature[j] != 0:
            d = d + armature[j]
        inv_d[j] = stages.cut(se.Pow(d, -1))
        u[j] = stages.cut(tau[base + j] - (pf[2] if joint.prismatic else pn[2]))
        if parent < 0 and not model.floating_base:
            continue
        Ia = inertia.minus_outer(U[j], inv_d[j]).named(stages)
        cn, cf = Ia.times(*acc_c[j])
        scale = stages.cut(u[j] * inv_d[j])
        pa = _named_pair(stages, (vadd(pn, cn, vscale(scale, U[j][0])), vadd(pf, cf, vscale(scale, U[j][1]))))
        (IA[parent] if parent >= 0 else root_I).append(Ia.to_parent(joint).named(stages))
        fr, nr = carry(joint, pa[1], pa[0])
        (pA[parent] if parent >= 0 else root_p).append(_named_pair(stages, (nr, fr)))
    # 3. accelerations, root first
    gam = ts.gravity_in_base()
    out = [None] * base
    if model.floating_base:
        inertia = Inertia6.total(root_I).named(stages)
        full = [[inertia.A[r][c] for c in range(3)] + [inertia.B[r][c] for c in range(3)] for r in range(3)]
        full += [[inertia.B[c][r] for c in range(3)] + [inertia.C[r][c] for c in range(3)] for r in range(3)]
        # the base's applied wrench tau[0:6] is (force, moment); the solve's order is (moment, force)
        rhs = ([t - x for t, x in zip(tau[3:6], vadd(*(p[0] for p in root_p)))]
               + [t - x for t, x in zip(tau[0:3], vadd(*(p[1] for p in root_p)))])
        a0 = stages.cut_all(ldlt_solve(full, stages.cut_all(rhs)))
        root_a = (a0[0:3], a0[3:6])                     # relative to free fall
        out = [a0[3 + r] + gam[r] for r in range(3)] + list(a0[0:3])
    else:
        root_a = ([ZERO] * 3, [-x for x in gam])
    acc, qdd = [None] * n, [None] * n
    for j, (joint, parent) in enumerate(zip(ts.joints, model.parents)):
        al, av = _motion_to_child(joint, *(acc[parent] if parent >= 0 else root_a))
        al, av = vadd(al, acc_c[j][0]), vadd(av, acc_c[j][1])
        al, av = _named_pair(stages, (al, av))
        qdd[j] = stages.cut((u[j] - dot(U[j][0], al) - dot(U[j][1], av)) * inv_d[j])
        if joint.prismatic:
            av = [av[0], av[1], av[2] + qdd[j]]
        else:
            al = [al[0], al[1], al[2] + qdd[j]]
        acc[j] = (al, av)
    return out + qdd


def forward_dynamics_aba(model: RobotModel, params: str = "numeric", name: str = "fd") -> SymbolicFunction:
    """``fd(q, qd, tau) -> qdd`` by the articulated-body algorithm (the armature in each
    joint's D, friction and offset taken from the applied torque)."""
    ts = setup(model, params)
    qd, tau = port_symbols("qd", (model.nv,)), port_symbols("tau", (model.nv,))
    stages = Stages()
    applied = transmitted(model, ts.q, qd, tau)
    armature = [se.sympify(model.armature(j)) for j in range(model.n)] if "armature" in model.effects else None
    qdd = aba(ts, qd, applied, stages, armature)
    return dynamics_function(name, ROUTE + "forward dynamics qdd = M^-1 (tau - c - g) by the articulated-body algorithm "
                             "(O(n), no inertia matrix).", ts,
                             (q_port(model), qd_port(model), force_port(model, "tau", "applied torque")),
                             (ts.q, qd, tau), (qdd_port(model),), (qdd,), stages, route="articulated-body")
