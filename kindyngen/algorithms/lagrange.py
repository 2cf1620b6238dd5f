"""Dynamic model by the identification paper's method: link velocities by moving frames,
kinetic energy by Koenig's theorem, ``M = Hessian of T in qd``, ``g = gradient of U``,
``S`` from the Christoffel symbols of ``M`` (paper eqs. 10-16), all on symengine DAGs.

The joint frames, grouped link bodies, gravity and ports it runs on are shared with the other
dynamics routes and live in :mod:`kindyngen.algorithms.rigid_bodies`; the function assembly is
:func:`kindyngen.algorithms.dynamics.dynamics_function`.

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> f = mass_matrix_lagrange(load_robot("robots/lwr4.yaml"))     # doctest: +SKIP
>>> f.outputs[0].shape                                            # doctest: +SKIP
(7, 7)
"""
from __future__ import annotations

from dataclasses import dataclass

import symengine as se

from .effect_torques import with_armature
from .kinematics_conventions import q_port
from .rigid_bodies import ZERO, cross, dot, flat, gravity, qd_port, vadd, vscale
from .dynamics import TreeSetup, crba, dynamics_function, setup
from ..model.robot_model import RobotModel
from .symbolic import Port, SymbolicFunction, port_symbols

HALF = se.Rational(1, 2)


# ----------------------------------------------------------------------------- the paper's method

def moving_frames(joints, qd):
    """Angular velocity and origin velocity of every joint frame, in its own axes
    (paper Sect. IV, steps a-d, with frame origins instead of centres of mass)."""
    w, v = [ZERO] * 3, [ZERO] * 3
    out = []
    for joint, qdj in zip(joints, qd):
        v = joint.rot_t(vadd(v, cross(w, joint.t)))
        w = joint.rot_t(w)
        if joint.prismatic:
            v = [v[0], v[1], v[2] + qdj]
        else:
            w = [w[0], w[1], w[2] + qdj]
        out.append((w, v))
    return out


def kinetic_energy(bodies, velocities):
    """Koenig's theorem in barycentric form: per link 1/2 m v.v + v.(w x h) + 1/2 w.I w."""
    terms = []
    for b, (w, v) in zip(bodies, velocities):
        Iw = [se.Add(*(b.I[r][k] * w[k] for k in range(3))) for r in range(3)]
        terms.append(HALF * dot(w, Iw))
        terms.append(dot(v, cross(w, b.h)))
        terms.append(HALF * b.m * dot(v, v))
    return se.Add(*terms)


def potential_energy(model: RobotModel, bodies, joints):
    """U = -sum gamma . (m o_j + R_0j h_j), gravity gamma in the base frame; evaluated as
    -sum gamma_j . (m p_j + h_j) with gamma carried into each joint frame."""
    gam = gravity(model)
    origin = [ZERO] * 3      # origin of frame j in its own axes relative to the base origin
    terms = []
    for joint, b in zip(joints, bodies):
        gam = joint.rot_t(gam)
        origin = joint.rot_t(vadd(origin, joint.t))
        terms.append(dot(gam, vadd(b.h, vscale(b.m, origin))))
    return -se.Add(*terms)


def christoffel_S(M, q, qd):
    """S from the Christoffel symbols of M (paper eq. 16):
    ``S_ij = 1/2 sum_k qd_k (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i)``, evaluated as
    ``Mdot + G - G^T`` with ``Mdot = sum_k dM/dq_k (qd_k / 2)`` and ``G = d(M qd / 2)/dq``
    (the halves applied once to qd; derivatives taken on the DAG by se.diff)."""
    n = len(q)
    dM = [[[None] * n for _ in range(n)] for _ in range(n)]   # dM[k][i][j] = dM_ij / dq_k
    for i in range(n):
        for j in range(i, n):
            for k in range(n):
                dM[k][i][j] = dM[k][j][i] = se.diff(M[i][j], q[k])
    h = [HALF * v for v in qd]
    Mdot = [[se.Add(*(dM[k][i][j] * h[k] for k in range(n))) for j in range(n)] for i in range(n)]
    G = [[se.Add(*(dM[j][i][k] * h[k] for k in range(n))) for j in range(n)] for i in range(n)]
    return [[Mdot[i][j] + G[i][j] - G[j][i] for j in range(n)] for i in range(n)]


@dataclass
class LagrangeModel:
    q: tuple
    qd: tuple
    M: list | None    # None: not derived (lagrange_model(mass=False))
    g: list
    T: se.Basic
    U: se.Basic
    ts: TreeSetup     # what it was derived from (the parameter ports)


