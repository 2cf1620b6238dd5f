"""Closed kinematic loops: the constraints a tree's loop joints impose, the coordinates the
dynamics is written in, and how the dependent joints follow from them.

A model with loops (:class:`kindyngen.model.robot_model.LoopClosure`) is a tree (``free``: every
joint a coordinate, no loop closed) whose configuration ``q_x`` (all n joints) must satisfy
``r(q_x) = 0``, one row per constrained direction of each loop joint (m rows, in frame A's
axes: the translations ``R_A^T (p_B - p_A)``, the rotations ``(R_A^T R_B)[2][1], [0][2],
[1][0]``). Its velocity satisfies ``K qd_x = 0`` with ``K = dr/dq_x`` (m x n), derived here
symbolically (:func:`residual`, :func:`constraint_jacobian`).

**Coordinates.** The independent joints ``y`` (n - m of them) are those the description names
(``independent:``; a URDF's ``<transmission>`` joints), else chosen by a rule: in joint order,
a joint is independent when the joints not yet chosen, without it, still have a constraint
Jacobian of full row rank at the reference configuration. Every rank decision is taken on
the singular values of K at the reference (the description's ``reference:``, default all
zero, with the dependent joints solved by Newton's method there): ``sigma_min / sigma_max``
above :data:`REGULAR` is regular, below :data:`SINGULAR` singular, in between undecided (an
error asking for ``independent:`` or another reference).

**Velocities.** With ``Jd``, ``Ji`` the columns of K of the dependent and independent joints,
``qd_x = G(q) qd_y`` with ``G = [I; -Jd^-1 Ji]`` (rows in joint order) and ``qdd_x = G qdd_y +
Gdot qd_y``, ``Gdot qd_y = [0; -Jd^-1 (Kdot qd_x)]``, ``Kdot qd_x = sum_k d(K qd_x)/dq_k qd_k``.
``Jd^-1`` is an unrolled elimination whose pivot order is fixed at the reference (partial
pivoting there, ties within :data:`PIVOT_TIE` by row order): valid wherever those pivots do
not vanish (:func:`velocity_map`).

**Dependent joints in closed form** (:func:`closed_form`), recognised exactly (rational and
exact-trigonometric arithmetic on the description's placements at the reference; anything
not proven is not recognised): a *planar loop* constrains the two translations of its plane
(``directions: [x, y]``, frame A's z the loop's normal) and every joint on it is revolute
about an axis parallel to that normal. After dropping its links of zero length in the plane
(two joints on one axis), such a loop is

* a **parallelogram** when four links remain and opposite ones are equal and antiparallel at
  the reference: then opposite links stay parallel, two relations linear in the joint angles
  (``sum s_j q_j`` along each link's path from the loop's root body, ``s_j = +-1`` the axis'
  sense), solved exactly for the loop's two dependent joints (:func:`coupled_model`: every
  loop a parallelogram makes G constant, the case of mimic joints);
* a **dyad** when its two dependent joints are the joints of the two bodies the loop joint
  connects (every other joint of the loop known): the loop point lies on the circles about
  the two dependent axes, ``F = P + a u + s h (n x u)``, ``u = (Q - P) / d`` in the plane,
  ``a = (r_a^2 - r_b^2 + d^2) / (2 d)``, ``h = sqrt(r_a^2 - a^2)``, the branch ``s`` the one
  the reference is on (decided with the margin :data:`BRANCH_MARGIN`), and the two angles
  follow by ``atan2`` (a four-bar driven by a crank, a parallelogram whose coordinates are
  not its crank's, a palletiser's rod).

Loops are solved in turn, each from the joints already known. Without a closed form the
functions take every joint's position (a configuration closing the loops: the generated
``loop_solve`` runs unrolled Newton steps from a guess, :mod:`kindyngen.algorithms.loop_functions`).

Example: the planar four-bar of :data:`FOUR_BAR`, its crank the coordinate:

>>> from kindyngen.readers.yaml_description import parse_robot
>>> system = loop_system(parse_robot(FOUR_BAR, tree=True))
>>> [system.free.joints[j].name for j in system.independent], system.closed.kinds
(['crank'], ('dyad',))
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
import symengine as se
import sympy

from ..model.robot_model import LOOP_DIRECTIONS, Mimic, RobotDescriptionError, RobotModel
from .geometry import compose, constant, constant_transform
from .kinematics import link_poses
from .symbolic import port_symbols

REGULAR = 1e-6          # sigma_min / sigma_max of a block above this: regular
SINGULAR = 1e-9         # below this: singular (in between: undecided, an error)
CLOSED = 1e-12          # the reference's residual after Newton's method (m, rad)
NEWTON_STEPS = 50
PIVOT_TIE = 1e-9        # a pivot candidate within this (relative) of the largest ties with it
BRANCH_MARGIN = 1e-6    # |sin| of the dyad's angle at the reference below this: a flat (singular) reference

# a planar four-bar in the x-y plane (a crank-rocker by Grashof's rule: ground 0.4 m, crank 0.2 m,
# coupler and rocker 0.5 m; the crank turns fully), assembled at q = 0 with crank and rocker along
# +y: the crank's end (0, 0.2), the rocker's (0.4, 0.5); the example of this module and the tutorial
FOUR_BAR = {
    "name": "four_bar", "dh": "none", "gravity": [0, -9.81, 0],
    "joints": [
        {"name": "crank", "lower": -3.14, "upper": 3.14},
        {"name": "coupler", "parent": "crank", "origin": {"xyz": [0, 0.2, 0]}, "lower": -3.14, "upper": 3.14},
        {"name": "rocker", "origin": {"xyz": [0.4, 0, 0]}, "lower": -3.14, "upper": 3.14}],
    "links": [
        {"mass": 0.4, "com": [0, 0.1, 0], "inertia": [0.0014, 0.0001, 0.0014, 0, 0, 0]},
        {"mass": 1.0, "com": [0.2, 0.15, 0], "inertia": [0.008, 0.014, 0.021, -0.0096, 0, 0]},
        {"mass": 0.8, "com": [0, 0.25, 0], "inertia": [0.017, 0.0002, 0.017, 0, 0, 0]}],
    "loops": [{"name": "pin", "type": "revolute", "link1": "coupler", "origin1": {"xyz": [0.4, 0.3, 0]},
               "link2": "rocker", "origin2": {"xyz": [0, 0.5, 0]}, "directions": ["x", "y"]}],
}


# ----------------------------------------------------------------------------- the constraint

def _error(model: RobotModel, field: str, reason: str) -> RobotDescriptionError:
    return RobotDescriptionError(model.source, field, reason)


def _frame_pose(links, body: int, placement):
    """(R, p) of ``placement`` on ``body``'s link frame (-1: the root) in the world (root)
    frame, from :func:`kindyngen.algorithms.kinematics.link_poses`' link poses."""
    above = links[body] if body >= 0 else (se.eye(3), se.zeros(3, 1))
    return compose(above, constant_transform(placement))


