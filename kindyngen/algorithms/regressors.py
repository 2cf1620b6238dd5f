"""Linear parametrisation of the dynamics: regressors on base parameters (identification
paper, Sect. V, eqs. 17, 18, 23), one derivation for every robot.

The dynamics is linear in the bodies' barycentric parameters (10 per body: m, mx, my, mz,
Ixx, Ixy, Iyy, Ixz, Iyz, Izz in the link frame, inertia about its origin; a floating base's
root body is body 0 and comes first, then the link of joint j as body j + 1, see
:mod:`kindyngen.model.inertial_parameters`) and in the description's joint-effect
coefficients (``fv1``, ``fc1``, ``f01``, ``Ia1``, ...: :mod:`kindyngen.algorithms.effect_torques`):

* ``Y(q, qd, qdd) -> Y``, shape ``(nv, p)``: ``tau = Y(q, qd, qdd) pi``, for every robot;
* ``Y_g(q) -> Y``, shape ``(n, p_g)``: ``g(q) = Y_g(q) pi_g`` (eq. 17);
* ``Y_m(q) -> Y``, shape ``(n(n+1)/2, p_m)``: the inertia stack ``m~(q) = Y_m(q) pi_m``
  (eq. 18), the lower triangle of M row by row: ``M00, M10, M11, M20, M21, M22, ...``
  (row ``i(i+1)/2 + j`` holds ``M_ij``, ``j <= i``, 0-based).

Y's column of a link parameter is the torque a unit value of it causes: that body's wrench in
its joint frame (``F = m a + U h``, ``N = I wd + w x I w + h x a`` with the motion of
:func:`kindyngen.algorithms.dynamics.motion_states`) carried up to every ancestor joint (and
the floating base), so entries for joints off the body's branch are exact zeros and nothing is
differentiated.  Y_g's and Y_m's columns are the parameter derivatives (``se.diff`` on the DAG)
of the Lagrange route's g and M (:data:`SOURCES`).  An effect coefficient's column is what
multiplies it on its joint's row (``qd_i``, the Coulomb shape, 1, ``qdd_i``; the armature's is 1
on ``M_ii`` in Y_m).

The base parameters are found by :func:`kindyngen.algorithms.base_parameters.find_base_parameters`
on one numeric evaluation of the full regressor at random states (:func:`random_states`,
:func:`evaluate_full`; every decision exact or with its stated margin): independent columns kept
in parameter order, the others grouped into them (paper eq. 23), so ``Y`` times the base values
equals the dynamics.  The regressors do not depend on the inertial values, so numeric and
symbolic mode register the same functions.

Example:

>>> from kindyngen.readers.urdf import parse_urdf
>>> from kindyngen.readers.urdf import TWO_PENDULUMS
>>> b = base_parameters(parse_urdf(TWO_PENDULUMS, tree=True), "Y")
>>> b.rank, b.names      # left turns about y: mx, mz, Iyy act; right about x: my, mz, Ixx
(6, ('mx1', 'mz1', 'Iyy1', 'my2', 'mz2', 'Ixx2'))
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache, reduce

import numpy as np
import symengine as se
import sympy

from .base_parameters import BaseParameterError, BaseParameters, find_base_parameters
from .dynamics import carry, conventions as dynamics_conventions, force_port, frame_body, motion_states, rnea, setup
from .effect_torques import effect_columns, effect_parameter_names, effect_parameter_values
from .joint_frame_steps import mat3
from .kinematics_conventions import q_port
from .lagrange import gravity_lagrange, mass_matrix_lagrange
from .loop_closure import coupled_model, loop_system
from .reduced_coordinates import coordinate_map, reduced_input
from .rigid_bodies import ZERO, cross, qd_port, qdd_port, vadd, vscale
from .symbolic import Port, Stages, SymbolicFunction, naming, port_symbols
from ..model.inertial_parameters import NAMES, barycentric, exact_parameter_vector
from ..model.robot_model import FREE_FLYER_NV, RobotModel

KINDS = ("Y_g", "Y_m", "Y")
# what Y_g and Y_m differentiate: the Lagrange route, whose parameter derivatives cost least
# after CSE (LWR4: Y_g 31/70 add/mul from g_lagrange against 47/107 from g; Y_m 328/764 from
# M_lagrange against 708/1086 from the composite-body M). That route sums a chain's energies,
# so Y_g and Y_m are chain-only (:func:`kinds`); Y's link columns are carried up the tree
# (LWR4: 512/719 against 3666/4792 from the Lagrange energy) and exist for every robot.
SOURCES = {"Y_g": gravity_lagrange,
           "Y_m": lambda model, params: mass_matrix_lagrange(model, params, effects=False)}
QUANTITY = {"Y_g": "g", "Y_m": "M", "Y": "tau"}
SAMPLES = {"Y_g": 40, "Y_m": 12, "Y": 40}          # random states for the rank analysis
SEEDS = (20140, 20141)                             # analysis, verification

SUMMARIES = {
    "Y_g": "Gravity regressor on base parameters: g(q) = Y_g(q) pi_g (identification paper eq. 17).",
    "Y_m": ("Inertia-stack regressor on base parameters: the lower triangle of M row by row "
            "(M00, M10, M11, M20, ...) = Y_m(q) pi_m (identification paper eq. 18)."),
    "Y": "Torque regressor on base parameters: tau = M(q) qdd + c(q, qd) + g(q) = Y(q, qd, qdd) pi.",
}


def kinds(model: RobotModel) -> tuple[str, ...]:
    """The regressors ``model`` has: Y always, Y_g and Y_m for a chain without mimic joints,
    however it was read (their sources, :data:`SOURCES`, are written for chains of independent
    joints)."""
    return KINDS if model.is_chain and not model.has_mimics and not model.has_loops else ("Y",)


def reduced_model(model: RobotModel) -> RobotModel | None:
    """The model the regressor is derived on: ``model``, or for a tree closed by loops that
    are all parallelograms its coupled model (constant G:
    :func:`kindyngen.algorithms.loop_closure.coupled_model`, itself: its mimic joints are
    the loops' linear relations); None for other loops."""
    if not model.has_loops or model.has_mimics:
        return model
    system = loop_system(model)
    return coupled_model(system) if system.closed is not None and system.closed.linear else None


# ----------------------------------------------------------------------------- parameters

def body_labels(model: RobotModel) -> tuple[str, ...]:
    """The link each parameter block belongs to, in column order."""
    return ((model.base_name,) if model.floating_base else ()) + tuple(
        _link_name(model, j) for j in range(model.n))


def _link_name(model: RobotModel, j: int) -> str:
    names = [f.name for f in model.frames if f.body == j and f.placement.is_identity]
    return names[0] if names else model.joints[j].name


def link_parameter_names(model: RobotModel) -> tuple[str, ...]:
    """``m0 .. Izz0`` for a floating base's root body, then ``m1 .. Izz1`` for joint 0's link, ..."""
    first = 0 if model.floating_base else 1
    return tuple(f"{name}{first + b}" for b in range(len(body_labels(model))) for name in NAMES)


def effect_names(model: RobotModel, kind: str) -> tuple[str, ...]:
    """The effect coefficients that are columns of regressor ``kind``: all of the
    description's for ``Y``, the armature for ``Y_m`` (only it enters M), none for ``Y_g``."""
    names = effect_parameter_names(model)
    return {"Y": names, "Y_m": tuple(n for n in names if n.startswith("Ia")), "Y_g": ()}[kind]


def full_values(model: RobotModel, kind: str) -> tuple:
    """Exact values of the full regressor's parameters: the barycentric ones of the bodies (a
    floating base's root first; a payload merged into the last link) followed by the effect
    coefficients of ``kind``."""
    root = barycentric(model.root) if model.floating_base else ()
    effects = dict(zip(effect_parameter_names(model), effect_parameter_values(model)))
    return tuple(root) + exact_parameter_vector(model) + tuple(effects[name] for name in effect_names(model, kind))


# ----------------------------------------------------------------------------- the full regressor

@dataclass(frozen=True)
class FullRegressor:
    """A dynamics quantity as rows linear in the parameters ``p``: the barycentric ones of the
    bodies, then the description's joint-effect coefficients of ``kind``.  A link parameter's
    column is ``d rigid_rows / d p_k`` where ``rigid_rows`` is given (Y_g, Y_m, the
    dual-quaternion Y_dq), else (Y) the torque its unit value causes, carried up the tree;
    an effect coefficient's is ``effect_columns[k - links]`` (per row)."""

    model: RobotModel
    kind: str
    inputs: tuple[Port, ...]
    input_symbols: tuple[tuple[se.Symbol, ...], ...]
    p: tuple[se.Symbol, ...]
    rigid_rows: tuple[se.Basic, ...] | None
    effect_columns: tuple[tuple[se.Basic, ...], ...]
    row_names: tuple[str, ...]

    @property
    def links(self) -> int:
        """How many of ``p`` are link parameters."""
        return len(self.p) - len(self.effect_columns)

    def columns(self, indices, stages: Stages | None = None) -> tuple[se.Basic, ...]:
        """Row-major entries of the regressor restricted to columns ``indices``; with
        ``stages``, Y's carried motion states and wrenches are named there. A model with mimic
        joints: the full tree's rows contracted with G (``G^T Y_x``) and rewritten in the
        independent coordinates (:mod:`kindyngen.algorithms.reduced_coordinates`), its
        intermediates too."""
        if self.model.has_mimics:
            cmap = coordinate_map(self.model)
            start = len(stages.definitions) if stages is not None else 0
            entries = full_regressor(cmap.free, self.kind).columns(indices, stages)
            entries = cmap.contract(entries, (cmap.nv_full, len(indices)), (0,))
            sub = cmap.substitution()
            if stages is not None:
                stages.substitute(sub, start)
            return tuple(e.xreplace(sub) for e in entries)
        wanted = sorted(k for k in indices if k < self.links)
        if self.rigid_rows is None:
            column = dict(zip(wanted, link_parameter_columns(self.model, frozenset(wanted), stages)))
        else:
            column = {k: [se.diff(row, self.p[k]) for row in self.rigid_rows] for k in wanted}
        return tuple(column[k][r] if k < self.links else self.effect_columns[k - self.links][r]
                     for r in range(len(self.row_names)) for k in indices)


@lru_cache(maxsize=None)
def full_regressor(model: RobotModel, kind: str) -> FullRegressor:
    """The rows (tau, g or the inertia stack) of ``model`` as functions of q (qd, qdd) and p."""
    if kind not in kinds(model):
        raise ValueError(f"kind must be one of {kinds(model)} for {model.identifier}, got {kind!r}")
    n, zero = model.n, se.Integer(0)
    if model.has_mimics:        # the full tree's, contracted and rewritten by columns()
        free = full_regressor(model.without_mimics(), kind)
        inputs = tuple(reduced_input(model, port, free.model) for port in free.inputs)
        symbols = (port_symbols("q", (model.nq,)), port_symbols("qd", (model.nv,)), port_symbols("qdd", (model.nv,)))
        return replace(free, model=model, inputs=inputs, input_symbols=symbols,
                       row_names=tuple(f"tau{i}" for i in range(model.nv)))
    if kind == "Y":
        inputs = (q_port(model), qd_port(model), qdd_port(model))
        input_symbols = (setup(model).q, port_symbols("qd", (model.nv,)), port_symbols("qdd", (model.nv,)))
        rigid_rows, link_names = None, link_parameter_names(model)
        base = FREE_FLYER_NV if model.floating_base else 0
        qd, qdd = input_symbols[1][base:], input_symbols[2][base:]
        y = None
        if "load_dependent_friction" in model.effects:
            # the load-dependent column |y| s holds the transmitted torque of the description's
            # own parameters (the term is bilinear): tau = Y p is exact at those parameters
            rigid = rnea(setup(model), input_symbols[1], input_symbols[2])[base:]
            y = [t + se.sympify(model.armature(i)) * qdd[i] if model.armature(i) != 0 else t
                 for i, t in enumerate(rigid)]
        shapes = effect_columns(model, input_symbols[0] if base == 0 else None, qd, qdd, y)
        row_index = {i: base + i for i in range(n)}
        row_names = tuple(f"tau{i}" for i in range(model.nv))
    else:
        f = SOURCES[kind](model, "symbolic")
        k = [port.name for port in f.inputs].index("p")
        link_names = tuple(map(str, f.input_symbols[k]))
        assert link_names == link_parameter_names(model), "catalog p is not the barycentric vector"
        inputs, input_symbols = f.inputs[:k] + f.inputs[k + 1:], f.input_symbols[:k] + f.input_symbols[k + 1:]
        exprs = f.output_exprs[0]
        # the armature's column is 1 on M_ii (qd = 0, qdd = 1 in its torque)
        shapes = effect_columns(model, [zero] * n, [zero] * n, [se.Integer(1)] * n, [zero] * n)
        if kind == "Y_m":
            rigid_rows = tuple(exprs[i * n + j] for i in range(n) for j in range(i + 1))
            row_names = tuple(f"M{i}{j}" if n <= 10 else f"M{i}_{j}" for i in range(n) for j in range(i + 1))
            row_index = {i: i * (i + 1) // 2 + i for i in range(n)}      # M_ii in the stack
        else:
            rigid_rows, row_names, row_index = tuple(exprs), tuple(f"g{i}" for i in range(n)), {}
    # the joint effects: coefficients appended to p, each a column that acts on one joint's row
    # (friction and offset on tau only, the armature on tau and M's diagonal)
    wanted = effect_names(model, kind)
    chosen = [c for name, c in zip(effect_parameter_names(model), shapes) if name in wanted]
    effect_cols = tuple(tuple(shape if r == row_index[i] else zero for r in range(len(row_names)))
                        for i, shape in chosen)
    p = tuple(se.Symbol(name) for name in link_names + wanted)
    return FullRegressor(model, kind, inputs, input_symbols, p, rigid_rows, effect_cols, row_names)


def _unit_wrenches(after, a, w, wd, U):
    """The wrench in the joint frame of each of a body's 10 unit parameters."""
    out = []
    for k in range(10):
        body = frame_body([1 if i == k else 0 for i in range(10)], after)
        h, I, m = body.h, body.I, body.m
        F = vscale(m, a) if U is None else vadd(vscale(m, a), mat3(U, h))
        N = cross(h, a) if U is None else vadd(mat3(I, wd), cross(w, mat3(I, w)), cross(h, a))
        out.append((F, N))
    return out


def link_parameter_columns(model: RobotModel, wanted=None, stages: Stages | None = None) -> list:
    """The torque regressor's link-parameter columns (each nv entries) in parameter order, only
    those in ``wanted`` if given, on the symbols of :func:`full_regressor`; with ``stages``,
    every motion state and carried wrench is named there."""
    name = naming(stages)
    ts = setup(model)
    qd, qdd = port_symbols("qd", (model.nv,)), port_symbols("qdd", (model.nv,))
    root_state, state = motion_states(ts, qd, qdd, True, stages)
    base = FREE_FLYER_NV if model.floating_base else 0
    blocks = ((None, -1, root_state),) if model.floating_base else ()
    blocks += tuple((model.joints[j].after, j, state[j]) for j in range(model.n))
    columns = []
    for index, (after, j, motion) in enumerate(blocks):
        for k, (F, N) in enumerate(_unit_wrenches(after, *motion)):
            if wanted is not None and 10 * index + k not in wanted:
                continue
            column = [ZERO] * model.nv
            node = j
            while node >= 0:
                column[base + node] = F[2] if model.joints[node].prismatic else N[2]
                F, N = carry(ts.joints[node], F, N)
                F, N = [name(e) for e in F], [name(e) for e in N]
                node = model.parents[node]
            if model.floating_base:
                column[0:6] = list(F) + list(N)
            columns.append(column)
    return columns


# ----------------------------------------------------------------------------- numeric evaluation

def random_states(model: RobotModel, count: int, seed: int) -> dict:
    """Random inputs of Y (those of Y_g and Y_m are its q): q with joints within their limits
    (clipped to +-pi) and a floating base anywhere within 1 m with a random unit quaternion;
    qd and qdd standard normal."""
    rng = np.random.default_rng(seed)
    lower = np.array([max(j.lower, -np.pi) for j in model.coordinate_joints])
    upper = np.array([min(j.upper, np.pi) for j in model.coordinate_joints])
    q = rng.uniform(lower, upper, size=(count, lower.size))
    if model.floating_base:
        quat = rng.standard_normal((count, 4))
        q = np.hstack([rng.uniform(-1, 1, (count, 3)), quat / np.linalg.norm(quat, axis=1, keepdims=True), q])
    velocities = rng.standard_normal((count, 2 * model.nv))
    return {"q": q, "qd": velocities[:, :model.nv], "qdd": velocities[:, model.nv:]}


def _select(*args):
    """A Piecewise's value: the first branch whose condition holds."""
    values = np.broadcast_arrays(*args)
    return np.select(values[1::2], values[0::2])


_FUNCTIONS = {"sin": np.sin, "cos": np.cos, "tanh": np.tanh, "exp1": lambda: np.e, "abs": np.abs, "atan2": np.arctan2,
              "piecewise": _select,
              "strictlessthan": np.less, "booleantrue": lambda: True}


def evaluate_dag(exprs, values: dict) -> list:
    """Numeric values of symengine expressions at arrays of ``values`` (symbol -> array), each
    shared node evaluated once, in one walk of the DAG (cheaper than compiling it: the full
    regressor is evaluated at one batch of states per decision).

    >>> x = se.Symbol("x")
    >>> evaluate_dag([se.sin(x) ** 2 + 3 * x], {x: np.array([0.0, 1.0])})[0].tolist()
    [0.0, 3.708073418273571]
    """
    done = {k: np.asarray(v, float) for k, v in values.items()}
    stack = list(exprs)
    while stack:
        e = stack[-1]
        if e in done:
            stack.pop()
            continue
        if e.is_Number:
            done[e] = float(e)
            stack.pop()
            continue
        pending = [a for a in e.args if a not in done]
        if pending:
            stack.extend(pending)
            continue
        stack.pop()
        args = [done[a] for a in e.args]
        if isinstance(e, se.Add):
            done[e] = sum(args[1:], args[0])
        elif isinstance(e, se.Mul):
            value = args[0]
            for a in args[1:]:
                value = value * a
            done[e] = value
        elif isinstance(e, se.Pow):
            done[e] = args[0] ** args[1]
        else:
            done[e] = _FUNCTIONS[type(e).__name__.lower()](*args)
    return [done[e] for e in exprs]


@lru_cache(maxsize=None)
def _all_columns(model: RobotModel, kind: str) -> tuple[se.Basic, ...]:
    full = full_regressor(model, kind)
    return full.columns(range(len(full.p)))


def evaluate_full(model: RobotModel, kind: str, inputs: dict, chunk: int = 512) -> np.ndarray:
    """The full regressor ``kind`` (samples x rows x parameters) at numeric ``inputs`` (port
    name -> samples x size), in chunks of ``chunk`` samples (the walk keeps every node's
    values)."""
    full = full_regressor(model, kind)
    x = np.concatenate([np.asarray(inputs[port.name], float).reshape(-1, port.size) for port in full.inputs], axis=1)
    symbols = [s for group in full.input_symbols for s in group]
    entries = _all_columns(model, kind)
    out = np.empty((x.shape[0], len(entries)))
    for start in range(0, x.shape[0], chunk):
        part = x[start:start + chunk]
        values = evaluate_dag(entries, {s: part[:, k] for k, s in enumerate(symbols)})
        out[start:start + chunk] = np.stack([np.broadcast_to(v, (part.shape[0],)) for v in values], axis=1)
    return out.reshape(x.shape[0], len(full.row_names), len(full.p))


# ----------------------------------------------------------------------------- base parameters

def common_denominator(model: RobotModel) -> int | None:
    """A common denominator of every grouping coefficient: the squared lcm of the joint
    placements' lengths' denominators (and of mimic multipliers) when all lengths are rational
    and every constant rotation is a signed permutation (DH: cos and sin of each alpha and
    offset in {0, 1, -1}, a revolute mimic's offset 0); else None."""
    dens = []
    for joint in model.joints:
        offsets = [joint.offset] + ([joint.mimic.offset] if joint.mimic is not None else [])
        if not joint.prismatic:
            for v in [f(o) for o in offsets for f in (sympy.cos, sympy.sin)]:
                if v not in (0, 1, -1):
                    return None
        if joint.mimic is not None:
            dens += [int(sympy.Rational(multiplier).q) for _, multiplier in joint.mimic.sources]
        lengths = offsets if joint.prismatic else []
        for placement in (joint.before, joint.after):
            R, p = placement.matrix()
            if any(v not in (0, 1, -1) for v in R):
                return None
            lengths += list(p)
        for length in lengths:
            length = sympy.sympify(length)
            if not length.is_Rational:
                return None
            dens.append(int(length.q))
    lcm = reduce(math.lcm, dens, 1)
    return lcm * lcm


@lru_cache(maxsize=None)
def base_parameters(model: RobotModel, kind: str = "Y") -> BaseParameters:
    """Rank analysis and grouping of the full regressor ``kind`` of ``model``."""
    full = full_regressor(model, kind)

    def evaluate(seed):
        return evaluate_full(model, kind, random_states(model, SAMPLES[kind], seed))

    return find_base_parameters(evaluate, tuple(map(str, full.p)), SEEDS, common_denominator(model))


def supported(model: RobotModel) -> bool:
    """Regressors need numeric lengths (the grouping coefficients are found numerically)."""
    return not model.length_symbols


@lru_cache(maxsize=None)
def unavailable(model: RobotModel, kind: str = "Y") -> str | None:
    """Why regressor ``kind`` is not generated for ``model``, or None when it is: symbolic
    lengths, or a rank / column decision the samples cannot make with the stated margin
    (:func:`kindyngen.algorithms.base_parameters.check_margin`; seen on real arms with millimetre
    offsets, e.g. the Kinova Jaco 2's joint 2, 1.6 mm off joint 1's axis). The other
    functions are generated all the same."""
    if not supported(model):
        return "symbolic lengths"
    if reduced_model(model) is None:
        return ("closed loops with a configuration-dependent G (the base parameters are decided on samples, and "
                "only parallelogram loops are reduced with a constant G)")
    model = reduced_model(model)
    try:
        base_parameters(model, kind)
    except BaseParameterError as exc:
        return f"base parameters undecided ({exc})"
    return None


def undecided_notes(model: RobotModel, only=None) -> list[str]:
    """One line per regressor (of ``only``, default all) left out because its base parameters
    could not be decided (robots with symbolic lengths have none, and say so elsewhere)."""
    return [f"{model.identifier}: regressor {kind} not generated: {unavailable(model, kind)}"
            for kind in kinds(model) if (only is None or kind in only)
            and unavailable(model, kind) not in (None, "symbolic lengths")]


# ----------------------------------------------------------------------------- the functions

def regressor(model: RobotModel, kind: str = "Y", name: str | None = None) -> SymbolicFunction | None:
    """``Y(q, qd, qdd)``, ``Y_g(q)`` or ``Y_m(q)`` on base parameters (output port ``Y``);
    None where :func:`unavailable` says why not."""
    if unavailable(model, kind):
        return None
    model = reduced_model(model)
    full = full_regressor(model, kind)
    base = base_parameters(model, kind)
    rows, cols = len(full.row_names), len(base.base)
    stages = Stages()
    exprs = full.columns(base.base, stages)
    what = {"Y_g": "gravity torques g", "Y_m": "inertia stack (lower triangle of M, row by row)",
            "Y": "base wrench and joint torques tau" if model.floating_base else "joint torques tau"}[kind]
    unit = "kg m^2" if kind == "Y_m" else force_port(model, "tau", "torque").unit
    port = Port("Y", (rows, cols), f"regressor of the {what} on the base parameters (row-major; "
                f"columns: {', '.join(base.names)})", f"{unit} per base parameter")
    gx, gy, gz = (float(g) for g in model.gravity)
    # a tree's joints and base are worded as its dynamics' headers word them
    lead = (dynamics_conventions(model).split(" Inertial parameters")[0] if model.is_tree else
            f"Joint space in DH order: q (rad), qd (rad/s), qdd (rad/s^2). Gravity in the base frame: "
            f"({gx:g}, {gy:g}, {gz:g}) m/s^2.")
    bodies = "per body, body 0 the floating base and body j + 1 the link of joint j" if model.floating_base \
        else "per link"
    conventions = (
        f"{lead} Rows: {', '.join(full.row_names)}. "
        f"Columns: the {cols} base parameters (rank of the full {len(base.full_names)}-column regressor), "
        f"named after the barycentric parameter each is led by (m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, "
        f"Izz {bodies}, inertia about the link frame origin in link-frame axes; suffix R: other "
        f"parameters grouped into it); their expressions and the robot's values are in "
        f"base_params.json. Y times those values equals the modelled quantity. {model.mimic_text}").strip()
    return SymbolicFunction(
        name=name or kind, summary=SUMMARIES[kind],
        inputs=full.inputs, outputs=(port,), input_symbols=full.input_symbols, output_exprs=(exprs,),
        conventions=conventions,
        metadata={"params": "none", "base_parameters": base.names}, stages=stages.definitions)


def base_params_document(model: RobotModel, left_out=()) -> dict | None:
    """Content of ``base_params.json``: per regressor the base parameters in column order,
    their expressions in the barycentric symbols and their values for the robot's
    description (``Y @ values`` is the modelled quantity), rank and column count; for a tree
    also which link each body is (None for a robot with symbolic lengths). A regressor in
    ``left_out`` (above a run's limits, kindyngen/codegen/budget.py) is not analysed: deciding
    its base parameters costs as much as deriving it."""
    if not supported(model):
        return None
    out = {}
    for kind in kinds(model):
        if kind in left_out:
            out[kind] = {"unavailable": "left out above the run's limits of CPU time and memory "
                                        "(docs/reference/cli.md, 'Large robots')"}
            continue
        if unavailable(model, kind):
            out[kind] = {"unavailable": unavailable(model, kind)}
            continue
        model = reduced_model(model)
        b = base_parameters(model, kind)
        out[kind] = {
            "names": list(b.names),
            "expressions": list(b.expression_strings()),
            # exact sums of the description's rationals, rounded once to a double
            "values": [float(v) for v in b.exact_values(full_values(model, kind))],
            "rank": b.rank,
            "full_columns": len(b.full_names),
            "exact": b.exact,
        }
        if model.is_tree:     # an arm's bodies are its links in order (its files predate the key)
            out[kind]["bodies"] = list(body_labels(model))
    return out
