"""Partial derivatives of the inverse and forward dynamics, for optimal control and MPC:

* ``tau_derivatives(q, qd, qdd) -> dtau_dq, dtau_dqd`` (``dtau_dqdd`` is ``M``, the function
  ``M``);
* ``fd_derivatives(q, qd, tau) -> dqdd_dq, dqdd_dqd, Minv`` and ``fd_derivatives_no_minv(q,
  qd, tau) -> dqdd_dq, dqdd_dqd`` (the same without ``M^-1``).

Both follow the model of ``tau`` and ``fd`` exactly (same grouped bodies, joint frames, params
mode, prismatic joints, friction and armature; any fixed-base tree, an arm being the tree
whose parent of joint j is j - 1), derived by hand-written forward and reverse (adjoint)
sweeps over the joint-frame Newton-Euler pass of :class:`kindyngen.algorithms.dynamics.NewtonEulerPass`
(written over ``parents[]``: a tangent runs down the subtree of its joint, an adjoint
gathers what the children carry back), which reuse its intermediates instead of
differentiating the expression DAG (``se.diff`` rebuilds ``d(Rz x)/dq`` from cos and sin as new
expressions that CSE cannot match with ``Rz x``; here the rotated vector itself is reused):

* the only explicit dependence of tau on ``q_m`` is joint m's transform: its rotation
  (``d(Rz^T x)/dq = -e_z x Rz^T x`` on the incoming velocity, acceleration and angular
  acceleration; ``d(Rz x)/dq = Rz (e_z x x)`` on the wrench link m passes to link m-1), or for a
  prismatic joint its translation ``t = t0 + C e_z q``; on ``qd_m`` the velocity terms of link m.
* ``tau_derivatives``: one adjoint sweep per output ``tau_i`` (the adjoints of link i's
  wrench carried up the chain, then the adjoints of every link's w, w', a carried down)
  gives row i of both ``dtau/dq`` and ``dtau/dqd`` as dot products with these seeds. The
  sweep is written once, for the gradient of ``sum_i s_i tau_i`` with weights s: a row of
  the identity gives row i (its zeros fold away links outside i's subtree).
* the C single calls run that weighted sweep as a lane program
  (:class:`kindyngen.algorithms.symbolic.LaneSweep`): the quantities of the Newton-Euler pass
  once, then one lane per row, each seeded with a row of the identity (a constant table),
  weighting the sweep by that row (``tau_derivatives``) or, at ``qdd = fd``, by the row of
  ``-M^-1`` it first solves from M's factor (``fd_derivatives``: row l of ``dqdd/dx = -M^-1
  dtau/dx`` is the sweep weighted by row l of ``-M^-1``; no product with ``M^-1`` afterwards,
  and that row is also row l of the ``Minv`` output), every lane the same arithmetic in one
  loop that compilers vectorise across lanes. It executes more
  operations than the scalar programs below (each lane covers the whole chain), in fewer
  instructions: lwr4 on AVX2, tau_derivatives 1.4x and fd_derivatives 1.6x faster
  (docs/latency.md, "Lane programs").
* ``fd_derivatives``: there ``qdd = fd(q, qd, tau)`` is a deep expression, and any sweep that
  multiplies through it makes symengine's CSE run for minutes, so tau's linearity in qdd is
  used: ``dtau/dq = d(c + g)/dq + sum_k dM_ik/dq_j qdd_k``, ``d(c + g)/dq`` by one forward
  (tangent) sweep per ``q_m`` on the bias pass, ``dM/dq`` by ``se.diff`` of the
  composite-rigid-body M (cheap: M has no velocities), and ``dtau/dqd = 2 S(q, qd)`` from the
  Christoffel symbols of these same partials: ``c_i = sum_jk Gamma_ijk qd_j qd_k`` with
  ``Gamma_ijk = 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i)`` symmetric in j, k, so
  ``dc_i/dqd_j = 2 sum_k Gamma_ijk qd_k``. Then ``dqdd/dx = -M^-1 dtau/dx`` (differentiating
  ``tau(q, qd, fd(q, qd, tau)) = tau``), with ``M`` including the armature, factorised once,
  ``M = L D L^T`` as in :mod:`kindyngen.algorithms.ldlt`; that factorisation gives ``qdd``,
  the columns of ``M^-1`` and of the products.
* joint effects: viscous friction adds ``fv_i`` to ``dtau_i/dqd_i``; smoothed Coulomb friction
  ``fc_i tanh(qd_i / eps)`` adds its derivative; the sign form adds 0 (its derivative wherever
  it has one, ``qd_i != 0``); offset and armature are constant in q and qd.

Candidates measured (add / mul after CSE, numeric LWR; Panda in brackets where taken), for
``tau_derivatives``: ``se.diff`` of the whole Newton-Euler DAG in q and qd 3939 / 4350;
``se.diff`` in q plus ``2 S`` 2889 / 3247 (Panda 3694 / 3678); tangent sweeps in q and in qd
2429 / 3034; tangent sweeps in q plus ``2 S`` 2061 / 2451 (2423 / 2733); adjoint sweeps
1809 / 2314 (2094 / 2627, kept; the gradient of ``l . (w x (w x h))`` as two cross products
instead of dot products: 1868 / 2390). For ``fd_derivatives``: ``se.diff`` of ``c + g`` plus
``dM qdd`` and ``2 S`` 3841 / 4353 (4635 / 4778); tangent sweeps of the bias plus ``dM qdd`` and ``2 S``
3030 / 3580 (3398 / 3875, kept); adjoint sweeps of the bias plus ``dM qdd`` 3234 / 4015;
tangent sweeps in qd instead of ``2 S`` 3840 / 4717; ``dM`` from the tangents' qdd
coefficients 5463 / 6272; tangent or adjoint sweeps through ``qdd = fd`` itself: CSE did not
finish in 2 minutes.

Worked example, the planar two-link arm with unit masses at the link ends and unit lengths,
``M = [[3 + 2 cos q1, 1 + cos q1], [1 + cos q1, 1]]``:

>>> import symengine as se
>>> q, qd = se.symbols("q0 q1"), se.symbols("qd0 qd1")
>>> M = [[3 + 2 * se.cos(q[1]), 1 + se.cos(q[1])], [1 + se.cos(q[1]), 1]]
>>> D = coriolis_velocity_jacobian(mass_matrix_partials(M, q), qd)
>>> [[se.expand(e) for e in row] for row in D]
[[-2*sin(q1)*qd1, -2*sin(q1)*qd0 - 2*sin(q1)*qd1], [2*sin(q1)*qd0, 0]]

which is the derivative of ``c = (-sin q1 (2 qd0 qd1 + qd1^2), sin q1 qd0^2)``.
"""
from __future__ import annotations