def residual(free: RobotModel, loops, q) -> list:
    """The constraint rows of ``loops`` at ``q`` (all joints of the tree ``free``), in order
    of the loops and, per loop, of its directions (module text)."""
    _, links, _ = link_poses(free, q)
    rows = []
    for loop in loops:
        Ra, pa = _frame_pose(links, loop.body_a, loop.placement_a)
        Rb, pb = _frame_pose(links, loop.body_b, loop.placement_b)
        d = pb - pa
        for direction in loop.directions:
            if direction in ("x", "y", "z"):
                k = "xyz".index(direction)
                rows.append(se.Add(*(Ra[r, k] * d[r] for r in range(3))))
            else:
                i, j = {"rx": (2, 1), "ry": (0, 2), "rz": (1, 0)}[direction]
                rows.append(se.Add(*(Ra[r, i] * Rb[r, j] for r in range(3))))
    return rows


def constraint_jacobian(rows, q) -> list:
    """``K = dr/dq`` (m x n nested lists), differentiated on the DAG."""
    return [[se.diff(r, qj) for qj in q] for r in rows]


def row_names(model: RobotModel) -> tuple[str, ...]:
    """``loop.direction`` of every constraint row, in order."""
    return tuple(f"{loop.name}.{d}" for loop in model.loops for d in loop.directions)


# ----------------------------------------------------------------------------- the system

@dataclass(frozen=True)
class ClosedForm:
    """How the dependent joints follow from the independent ones: ``steps``, in order, each
    ``(kind, loop index, dependent joints, data)`` with kind "linear" (data: the exact
    relation rows over all joints, and their right-hand sides) or "dyad" (data:
    :class:`Dyad`)."""

    steps: tuple

    @property
    def kinds(self) -> tuple[str, ...]:
        return tuple(step[0] for step in self.steps)

    @property
    def linear(self) -> bool:
        return all(kind == "linear" for kind in self.kinds)


@dataclass(frozen=True)
class Dyad:
    """A dyad's constants: its two dependent joints (those of the loop joint's bodies a and
    b), the loop point's distance from each one's axis in the plane and its angle about it in
    the joint's moving frame (exact), and the branch's sign (the side of the line from joint a's
    axis to joint b's the loop point is on at the reference)."""

    joint_a: int
    joint_b: int
    radius_a: sympy.Expr
    angle_a: sympy.Expr
    radius_b: sympy.Expr
    angle_b: sympy.Expr
    sign: int


