"""The torque regressor of a kinematic tree on its base parameters: ``tau = Y(q, qd, qdd) pi``.

tau is linear in the bodies' barycentric parameters (10 per body: m, mx, my, mz, Ixx, Ixy,
Iyy, Ixz, Iyz, Izz in the link frame, inertia about its origin; a floating base's root body
is body 0 and comes first, then the link of joint j as body j + 1). Column k of the full
regressor is the torque a unit parameter k causes: that body's wrench in its joint frame
(``F = m a + U h``, ``N = I wd + w x I w + h x a`` with the motion of
:func:`kindyngen.algorithms.dynamics.motion_states`; each unit parameter gives one term) carried up
to every ancestor joint (and the floating base), so entries for joints off the body's branch
are exact zeros and nothing is differentiated. The base parameters are found by
:func:`kindyngen.algorithms.base_parameters.find_base_parameters` (independent columns in parameter
order, the others grouped into them, every decision with its stated margin), and ``Y`` keeps
the base columns.

Example:

>>> from kindyngen.readers.urdf import parse_urdf
>>> from kindyngen.readers.urdf import TWO_PENDULUMS
>>> b = tree_base_parameters(parse_urdf(TWO_PENDULUMS, tree=True))
>>> b.rank, b.names      # left turns about y: mx, mz, Iyy act; right about x: my, mz, Ixx
(6, ('mx1', 'mz1', 'Iyy1', 'my2', 'mz2', 'Ixx2'))
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import symengine as se

from .base_parameters import BaseParameterError, BaseParameters, find_base_parameters
from ..model.inertial_parameters import NAMES, barycentric
from .rigid_bodies import ZERO, cross, vadd, vscale
from .joint_frame_steps import mat3
from .symbolic import Port, Stages, SymbolicFunction, naming, port_symbols
from .kinematics_conventions import q_port
from .rigid_bodies import qd_port, qdd_port
from .dynamics import carry, conventions, frame_body, motion_states, setup
from ..model.robot_model import FREE_FLYER_NV, RobotModel

SAMPLES, SEEDS = 40, (20140, 20141)      # random states for the rank analysis; analysis, verification


def body_labels(model: RobotModel) -> tuple[str, ...]:
    """The link each parameter block belongs to, in column order."""
    return ((model.base_name,) if model.floating_base else ()) + tuple(
        _link_name(model, j) for j in range(model.n))


def _link_name(model: RobotModel, j: int) -> str:
    names = [f.name for f in model.frames if f.body == j and f.placement.is_identity]
    return names[0] if names else model.joints[j].name


def parameter_names(model: RobotModel) -> tuple[str, ...]:
    """``m0 .. Izz0`` for a floating base's root body, then ``m1 .. Izz1`` for joint 0's link, ..."""
    first = 0 if model.floating_base else 1
    return tuple(f"{name}{first + b}" for b in range(len(body_labels(model))) for name in NAMES)


def parameter_values(model: RobotModel) -> tuple:
    """The description's barycentric parameters, exact, in :func:`parameter_names` order."""
    links = ((model.root,) if model.floating_base else ()) + tuple(model.links)
    return tuple(v for link in links for v in barycentric(link))


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


@lru_cache(maxsize=None)
def full_tree_regressor(model: RobotModel):
    """(q, qd, qdd symbols, rows: nv lists of 10 B expressions) of the full regressor."""
    symbols, columns = link_parameter_columns(model)
    return symbols, tuple(tuple(column[r] for column in columns) for r in range(model.nv))


def link_parameter_columns(model: RobotModel, wanted=None, stages: Stages | None = None):
    """(q, qd, qdd symbols, the regressor's columns in parameter order, only those in
    ``wanted`` if given); with ``stages``, every motion state and carried wrench is named
    there."""
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
    return (ts.q, qd, qdd), columns


def random_states(model: RobotModel, count: int, seed: int) -> np.ndarray:
    """q (joints within limits, clipped to +-pi; a floating base anywhere within 1 m with a
    random unit quaternion), qd and qdd standard normal, stacked per sample."""
    rng = np.random.default_rng(seed)
    lower = np.array([max(j.lower, -np.pi) for j in model.joints])
    upper = np.array([min(j.upper, np.pi) for j in model.joints])
    q = rng.uniform(lower, upper, size=(count, model.n))
    if model.floating_base:
        quat = rng.standard_normal((count, 4))
        q = np.hstack([rng.uniform(-1, 1, (count, 3)), quat / np.linalg.norm(quat, axis=1, keepdims=True), q])
    return np.hstack([q, rng.standard_normal((count, 2 * model.nv))])


