"""Partial derivatives of a kinematic tree's inverse and forward dynamics in the world-frame
formulation of Carpentier and Mansard (RSS 2018, "Analytical derivatives of rigid body
dynamics algorithms"), for any tree (``parents[]``; an arm is the one-branch tree):

* ``tau_derivatives(q, qd, qdd) -> dtau_dq, dtau_dqd`` (``dtau_dqdd`` is ``M``);
* ``fd_derivatives(q, qd, tau) -> dqdd_dq, dqdd_dqd, Minv`` and
  ``fd_derivatives_no_minv(q, qd, tau) -> dqdd_dq, dqdd_dqd`` (the same without ``M^-1``).

Everything is expressed in one frame that does not move with any joint ("world": the root
link's frame with a fixed base, the base frame at this instant with a floating one), in
Plücker coordinates: a motion (linear velocity of the point at the origin, angular
velocity), a force (force, moment about the origin). Joint j's world axis ``S_j`` depends on
the joints above it only; moving ``q_j`` turns j's whole subtree rigidly about ``S_j``, so
every quantity attached to that subtree changes by one spatial cross product (``S_j x m``,
``S_j x* f``, ``S_j x* I - I S_j x``) except for the parts the subtree inherits from j's
parent ``p`` (its velocity ``v_p`` and acceleration ``a_p``, gravity included as
``a_root = -g``). Summing the body forces ``f_l = I_l a_l + v_l x* I_l v_l`` over a subtree
(composites ``Ic_k``, forces ``F_k``, and ``Bc_k = sum B_l`` with ``B_l x = I_l (x x v_l) + x
x* (I_l v_l) + v_l x* (I_l x)``) gives, with ``u_j = S_j x v_p`` and ``psi_j = S_j x a_p +
v_p x u_j``, for k in j's subtree::

    dF_k/dq_j  = S_j x* F_k - Ic_k psi_j - Bc_k u_j
    dF_k/dqd_j = Bc_k S_j - 2 Ic_k u_j

and ``tau_i = S_i . F_i``. For i in j's subtree the rotation of ``S_i`` cancels the ``S_j x*
F_i`` term, so ``dtau_i/dq_j = -(r_i . psi_j + s_i . u_j)`` with the rows ``r_i = Ic_i S_i``,
``s_i = Bc_i^T S_i`` computed once per joint; for i above j, ``dtau_i/dq_j = S_i . Y_j`` with
``Y_j = dF_j/dq_j`` once per column (and the same for qd). Each entry is one 6-vector dot
product or two: O(n d) entries, O(1) each. The floating base's velocity columns differ only
in the factor (its ``a_root`` does not depend on the base twist); its position columns are
zero and its orientation columns (Pinocchio's local tangent ``R exp(theta)``) are ``r_i .
(e_k x g_b, 0)``, gravity g_b in the base frame.

``fd``: ``dqdd/dx = -M^-1 dtau/dx`` at ``qdd = fd(q, qd, tau)`` (differentiating ``tau(q, qd,
fd(q, qd, tau)) = tau``), ``M`` factorised once as the tree-sparse ``L^T D L`` of
:func:`kindyngen.algorithms.ldlt.tree_ldlt_solve`; every column is solved through the
factor, ``M^-1`` only where the caller asks for it. The C single call runs it as a lane program
(:class:`kindyngen.algorithms.symbolic.LaneSweep`, as the chains' derivatives do): the pass, the
factor and the terms ``r_i, s_i, u_j, psi_j, Y_j, Z_j`` once, then lane l, seeded with row l of
the identity, solves ``x = M^-1 e_l`` from the factor (row l of ``M^-1``) and forms row l of
``dqdd/dx = -x^T dtau/dx`` from the terms by subtree and ancestor sums
(:meth:`WorldPass.weighted_rows`), every lane the same arithmetic in one loop that compilers
vectorise; on the G1 (nv = 35) 34k operations once and 36 lanes of 4.4k against 121k scalar,
2.1x faster (docs/latency.md, "Lane programs over a tree").

Trees carry no joint effects (friction, armature): these are the rigid-body derivatives.

Example: a body with two pendulums, floating (nv = 8); the pendulums hang from the body, so
neither joint's torque depends on the other joint's angle:

>>> from kindyngen.readers.urdf import parse_urdf
>>> from kindyngen.readers.urdf import TWO_PENDULUMS
>>> f = tau_derivatives_tree(parse_urdf(TWO_PENDULUMS, floating_base=True))
>>> [(p.name, p.shape) for p in f.outputs]
[('dtau_dq', (8, 8)), ('dtau_dqd', (8, 8))]
>>> f.output_exprs[0][6 * 8 + 7], f.output_exprs[0][7 * 8 + 6]
(0, 0)
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import symengine as se

from .kinematics_conventions import q_port
from .rigid_bodies import ZERO, Body, cross, qd_port, qdd_port, vadd
from .symbolic import JointLoops, LaneSweep, LoopBody, Port, Stages, SymbolicFunction, naming, port_symbols
from .dynamics import ROUTE, TreeSetup, crba, expanded_parents, force_port, rnea, dynamics_function, setup
from .ldlt import tree_ldlt_factor, tree_ldlt_substitute
from ..model.robot_model import FREE_FLYER_NV, RobotModel


# ----------------------------------------------------------------------------- spatial algebra
# motions (v, w) and forces (f, n) are lists of 6 expressions, linear part first

def mcross(a, b):
    """Motion cross product ``a x b``; with :func:`fcross` dual: ``(a x b) . f = -b . (a x* f)``.

    >>> a, b, f = [1, 2, 3, 4, 5, 6], [0, 1, 0, 2, 0, 1], [3, 1, 4, 1, 5, 9]
    >>> dot6(mcross(a, b), f), -dot6(b, fcross(a, f))
    (-52, -52)
    """
    return vadd(cross(a[3:], b[:3]), cross(a[:3], b[3:])) + cross(a[3:], b[3:])


def fcross(a, f):
    """Force cross product ``a x* f`` (the motion a acting on the force f)."""
    return cross(a[3:], f[:3]) + vadd(cross(a[3:], f[3:]), cross(a[:3], f[:3]))


def inertia_times(body: Body, x):
    """The momentum ``I x`` of a body (mass m, first moment h, inertia I about the origin)
    moving with the motion x: ``(m v - h x w, h x v + I w)``."""
    v, w = x[:3], x[3:]
    linear = vadd([body.m * e for e in v], [-e for e in cross(body.h, w)])
    return linear + vadd(cross(body.h, v), [se.Add(*(body.I[r][c] * w[c] for c in range(3))) for r in range(3)])


def dot6(a, b):
    return se.Add(*(x * y for x, y in zip(a, b)))


def _add6(*vs):
    return [se.Add(*(v[k] for v in vs)) for k in range(6)]


def _scale6(s, v):
    return [s * x for x in v]


UNIT = [[se.Integer(1 if r == k else 0) for r in range(6)] for k in range(6)]


# ----------------------------------------------------------------------------- the world-frame pass

@dataclass(frozen=True)
class WorldKinematics:
    """Per joint j: the rotation R and origin o of its frame, its axis S, velocity v and
    acceleration a (world frame, :mod:`module text <kindyngen.algorithms.derivatives_world_frame>`);
    the gravity in the base frame and the root's v0, a0 (gravity as ``a_root = -g``)."""

    gravity: list
    v0: list
    a0: list
    R: list
    o: list
    S: list
    v: list
    a: list