@dataclass(frozen=True)
class LoopSystem:
    """A model's loops prepared for derivation (module text)."""

    model: RobotModel
    free: RobotModel
    independent: tuple[int, ...]
    dependent: tuple[int, ...]
    reference: tuple[float, ...]        # the assembled reference configuration (all joints)
    pivots: tuple[int, ...]             # row of Jd eliminated at each step (column k of Jd)
    closed: ClosedForm | None

    @property
    def m(self) -> int:
        return len(self.dependent)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.free.joints[j].name for j in self.independent)

    @property
    def dependent_names(self) -> tuple[str, ...]:
        return tuple(self.free.joints[j].name for j in self.dependent)

    @property
    def text(self) -> str:
        """What every loop function's header says about the loops and the coordinates."""
        loops = "; ".join(f"{loop.name}: {loop.kind} joint between the bodies of "
                          f"{_body_name(self.free, loop.body_a)} and {_body_name(self.free, loop.body_b)}, "
                          f"constraining {', '.join(loop.directions)} of frame A" for loop in self.model.loops)
        how = ("the dependent joints in closed form from them (" + ", ".join(
            f"{self.model.loops[step[1]].name}: {step[0]}" for step in self.closed.steps) + ")"
               if self.closed else "no closed form: q is every joint, a configuration closing the loops (loop_solve: "
               "Newton steps from a guess)")
        return (f"Closed loops ({loops}). Independent joints: {', '.join(self.names)}; dependent: "
                f"{', '.join(self.dependent_names)}; {how}. Velocities qd_x = G(q) qd with G = [I; -Jd^-1 Ji] "
                f"(K = dr/dq, pivot order fixed at the reference configuration), qdd_x = G qdd + Gdot qd; forces "
                f"in the independent coordinates: G^T of the tree's.")


def _body_name(free: RobotModel, body: int) -> str:
    return free.joints[body].name if body >= 0 else (free.base_name or "base")


def _svd_ratio(A: np.ndarray) -> float:
    s = np.linalg.svd(A, compute_uv=False)
    return float(s[-1] / s[0]) if s.size and s[0] > 0 else 0.0


def _regular(ratio: float) -> bool | None:
    """True above :data:`REGULAR`, False below :data:`SINGULAR`, None in between."""
    return True if ratio > REGULAR else False if ratio < SINGULAR else None


class _Numeric:
    """r and K of a model's loops, evaluated at float configurations (symengine's Lambdify:
    the values only feed decisions taken with the module's margins)."""

    def __init__(self, free: RobotModel, loops):
        q = port_symbols("q", (free.n,))
        rows = residual(free, loops, q)
        K = constraint_jacobian(rows, q)
        self.m = len(rows)
        self.function = se.Lambdify(list(q), rows + [e for row in K for e in row], real=True)

    def evaluate(self, q: np.ndarray):
        values = np.asarray(self.function(np.asarray(q, float)), float).ravel()
        return values[:self.m], values[self.m:].reshape(self.m, -1)


@lru_cache(maxsize=16)
def loop_system(model: RobotModel) -> LoopSystem:
    """The coordinates, reference and closed form of ``model``'s loops (module text); a
    description whose loops cannot be reduced is a RobotDescriptionError naming the field."""
    assert model.has_loops and not model.has_mimics and not model.floating_base
    named = [str(s) for s in model.length_symbols] + [str(s) for loop in model.loops
                                                      for placement in (loop.placement_a, loop.placement_b)
                                                      for kind, *rest in placement.factors if kind == "trans"
                                                      for s in rest[0] if isinstance(s, sympy.Symbol)]
    if named:
        raise _error(model, "loops", f"closed loops need numeric lengths (the coordinates and closed forms are decided "
                     f"at the reference configuration), got the names {', '.join(dict.fromkeys(named))}")
    free = model.without_mimics()
    numeric = _Numeric(free, model.loops)
    n, m = free.n, numeric.m
    q = np.array([float(v) for v in model.reference_values])
    _, K = numeric.evaluate(q)
    if m > n or _regular(_svd_ratio(K)) is not True:
        raise _error(model, "loops", f"the {m} constrained directions ({', '.join(row_names(model))}) are not "
                     "independent at the reference configuration (a planar loop constrains only the two translations "
                     "in its plane: 'directions: [x, y]'; else give another 'reference')")
    if m == n:
        raise _error(model, "loops", f"{m} constrained directions leave no motion to the {n} joints")
    independent = _choose(model, K, n, m)
    dependent = tuple(j for j in range(n) if j not in independent)
    q = _assemble(model, numeric, q, dependent)
    _, K = numeric.evaluate(q)
    if _regular(_svd_ratio(K[:, dependent])) is not True:
        raise _error(model, "independent" if model.independent is not None else "loops",
                     "the dependent joints cannot be solved from the loops at the assembled reference configuration "
                     "(their constraint Jacobian is singular there)")
    pivots = _pivots(K[:, dependent])
    system = LoopSystem(model, free, independent, dependent, tuple(float(v) for v in q), pivots, None)
    return replace(system, closed=closed_form(system))


def resolved(model: RobotModel) -> RobotModel:
    """``model`` with its independent joints chosen (a tree closed by loops; any other model
    as it is): its ``coordinates``, ``nq`` and ``nv`` are then the loops' independent joints."""
    if not model.has_loops or model.independent is not None:
        return model
    return replace(model, independent=loop_system(model).independent)