from dataclasses import replace

import symengine as se

from .joint_frame_steps import mat3, u_matrix
from .ldlt import ldlt_factor, ldlt_substitute
from .effect_torques import (additive_derivatives, has_load_friction, joint_torque_derivatives,
                             transmitted_derivatives, transmitted_torques, with_armature)
from .kinematics_conventions import q_port
from .rigid_bodies import (ZERO, cross, dot, flat, matvec, qd_port, qdd_port,
                           tau_port, vadd, vscale)
from ..model.robot_model import RobotModel
from .dynamics import NewtonEulerPass, crba, dynamics_function, setup
from .symbolic import LaneSweep, Port, SymbolicFunction, port_symbols


# ----------------------------------------------------------------------------- derivatives

def mass_matrix_partials(M, q):
    """``dM[k][i][j] = dM_ij / dq_k`` by ``se.diff`` on the DAG (each symmetric pair once)."""
    n = len(q)
    dM = [[[None] * n for _ in range(n)] for _ in range(n)]
    for i in range(n):
        for j in range(i, n):
            for k in range(n):
                dM[k][i][j] = dM[k][j][i] = se.diff(M[i][j], q[k])
    return dM


def coriolis_velocity_jacobian(dM, qd):
    """``dc/dqd = 2 S`` from the partials of M: ``Mdot + G - G^T`` with
    ``Mdot_ij = sum_k dM_ij/dq_k qd_k`` and ``G_ij = sum_k dM_ik/dq_j qd_k``."""
    n = len(qd)
    Mdot = [[se.Add(*(dM[k][i][j] * qd[k] for k in range(n))) for j in range(n)] for i in range(n)]
    G = [[se.Add(*(dM[j][i][k] * qd[k] for k in range(n))) for j in range(n)] for i in range(n)]
    return [[Mdot[i][j] + G[i][j] - G[j][i] for j in range(n)] for i in range(n)]