def world_kinematics(ts: TreeSetup, qd, qdd, name) -> WorldKinematics:
    """The forward pass of the world-frame quantities, each named by ``name``."""
    model = ts.model
    base = FREE_FLYER_NV if model.floating_base else 0
    n = model.n
    g = [name(e) for e in ts.gravity_in_base()]
    if model.floating_base:
        v0 = list(qd[0:6])
        a0 = [qdd[r] - g[r] for r in range(3)] + list(qdd[3:6])
    else:
        v0 = [ZERO] * 6
        a0 = [-e for e in g] + [ZERO] * 3
    eye = [[se.Integer(1 if r == c else 0) for c in range(3)] for r in range(3)]
    R, o = [None] * n, [None] * n
    S, v, a = [None] * n, [None] * n, [None] * n
    for j, (joint, parent) in enumerate(zip(ts.joints, model.parents)):
        Rp, op = (R[parent], o[parent]) if parent >= 0 else (eye, [ZERO] * 3)
        vp, ap = (v[parent], a[parent]) if parent >= 0 else (v0, a0)
        A = [[name(se.Add(*(Rp[r][k] * joint.C[k][c] for k in range(3) if joint.C[k][c] != 0)))
              for c in range(3)] for r in range(3)]
        c, s = joint.c, joint.s
        R[j] = [[name(c * A[r][0] + s * A[r][1]), name(c * A[r][1] - s * A[r][0]), A[r][2]] for r in range(3)]
        o[j] = [name(op[r] + se.Add(*(Rp[r][k] * joint.t[k] for k in range(3)))) for r in range(3)]
        z = [A[r][2] for r in range(3)]
        S[j] = z + [ZERO] * 3 if joint.prismatic else [name(e) for e in cross(o[j], z)] + z
        qdj, qddj = qd[base + j], qdd[base + j]
        v[j] = [name(e) for e in _add6(vp, _scale6(qdj, S[j]))]
        a[j] = [name(e) for e in _add6(ap, _scale6(qddj, S[j]), _scale6(qdj, mcross(v[j], S[j])))]
    return WorldKinematics(g, v0, a0, R, o, S, v, a)