def _choose(model: RobotModel, K: np.ndarray, n: int, m: int) -> tuple[int, ...]:
    """The independent joints: the description's, checked, or by the module's rule."""
    if model.independent is not None:
        if len(model.independent) != n - m:
            raise _error(model, "independent", f"{len(model.independent)} joints named; the loops leave {n - m} of the "
                         f"{n} joints independent ({m} constrained directions)")
        dependent = [j for j in range(n) if j not in model.independent]
        ratio = _svd_ratio(K[:, dependent])
        if _regular(ratio) is not True:
            raise _error(model, "independent", "the other joints cannot be solved from the loops at the reference "
                         f"configuration (their constraint Jacobian is {'singular' if _regular(ratio) is False else 'nearly singular'}"
                         f" there: sigma_min / sigma_max = {ratio:.2g})")
        return tuple(model.independent)
    chosen: list[int] = []
    for j in range(n):
        if len(chosen) == n - m:
            break
        rest = [k for k in range(n) if k not in chosen and k != j]
        regular = _regular(_svd_ratio(K[:, rest]))
        if regular is None:
            raise _error(model, "independent", f"whether joint {model.joints[j].name!r} may be independent is "
                         "undecided at the reference configuration (nearly singular): name the independent joints")
        if regular:
            chosen.append(j)
    assert len(chosen) == n - m, "K has full row rank, so the rule ends with n - m joints"
    return tuple(chosen)


def _assemble(model: RobotModel, numeric: _Numeric, q: np.ndarray, dependent) -> np.ndarray:
    """The reference with its dependent joints solved by Newton's method (the independent ones
    as given)."""
    q = q.copy()
    dependent = list(dependent)
    for _ in range(NEWTON_STEPS):
        r, K = numeric.evaluate(q)
        if np.max(np.abs(r)) <= CLOSED:
            return q
        q[dependent] -= np.linalg.solve(K[:, dependent], r)
    r, _ = numeric.evaluate(q)
    if np.max(np.abs(r)) <= CLOSED and np.all(np.isfinite(q)):
        return q
    raise _error(model, "reference", f"the loops do not close near the reference configuration (largest residual "
                 f"{np.max(np.abs(r)):.3g} after {NEWTON_STEPS} Newton steps on the dependent joints): give a "
                 "'reference' near an assembled configuration")


def _pivots(Jd: np.ndarray) -> tuple[int, ...]:
    """Row eliminated at each step of Gaussian elimination of ``Jd`` with partial pivoting
    (candidates within :data:`PIVOT_TIE` of the largest tie; the first row wins)."""
    A = np.array(Jd, float)
    m = A.shape[0]
    left, order = list(range(m)), []
    for k in range(m):
        values = np.abs(A[left, k])
        best = values.max()
        p = next(r for r, v in zip(left, values) if v >= best * (1 - PIVOT_TIE))
        order.append(p)
        left.remove(p)
        for r in left:
            A[r] -= A[r, k] / A[p, k] * A[p]
    return tuple(order)


# ----------------------------------------------------------------------------- velocities

def eliminate(Jd, pivots, name):
    """The unrolled elimination of ``Jd`` (m x m expressions) in the fixed pivot order:
    ``(multipliers, U, inverse pivots)`` for :func:`solve`; exact zeros skip their work."""
    m = len(Jd)
    A = [list(row) for row in Jd]
    left = list(range(m))
    multipliers, inv = [], []
    for k, p in enumerate(pivots):
        left.remove(p)
        inv.append(name(se.Pow(A[p][k], -1)))
        step = []
        for r in left:
            if A[r][k] == 0:
                continue
            factor = name(A[r][k] * inv[k])
            step.append((r, factor))
            for c in range(k + 1, m):
                if A[p][c] != 0:
                    A[r][c] = name(A[r][c] - factor * A[p][c])
        multipliers.append(step)
    return multipliers, A, inv


def solve(factor, pivots, b, name) -> list:
    """``Jd^-1 b`` from :func:`eliminate`'s factor."""
    multipliers, U, inv = factor
    y = list(b)
    for k, p in enumerate(pivots):
        for r, factor_k in multipliers[k]:
            if y[p] != 0:
                y[r] = name(y[r] - factor_k * y[p])
    m = len(pivots)
    x = [None] * m
    for k in range(m - 1, -1, -1):
        p = pivots[k]
        x[k] = name(se.Add(y[p], *(-U[p][c] * x[c] for c in range(k + 1, m) if U[p][c] != 0)) * inv[k])
    return x