def lagrange_model(model: RobotModel, params: str = "numeric", mass: bool = True) -> LagrangeModel:
    """T, U and their derivatives; ``mass=False`` leaves M (the n^2 second derivatives of T,
    None) out for what needs only g: a 29-joint chain's g_lagrange took 7.5 s CPU with it."""
    ts = setup(model, params)
    q, qd, joints, bodies = ts.q, port_symbols("qd", (model.n,)), ts.joints, ts.bodies
    T = kinetic_energy(bodies, moving_frames(joints, qd))
    U = potential_energy(model, bodies, joints)
    n = model.n
    M = None
    if mass:
        dT = [se.diff(T, qd[i]) for i in range(n)]
        M = [[None] * n for _ in range(n)]
        for i in range(n):
            for j in range(i, n):
                M[i][j] = M[j][i] = se.diff(dT[i], qd[j])
    g = [se.diff(U, qi) for qi in q]
    return LagrangeModel(q, qd, M, g, T, U, ts)


LAGRANGE = ("Lagrange route (the identification paper's method): velocities by moving frames, "
            "kinetic energy by Koenig's theorem, ")


def mass_matrix_lagrange(model: RobotModel, params: str = "numeric", name: str = "M_lagrange",
                         effects: bool = True) -> SymbolicFunction:
    """``M(q) -> M`` as the Hessian of the kinetic energy in qd (plus the armature)."""
    L = lagrange_model(model, params)
    M = with_armature(model, L.M) if effects else L.M
    return dynamics_function(name, LAGRANGE + "M = Hessian of T in qd.", L.ts,
                             (q_port(model),), (L.q,),
                             (Port("M", (model.n, model.n), "joint-space inertia matrix (symmetric, row-major)",
                                   "kg m^2"),),
                             (flat(M),))


def gravity_lagrange(model: RobotModel, params: str = "numeric", name: str = "g_lagrange") -> SymbolicFunction:
    """``g(q) -> g`` as the gradient of the potential energy."""
    L = lagrange_model(model, params, mass=False)
    return dynamics_function(name, LAGRANGE + "g = gradient of the potential energy U.", L.ts,
                             (q_port(model),), (L.q,),
                             (Port("g", (model.n,), "gravity torques", "N m"),), (L.g,))


def _christoffel_setup(model: RobotModel, params: str, route: str):
    """(M nested lists, q, tree setup) of the M whose Christoffel symbols
    give S: "crba" (composite rigid bodies, the cheaper DAG) or "lagrange" (energy Hessian)."""
    if route == "lagrange":
        L = lagrange_model(model, params)
        return L.M, L.q, L.ts
    ts = setup(model, params)
    return crba(ts)[0], ts.q, ts


def coriolis_matrix(model: RobotModel, params: str = "numeric", name: str = "S", route: str = "crba") -> SymbolicFunction:
    """``S(q, qd) -> S`` from the Christoffel symbols of M."""
    M, q, ts = _christoffel_setup(model, params, route)
    qd = port_symbols("qd", (model.n,))
    S = christoffel_S(M, q, qd)
    which = "the composite-rigid-body M" if route == "crba" else "the energy-Hessian M"
    return dynamics_function(name, f"Christoffel route: Coriolis/centrifugal matrix S from the Christoffel symbols "
                             f"(paper eq. 16) of {which}, differentiated on the DAG; c = S qd, Mdot - 2 S is "
                             f"skew-symmetric.", ts,
                             (q_port(model), qd_port(model)), (q, qd),
                             (Port("S", (model.n, model.n),
                                   "Christoffel Coriolis/centrifugal matrix, c = S qd (row-major)", "N m s"),),
                             (flat(S),))


def coriolis_christoffel(model: RobotModel, params: str = "numeric", name: str = "c_christoffel",
                         route: str = "crba") -> SymbolicFunction:
    """``c(q, qd) -> c = S(q, qd) qd`` with S from the Christoffel symbols."""
    f = coriolis_matrix(model, params, route=route)
    n = model.n
    qd = f.input_symbols[1]
    S = f.output_exprs[0]
    c = [se.Add(*(S[i * n + j] * qd[j] for j in range(n))) for i in range(n)]
    which = "the composite-rigid-body M" if route == "crba" else "the energy-Hessian M"
    return dynamics_function(name, f"Christoffel route: Coriolis and centrifugal torques c = S qd (paper eq. 15), "
                             f"S from the Christoffel symbols (eq. 16) of {which}.", setup(model, params),
                             f.inputs[:2], f.input_symbols[:2],
                             (Port("c", (n,), "Coriolis and centrifugal torques", "N m"),), (c,))