class WorldPass:
    """The world-frame quantities of :mod:`the module text <kindyngen.algorithms.derivatives_world_frame>` at
    (q, qd, qdd), each named in ``stages``: per joint its axis S, velocity v, acceleration a,
    and per subtree the composite inertia Ic, force F and matrix Bc; the root's (index -1)
    with a floating base."""

    def __init__(self, ts: TreeSetup, qd, qdd, stages: Stages):
        model = self.model = ts.model
        name = self.name = naming(stages)
        self.base = FREE_FLYER_NV if model.floating_base else 0
        n = model.n
        k = world_kinematics(ts, qd, qdd, name)
        self.gravity, self.v0, self.a0 = k.gravity, k.v0, k.a0
        v0, a0, v, a = k.v0, k.a0, k.v, k.a
        self.S, self.v, self.a = k.S, v, a
        bodies = [ts.bodies[j].moved(k.R[j], k.o[j]) for j in range(n)]
        forces = [self._force(b, vj, aj) for b, vj, aj in zip(bodies, v, a)]
        coriolis = [self._b_matrix(b, vj) for b, vj in zip(bodies, v)]
        parts = [[(b, f, B)] for b, f, B in zip(bodies, forces, coriolis)]
        root = [(ts.root, self._force(ts.root, v0, a0), self._b_matrix(ts.root, v0))] if model.floating_base else []
        Ic, F, Bc = [None] * n, [None] * n, [None] * n
        for j in range(n - 1, -1, -1):
            Ic[j], F[j], Bc[j] = self._sum(parts[j])
            (parts[model.parents[j]] if model.parents[j] >= 0 else root).append((Ic[j], F[j], Bc[j]))
        self.Ic, self.F, self.Bc = Ic, F, Bc
        self.root = self._sum(root) if model.floating_base else None

    def _force(self, body: Body, v, a):
        return _add6(inertia_times(body, a), fcross(v, inertia_times(body, v)))

    def _b_matrix(self, body: Body, v):
        """B's columns ``B e_k`` (6 x 6 as a list of columns)."""
        Iv = inertia_times(body, v)
        return [_add6(inertia_times(body, mcross(e, v)), fcross(e, Iv), fcross(v, inertia_times(body, e)))
                for e in UNIT]

    def _sum(self, parts):
        name = self.name
        I = [[name(se.Add(*(p[0].I[r][c] for p in parts))) for c in range(3)] for r in range(3)]
        for r in range(3):
            for c in range(r):
                I[r][c] = I[c][r]
        body = Body(name(se.Add(*(p[0].m for p in parts))), [name(e) for e in vadd(*(p[0].h for p in parts))], I)
        force = [name(e) for e in _add6(*(p[1] for p in parts))]
        columns = [[name(e) for e in _add6(*(p[2][k] for p in parts))] for k in range(6)]
        return body, force, columns

    def derivatives(self):
        """(dtau_dq, dtau_dqd) as nv x nv nested lists (module text)."""
        model, name, base = self.model, self.name, self.base
        n, nv = model.n, model.nv
        S, v, a, Ic, F, Bc = self.S, self.v, self.a, self.Ic, self.F, self.Bc
        dq = [[ZERO] * nv for _ in range(nv)]
        dqd = [[ZERO] * nv for _ in range(nv)]
        r = [[name(e) for e in inertia_times(Ic[i], S[i])] for i in range(n)]
        s = [[name(dot6(S[i], Bc[i][k])) for k in range(6)] for i in range(n)]
        columns, orientation, twist = [], [], []
        for j in range(n):
            parent = model.parents[j]
            vp, ap = (v[parent], a[parent]) if parent >= 0 else (self.v0, self.a0)
            u = [name(e) for e in mcross(S[j], vp)]
            psi = [name(e) for e in _add6(mcross(S[j], ap), mcross(vp, u))]
            Bu = _matvec6(Bc[j], u)
            Y = [name(e) for e in _add6(fcross(S[j], F[j]), [-e for e in inertia_times(Ic[j], psi)],
                                       [-e for e in Bu])]
            Z = [name(e) for e in _add6(_matvec6(Bc[j], S[j]), _scale6(-2, inertia_times(Ic[j], u)))]
            columns.append((u, psi, Y, Z))
            for i in _subtree(model, j):
                dq[base + i][base + j] = -(dot6(r[i], psi) + dot6(s[i], u))
                dqd[base + i][base + j] = dot6(s[i], S[j]) - 2 * dot6(r[i], u)
            for i in model.ancestors(j)[1:]:
                dq[base + i][base + j] = dot6(S[i], Y)
                dqd[base + i][base + j] = dot6(S[i], Z)
            for k in range(base):
                dq[k][base + j], dqd[k][base + j] = Y[k], Z[k]
        if model.floating_base:
            body0, _, B0 = self.root
            v0, g = self.v0, self.gravity
            for k in range(3):          # orientation columns: gravity turns in the base frame
                m = cross(UNIT[k][:3], g) + [ZERO] * 3
                col = [name(e) for e in inertia_times(body0, m)]
                orientation.append((m, col))
                for row in range(6):
                    dq[row][3 + k] = col[row]
                for i in range(n):
                    dq[base + i][3 + k] = dot6(r[i], m)
            for k in range(6):          # base twist columns
                w = [name(e) for e in mcross(UNIT[k], v0)]
                col = _add6(B0[k], [-e for e in inertia_times(body0, w)])
                twist.append((w, col))
                for row in range(6):
                    dqd[row][k] = col[row]
                for i in range(n):
                    dqd[base + i][k] = s[i][k] - dot6(r[i], w)
        self._terms = r, s, columns, orientation, twist
        return dq, dqd

    def weighted_rows(self, x, name, once):
        """``(sum_i x_i dtau_i/dq_j, sum_i x_i dtau_i/dqd_j)`` for every column j (lists of nv)
        from the terms of :meth:`derivatives` (called first), without forming its entries: with
        ``R_j``, ``P_j`` the sums of ``x_i r_i``, ``x_i s_i`` over j's subtree (leaves first) and
        ``A_j`` the base's weights plus ``x_i S_i`` over j's strict ancestors (root first),
        column j is ``A_j . Y_j - R_j . psi_j - P_j . u_j`` (q) and ``P_j . S_j - 2 R_j . u_j
        + A_j . Z_j`` (qd): O(n) 6-vector operations instead of one per entry. ``name`` names
        what depends on x, ``once`` what does not (the base columns' terms)."""
        model, base = self.model, self.base
        n, nv = model.n, model.nv
        r, s, columns, orientation, twist = self._terms
        S, parents = self.S, model.parents
        R, P = [None] * n, [None] * n
        below = [[] for _ in range(n)]
        roots = []
        for i in range(n - 1, -1, -1):
            xi = x[base + i]
            R[i] = [name(se.Add(xi * r[i][k], *(c[0][k] for c in below[i]))) for k in range(6)]
            P[i] = [name(se.Add(xi * s[i][k], *(c[1][k] for c in below[i]))) for k in range(6)]
            (below[parents[i]] if parents[i] >= 0 else roots).append((R[i], P[i]))
        A = [None] * n
        for j in range(n):
            p = parents[j]
            A[j] = ([name(A[p][k] + x[base + p] * S[p][k]) for k in range(6)] if p >= 0
                    else list(x[:base]) if base else [ZERO] * 6)
        dq, dqd = [ZERO] * nv, [ZERO] * nv
        for j, (u, psi, Y, Z) in enumerate(columns):
            dq[base + j] = se.Add(dot6(A[j], Y), -dot6(R[j], psi), -dot6(P[j], u))
            dqd[base + j] = se.Add(dot6(P[j], S[j]), -2 * dot6(R[j], u), dot6(A[j], Z))
        if base:
            total_r = [name(se.Add(*(c[0][k] for c in roots))) for k in range(6)]
            total_s = [se.Add(*(c[1][k] for c in roots)) for k in range(6)]
            for k, (m, col) in enumerate(orientation):
                dq[3 + k] = se.Add(dot6(x[:6], col), dot6(total_r, m))
            for k, (w, col) in enumerate(twist):
                dqd[k] = se.Add(dot6(x[:6], [once(e) for e in col]), total_s[k], -dot6(total_r, w))
        return dq, dqd