@dataclass
class VelocityMap:
    """``G`` (n x ny nested lists, rows in joint order) and the unrolled factor of ``Jd``, all
    in the tree's symbols q_0 .. q_{n-1} (:func:`velocity_map`)."""

    system: LoopSystem
    K: list
    G: list
    factor: tuple
    name: object

    def full(self, reduced) -> list:
        """``G v`` for reduced velocities (accelerations) ``v``: each joint's."""
        return [self.name(se.Add(*(g * v for g, v in zip(row, reduced) if g != 0))) for row in self.G]

    def drift(self, qd_full) -> list:
        """``Gdot qd`` (n entries) at the joints' velocities ``qd_full`` (= G qd): ``-Jd^-1
        (Kdot qd_x)`` on the dependent joints, 0 on the independent ones."""
        system = self.system
        q = port_symbols("q", (system.free.n,))
        v = [se.Symbol(f"_v{j}") for j in range(system.free.n)]
        values = dict(zip(v, qd_full))
        gamma = []
        for row in self.K:
            w = se.Add(*(k * vj for k, vj in zip(row, v) if k != 0))
            g = se.Add(*(se.diff(w, qk) * vk for qk, vk in zip(q, v)))
            gamma.append(self.name(g.xreplace(values)))
        dep = solve(self.factor, system.pivots, gamma, self.name)
        out = [se.Integer(0)] * system.free.n
        for j, x in zip(system.dependent, dep):
            out[j] = self.name(-x)
        return out

    def transpose_times(self, forces) -> list:
        """``G^T f`` (ny entries) of forces on the joints."""
        ny = len(self.system.independent)
        return [self.name(se.Add(*(self.G[j][a] * f for j, f in enumerate(forces) if self.G[j][a] != 0 and f != 0)))
                for a in range(ny)]

    def congruence(self, M) -> list:
        """``G^T M G`` (ny x ny nested lists, symmetric) of an n x n M."""
        n, ny = self.system.free.n, len(self.system.independent)
        MG = [[self.name(se.Add(*(M[i][k] * self.G[k][a] for k in range(n) if M[i][k] != 0 and self.G[k][a] != 0)))
               for a in range(ny)] for i in range(n)]
        upper = {(a, b): self.name(se.Add(*(self.G[i][a] * MG[i][b] for i in range(n)
                                            if self.G[i][a] != 0 and MG[i][b] != 0)))
                 for a in range(ny) for b in range(a, ny)}
        return [[upper[min(a, b), max(a, b)] for b in range(ny)] for a in range(ny)]

    def columns(self, exprs, shape) -> list:
        """A row-major array of ``shape`` whose last axis has n entries (one per joint) times G:
        the same array with ny in its last axis."""
        n, ny = self.system.free.n, len(self.system.independent)
        rows = len(exprs) // n
        out = []
        for r in range(rows):
            row = exprs[r * n:(r + 1) * n]
            out.extend(self.name(se.Add(*(row[k] * self.G[k][a] for k in range(n) if row[k] != 0 and self.G[k][a] != 0)))
                       for a in range(ny))
        return out


def velocity_map(system: LoopSystem, name) -> VelocityMap:
    """G of ``system`` in the tree's symbols, its intermediates named by ``name`` (module text)."""
    free = system.free
    q = port_symbols("q", (free.n,))
    raw = constraint_jacobian(residual(free, system.model.loops, q), q)
    K = [[name(e) if e != 0 else e for e in row] for row in raw]
    Jd = [[row[j] for j in system.dependent] for row in K]
    factor = eliminate(Jd, system.pivots, name)
    ny = len(system.independent)
    X = [solve(factor, system.pivots, [K[r][j] for r in range(len(K))], name) for j in system.independent]
    G = [[se.Integer(0)] * ny for _ in range(free.n)]
    for a, j in enumerate(system.independent):
        G[j][a] = se.Integer(1)
    for d, j in enumerate(system.dependent):
        for a in range(ny):
            G[j][a] = name(-X[a][d]) if X[a][d] != 0 else se.Integer(0)
    # the drift differentiates K again: the raw expressions, not the named ones
    return VelocityMap(system, raw, G, factor, name)


# ----------------------------------------------------------------------------- closed forms

def _exact_poses(free: RobotModel, q) -> tuple[list, list]:
    """Exact (sympy) world poses of each joint's frame before its motion and of its link frame
    after it, at the exact configuration ``q``."""
    frames, links = [], []
    for j, joint in enumerate(free.joints):
        parent = free.parents[j]
        R0, p0 = links[parent] if parent >= 0 else (sympy.eye(3), sympy.zeros(3, 1))
        Rb, pb = joint.before.matrix()
        Rf, pf = R0 * Rb, p0 + R0 * pb
        frames.append((Rf, pf))
        value = sympy.sympify(q[j]) + sympy.sympify(joint.offset)
        if joint.prismatic:
            Rm, pm = sympy.eye(3), sympy.Matrix([0, 0, value])
        else:
            c, s = sympy.cos(value), sympy.sin(value)
            Rm, pm = sympy.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]]), sympy.zeros(3, 1)
        Ra, pa = joint.after.matrix()
        Rl, pl = Rf * Rm, pf + Rf * pm
        links.append((Rl * Ra, pl + Rl * pa))
    return frames, links


def _zero(value) -> bool | None:
    """Whether an exact constant is zero: True, False, or None where sympy cannot tell."""
    value = sympy.sympify(value)
    if value.is_Number:
        return value == 0
    return sympy.simplify(value).equals(0)


def _vector_zero(v) -> bool | None:
    results = [_zero(x) for x in v]
    if any(r is False for r in results):
        return False
    return True if all(r is True for r in results) else None


def _path(free: RobotModel, loop) -> tuple[list, list, int]:
    """The loop's joints from body a up to (not including) the common ancestor, from body b up
    to it, and that ancestor (-1: the root)."""
    up_a = list(free.ancestors(loop.body_a)) if loop.body_a >= 0 else []
    up_b = list(free.ancestors(loop.body_b)) if loop.body_b >= 0 else []
    common = next((j for j in up_a if j in up_b), -1)
    return ([j for j in up_a[:up_a.index(common)]] if common >= 0 else up_a,
            [j for j in up_b[:up_b.index(common)]] if common >= 0 else up_b, common)