_FUNCTIONS = {"sin": np.sin, "cos": np.cos}


def evaluate_dag(exprs, values: dict) -> list:
    """Numeric values of symengine expressions at arrays of ``values`` (symbol -> array), each
    shared node evaluated once, in one walk of the DAG (cheaper than compiling it here: the
    full regressor is evaluated at one batch of samples only).

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
            done[e] = _FUNCTIONS[type(e).__name__.lower()](args[0])
    return [done[e] for e in exprs]


def _full_numeric(model: RobotModel, states: np.ndarray) -> np.ndarray:
    """The full regressor at stacked states (samples x (nq + 2 nv)): samples x nv x 10 B."""
    symbols, rows = full_tree_regressor(model)
    args = [s for group in symbols for s in group]
    entries = [e for row in rows for e in row]
    values = evaluate_dag(entries, {s: states[:, k] for k, s in enumerate(args)})
    out = np.stack([np.broadcast_to(v, (states.shape[0],)) for v in values], axis=1)
    return out.reshape(states.shape[0], model.nv, -1)


@lru_cache(maxsize=None)
def tree_base_parameters(model: RobotModel) -> BaseParameters:
    """Rank analysis and grouping of the full regressor (see the module text)."""
    names = parameter_names(model)

    def evaluate(seed):
        return _full_numeric(model, random_states(model, SAMPLES, seed))

    return find_base_parameters(evaluate, names, SEEDS, None)


def unavailable(model: RobotModel) -> str | None:
    """Why Y is not generated (a rank or column decision the samples cannot make with the
    stated margin), or None."""
    try:
        tree_base_parameters(model)
    except BaseParameterError as exc:
        return f"base parameters undecided ({exc})"
    return None


def tree_regressor(model: RobotModel, name: str = "Y") -> SymbolicFunction | None:
    """``Y(q, qd, qdd)`` on the base parameters (None where :func:`unavailable` says why not)."""
    if unavailable(model):
        return None
    b = tree_base_parameters(model)
    stages = Stages()
    (q, qd, qdd), columns = link_parameter_columns(model, frozenset(b.base), stages)
    column = {k: columns[i] for i, k in enumerate(sorted(b.base))}
    exprs = tuple(column[k][r] for r in range(model.nv) for k in b.base)
    port = Port("Y", (model.nv, len(b.base)), "regressor of tau on the base parameters (row-major; columns: "
                + ", ".join(b.names) + ")", "tau's units per base parameter")
    text = (f"{conventions(model).split(' Inertial parameters')[0]} Columns: the {len(b.base)} base parameters "
            f"(rank of the full {len(b.full_names)}-column regressor), named after the barycentric parameter each "
            "is led by (m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz per body, inertia about the link frame origin "
            "in link-frame axes; body 0 the floating base, body j + 1 the link of joint j; suffix R: parameters "
            "grouped into it); expressions and the robot's values in base_params.json. Y times those values is tau.")
    return SymbolicFunction(name, "Torque regressor on base parameters: tau = M qdd + c + g = Y(q, qd, qdd) pi.",
                            (q_port(model), qd_port(model), qdd_port(model)), (port,),
                            (q, qd, qdd), (exprs,), conventions=text,
                            metadata={"params": "none", "base_parameters": b.names}, stages=stages.definitions)


def tree_base_params_document(model: RobotModel) -> dict:
    """Content of ``base_params.json`` for a tree: Y's base parameters, their expressions in the
    barycentric symbols, their values for the description, and which link each body is."""
    reason = unavailable(model)
    if reason:
        return {"Y": {"unavailable": reason}}
    b = tree_base_parameters(model)
    return {"Y": {"names": list(b.names), "expressions": list(b.expression_strings()),
                  "values": [float(v) for v in b.exact_values(parameter_values(model))],
                  "rank": b.rank, "full_columns": len(b.full_names), "exact": b.exact,
                  "bodies": list(body_labels(model))}}