def _matvec6(columns, x):
    return [se.Add(*(columns[k][row] * x[k] for k in range(6))) for row in range(6)]


def _subtree(model: RobotModel, j: int):
    """j and the joints below it (depth-first order: a contiguous run after j)."""
    out = [j]
    for i in range(j + 1, model.n):
        if model.parents[i] not in out:
            break
        out.append(i)
    return out


# ----------------------------------------------------------------------------- joint loops

W_ROWS = ("R", 9), ("o", 3), ("S", 6), ("vp", 6), ("ap", 6), ("v", 6), ("a", 6)
"""The rows of ``kdg_w`` per joint: its frame's rotation (row-major) and origin, its axis, its
parent's velocity and acceleration (the root's for a joint on the root), its own."""
C_ROWS = ("m", 1), ("h", 3), ("I", 6), ("F", 6), ("K", 21), ("H", 6)
"""The rows of ``kdg_c`` (summed over a subtree): mass, first moment, inertia (xx xy xz yy yz zz),
force, the symmetric ``K + K^T`` (upper triangle by rows) with ``K x = I (v x x)``, momentum ``I v``."""
T_ROWS = ("u", 6), ("psi", 6), ("Y", 6), ("Z", 6), ("r", 6), ("s", 6)
"""The rows of ``kdg_t`` per joint: the terms of :meth:`WorldPass.derivatives`."""
LOOP_LANE = 8
"""Joint loops run over the joints padded with zero lanes to a multiple of this (an AVX-512
vector of doubles), so they vectorise without a remainder."""
_PAIRS = tuple((k, r) for k in range(6) for r in range(k, 6))
_SYM6 = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _rows(layout, name: str) -> dict:
    """{quantity: first row} of a layout such as :data:`W_ROWS`, and the total under ``name``."""
    out, row = {}, 0
    for key, size in layout:
        out[key] = row
        row += size
    out[name] = row
    return out