@dataclass(frozen=True)
class _Planar:
    """A planar loop's exact geometry at the reference: the normal n (world), each path joint's
    sense s_j (its axis . n = +-1), the in-plane link vectors of the cycle's bodies with the
    joints each body's orientation sums, and the loop point."""

    side_a: tuple
    side_b: tuple
    normal: sympy.Matrix
    sense: dict
    links: tuple          # ((vector, joints of its orientation), ...), zero-length ones dropped


def _planar(free: RobotModel, loop, q_exact) -> _Planar | None:
    """The exact planar geometry of ``loop`` (module text), or None where it is not (provably)
    a planar loop of revolute joints."""
    if loop.directions != ("x", "y") or loop.kind == "fixed":
        return None
    side_a, side_b, _ = _path(free, loop)
    joints = side_a + side_b
    if any(free.joints[j].prismatic for j in joints):
        return None
    frames, links = _exact_poses(free, q_exact)
    world = (sympy.eye(3), sympy.zeros(3, 1))

    def pose(body, placement):
        R, p = links[body] if body >= 0 else world
        Rp, pp = placement.matrix()
        return R * Rp, p + R * pp

    Ra, pa = pose(loop.body_a, loop.placement_a)
    normal = Ra[:, 2]
    sense = {}
    for j in joints:
        axis = frames[j][0][:, 2]
        if _vector_zero(axis.cross(normal)) is not True:
            return None
        dot = axis.dot(normal)
        if _zero(dot - 1) is True:
            sense[j] = 1
        elif _zero(dot + 1) is True:
            sense[j] = -1
        else:
            return None
    point = {("F",): pa, **{("j", j): frames[j][1] for j in joints}}
    # the cycle's bodies (first pivot, second pivot, the joints their orientation sums from the
    # ancestor): body a (F -> a_k) up to a_1's link, the ancestor (a_1 -> b_1), b_1's link
    # down to body b (b_l -> F)
    pivots_a = [("F",)] + [("j", j) for j in side_a]
    cycle = [(pivots_a[k], ("j", j), tuple(side_a[k:])) for k, j in enumerate(side_a)]
    cycle.append((("j", side_a[-1]) if side_a else ("F",), ("j", side_b[-1]) if side_b else ("F",), ()))
    for k in range(len(side_b) - 1, -1, -1):
        cycle.append((("j", side_b[k]), ("j", side_b[k - 1]) if k > 0 else ("F",), tuple(side_b[k:])))
    vectors = []
    for start, end, path in cycle:
        v = point[end] - point[start]
        v = v - normal * normal.dot(v)
        zero = _vector_zero(v)
        if zero is None:
            return None
        if not zero:
            vectors.append((v, path))
    return _Planar(tuple(side_a), tuple(side_b), normal, sense, tuple(vectors))


def _parallelogram(planar: _Planar, q_exact) -> tuple | None:
    """The two exact linear relations ``(coefficients {joint: c}, value)`` of a parallelogram
    (opposite links antiparallel and equal at the reference, not flat), or None."""
    links = planar.links
    if len(links) != 4:
        return None
    (v0, p0), (v1, p1), (v2, p2), (v3, p3) = links
    if _vector_zero(v0 + v2) is not True or _vector_zero(v1 + v3) is not True:
        return None
    if _vector_zero(v0.cross(v1)) is not False:
        return None                     # flat: the parallelogram's branch point
    relations = []
    for first, second in ((p0, p2), (p1, p3)):
        coefficients: dict = {}
        for j in first:
            coefficients[j] = coefficients.get(j, 0) + planar.sense[j]
        for j in second:
            coefficients[j] = coefficients.get(j, 0) - planar.sense[j]
        coefficients = {j: c for j, c in coefficients.items() if c != 0}
        value = sum((c * sympy.sympify(q_exact[j]) for j, c in coefficients.items()), sympy.Integer(0))
        relations.append((coefficients, value))
    return tuple(relations)