def with_diagonal(A, diagonal):
    """A (nested lists) with ``diagonal`` added on its diagonal (exact zeros skipped)."""
    out = [list(row) for row in A]
    for i, d in enumerate(diagonal):
        if d != 0:
            out[i][i] = out[i][i] + d
    return out


def inverse_from_ldlt(L, inv_d):
    """``M^-1`` (nested lists, symmetric) from the factors of :func:`ldlt_factor`: column k
    solves ``M x = e_k`` (the zeros of e_k fold away); entries i >= k are kept and mirrored."""
    n = len(inv_d)
    out = [[None] * n for _ in range(n)]
    for k in range(n):
        column = ldlt_substitute(L, inv_d, [se.Integer(1 if i == k else 0) for i in range(n)])
        for i in range(k, n):
            out[i][k] = out[k][i] = column[i]
    return out


def solve_columns(L, inv_d, B):
    """``-M^-1 B`` column by column from the factors (``B`` nested lists, n x m)."""
    n, m = len(B), len(B[0])
    columns = [ldlt_substitute(L, inv_d, [-B[i][j] for i in range(n)]) for j in range(m)]
    return [[columns[j][i] for j in range(m)] for i in range(n)]


# ----------------------------------------------------------------------------- tangent Newton-Euler

class _NewtonEuler(NewtonEulerPass):
    """:class:`kindyngen.algorithms.dynamics.NewtonEulerPass` with the sweeps of
    :meth:`tangent` and :meth:`adjoint` over its intermediates."""

    def seed(self, m: int):
        """The tangents ``(dw, dw', da)`` of link m's velocity, angular and linear
        acceleration per unit ``q_m``: the only explicit dependence on ``q_m`` is joint m's
        transform, its rotation ``Rz^T`` (``d(Rz^T x)/dq = -e_z x Rz^T x``, on the incoming
        vectors, reusing the rotated vectors themselves) or, prismatic, its translation ``t =
        t0 + C e_z q`` (in the incoming ``a + U t``)."""
        joint, zero = self.joints[m], [ZERO] * 3
        if joint.prismatic:
            parent = self.parents[m]
            if parent < 0 or self.U[parent] is None:      # the parent does not turn: U = 0
                return zero, zero, zero
            return zero, zero, joint.rot_t(mat3(self.U[parent], [joint.C[r][2] for r in range(3)]))
        wr, wdr, ar = self.wr[m], self.wdr[m], self.ar[m]
        qdm = self.qd[m] if self.qd is not None else ZERO
        return [wr[1], -wr[0], ZERO], [wdr[1] - qdm * wr[0], -wdr[0] - qdm * wr[1], ZERO], [ar[1], -ar[0], ZERO]

    def tangent(self, m: int) -> list:
        """``d tau / d q_m`` for all joints: one forward (tangent) sweep from link m's
        :meth:`seed` over the links below m (the others carry no tangent), then backward over
        the whole tree, where joint m also turns the wrench it passes to its parent,
        ``d(Rz x)/dq = Rz (e_z x x)`` (prismatic: moves its origin)."""
        joints, bodies, qd = self.joints, self.bodies, self.qd
        n = len(joints)
        zero = [ZERO] * 3
        below = self.subtree(m)
        tangents, dforces = {}, {}
        for k in sorted(below):
            if k == m:
                dw, dwd, da = self.seed(m)
            else:
                joint = joints[k]
                pw, pwd, pa, dU = tangents[self.parents[k]]
                da = joint.rot_t(vadd(pa, mat3(dU, joint.t)))
                dwr, dwdr = joint.rot_t(pw), joint.rot_t(pwd)
                qdk = qd[k] if qd is not None else ZERO
                if joint.prismatic:
                    dw, dwd = dwr, dwdr
                    da = [da[0] + 2 * qdk * dw[1], da[1] - 2 * qdk * dw[0], da[2]]
                else:
                    dw = dwr
                    dwd = [dwdr[0] + qdk * dwr[1], dwdr[1] - qdk * dwr[0], dwdr[2]]
            w = self.w[k]
            dU = u_matrix(dw, dwd, _product_tangents(w, dw))
            tangents[k] = (dw, dwd, da, dU)
            body = bodies[k]
            h, I = body.h, body.I
            dforces[k] = (vadd(vscale(body.m, da), mat3(dU, h)),
                          vadd(mat3(I, dwd), cross(dw, self.Iw[k]), cross(w, mat3(I, dw)), cross(h, da)))
        out = [None] * n
        wrenches = [None] * n
        for k in range(n - 1, -1, -1):
            dF, dN = dforces.get(k, (zero, zero))
            dfs, dns = [dF], [dN]
            for c in self.children[k]:
                joint = joints[c]
                df, dnn = wrenches[c]
                dfr, dnnr = joint.rot(df), joint.rot(dnn)
                extra = zero
                if c == m:
                    f, nn = self.f[m], self.nn[m]
                    if joint.prismatic:
                        extra = cross([joint.C[r][2] for r in range(3)], joint.rot(f))
                    else:
                        dfr = vadd(dfr, _rot_ez_cross(joint, f))
                        dnnr = vadd(dnnr, _rot_ez_cross(joint, nn))
                dfs.append(dfr)
                dns += [dnnr, cross(joint.t, dfr), extra]
            wrenches[k] = (vadd(*dfs), vadd(*dns)) if self.children[k] else (dF, dN)
            df, dnn = wrenches[k]
            out[k] = df[2] if joints[k].prismatic else dnn[2]
        return out

    def adjoint(self, seeds) -> tuple[list, list]:
        """``sum_i seeds[i] * (row i of dtau/dq, row i of dtau/dqd)``: one reverse sweep from the
        weighted torques (seeds a row of the identity: row i of both; symbols: the program that
        the C runs once per lane, :class:`kindyngen.algorithms.symbolic.LaneSweep`).

        Down the tree from the root, the adjoints ``(lf, ln)`` of the wrench of each link k in
        frame k (``lf_k = R^T (lf_p + ln_p x t)``, ``ln_k = R^T ln_p``, p its parent, plus
        ``seeds[k]`` on its joint's axis: the wrench link k passes on holds those of its
        subtree); back up to the root, the adjoints ``(Lw, Lwd, La)`` of each link's w, w', a:
        from its own force ``F = m a + w' x h + w x (w x h)``, ``N = I w' + w x I w + h x a``
        (``d(l . (w x (w x h)))/dw = l (w.h) + h (l.w) - 2 (l.h) w``, ``d(l . (w x I w))/dw =
        I w x l + I (l x w)``) plus those carried back from its children through their
        rotations, velocity terms and the ``U t`` of their origins' acceleration. Column m is
        then these adjoints dotted with the :meth:`seed` of link m (q) and with its velocity
        terms (qd), plus joint m turning the wrench it passes to its parent: ``lf_m . (e_z x
        f_m) + ln_m . (e_z x n_m)`` (prismatic: the moving origin, ``ln_m . (e_z x f_m)``),
        to which m's own seed, on e_z, adds nothing. With a unit seed the zeros fold: links
        outside the seeded joint's subtree carry no wrench adjoint."""
        joints, bodies, qd = self.joints, self.bodies, self.qd
        n = len(joints)
        zero = [ZERO] * 3
        lf, ln = [None] * n, [None] * n
        for k in range(n):
            joint, p = joints[k], self.parents[k]
            if p >= 0:
                lf[k] = joint.rot_t(vadd(lf[p], cross(ln[p], joint.t)))
                ln[k] = joint.rot_t(ln[p])
            else:
                lf[k], ln[k] = zero, zero
            if joint.prismatic:
                lf[k] = [lf[k][0], lf[k][1], lf[k][2] + seeds[k]]
            else:
                ln[k] = [ln[k][0], ln[k][1], ln[k][2] + seeds[k]]
        dq, dqd = [None] * n, [None] * n
        carried = [[] for _ in range(n)]
        for k in range(n - 1, -1, -1):
            joint, body = joints[k], bodies[k]
            w = self.w[k]
            parts = carried[k]
            if len(parts) == 1:
                Lw, Lwd, La = parts[0]
            elif parts:
                Lw, Lwd, La = (vadd(*(part[r] for part in parts)) for r in range(3))
            else:
                Lw = Lwd = La = zero
            F, N, h, I = lf[k], ln[k], body.h, body.I
            La = vadd(La, vscale(body.m, F), cross(N, h))
            Lwd = vadd(Lwd, cross(h, F), mat3(I, N))
            Lw = vadd(Lw, vscale(dot(w, h), F), vscale(dot(F, w), h), vscale(-2 * dot(F, h), w),
                      cross(self.Iw[k], N), mat3(I, cross(N, w)))
            wr, qdk = self.wr[k], qd[k] if qd is not None else ZERO
            dw, dwd, da = self.seed(k)
            f, nn = self.f[k], self.nn[k]
            if joint.prismatic:
                turned = ln[k][1] * f[0] - ln[k][0] * f[1]
                dqd[k] = 2 * (La[0] * w[1] - La[1] * w[0])
            else:
                turned = lf[k][1] * f[0] - lf[k][0] * f[1] + ln[k][1] * nn[0] - ln[k][0] * nn[1]
                dqd[k] = Lw[2] + Lwd[0] * wr[1] - Lwd[1] * wr[0]
            dq[k] = se.Add(dot(Lw, dw), dot(Lwd, dwd), dot(La, da), turned)
            p = self.parents[k]
            if p >= 0:
                if joint.prismatic:
                    Lwr = vadd(Lw, [-2 * qdk * La[1], 2 * qdk * La[0], ZERO])
                else:
                    Lwr = vadd(Lw, [-qdk * Lwd[1], qdk * Lwd[0], ZERO])
                t, wp = joint.t, self.w[p]
                La = joint.rot(La)
                Lwd = vadd(joint.rot(Lwd), cross(t, La))
                Lw = vadd(joint.rot(Lwr), vscale(dot(wp, t), La), vscale(dot(La, wp), t), vscale(-2 * dot(La, t), wp))
                carried[p].append((Lw, Lwd, La))
        return dq, dqd


