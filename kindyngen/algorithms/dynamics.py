"""Dynamics of every robot, a kinematic tree with a fixed or floating base (a serial arm is
the tree whose parent of joint j is j - 1), derived symbolically in joint frames with the
primitives of :mod:`kindyngen.algorithms.joint_frame_steps`; one recursion per algorithm, for arms
and trees alike, in both inertial-parameter modes ("numeric": the description's values;
"symbolic": the input ``p`` of 10 barycentric parameters per body, a floating base's root
body first) and with the description's joint effects (friction and offset in tau and fd's
bias, the armature on M's diagonal):

* **Joint frames.** Joint j's frame is placed on its parent's joint frame by an exact
  constant rotation ``C_j`` and translation ``t_j`` (``after_parent * before_j``), so every
  joint axis is e_z (:class:`kindyngen.algorithms.rigid_bodies.JointFrame`); the root body's frame is
  the root link's frame.
* **Grouped parameters.** Each revolute joint's link hands its rotation-invariant part
  (m, MZ, YY) to its parent (a prismatic one its rotational inertia), tip first: M, c, g
  and tau are exactly unchanged, and most link masses vanish. With a floating base the
  parts reach the root body, which keeps everything; with a fixed base they are dropped
  from the dynamics (the root does not move) but kept for the centre of mass.
* **Floating base** (Pinocchio's free-flyer layout): ``q[0:3]`` base position and
  ``q[3:7]`` unit quaternion (x, y, z, w) of the base orientation R in the world; ``qd[0:6]``
  the base twist (linear velocity of the base origin, angular velocity) in the base frame,
  ``qdd[0:6]`` its derivative (the spatial acceleration in body coordinates). Only gravity
  depends on the base pose: the world's gravity is turned into the base frame by R^T. The
  base's entries of tau are the wrench (force, then moment about the base origin) the base
  needs, in the base frame.
* **tau** by recursive Newton-Euler in O(n); **g** by composite first moments; **c** =
  tau(q, qd, 0) without gravity; **M** by composite rigid bodies, each column carried up
  its own branch only (O(n d), d the depth); **fd** by ``M = L^T D L`` with L as sparse as
  the tree (Featherstone's LTDL, O(n d^2), no fill-in), see :func:`tree_ldlt_solve` (the
  catalog sets the articulated-body route of :mod:`kindyngen.algorithms.articulated_body` beside it and
  keeps the cheaper).
* **Named intermediates.** Each recursion names its per-body quantities in a
  :class:`kindyngen.algorithms.symbolic.Stages` (states, summed wrenches, composites, carried columns,
  factor entries): CSE then stays linear in the code it produces.
* **Centroidal quantities** come out of M's base rows: with a floating base ``M[0:6, :]
  qd`` is the spatial momentum about the base origin in the base frame (with a fixed base
  the same rows are the root wrenches CRBA carries its columns to). The centre of mass is
  ``c = p + R h/m`` (h, m the composite first moment and mass at the root), its Jacobian
  ``R M[0:3, :] / m`` and the centroidal momentum matrix ``Ag = [R M_lin; R (M_ang -
  [c_b]x M_lin)]`` (world-aligned axes at the CoM: Pinocchio's ``ccrba``). With a fixed base
  the root link is not counted (as in Pinocchio: it is the universe).

Example: the two pendulums on a floating body of :mod:`kindyngen.readers.urdf`:

>>> from kindyngen.readers.urdf import parse_urdf
>>> from kindyngen.readers.urdf import TWO_PENDULUMS
>>> tree = parse_urdf(TWO_PENDULUMS, floating_base=True)
>>> f = inverse_dynamics_tree(tree)
>>> [(p.name, p.shape) for p in f.inputs], f.outputs[0].shape
([('q', (9,)), ('qd', (8,)), ('qdd', (8,))], (8,))
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import symengine as se

from .joint_frame_steps import joint_step, mat3, omega_products, rotate_body, u_matrix
from .ldlt import tree_ldlt_solve
from .geometry import constant_parts, exact, joint_cos_sin
from .kinematics_conventions import joint_units, q_port
from ..model.placement import Placement
from .effect_torques import joint_torques, transmitted_torques, with_armature
from .rigid_bodies import (ZERO, Body, JointFrame, conventions as arm_conventions, cross, inertials, qd_port, qdd_port,
                           root_inertials, vadd, vscale)
from .symbolic import Port, Stages, SymbolicFunction, naming, port_symbols
from ..model.robot_model import FREE_FLYER_NV, RobotModel

ROUTE = "Newton-Euler family over the tree (joint frames, grouped parameters): "


# ----------------------------------------------------------------------------- ports

def force_port(model: RobotModel, name: str, what: str) -> Port:
    text = (f"base {what} (force, then moment about the base origin) in the base frame, then joint {what}s"
            if model.floating_base else f"joint {what}s")
    return Port(name, (model.nv,), text, ("N, N m, " if model.floating_base else "") + joint_units(model, "N m", "N"))


def conventions(model: RobotModel, params: str = "numeric") -> str:
    """The text every dynamics header carries (an arm's: :func:`kindyngen.algorithms.rigid_bodies.conventions`)."""
    if not model.is_tree:
        return arm_conventions(model, params)
    gx, gy, gz = (float(v) for v in model.gravity)
    base = ("Floating base (Pinocchio's free-flyer layout): q = base position, unit quaternion (x, y, z, w), "
            "joints; qd, qdd and tau start with the base's 6 entries (linear, angular) in the base frame. "
            if model.floating_base else f"Fixed base: the root link '{model.base_name}' does not move. ")
    return (f"{base}Joints in {model.order_text}. Equation of motion: tau = M(q) qdd + c(q, qd) + g(q). "
            f"Gravity in the {'world' if model.floating_base else 'root'} frame: ({gx:g}, {gy:g}, {gz:g}) m/s^2. "
            + (PARAMETERS_INPUT.format(root="the root body's (base frame), then " if model.floating_base else "")
               if params == "symbolic" else "Inertial parameters: the robot description's values, baked in."))


PARAMETERS_INPUT = ("Inertial parameters: input p, 10 per body, {root}each joint's link in joint order (its link "
                    "frame): m, m*cx, m*cy, m*cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz (inertia about the link frame origin, "
                    "link-frame axes; Pinocchio's model.inertias[1:] by toDynamicParameters).")


# ----------------------------------------------------------------------------- the tree in joint frames

@dataclass(frozen=True)
class TreeSetup:
    """What every tree derivation starts from: the joint frames, the grouped bodies in them,
    the root body (all of it with a floating base; with a fixed base only the parts grouped
    into it, for the centre of mass) and the base pose (None with a fixed base)."""

    model: RobotModel
    q: tuple
    joints: tuple[JointFrame, ...]
    bodies: tuple[Body, ...]
    root: Body
    rotation: list | None        # R (world <- base), 3x3 nested lists, from the quaternion
    position: list | None
    params: str = "numeric"
    param_ports: tuple = ()      # the input p in symbolic mode
    param_symbols: tuple = ()

    def gravity_in_base(self) -> list:
        """The gravity vector in the root frame (R^T gamma with a floating base)."""
        gam = [se.sympify(v) for v in self.model.gravity]
        if self.rotation is None:
            return gam
        R = self.rotation
        return [se.Add(*(R[k][r] * gam[k] for k in range(3))) for r in range(3)]


def quaternion_rotation(x, y, z, w) -> list:
    """The rotation of a unit quaternion (x, y, z, w), as Eigen and Pinocchio build it.

    >>> quaternion_rotation(0, 0, 0, 1)
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    """
    xx, yy, zz = 2 * x * x, 2 * y * y, 2 * z * z
    xy, xz, yz, wx, wy, wz = 2 * x * y, 2 * x * z, 2 * y * z, 2 * w * x, 2 * w * y, 2 * w * z
    return [[1 - yy - zz, xy - wz, xz + wy], [xy + wz, 1 - xx - zz, yz - wx], [xz - wy, yz + wx, 1 - xx - yy]]


def joint_frames(model: RobotModel, joint_q) -> tuple[JointFrame, ...]:
    """Each joint's frame on its parent's joint frame (the root: the root link frame)."""
    out = []
    for joint, parent, qj in zip(model.joints, model.parents, joint_q):
        above = model.joints[parent].after if parent >= 0 else Placement()
        C, t = constant_parts(above * joint.before)
        if joint.prismatic:
            slide = qj + exact(joint.offset)
            out.append(JointFrame(C=C, t=[t[r] + C[r][2] * slide for r in range(3)], c=se.Integer(1), s=ZERO,
                                  prismatic=True))
        else:
            c, s = joint_cos_sin(qj, joint.offset)
            out.append(JointFrame(C=C, t=t, c=c, s=s))
    return tuple(out)


def frame_body(values, after: Placement | None = None) -> Body:
    """A body from its 10 barycentric parameters (m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz
    in its link frame), seen from the joint frame (``after``: the link frame's placement
    there; None or the identity for the root)."""
    m, mx, my, mz, ixx, ixy, iyy, ixz, iyz, izz = (se.sympify(v) for v in values)
    body = Body(m, [mx, my, mz], [[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    if after is None or after.is_identity:
        return body
    return body.moved(*constant_parts(after))


def grouped(model: RobotModel, joints, bodies, root: Body) -> tuple[list[Body], Body]:
    """Hand each link's rotation-invariant part to its parent, tip first (module text);
    returns the bodies and the root body with the parts that reached it."""
    bodies = list(bodies)
    zero3 = [[ZERO] * 3 for _ in range(3)]
    for j in range(model.n - 1, -1, -1):
        b, frame, parent = bodies[j], joints[j], model.parents[j]
        if frame.prismatic:
            bodies[j] = Body(b.m, list(b.h), zero3)
            part = Body(ZERO, [ZERO] * 3, b.I).moved(frame.C, [ZERO] * 3)
        else:
            yy, mz = b.I[1][1], b.h[2]
            bodies[j] = Body(ZERO, [b.h[0], b.h[1], ZERO],
                             [[b.I[0][0] - yy, b.I[0][1], b.I[0][2]], [b.I[1][0], ZERO, b.I[1][2]],
                              [b.I[2][0], b.I[2][1], b.I[2][2]]])
            part = Body(b.m, [ZERO, ZERO, mz], [[yy, ZERO, ZERO], [ZERO, yy, ZERO], zero3[2]]).moved(frame.C, frame.t)
        if parent >= 0:
            bodies[parent] = bodies[parent] + part
        else:
            root = root + part
    return bodies, root


@lru_cache(maxsize=8)
def setup(model: RobotModel, params: str = "numeric") -> TreeSetup:
    """Joint frames, grouped bodies and base pose of ``model`` on ``q`` symbols, with the
    inertial parameters of ``params`` ("numeric": the description's, a payload merged into
    the last link; "symbolic": the input ``p`` of 10 barycentric parameters per body, a
    floating base's root body first, grouped expressions collected); cached: every function
    starts from it (its exact constant transforms cost a tenth of a second on a humanoid) and
    nothing changes it. A model with mimic joints is derived as the same tree without them and
    then reduced (:mod:`kindyngen.algorithms.reduced_coordinates`)."""
    if model.has_mimics or model.has_loops:
        raise ValueError(f"{model.name}: mimic joints or loops: derive on model.without_mimics() and reduce "
                         f"(kindyngen.algorithms.reduced_coordinates, loop_closure)")
    q = port_symbols("q", (model.nq,))
    joint_q = q[7:] if model.floating_base else q
    joints = joint_frames(model, joint_q)
    links, ports, syms = inertials(model, params)
    bodies = [frame_body(li.as_vector(), joint.after) for li, joint in zip(links, model.joints)]
    empty = Body(ZERO, [ZERO] * 3, [[ZERO] * 3 for _ in range(3)])
    bodies, root = grouped(model, joints, bodies, frame_body(root_inertials(model, syms)) if model.floating_base else empty)
    if params == "symbolic":
        bodies = [b.collected() for b in bodies]
        root = root.collected() if model.floating_base else root
    rotation = quaternion_rotation(*q[3:7]) if model.floating_base else None
    return TreeSetup(model, q, joints, tuple(bodies), root, rotation, list(q[0:3]) if model.floating_base else None,
                     params, ports, syms)


# ----------------------------------------------------------------------------- algorithms

def wrench(body: Body, a, w, wd, U):
    """Force and moment about the frame origin of a body with origin acceleration a, angular
    velocity w and acceleration wd (``U = skew(wd) + skew(w)^2``, None when both are zero)."""
    h, I, m = body.h, body.I, body.m
    if U is None:
        return vscale(m, a), cross(h, a)
    return (vadd(vscale(m, a), mat3(U, h)), vadd(mat3(I, wd), cross(w, mat3(I, w)), cross(h, a)))


def motion_states(ts: TreeSetup, qd, qdd, with_gravity: bool = True, stages: Stages | None = None, record=None):
    """The forward pass of :func:`rnea`: (root state, state of each joint frame), a state
    being (origin acceleration a, angular velocity w, angular acceleration wd, ``U =
    skew(wd) + skew(w)^2`` or None when w and wd are exact zeros), gravity entering as the
    root's acceleration ``-gamma``; ``qd``/``qdd`` None are zero (Khalil-Kleinfinger form,
    each joint starting from its parent's state). With ``stages``, every joint's state is
    named there; ``record`` (a :class:`NewtonEulerPass`) gets the incoming vectors rotated into
    each joint frame (``ar``, ``wr``, ``wdr``)."""
    model = ts.model
    name = naming(stages)
    base = FREE_FLYER_NV if model.floating_base else 0
    gam = ts.gravity_in_base() if with_gravity else [ZERO] * 3
    a0 = [-x for x in gam]
    w0 = wd0 = [ZERO] * 3
    if model.floating_base and qd is not None:
        v, w0 = list(qd[0:3]), list(qd[3:6])
        a0 = vadd(a0, cross(w0, v))
    if model.floating_base and qdd is not None:
        a0, wd0 = vadd(a0, list(qdd[0:3])), list(qdd[3:6])
    moving = any(x != 0 for x in w0 + wd0)
    root_state = (a0, w0, wd0, u_matrix(w0, wd0, omega_products(w0)) if moving else None)
    state = [None] * model.n
    for j, (joint, parent) in enumerate(zip(ts.joints, model.parents)):
        a, w, wd, U = state[parent] if parent >= 0 else root_state
        a = joint.rot_t(a if U is None else vadd(a, mat3(U, joint.t)))
        wr, wdr = joint.rot_t(w), joint.rot_t(wd)
        if record is not None:
            record.ar.append(a)
            record.wr.append(wr)
            record.wdr.append(wdr)
        a, w, wd = joint_step(joint, a, wr, wdr, qd[base + j] if qd is not None else ZERO,
                              qdd[base + j] if qdd is not None else ZERO)
        a, w, wd = ([name(e) for e in v] for v in (a, w, wd))
        U = u_matrix(w, wd, omega_products(w)) if any(x != 0 for x in w + wd) else None
        state[j] = (a, w, wd, None if U is None else [[name(e) for e in row] for row in U])
    return root_state, state


def rnea(ts: TreeSetup, qd, qdd, with_gravity: bool = True, stages: Stages | None = None) -> list:
    """tau (size nv) by recursive Newton-Euler over the tree (:class:`NewtonEulerPass`);
    ``qd``/``qdd`` None are zero."""
    return NewtonEulerPass(ts, qd, qdd, with_gravity, stages).tau


class NewtonEulerPass:
    """Recursive Newton-Euler over the tree, its intermediates kept per joint j (in frame j):
    the incoming velocity, angular and linear acceleration rotated into frame j (``wr``,
    ``wdr``, ``ar``), the angular velocity ``w``, ``U`` (None where w and w' are exact zeros),
    ``Iw = I w``, the wrench ``f``, ``nn`` link j passes to its parent; ``tau`` (size nv);
    :mod:`kindyngen.algorithms.derivatives_sweeps` sweeps over them (fixed base). Forward:
    :func:`motion_states`; backward: each joint's wrench plus its children's, tip first (with
    ``stages``, every state and summed wrench named there).

    Per link (Khalil-Kleinfinger form, all in frame j): ``U = skew(w') + skew(w)^2`` from the
    six products of w's components; ``F = m a + U h``; ``N = I w' + w x (I w) + h x a``.
    (Variants with cross products for F, or products of w for ``w x I w``, cost more after
    CSE on the LWR and Panda.)"""

    def __init__(self, ts: TreeSetup, qd, qdd, with_gravity: bool = True, stages: Stages | None = None):
        model, n = ts.model, ts.model.n
        name = naming(stages)
        base = FREE_FLYER_NV if model.floating_base else 0
        self.joints, self.bodies, self.parents = ts.joints, ts.bodies, model.parents
        self.children = [[c for c in range(n) if model.parents[c] == j] for j in range(n)]
        self.qd = None if qd is None else list(qd[base:])
        self.ar, self.wr, self.wdr = [], [], []
        root_state, state = motion_states(ts, qd, qdd, with_gravity, stages, self)
        self.w = [s[1] for s in state]
        self.U = [s[3] for s in state]
        self.Iw = [mat3(body.I, s[1]) for body, s in zip(ts.bodies, state)]
        forces = [wrench(body, *s) for body, s in zip(ts.bodies, state)]
        f_parts = [[F] for F, _ in forces]
        n_parts = [[N] for _, N in forces]
        root_f, root_n = [], []
        self.f, self.nn, tau = [None] * n, [None] * n, [None] * n
        for j in range(n - 1, -1, -1):
            joint, parent = ts.joints[j], model.parents[j]
            f, nn = [name(e) for e in vadd(*f_parts[j])], [name(e) for e in vadd(*n_parts[j])]
            self.f[j], self.nn[j] = f, nn
            tau[j] = f[2] if joint.prismatic else nn[2]
            fr, nr = carry(joint, f, nn)
            targets = (f_parts[parent], n_parts[parent]) if parent >= 0 else (root_f, root_n)
            targets[0].append(fr)
            targets[1].append(nr)
        if model.floating_base:
            F, N = wrench(ts.root, *root_state)
            tau = vadd(F, *root_f) + vadd(N, *root_n) + tau
        self.tau = tau

    def subtree(self, j: int) -> frozenset:
        """Joint j and every joint below it."""
        out = {j}
        for k in range(j + 1, len(self.joints)):
            if self.parents[k] in out:
                out.add(k)
        return frozenset(out)


def carry(joint: JointFrame, f, nn):
    """A wrench (force, moment about the origin) in joint frame j seen in its parent's frame."""
    fr = joint.rot(f)
    return fr, vadd(joint.rot(nn), cross(joint.t, fr))


def composites(ts: TreeSetup, stages: Stages | None = None) -> tuple[list[Body], Body]:
    """The composite body of each joint's subtree in its joint frame, and of the whole tree
    in the root frame (the root body included); each named in ``stages`` if given."""
    model = ts.model
    name = naming(stages)
    parts = [[b] for b in ts.bodies]
    root = [ts.root]
    comp = [None] * model.n
    for j in range(model.n - 1, -1, -1):
        comp[j] = _sum_bodies(parts[j], name)
        parent = model.parents[j]
        (parts[parent] if parent >= 0 else root).append(rotate_body(ts.joints[j], comp[j]))
    return comp, _sum_bodies(root, name)


def _sum_bodies(bodies: list[Body], name) -> Body:
    """The sum of ``bodies``, its entries passed through ``name`` (I by its upper triangle)."""
    upper = {(r, c): name(se.Add(*(b.I[r][c] for b in bodies))) for r in range(3) for c in range(r, 3)}
    return Body(name(se.Add(*(b.m for b in bodies))), [name(e) for e in vadd(*(b.h for b in bodies))],
                [[upper[min(r, c), max(r, c)] for c in range(3)] for r in range(3)])


def crba(ts: TreeSetup, stages: Stages | None = None):
    """(M as nv x nv nested lists, the root wrench of every joint column as (f, n), the
    composite of the whole tree at the root). Each column is carried up its branch only:
    entries between joints on different branches are exact zeros. With ``stages``, the
    composites and every carried wrench are named intermediates."""
    model = ts.model
    nv, base = model.nv, FREE_FLYER_NV if model.floating_base else 0
    name = naming(stages)
    comp, whole = composites(ts, stages)
    M = [[ZERO] * nv for _ in range(nv)]
    root_columns = []
    for j in range(model.n):
        body, joint = comp[j], ts.joints[j]
        if joint.prismatic:          # the wrench of a unit acceleration along z
            f, nn = [ZERO, ZERO, body.m], [body.h[1], -body.h[0], ZERO]
            M[base + j][base + j] = f[2]
        else:                        # ... of a unit angular acceleration about z
            f, nn = [-body.h[1], body.h[0], ZERO], [body.I[0][2], body.I[1][2], body.I[2][2]]
            M[base + j][base + j] = nn[2]
        node = j
        while True:
            f, nn = carry(ts.joints[node], f, nn)
            f, nn = [name(e) for e in f], [name(e) for e in nn]
            node = model.parents[node]
            if node < 0:
                break
            M[base + node][base + j] = M[base + j][base + node] = f[2] if ts.joints[node].prismatic else nn[2]
        root_columns.append((f, nn))
    if model.floating_base:
        m, h, I = whole.m, whole.h, whole.I
        hx = [[ZERO, -h[2], h[1]], [h[2], ZERO, -h[0]], [-h[1], h[0], ZERO]]
        for r in range(3):
            for c in range(3):
                M[r][c] = m if r == c else ZERO
                M[3 + r][c] = hx[r][c]
                M[r][3 + c] = -hx[r][c]
                M[3 + r][3 + c] = I[r][c]
        for j, (f, nn) in enumerate(root_columns):
            for r in range(3):
                M[r][base + j] = M[base + j][r] = f[r]
                M[3 + r][base + j] = M[base + j][3 + r] = nn[r]
    return M, root_columns, whole


def gravity_composite(ts: TreeSetup) -> list:
    """g (size nv) from composite first moments carried up the tree: ``g_j = -e_z .
    (h^c_j x gamma_j)`` (a prismatic joint ``-m^c_j gamma_j . e_z``); the floating base's
    entries are the wrench ``(-m gamma, -h x gamma)`` of the whole tree."""
    model = ts.model
    gam0 = ts.gravity_in_base()
    gams = [None] * model.n
    for j, (joint, parent) in enumerate(zip(ts.joints, model.parents)):
        gams[j] = joint.rot_t(gams[parent] if parent >= 0 else gam0)
    h_parts, m_parts = [[b.h] for b in ts.bodies], [[b.m] for b in ts.bodies]
    root_h, root_m = [ts.root.h], [ts.root.m]
    g = [None] * model.n
    for j in range(model.n - 1, -1, -1):
        joint, parent = ts.joints[j], model.parents[j]
        hc, mc = vadd(*h_parts[j]), se.Add(*m_parts[j])
        gj = gams[j]
        g[j] = -mc * gj[2] if joint.prismatic else -(hc[0] * gj[1] - hc[1] * gj[0])
        targets = (h_parts[parent], m_parts[parent]) if parent >= 0 else (root_h, root_m)
        targets[0].extend((joint.rot(hc), vscale(mc, joint.t)))
        targets[1].append(mc)
    if not model.floating_base:
        return g
    hc, mc = vadd(*root_h), se.Add(*root_m)
    return vscale(-mc, gam0) + [-x for x in cross(hc, gam0)] + g


def expanded_parents(model: RobotModel) -> tuple[int, ...]:
    """The parent of each velocity coordinate: the floating base's six form a chain, its
    children hang from the last of them.

    >>> from kindyngen.readers.urdf import parse_urdf
    >>> from kindyngen.readers.urdf import TWO_PENDULUMS
    >>> expanded_parents(parse_urdf(TWO_PENDULUMS, floating_base=True))
    (-1, 0, 1, 2, 3, 4, 5, 5)
    """
    if not model.floating_base:
        return model.parents
    base = FREE_FLYER_NV
    return tuple(range(-1, base - 1)) + tuple(base + p if p >= 0 else base - 1 for p in model.parents)


def centroidal(ts: TreeSetup, root_columns, whole: Body, M):
    """(centre of mass (3), its Jacobian (3 x nv), centroidal momentum matrix (6 x nv)) from
    M's base rows (module text)."""
    model = ts.model
    if model.floating_base:
        lin = [M[r] for r in range(3)]
        ang = [M[3 + r] for r in range(3)]
    else:
        lin = [[f[r] for f, _ in root_columns] for r in range(3)]
        ang = [[nn[r] for _, nn in root_columns] for r in range(3)]
    inv_m = se.Pow(whole.m, -1)
    cb = [x * inv_m for x in whole.h]
    # moments about the CoM: n_G = n_O - c_b x f
    ang_g = [[ang[r][k] - (cb[(r + 1) % 3] * lin[(r + 2) % 3][k] - cb[(r + 2) % 3] * lin[(r + 1) % 3][k])
              for k in range(model.nv)] for r in range(3)]
    R = ts.rotation
    if R is None:
        return cb, [[x * inv_m for x in row] for row in lin], lin + ang_g
    rotate = (lambda rows: [[se.Add(*(R[r][k] * rows[k][c] for k in range(3))) for c in range(model.nv)]
                            for r in range(3)])
    lin_w = rotate(lin)
    com = [ts.position[r] + se.Add(*(R[r][k] * cb[k] for k in range(3))) for r in range(3)]
    return com, [[x * inv_m for x in row] for row in lin_w], lin_w + rotate(ang_g)


# ----------------------------------------------------------------------------- functions

def dynamics_function(name, summary, ts: TreeSetup, inputs, input_symbols, outputs, output_exprs,
                      stages: Stages | None = None, route: str | None = None) -> SymbolicFunction:
    """A dynamics SymbolicFunction of every route (tree, Lagrange, dual quaternion, sweeps): the
    inputs followed by the parameter port of the params mode, the shared conventions text, the
    named intermediates of ``stages`` (``route`` names the algorithm where a function has several)."""
    return SymbolicFunction(
        name=name, summary=summary, inputs=tuple(inputs) + ts.param_ports, outputs=tuple(outputs),
        input_symbols=tuple(input_symbols) + ts.param_symbols,
        output_exprs=tuple(tuple(se.sympify(e) for e in exprs) for exprs in output_exprs),
        conventions=conventions(ts.model, ts.params),
        metadata={"params": ts.params, **({"route": route} if route else {})},
        stages=stages.definitions if stages is not None else ())


def _flat(matrix):
    return [e for row in matrix for e in row]


def joint_effects(model: RobotModel, q, qd, qdd, rigid) -> list:
    """The joint torques from the rigid-body torques ``rigid`` with the description's effects
    (:func:`kindyngen.algorithms.effect_torques.joint_torques`) on the velocity coordinates (a
    floating base's six unchanged)."""
    base = FREE_FLYER_NV if model.floating_base else 0
    if not model.effects:
        return list(rigid)
    inner = joint_torques(model, rigid[base:], q[base:] if base == 0 else None, qd[base:],
                          None if qdd is None else qdd[base:])
    return list(rigid[:base]) + inner


def transmitted(model: RobotModel, q, qd, tau) -> list:
    """The applied torques ``tau`` less the description's friction, offset and ripple: what
    accelerates the rigid bodies and the armature
    (:func:`kindyngen.algorithms.effect_torques.transmitted_torques`)."""
    base = FREE_FLYER_NV if model.floating_base else 0
    if not model.effects:
        return list(tau)
    return list(tau[:base]) + transmitted_torques(model, tau[base:], q[base:] if base == 0 else None, qd[base:])


def mass_matrix_with_armature(model: RobotModel, M):
    """M with each joint's armature on its diagonal entry."""
    if "armature" not in model.effects:
        return M
    base = FREE_FLYER_NV if model.floating_base else 0
    inner = with_armature(model, [row[base:] for row in M[base:]])
    return [list(row) for row in M[:base]] + [list(row[:base]) + inner[k] for k, row in enumerate(M[base:])]


def _mass_unit(model: RobotModel) -> str:
    return "kg m^2" if not model.floating_base and not any(j.prismatic for j in model.joints) else "kg, kg m, kg m^2"


def inverse_dynamics_tree(model: RobotModel, params: str = "numeric", name: str = "tau",
                          effects: bool = True, named: bool = True) -> SymbolicFunction:
    """``tau(q, qd, qdd) -> tau = M qdd + c + g`` by recursive Newton-Euler (O(n)), plus the
    description's friction, offset and armature torques (``effects=False``: rigid bodies only;
    ``named=False``: one DAG without named intermediates, to differentiate)."""
    ts, stages = setup(model, params), Stages() if named else None
    qd, qdd = port_symbols("qd", (model.nv,)), port_symbols("qdd", (model.nv,))
    tau = rnea(ts, qd, qdd, True, stages)
    if effects:
        tau = joint_effects(model, ts.q, qd, qdd, tau)
    return dynamics_function(name, ROUTE + "inverse dynamics tau = M qdd + c + g by recursive Newton-Euler over the tree.",
                             ts, (q_port(model), qd_port(model), qdd_port(model)), (ts.q, qd, qdd),
                             (force_port(model, "tau", "torque"),), (tau,), stages)


def coriolis_tree(model: RobotModel, params: str = "numeric", name: str = "c") -> SymbolicFunction:
    """``c(q, qd) -> tau(q, qd, 0)`` without gravity."""
    ts, stages = setup(model, params), Stages()
    qd = port_symbols("qd", (model.nv,))
    return dynamics_function(name, ROUTE + "Coriolis and centrifugal forces c = tau(q, qd, 0) without gravity, by "
                             "recursive Newton-Euler.", ts, (q_port(model), qd_port(model)), (ts.q, qd),
                             (force_port(model, "c", "Coriolis and centrifugal torque"),),
                             (rnea(ts, qd, None, False, stages),), stages)


def gravity_tree(model: RobotModel, params: str = "numeric", name: str = "g") -> SymbolicFunction:
    """``g(q) -> tau(q, 0, 0)`` by composite first moments."""
    ts = setup(model, params)
    return dynamics_function(name, ROUTE + "gravity forces g = tau(q, 0, 0), by composite first moments.", ts,
                             (q_port(model),), (ts.q,), (force_port(model, "g", "gravity torque"),),
                             (gravity_composite(ts),))


def mass_matrix_tree(model: RobotModel, params: str = "numeric", name: str = "M",
                     effects: bool = True) -> SymbolicFunction:
    """``M(q) -> M`` by composite rigid bodies over the tree (plus the armature)."""
    ts, stages = setup(model, params), Stages()
    M, _, _ = crba(ts, stages)
    if effects:
        M = mass_matrix_with_armature(model, M)
    return dynamics_function(name, ROUTE + "inertia matrix M(q) by composite rigid bodies, each column carried up its "
                             "branch (entries between branches are exact zeros).", ts, (q_port(model),), (ts.q,),
                             (Port("M", (model.nv, model.nv), "joint-space inertia matrix (symmetric, row-major)",
                               _mass_unit(model)),), (_flat(M),), stages)


def forward_dynamics_tree(model: RobotModel, params: str = "numeric", name: str = "fd") -> SymbolicFunction:
    """``fd(q, qd, tau) -> qdd = M^-1 (tau - c - g)`` by the tree-sparse ``L^T D L`` (the
    armature in M, friction and offset in the bias)."""
    ts = setup(model, params)
    qd, tau = port_symbols("qd", (model.nv,)), port_symbols("tau", (model.nv,))
    stages = Stages()
    M, _, _ = crba(ts, stages)
    M = mass_matrix_with_armature(model, M)
    bias = rnea(ts, qd, None, True, stages)
    qdd = tree_ldlt_solve(M, expanded_parents(model), [t - b for t, b in zip(transmitted(model, ts.q, qd, tau), bias)],
                          stages)
    return dynamics_function(name, ROUTE + "forward dynamics qdd = M^-1 (tau - c - g): M by composite rigid bodies, c + g "
                             "by one Newton-Euler pass (qdd = 0), M = L^T D L with L as sparse as the tree (no fill-in) "
                             "and the two sparse triangular solves.", ts,
                             (q_port(model), qd_port(model), force_port(model, "tau", "applied torque")), (ts.q, qd, tau),
                             (qdd_port(model),), (qdd,), stages, route="sparse L^T D L")


def centre_of_mass_tree(model: RobotModel, params: str = "numeric", name: str = "com") -> SymbolicFunction:
    """``com(q) -> c, J_c, A_g``: centre of mass, its Jacobian and the centroidal momentum matrix."""
    ts, stages = setup(model, params), Stages()
    M, root_columns, whole = crba(ts, stages)
    com, jac, ag = centroidal(ts, root_columns, whole, M)
    # an arm read from DH rows has no base link name: its base is DH frame 0
    frame = ("world frame" if model.floating_base else f"root link '{model.base_name}' frame" if model.base_name
             else "DH frame 0" if model.is_dh else "base frame")
    counted = "" if model.floating_base else " (the fixed root link not counted, as in Pinocchio)"
    return dynamics_function(name, ROUTE + f"centre of mass{counted}, its Jacobian and the centroidal momentum matrix "
                             "(from the base rows of composite rigid bodies).", ts, (q_port(model),), (ts.q,),
                             (Port("com", (3,), f"centre of mass in the {frame}", "m"),
                          Port("J_com", (3, model.nv), f"d com/dt = J_com qd, in the {frame}", "m per unit of qd"),
                          Port("A_g", (6, model.nv), "centroidal momentum matrix: h_G = A_g qd, linear then angular "
                               f"momentum about the CoM, {frame.removesuffix(' frame')} axes (Pinocchio's ccrba)",
                               "kg m, kg m^2 per unit of qd")),
                         (com, _flat(jac), _flat(ag)), stages)