def _dyad(system: LoopSystem, loop, planar: _Planar, dependent: set) -> Dyad | None:
    """The dyad of ``loop`` when its dependent joints are the joints of the bodies it connects
    (module text), or None."""
    if not planar.side_a or not planar.side_b:
        return None
    ja, jb = loop.body_a, loop.body_b
    if dependent != {ja, jb}:
        return None
    free = system.free

    def radius_angle(body, placement):
        """The loop point's distance from the axis of body's joint and its angle about it, in
        the joint's moving frame (where its link's ``after`` placement starts)."""
        _, pp = placement.matrix()
        Ra, pa = free.joints[body].after.matrix()
        point = pa + Ra * pp
        radius = sympy.sqrt(point[0] ** 2 + point[1] ** 2)
        if _zero(radius) is not False:
            return None
        return radius, sympy.atan2(point[1], point[0])

    a = radius_angle(ja, loop.placement_a)
    b = radius_angle(jb, loop.placement_b)
    if a is None or b is None:
        return None
    # the branch: the side of the line P -> Q the loop point is on at the (float) reference,
    # about joint a's axis as the generated code takes it
    frames, links = _float_poses(free, np.array(system.reference))
    n, P = frames[ja][0][:, 2], frames[ja][1]
    Q = frames[jb][1]
    F = links[ja][0] @ np.array([float(v) for v in loop.placement_a.matrix()[1]]) + links[ja][1]
    u = (Q - P) - n * np.dot(n, Q - P)
    w = (F - P) - n * np.dot(n, F - P)
    cross = float(np.dot(n, np.cross(u, w)))
    if abs(cross) <= BRANCH_MARGIN * np.linalg.norm(u) * np.linalg.norm(w):
        raise _error(system.model, "reference", f"loop {loop.name!r} is flat at the reference configuration (its "
                     "two dependent joints' axes and the loop point in line): give a reference off that singularity")
    return Dyad(ja, jb, a[0], a[1], b[0], b[1], 1 if cross > 0 else -1)


def _float_poses(free: RobotModel, q: np.ndarray):
    """Float world poses (R, p) of each joint's frame before its motion and of its link frame."""
    frames, links = [], []
    for j, joint in enumerate(free.joints):
        parent = free.parents[j]
        R0, p0 = links[parent] if parent >= 0 else (np.eye(3), np.zeros(3))
        Rb, pb = (np.array(m, float).reshape(3, -1) for m in joint.before.matrix())
        Rf, pf = R0 @ Rb, p0 + R0 @ pb[:, 0]
        frames.append((Rf, pf))
        value = q[j] + float(joint.offset)
        if joint.prismatic:
            Rm, pm = np.eye(3), np.array([0, 0, value])
        else:
            c, s = np.cos(value), np.sin(value)
            Rm, pm = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), np.zeros(3)
        Ra, pa = (np.array(m, float).reshape(3, -1) for m in joint.after.matrix())
        Rl, pl = Rf @ Rm, pf + Rf @ pm
        links.append((Rl @ Ra, pl + Rl @ pa[:, 0]))
    return frames, links


def closed_form(system: LoopSystem) -> ClosedForm | None:
    """The loops' closed form (module text), or None where some loop has none."""
    model, free = system.model, system.free
    exact = model.reference_values
    known = set(system.independent)
    pending = list(range(len(model.loops)))
    steps = []
    while pending:
        progress = False
        for index in list(pending):
            loop = model.loops[index]
            side_a, side_b, _ = _path(free, loop)
            unknown = {j for j in side_a + side_b if j not in known}
            if len(unknown) != len(loop.directions):
                continue
            planar = _planar(free, loop, exact)
            if planar is None:
                return None
            relations = _parallelogram(planar, exact)
            if relations is not None and _solvable(relations, unknown):
                steps.append(("linear", index, tuple(sorted(unknown)), relations))
            else:
                dyad = _dyad(system, loop, planar, unknown)
                if dyad is None:
                    return None
                steps.append(("dyad", index, (dyad.joint_a, dyad.joint_b), dyad))
            known |= unknown
            pending.remove(index)
            progress = True
        if not progress:
            return None
    if known != set(range(free.n)):
        return None
    return ClosedForm(tuple(steps))


def _solvable(relations, unknown) -> bool:
    """Whether the relations determine the unknown joints (their exact matrix is invertible)."""
    unknown = sorted(unknown)
    A = sympy.Matrix([[c.get(j, 0) for j in unknown] for c, _ in relations])
    return A.shape[0] == A.shape[1] and A.det() != 0


def _linear_solution(relations, unknown) -> dict:
    """Each unknown joint as ``({joint: coefficient}, offset)`` over the other joints, exact."""
    unknown = sorted(unknown)
    A = sympy.Matrix([[c.get(j, 0) for j in unknown] for c, _ in relations])
    others = sorted({j for c, _ in relations for j in c} - set(unknown))
    B = sympy.Matrix([[-c.get(j, 0) for j in others] for c, _ in relations])
    values = sympy.Matrix([v for _, v in relations])
    inverse = A.inv()
    coefficients, offsets = inverse * B, inverse * values
    return {j: ({k: coefficients[r, c] for c, k in enumerate(others) if coefficients[r, c] != 0}, offsets[r])
            for r, j in enumerate(unknown)}