def _columns(columns):
    """Nested-list matrix whose column j is ``columns[j]``."""
    return [list(row) for row in zip(*columns)]






def _product_tangents(w, dw):
    """Tangents of (xx, yy, zz, xy, xz, yz) of :func:`kindyngen.algorithms.joint_frame_steps.omega_products`."""
    (x, y, z), (dx, dy, dz) = w, dw
    return 2 * x * dx, 2 * y * dy, 2 * z * dz, dx * y + x * dy, dx * z + x * dz, dy * z + y * dz




def _rot_ez_cross(joint, v):
    """``d(R v)/dq = C Rz (e_z x v) = C (e_z x Rz v)``, sharing ``Rz v`` with ``R v``."""
    x, y, z = v
    rx, ry = joint.c * x - joint.s * y, joint.s * x + joint.c * y
    return matvec(joint.C, [-ry, rx, ZERO])


# ----------------------------------------------------------------------------- ports

def _matrix_unit(model: RobotModel, row: tuple[str, str], column: tuple[str, str], revolute: str) -> str:
    """Unit of a matrix d(row quantity)/d(column quantity) over the joints: ``revolute`` when
    every joint is revolute, otherwise entry (i, j) is row i's unit per column j's unit."""
    if all(not j.prismatic for j in model.joints):
        return revolute
    moving = ", ".join(str(i) for i, j in enumerate(model.joints) if j.prismatic)
    return (f"{revolute} between revolute joints; entry (i, j) is {row[0]} (revolute joint i) or {row[1]} "
            f"(prismatic) per {column[0]} (revolute joint j) or {column[1]} (prismatic); prismatic joints "
            f"{moving} (0-based)")