W, C, T = _rows(W_ROWS, "rows"), _rows(C_ROWS, "rows"), _rows(T_ROWS, "rows")


def _full3(six):
    I = [[None] * 3 for _ in range(3)]
    for k, (r, c) in enumerate(_SYM6):
        I[r][c] = I[c][r] = six[k]
    return I


def body_sums(body: Body, v, a) -> list:
    """A body's rows of ``kdg_c`` (:data:`C_ROWS`) moving with v, accelerating with a. The
    world-frame ``B`` of the module text is linear in the body, and ``B x = -(K + K^T) x + x
    x* (I v)`` with ``K x = I (v x x)`` (the cross products' duality, I symmetric), so its sum
    over a subtree is the sums of ``K + K^T`` (21 entries) and of ``I v`` (6), not 36.

    >>> body = Body(se.Integer(2), [0, 0, 0], [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> len(body_sums(body, [0] * 6, [0, 0, 9, 0, 0, 0]))
    43
    """
    Iv = inertia_times(body, v)
    force = _add6(inertia_times(body, a), fcross(v, Iv))
    K = [inertia_times(body, mcross(v, e)) for e in UNIT]       # K e_k
    return ([body.m] + list(body.h) + [body.I[r][c] for r, c in _SYM6] + force
            + [K[k][r] + K[r][k] for k, r in _PAIRS] + Iv)


def _composite(sums) -> Body:
    """The composite body of a subtree's sums (:func:`body_sums`)."""
    return Body(sums[C["m"]], list(sums[C["h"]:C["h"] + 3]), _full3(sums[C["I"]:C["I"] + 6]))


def _b_columns(sums) -> list:
    """``B e_k`` of a subtree from its ``K + K^T`` and ``I v`` sums (:func:`body_sums`)."""
    K = {}
    for q, (k, r) in enumerate(_PAIRS):
        K[k, r] = K[r, k] = sums[C["K"] + q]
    H = sums[C["H"]:C["H"] + 6]
    return [[fcross(e, H)[r] - K[k, r] for r in range(6)] for k, e in enumerate(UNIT)]


def _loop(name, sources, build) -> LoopBody:
    """A :class:`LoopBody` whose input k reads ``sources[k]``; ``build(lane symbols)`` gives
    (places, expressions)."""
    lane = port_symbols("lane", (len(sources),))
    places, exprs = build(lane)
    function = SymbolicFunction(name, "", (Port("lane", (len(lane),), ""),), (Port("out", (len(exprs),), ""),),
                                (lane,), (tuple(se.sympify(e) for e in exprs),))
    return LoopBody(function, tuple(sources), tuple(places))


def _w(key, k, index="j"):
    return ("kdg_w", W[key] + k, "", 0, index)


def _t(key, k, index="j"):
    return ("kdg_t", T[key] + k, "", 0, index)