def coupled_model(system: LoopSystem) -> RobotModel:
    """A model whose loops are all parallelograms as the same tree with its dependent joints
    linear in the independent ones (:class:`kindyngen.model.robot_model.Mimic` with terms): the
    constant-G case of :mod:`kindyngen.algorithms.reduced_coordinates` (the loops kept for the
    texts)."""
    assert system.closed is not None and system.closed.linear
    expressions: dict = {j: ({j: sympy.Integer(1)}, sympy.Integer(0)) for j in system.independent}
    for _, _, unknown, relations in system.closed.steps:
        for j, (terms, offset) in _linear_solution(relations, unknown).items():
            total: dict = {}
            for k, c in terms.items():
                inner, inner_offset = expressions[k]
                offset += c * inner_offset
                for i, ci in inner.items():
                    total[i] = total.get(i, 0) + c * ci
            expressions[j] = ({i: c for i, c in total.items() if c != 0}, offset)
    joints = list(system.free.joints)
    for j in system.dependent:
        terms, offset = expressions[j]
        sources = sorted(terms.items())
        if not sources:
            raise _error(system.model, "loops", f"joint {joints[j].name!r} is held fixed by the loops")
        (first, multiplier), rest = sources[0], tuple(sources[1:])
        joints[j] = replace(joints[j], mimic=Mimic(first, multiplier, offset, rest))
    return replace(system.model, joints=tuple(joints))


def closed_form_expressions(system: LoopSystem, q_reduced, name, trig: dict | None = None) -> list:
    """Every joint's position (n expressions) in the independent joints ``q_reduced``: the
    closed form's steps in turn, each step's intermediates named by ``name``. ``trig``, if
    given, receives ``cos(q_j)`` and ``sin(q_j)`` (in the tree's symbols) of each dyad joint j
    as expressions without a call: its loop point's in-plane vector ``(x, y)`` in j's frame has
    the constant length r and the angle ``q_j + alpha``, so ``cos(q_j) = (x cos(alpha) + y
    sin(alpha)) / r``, ``sin(q_j) = (y cos(alpha) - x sin(alpha)) / r``."""
    free = system.free
    full = [None] * free.n
    for a, j in enumerate(system.independent):
        full[j] = q_reduced[a]
    symbols = port_symbols("q", (free.n,))
    for kind, index, unknown, data in system.closed.steps:
        if kind == "linear":
            for j, (terms, offset) in _linear_solution(data, unknown).items():
                full[j] = name(se.Add(constant(offset), *(constant(c) * full[k] for k, c in terms.items())))
            continue
        loop = system.model.loops[index]
        # the poses of the two dependent joints' frames, every joint above them known
        values = {s: full[k] for k, s in enumerate(symbols) if full[k] is not None}
        _, links, axes = link_poses(free, symbols)
        z, P = axes[data.joint_a]
        Rqa = _joint_frame_rotation(free, links, data.joint_a)
        _, Q = axes[data.joint_b]
        Rqb = _joint_frame_rotation(free, links, data.joint_b)
        z, P, Q = (m.xreplace(values) for m in (z, P, Q))
        Rqa, Rqb = Rqa.xreplace(values), Rqb.xreplace(values)
        z = [name(e) for e in z]
        dq = [name(Q[k] - P[k]) for k in range(3)]
        along = name(se.Add(*(z[k] * dq[k] for k in range(3))))
        u = [name(dq[k] - along * z[k]) for k in range(3)]
        d2 = name(se.Add(*(e * e for e in u)))
        ra2, rb2 = constant(data.radius_a ** 2), constant(data.radius_b ** 2)
        # a u + s h (n x u) over d: with t = a / d and k = h / d, F - P = t u + s k (n x u)
        t = name((ra2 - rb2 + d2) / (2 * d2))
        k = name(se.sqrt(ra2 / d2 - t * t))
        nxu = [z[1] * u[2] - z[2] * u[1], z[2] * u[0] - z[0] * u[2], z[0] * u[1] - z[1] * u[0]]
        w = [name(t * u[c] + data.sign * k * nxu[c]) for c in range(3)]
        wb = [name(w[c] - u[c]) for c in range(3)]
        for joint, R, vector, angle, radius in ((data.joint_a, Rqa, w, data.angle_a, data.radius_a),
                                                (data.joint_b, Rqb, wb, data.angle_b, data.radius_b)):
            # the vector's angle in the joint's frame is q + angle + offset; measured from its
            # value at the reference, so that atan2's cut lies half a turn from the reference
            x = name(se.Add(*(R[c, 0] * vector[c] for c in range(3))))
            y = name(se.Add(*(R[c, 1] * vector[c] for c in range(3))))
            if trig is not None and free.joints[joint].offset == 0:
                ca, sa = constant(sympy.cos(angle) / radius), constant(sympy.sin(angle) / radius)
                trig[se.cos(symbols[joint])] = name(ca * x + sa * y)
                trig[se.sin(symbols[joint])] = name(ca * y - sa * x)
            # (the reference to a thousandth: any value serves, a round one prints the same everywhere)
            at = sympy.Rational(round(system.reference[joint] * 1000), 1000)
            turn = sympy.sympify(at) + angle + sympy.sympify(free.joints[joint].offset)
            c, s = constant(sympy.cos(turn)), constant(sympy.sin(turn))
            full[joint] = name(se.atan2(name(c * y - s * x), name(c * x + s * y)) + constant(at))
    return full


def _joint_frame_rotation(free: RobotModel, links, j: int):
    """The world rotation of joint j's frame before its motion (z: its axis)."""
    parent = free.parents[j]
    above = links[parent] if parent >= 0 else (se.eye(3), se.zeros(3, 1))
    frame = compose(above, constant_transform(free.joints[j].before))
    return frame[0]