TORQUE, ANGLE, RATE, ACCEL = ("N m", "N"), ("rad", "m"), ("rad/s", "m/s"), ("rad/s^2", "m/s^2")


def _conventions_note(model: RobotModel) -> str:
    note = (" Matrices are row-major, row i the output of joint i, column j the input of joint j "
            "(d out_i / d in_j).")
    if any(model.friction(i).coulomb != 0 for i in range(model.n)) and model.coulomb_smoothing is None:
        note += (" The Coulomb term fc sign(qd) contributes 0 to the qd derivatives (its derivative "
                 "wherever it has one, qd != 0).")
    return note


# ----------------------------------------------------------------------------- functions

def _fixed_base_setup(model: RobotModel, params: str):
    """The tree setup the sweeps run on: a fixed base (a floating base's six coordinates have
    no sweep here)."""
    if model.floating_base:
        raise ValueError(f"{model.name}: the derivatives are derived for a fixed base")
    return setup(model, params)


def tau_derivatives(model: RobotModel, params: str = "numeric", name: str = "tau_derivatives") -> SymbolicFunction:
    """``tau_derivatives(q, qd, qdd) -> dtau_dq, dtau_dqd`` of ``tau`` with its joint effects."""
    ts = _fixed_base_setup(model, params)
    q = ts.q
    n = model.n
    qd, qdd = port_symbols("qd", (n,)), port_symbols("qdd", (n,))
    ne = _NewtonEuler(ts, qd, qdd)
    rows = [ne.adjoint(_unit(i, n)) for i in range(n)]
    dq, dqd = [row[0] for row in rows], [row[1] for row in rows]
    if has_load_friction(model):
        # tau = y + fl |y| s + a: row i of dy/dx times 1 + fl s sign(y_i), then a's diagonal
        y = [t + se.sympify(model.armature(i)) * qdd[i] if model.armature(i) != 0 else t
             for i, t in enumerate(ne.tau)]
        factor, diag_q, diag_qd = joint_torque_derivatives(model, y, q, qd)
        dq = [[factor[i] * e for e in row] if factor[i] != 1 else row for i, row in enumerate(dq)]
        dqd = [[factor[i] * e for e in row] if factor[i] != 1 else row for i, row in enumerate(dqd)]
        lanes = None        # the row factors depend on the state: the identity seeds would not stay constant
    else:
        diag_q, diag_qd = additive_derivatives(model, q, qd)
        lanes = _lane_sweep(model, ne, diagonal=(diag_q, diag_qd))
    dq, dqd = with_diagonal(dq, diag_q), with_diagonal(dqd, diag_qd)
    f = dynamics_function(
        name, "Partial derivatives of the inverse dynamics tau(q, qd, qdd) (the function tau, effects included): "
        "dtau/dq and dtau/dqd by one adjoint (reverse) sweep per joint over the Newton-Euler pass (plus the "
        + ("effects' derivatives on the diagonals); dtau/dqdd is M" if _position_dependent(model) else
           "friction derivative on the diagonal of dtau/dqd); dtau/dqdd is M")
        + (", each row times 1 + fl s sign(y) (load-dependent friction)." if has_load_friction(model) else "."),
        ts, (q_port(model), qd_port(model), qdd_port(model)), (q, qd, qdd),
        (Port("dtau_dq", (n, n), "dtau_i / dq_j (row-major)", _matrix_unit(model, TORQUE, ANGLE, "N m/rad")),
         Port("dtau_dqd", (n, n), "dtau_i / dqd_j (row-major)", _matrix_unit(model, TORQUE, RATE, "N m s/rad"))),
        (flat(dq), flat(dqd)))
    return _with_note(replace(f, lanes=lanes), model)