def joint_loops(ts: TreeSetup, inputs, input_symbols, qd, qdd, out_names) -> JointLoops:
    """``tau_derivatives`` of the tree as :class:`JointLoops` (numeric parameters): the
    kinematics of :func:`world_kinematics` once, the bodies' sums (:func:`body_sums`) per
    joint, summed over subtrees, the terms ``u, psi, Y, Z, r, s`` of :meth:`WorldPass.derivatives`
    per joint, then each entry from them. ``out_names``: the caller's two output ports."""
    model = ts.model
    n = model.n
    base = FREE_FLYER_NV if model.floating_base else 0
    lanes = -(-n // LOOP_LANE) * LOOP_LANE
    stages = Stages()
    k = world_kinematics(ts, qd, qdd, naming(stages))
    parent_v = [k.v[p] if p >= 0 else k.v0 for p in model.parents]
    parent_a = [k.a[p] if p >= 0 else k.a0 for p in model.parents]
    per_joint = {"R": [[e for row in R for e in row] for R in k.R], "o": k.o, "S": k.S, "vp": parent_v,
                 "ap": parent_a, "v": k.v, "a": k.a}
    w = [per_joint[key][j][r] if j < n else ZERO for key, size in W_ROWS for r in range(size) for j in range(lanes)]
    ports, exprs = [Port("kdg_w", (W["rows"], lanes), "")], [w]
    if base:
        root = body_sums(ts.root, k.v0, k.a0)
        g = k.gravity
        orientation = [e for kk in range(3) for e in cross(UNIT[kk][:3], g)]
        twist = [e for kk in range(6) for e in mcross(UNIT[kk], k.v0)]
        ports += [Port("kdg_root", (C["rows"],), ""), Port("kdg_base", (9 + 36,), "")]
        exprs += [root, orientation + twist]
    once = SymbolicFunction("once", "", tuple(inputs), tuple(ports), tuple(input_symbols),
                            tuple(tuple(se.sympify(e) for e in x) for x in exprs), stages=stages.definitions)
    table = tuple(tuple(se.sympify(v) for v in row) for row in zip(*(
        [b.m] + list(b.h) + [b.I[r][c] for r, c in _SYM6] for b in ts.bodies)))
    table = tuple(row + (se.Integer(0),) * (lanes - n) for row in table)

    def body(x):
        R, o, v, a = x[0:9], x[9:12], x[12:18], x[18:24]
        b = Body(x[24], list(x[25:28]), _full3(x[28:34])).moved([R[0:3], R[3:6], R[6:9]], o)
        sums = body_sums(b, v, a)
        return [("kdg_c", r, "", 0, "j") for r in range(len(sums))], sums

    body_sources = ([_w("R", r) for r in range(9)] + [_w("o", r) for r in range(3)] + [_w("v", r) for r in range(6)]
                    + [_w("a", r) for r in range(6)] + [("kdg_table", r, "", 0, "j") for r in range(10)])

    def columns(x):
        S, vp, ap, sums = x[0:6], x[6:12], x[12:18], x[18:]
        Ic = _composite(sums)
        F = sums[C["F"]:C["F"] + 6]
        B = _b_columns(sums)
        u = mcross(S, vp)
        psi = _add6(mcross(S, ap), mcross(vp, u))
        Y = _add6(fcross(S, F), [-e for e in inertia_times(Ic, psi)], [-e for e in _matvec6(B, u)])
        Z = _add6(_matvec6(B, S), _scale6(-2, inertia_times(Ic, u)))
        r = inertia_times(Ic, S)
        s_ = [dot6(S, B[kk]) for kk in range(6)]
        terms = [*u, *psi, *Y, *Z, *r, *s_]
        return [("kdg_t", q, "", 0, "j") for q in range(len(terms))], terms

    column_sources = ([_w("S", r) for r in range(6)] + [_w("vp", r) for r in range(6)] + [_w("ap", r) for r in range(6)]
                      + [("kdg_c", r, "", 0, "j") for r in range(C["rows"])])
    dq, dqd = out_names

    def lower(x):
        r, s_, psi, u, S = x[0:6], x[6:12], x[12:18], x[18:24], x[24:30]
        return ([(dq, base, "i", base, "j"), (dqd, base, "i", base, "j")],
                [-(dot6(r, psi) + dot6(s_, u)), dot6(s_, S) - 2 * dot6(r, u)])

    lower_sources = ([_t("r", q, "i") for q in range(6)] + [_t("s", q, "i") for q in range(6)]
                     + [_t("psi", q) for q in range(6)] + [_t("u", q) for q in range(6)] + [_w("S", q) for q in range(6)])

    def upper(x):
        S, Y, Z = x[0:6], x[6:12], x[12:18]
        return [(dq, base, "i", base, "j"), (dqd, base, "i", base, "j")], [dot6(S, Y), dot6(S, Z)]

    upper_sources = [_w("S", q, "i") for q in range(6)] + [_t("Y", q) for q in range(6)] + [_t("Z", q) for q in range(6)]
    joint = row = root_loop = None
    if base:
        joint = _loop("joint", [_t("Y", q) for q in range(6)] + [_t("Z", q) for q in range(6)],
                      lambda x: ([(dq, q, "", base, "j") for q in range(6)] + [(dqd, q, "", base, "j") for q in range(6)],
                                 list(x)))

        def row_terms(x):
            r, s_, m, tw = x[0:6], x[6:12], x[12:21], x[21:57]
            places = ([(dq, base, "i", 3 + kk, "") for kk in range(3)] + [(dqd, base, "i", kk, "") for kk in range(6)])
            return places, ([dot6(r[:3], m[3 * kk:3 * kk + 3]) for kk in range(3)]
                            + [s_[kk] - dot6(r, tw[6 * kk:6 * kk + 6]) for kk in range(6)])

        row = _loop("row", [_t("r", q, "i") for q in range(6)] + [_t("s", q, "i") for q in range(6)]
                    + [("kdg_base", 0, "", q, "") for q in range(45)], row_terms)

        def root_terms(x):
            sums, m, tw = x[:C["rows"]], x[C["rows"]:C["rows"] + 9], x[C["rows"] + 9:]
            body0 = _composite(sums)
            B0 = _b_columns(sums)
            places, terms = [], []
            for kk in range(3):
                col = inertia_times(body0, list(m[3 * kk:3 * kk + 3]) + [ZERO] * 3)
                places += [(dq, rr, "", 3 + kk, "") for rr in range(6)]
                terms += col
            for kk in range(6):
                col = _add6(B0[kk], [-e for e in inertia_times(body0, tw[6 * kk:6 * kk + 6])])
                places += [(dqd, rr, "", kk, "") for rr in range(6)]
                terms += col
            return places, terms

        root_loop = _loop("root", [("kdg_root", 0, "", q, "") for q in range(C["rows"])]
                          + [("kdg_base", 0, "", q, "") for q in range(45)], root_terms)
    return JointLoops(joints=n, lanes=lanes, parents=tuple(model.parents),
                      ends=tuple(_subtree(model, j)[-1] + 1 for j in range(n)), table=table, once=once,
                      body=_loop("body", body_sources, body), columns=_loop("columns", column_sources, columns),
                      joint=joint, lower=_loop("lower", lower_sources, lower),
                      upper=_loop("upper", upper_sources, upper), row=row, root=root_loop)


# ----------------------------------------------------------------------------- the tree-sparse factor

# ----------------------------------------------------------------------------- functions

NOTE = (" Matrices are row-major, row i the output of coordinate i, column j the input of coordinate j (d out_i "
        "/ d in_j). Derivatives in q are taken in the tangent space: a joint's own coordinate, and for a floating "
        "base the local perturbation q * exp(dx) of its pose (Pinocchio's convention), so they have nv columns.")


def _flat(matrix):
    return [e for row in matrix for e in row]


def _matrix_port(model: RobotModel, name: str, what: str, unit: str) -> Port:
    return Port(name, (model.nv, model.nv), what + " (row-major, nv x nv)", unit)


def tau_derivatives_tree(model: RobotModel, name: str = "tau_derivatives", params: str = "numeric") -> SymbolicFunction:
    """``tau_derivatives(q, qd, qdd) -> dtau_dq, dtau_dqd`` in the world-frame formulation
    (``params``: see :func:`kindyngen.algorithms.dynamics.setup`)."""
    ts, stages = setup(model, params), Stages()
    qd, qdd = port_symbols("qd", (model.nv,)), port_symbols("qdd", (model.nv,))
    dq, dqd = WorldPass(ts, qd, qdd, stages).derivatives()
    inputs = (q_port(model), qd_port(model), qdd_port(model))
    f = dynamics_function(name, ROUTE + "partial derivatives of the inverse dynamics tau(q, qd, qdd) in the world-frame "
                          "formulation of Carpentier and Mansard (RSS 2018): a joint's motion turns its subtree rigidly, "
                          "each entry one or two spatial dot products; dtau/dqdd is M.", ts,
                          inputs, (ts.q, qd, qdd),
                          (_matrix_port(model, "dtau_dq", "dtau_i / dq_j", "N m/rad and mixed units by coordinate"),
                       _matrix_port(model, "dtau_dqd", "dtau_i / dqd_j", "N m s/rad and mixed units by coordinate")),
                      (_flat(dq), _flat(dqd)), stages, route="world frame")
    if params == "numeric":
        f = replace(f, joint_loops=joint_loops(ts, f.inputs, f.input_symbols, qd, qdd, ("dtau_dq", "dtau_dqd")))
    return _noted(f)


def fd_derivatives_tree(model: RobotModel, name: str = "fd_derivatives", with_minv: bool = True,
                        params: str = "numeric") -> SymbolicFunction:
    """``fd_derivatives(q, qd, tau) -> dqdd_dq, dqdd_dqd[, Minv]``: ``-M^-1 dtau/dx`` at
    ``qdd = fd(q, qd, tau)``, every column solved through one tree-sparse factor of M."""
    ts, stages = setup(model, params), Stages()
    name_ = naming(stages)
    nv = model.nv
    qd, tau = port_symbols("qd", (nv,)), port_symbols("tau", (nv,))
    M, _, _ = crba(ts, stages)
    factor = tree_ldlt_factor(M, expanded_parents(model), stages)
    bias = rnea(ts, qd, None, True, stages)
    qdd = tree_ldlt_substitute(factor, [t - b for t, b in zip(tau, bias)], name_)
    world = WorldPass(ts, qd, qdd, stages)
    dq, dqd = world.derivatives()
    lanes = _solved_rows(factor, world, stages.definitions, 2 if with_minv else None)
    solved = [[tree_ldlt_substitute(factor, [-B[i][j] for i in range(nv)], name_) for j in range(nv)]
              for B in (dq, dqd)]
    outputs = [[col[i] for i in range(nv) for col in columns] for columns in solved]
    ports = [_matrix_port(model, "dqdd_dq", "dqdd_i / dq_j", "1/s^2 and mixed units by coordinate"),
             _matrix_port(model, "dqdd_dqd", "dqdd_i / dqd_j", "1/s and mixed units by coordinate")]
    what = "dqdd/dtau is M^-1"
    if with_minv:
        columns = [tree_ldlt_substitute(factor, _unit_column(nv, k), name_) for k in range(nv)]
        outputs.append([columns[min(i, k)][max(i, k)] for i in range(nv) for k in range(nv)])
        ports.append(_matrix_port(model, "Minv", "inverse joint-space inertia matrix M^-1 = dqdd/dtau (symmetric)",
                                  "1/(kg m^2) and mixed units by coordinate"))
    else:
        what += ", not formed here (the function fd_derivatives has it)"
    f = dynamics_function(name, ROUTE + "partial derivatives of the forward dynamics qdd = fd(q, qd, tau): dqdd/dx = "
                          "-M^-1 dtau/dx at qdd = fd(q, qd, tau), dtau/dx in the world-frame formulation of Carpentier and "
                          "Mansard (RSS 2018), every column solved through one tree-sparse L^T D L factor of M; "
                          + what + ".", ts,
                          (q_port(model), qd_port(model), force_port(model, "tau", "applied torque")), (ts.q, qd, tau),
                          tuple(ports), tuple(outputs), stages, route="world frame")
    return _noted(replace(f, lanes=lanes))


def _solved_rows(factor, world: WorldPass, once, minv_port=None) -> LaneSweep:
    """``-M^-1 dtau/dq`` and ``-M^-1 dtau/dqd`` (ports 0 and 1) as a lane program for the C
    single call: lane l, seeded with row l of the identity, solves ``x = M^-1 e_l`` from the
    tree-sparse ``factor`` (row l of ``M^-1``, M symmetric), and row l of both ports is
    :meth:`WorldPass.weighted_rows` weighted by ``-x`` (the terms of ``world.derivatives()``,
    not its entries); ``minv_port`` (if given) gets x itself. ``once``: the named intermediates
    of the pass and the factor, computed before the lanes; what the lanes compute is named
    apart (prefix ``_l``: it reads the seeds, so it is per lane). Every lane does the same
    arithmetic, so the loop over lanes vectorises.

    G1 (nv = 35): 16045 add / 18248 mul once, 36 lanes of 2099 / 2268, against 57520 / 63884 for
    the scalar program; forming the entries once and summing ``-x_i dtau_i/dx_j`` over the
    non-zero ones in the lanes: 20295 / 23140 once, lanes of 1728 / 1863, 6 % slower (docs/latency.md).
    """
    nv = len(factor[1])
    entries = Stages("_d")
    seeds = tuple(se.Symbol(f"_seed{k}") for k in range(nv))
    solve = Stages("_l")
    x = tree_ldlt_substitute(factor, list(seeds), solve.cut)
    rows = world.weighted_rows([-e for e in x], solve.cut, entries.cut)
    exprs = [e for row in rows for e in row]
    places = [(port, j, nv) for port in range(2) for j in range(nv)]
    if minv_port is not None:
        exprs += x
        places += [(minv_port, k, nv) for k in range(nv)]
    return LaneSweep(seeds=seeds, values=tuple(tuple(_unit_column(nv, l)) for l in range(nv)), exprs=tuple(exprs),
                     places=tuple(places), stages=tuple(once) + entries.definitions + solve.definitions)


def _unit_column(n: int, k: int) -> list:
    return [se.Integer(1 if i == k else 0) for i in range(n)]


def _noted(f: SymbolicFunction) -> SymbolicFunction:
    return replace(f, conventions=f.conventions + NOTE)