def _unit(i: int, n: int) -> tuple:
    return tuple(se.Integer(1 if k == i else 0) for k in range(n))


def _lane_sweep(model: RobotModel, ne: "_NewtonEuler", stages=(), factor=None, minv_port=None,
                diagonal=None) -> LaneSweep:
    """:meth:`_NewtonEuler.adjoint` weighted by lane as a lane program: lane l, seeded with row
    l of the identity, gives row l of the ports dq (0) and dqd (1), the effects' derivatives
    ``weight_k diagonal[0][k]`` on column k of dtau/dq and ``weight_k diagonal[1][k]`` on
    column k of dtau/dqd (``diagonal``: per joint, the effect torque's derivatives by its own
    q and qd). With ``factor`` (the ``(L,
    inv_d)`` of :func:`kindyngen.algorithms.ldlt.ldlt_factor`) the weights are row l of
    ``-M^-1``, solved from the factor in the lane itself, and ``minv_port`` (if given) gets
    row l of ``M^-1``: the seeds stay a constant table, which compilers vectorise the loop
    over (clang 14 does not when the seeds are a table filled at run time)."""
    n = model.n
    seeds = tuple(se.Symbol(f"_seed{k}") for k in range(n))
    weights = seeds if factor is None else tuple(-x for x in ldlt_substitute(*factor, list(seeds)))
    dq, dqd = ne.adjoint(weights)
    diag_q, diag_qd = diagonal
    dq = [d + weights[k] * diag_q[k] if diag_q[k] != 0 else d for k, d in enumerate(dq)]
    dqd = [d + weights[k] * diag_qd[k] if diag_qd[k] != 0 else d for k, d in enumerate(dqd)]
    exprs = tuple(dq) + tuple(dqd)
    places = tuple((0, k, n) for k in range(n)) + tuple((1, k, n) for k in range(n))
    if minv_port is not None:
        exprs += tuple(-w for w in weights)
        places += tuple((minv_port, k, n) for k in range(n))
    return LaneSweep(seeds=seeds, values=tuple(_unit(i, n) for i in range(n)), exprs=exprs, places=places,
                     stages=tuple(stages))


def fd_derivatives(model: RobotModel, params: str = "numeric", name: str = "fd_derivatives",
                   with_minv: bool = True) -> SymbolicFunction:
    """``fd_derivatives(q, qd, tau) -> dqdd_dq, dqdd_dqd[, Minv]`` of ``fd`` with its joint
    effects (``Minv`` left out with ``with_minv=False``: its n columns through the factor are
    then not formed)."""
    ts = _fixed_base_setup(model, params)
    q = ts.q
    n = model.n
    qd, tau = port_symbols("qd", (n,)), port_symbols("tau", (n,))
    M = crba(ts)[0]
    L, inv_d = ldlt_factor(with_armature(model, M))
    rigid_bias = _NewtonEuler(ts, qd, None)
    applied = transmitted_torques(model, tau, q, qd)
    qdd = ldlt_substitute(L, inv_d, [t - b for t, b in zip(applied, rigid_bias.tau)])
    dM = mass_matrix_partials(M, q)
    dbias = _columns([rigid_bias.tangent(m) for m in range(n)])
    dq = [[se.Add(dbias[i][j], *(dM[j][i][k] * qdd[k] for k in range(n))) for j in range(n)] for i in range(n)]
    dqd = coriolis_velocity_jacobian(dM, qd)
    diagonal = transmitted_derivatives(model, tau, q, qd)
    dq, dqd = with_diagonal(dq, diagonal[0]), with_diagonal(dqd, diagonal[1])
    ddq, ddqd = solve_columns(L, inv_d, dq), solve_columns(L, inv_d, dqd)
    ports = [Port("dqdd_dq", (n, n), "dqdd_i / dq_j (row-major)", _matrix_unit(model, ACCEL, ANGLE, "1/s^2")),
             Port("dqdd_dqd", (n, n), "dqdd_i / dqd_j (row-major)", _matrix_unit(model, ACCEL, RATE, "1/s"))]
    outputs = [flat(ddq), flat(ddqd)]
    m_inv = inverse_from_ldlt(L, inv_d)
    if with_minv:
        ports.append(Port("Minv", (n, n), "inverse joint-space inertia matrix M^-1 = dqdd/dtau (symmetric, row-major)",
                          _matrix_unit(model, ACCEL, TORQUE, "1/(kg m^2)")))
        outputs.append(flat(m_inv))
        products, minv = "M^-1 and the products", "dqdd/dtau is Minv"
    else:
        products, minv = "the products", "dqdd/dtau is M^-1, not formed here (the function fd_derivatives has it)"
    # the lanes: row l of dqdd/dx = -(row l of M^-1) dtau/dx is the adjoint sweep weighted by
    # that row, at qdd = fd named once (a sweep through fd's expression is too deep for CSE)
    named = tuple(se.Symbol(f"_qdd{k}") for k in range(n))
    lanes = _lane_sweep(model, _NewtonEuler(ts, qd, named), tuple(zip(named, qdd)), (L, inv_d),
                        2 if with_minv else None, diagonal)
    f = dynamics_function(
        name, "Partial derivatives of the forward dynamics qdd = fd(q, qd, tau) (the function fd, effects "
        "included): dqdd/dx = -M^-1 dtau/dx at qdd = fd(q, qd, tau), with dtau/dq = d(c + g)/dq (one tangent "
        "sweep per joint over the Newton-Euler pass) + dM/dq qdd, dtau/dqd = 2 S(q, qd) (Christoffel symbols) "
        f"plus the {'effects' if _position_dependent(model) else 'friction'} derivative"
        f"{'s (ripple on dtau/dq)' if _position_dependent(model) else ''}, and {products} from one unrolled LDL^T factorisation of M (no "
        f"square roots); {minv}.",
        ts, (q_port(model), qd_port(model), tau_port(model, "applied joint torques")), (q, qd, tau),
        tuple(ports), tuple(outputs))
    return _with_note(replace(f, lanes=lanes), model)


def _position_dependent(model: RobotModel) -> bool:
    """Whether an effect depends on q (the ripple) or is load-dependent: the headers say so."""
    return any(e in model.effects for e in ("position_ripple", "load_dependent_friction"))


def _with_note(f: SymbolicFunction, model: RobotModel) -> SymbolicFunction:
    return replace(f, conventions=f.conventions + _conventions_note(model))
