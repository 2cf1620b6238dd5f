"""Linear parametrisation of the dynamics: regressors on base parameters (identification
paper, Sect. V, eqs. 17, 18, 23).

The dynamics is linear in the standard barycentric parameters ``p`` (10 per link, see
:mod:`kindyngen.model.inertial_parameters`), so each regressor column is the derivative of a
symbolic dynamics function with respect to one parameter, taken on the DAG with ``se.diff``
(nothing is expanded):

* ``Y_g(q) -> Y``, shape ``(n, p_g)``: ``g(q) = Y_g(q) pi_g`` (eq. 17);
* ``Y_m(q) -> Y``, shape ``(n(n+1)/2, p_m)``: the inertia stack ``m~(q) = Y_m(q) pi_m``
  (eq. 18), the lower triangle of M row by row: ``M00, M10, M11, M20, M21, M22, ...``
  (row ``i(i+1)/2 + j`` holds ``M_ij``, ``j <= i``, 0-based);
* ``Y(q, qd, qdd) -> Y``, shape ``(n, p)``: ``tau = Y(q, qd, qdd) pi``.

The columns are those of the base parameters of each (found by
:mod:`kindyngen.algorithms.base_parameters`: independent columns kept in parameter order, the others
grouped into them, paper eq. 23), so ``Y`` times the base values equals the dynamics.  The
symbolic dynamics comes from the catalog in symbolic mode (``g_lagrange``, ``M_lagrange`` and
``tau``: the routes whose derivatives are cheapest after CSE, see :data:`SOURCES`); the
regressor does not depend on the inertial values, so numeric and symbolic mode register the
same functions.

The paper's parameters (mass, CoM, inertia about the CoM) are in
:mod:`kindyngen.algorithms.paper_parameters`.

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> b = base_parameters(load_robot("robots/lwr4.yaml"), "Y_g")    # doctest: +SKIP
>>> b.rank, b.names[:2]                                            # doctest: +SKIP
(12, ('mx2', 'mz2R'))
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache, reduce

import numpy as np
import symengine as se
import sympy

from .base_parameters import BaseParameterError, BaseParameters, find_base_parameters
from .lagrange import gravity_lagrange, mass_matrix_lagrange
from .dynamics import inverse_dynamics_tree
from ..model.inertial_parameters import exact_parameter_vector, parameter_symbols
from .effect_torques import effect_columns, effect_parameter_names, effect_parameter_values
from ..model.robot_model import RobotModel
from .symbolic import Port, Stages, SymbolicFunction
from .tree_regressors import link_parameter_columns

KINDS = ("Y_g", "Y_m", "Y")
# catalog functions each regressor is differentiated from, first available wins: the routes
# whose parameter derivatives cost least after CSE (LWR4: Y_g 31/70 add/mul from g_lagrange
# against 47/107 from g; Y_m 328/764 from M_lagrange against 708/1086 from the composite-body
# M; Y 512/719 from Newton-Euler tau against 3666/4792 from the Lagrange energy)
# the dynamics each regressor differentiates: the routes whose derivatives are cheapest after CSE
# (rigid bodies only: the joint effects are appended as their own columns, see full_regressor)
SOURCES = {"Y_g": gravity_lagrange,
           "Y_m": lambda model, params: mass_matrix_lagrange(model, params, effects=False),
           "Y": lambda model, params: inverse_dynamics_tree(model, params, effects=False, named=False)}
QUANTITY = {"Y_g": "g", "Y_m": "M", "Y": "tau"}
SAMPLES = {"Y_g": 40, "Y_m": 12, "Y": 40}          # random samples for the rank analysis
SEEDS = (20140, 20141)                             # analysis, verification

SUMMARIES = {
    "Y_g": "Gravity regressor on base parameters: g(q) = Y_g(q) pi_g (identification paper eq. 17).",
    "Y_m": ("Inertia-stack regressor on base parameters: the lower triangle of M row by row "
            "(M00, M10, M11, M20, ...) = Y_m(q) pi_m (identification paper eq. 18)."),
    "Y": "Torque regressor on base parameters: tau = M(q) qdd + c(q, qd) + g(q) = Y(q, qd, qdd) pi.",
}


@dataclass(frozen=True)
class FullRegressor:
    """A dynamics quantity as rows of expressions linear in the parameters ``p``: the 10 n
    barycentric symbols, then the description's joint-effect coefficients (``fv1``, ...).
    Column k is ``d rigid_rows / d p_k`` for a link parameter, ``effect_columns[k - 10 n]``
    (per row) for an effect coefficient."""

    kind: str
    inputs: tuple[Port, ...]
    input_symbols: tuple[tuple[se.Symbol, ...], ...]
    p: tuple[se.Symbol, ...]
    rigid_rows: tuple[se.Basic, ...]
    effect_columns: tuple[tuple[se.Basic, ...], ...]
    row_names: tuple[str, ...]
    gravity: tuple[float, float, float]

    @property
    def rows(self) -> tuple[se.Basic, ...]:
        """The modelled quantity, linear in ``p``."""
        rigid = len(self.p) - len(self.effect_columns)
        return tuple(se.Add(row, *(self.p[rigid + j] * column[r] for j, column in enumerate(self.effect_columns)))
                     for r, row in enumerate(self.rigid_rows))

    def columns(self, indices) -> tuple[se.Basic, ...]:
        """Row-major entries of the regressor restricted to columns ``indices``."""
        rigid = len(self.p) - len(self.effect_columns)
        return tuple(se.diff(row, self.p[k]) if k < rigid else self.effect_columns[k - rigid][r]
                     for r, row in enumerate(self.rigid_rows) for k in indices)


def effect_names(model: RobotModel, kind: str) -> tuple[str, ...]:
    """The effect coefficients that are columns of regressor ``kind``: all of the
    description's for ``Y``, the armature for ``Y_m`` (only it enters M), none for ``Y_g``."""
    names = effect_parameter_names(model)
    return {"Y": names, "Y_m": tuple(n for n in names if n.startswith("Ia")), "Y_g": ()}[kind]


def full_values(model: RobotModel, kind: str) -> tuple:
    """Exact values of the full regressor's parameters: the barycentric link parameters (the
    payload merged into the last link) followed by the effect coefficients of ``kind``."""
    effects = dict(zip(effect_parameter_names(model), effect_parameter_values(model)))
    return exact_parameter_vector(model) + tuple(effects[name] for name in effect_names(model, kind))


@lru_cache(maxsize=None)
def full_regressor(model: RobotModel, kind: str) -> FullRegressor:
    """The rows (g, the inertia stack, or tau) of ``model`` as functions of q (qd, qdd) and p."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    f = SOURCES[kind](model, "symbolic")
    names = [port.name for port in f.inputs]
    k = names.index("p")
    p = f.input_symbols[k]
    assert tuple(map(str, p)) == tuple(map(str, parameter_symbols(model.n))), "catalog p is not the barycentric vector"
    inputs = tuple(port for port in f.inputs if port.name != "p")
    input_symbols = tuple(s for port, s in zip(f.inputs, f.input_symbols) if port.name != "p")
    exprs = f.output_exprs[0]
    n = model.n
    # the description's joint effects: coefficients appended to p, each a column that acts on
    # one joint's torque (friction and offset on tau only, the armature on tau and M's diagonal)
    values = {port.name: syms for port, syms in zip(inputs, input_symbols)}
    wanted = effect_names(model, kind)
    effect_symbols = tuple(se.Symbol(name) for name in wanted)
    zero = se.Integer(0)
    if kind == "Y":
        columns = effect_columns(model, values["qd"], values["qdd"])
    else:   # Y_m: the armature's column is 1 on M_ii
        columns = effect_columns(model, [zero] * n, [se.Integer(1)] * n)
    chosen = [c for name, c in zip(effect_parameter_names(model), columns) if name in wanted]
    if kind == "Y_m":
        rows = tuple(exprs[i * n + j] for i in range(n) for j in range(i + 1))
        row_names = tuple(f"M{i}{j}" if n <= 10 else f"M{i}_{j}" for i in range(n) for j in range(i + 1))
        row_index = {i: i * (i + 1) // 2 + i for i in range(n)}      # M_ii in the stack
    else:
        rows = tuple(exprs)
        row_names = tuple(f"{QUANTITY[kind]}{i}" for i in range(n))
        row_index = {i: i for i in range(n)}
    effect_cols = tuple(tuple(shape if r == row_index[i] else zero for r in range(len(rows))) for i, shape in chosen)
    return FullRegressor(kind, inputs, input_symbols, tuple(p) + effect_symbols, rows, effect_cols, row_names,
                         tuple(float(g) for g in model.gravity))


def random_inputs(model: RobotModel, inputs: tuple[Port, ...], count: int, seed: int) -> dict:
    """Random samples for each input port: q uniform within the joint limits, others
    (velocities, accelerations) standard normal."""
    rng = np.random.default_rng(seed)
    out = {}
    for port in inputs:
        if port.name == "q":
            out[port.name] = rng.uniform(model.lower, model.upper, size=(count, model.n))
        else:
            out[port.name] = rng.normal(size=(count, port.size))
    return out


@lru_cache(maxsize=None)
def _numeric(model: RobotModel, kind: str):
    full = full_regressor(model, kind)
    args = [s for syms in full.input_symbols for s in syms] + list(full.p)
    return se.Lambdify(args, list(full.rows), cse=True)


def evaluate_full(model: RobotModel, kind: str, inputs: dict) -> np.ndarray:
    """The full regressor (samples x rows x 10 n) at numeric inputs, by evaluating the
    dynamics at every unit parameter vector (the dynamics is linear and homogeneous in p)."""
    full = full_regressor(model, kind)
    fn = _numeric(model, kind)
    x = np.concatenate([np.asarray(inputs[port.name], float).reshape(-1, port.size) for port in full.inputs], axis=1)
    count, P = x.shape[0], len(full.p)
    batch = np.concatenate([np.repeat(x, P, axis=0), np.tile(np.eye(P), (count, 1))], axis=1)
    out = np.asarray(fn(batch), float).reshape(count, P, len(full.rows))
    return out.transpose(0, 2, 1)


def common_denominator(model: RobotModel) -> int | None:
    """A common denominator of every grouping coefficient: the squared lcm of the joint
    placements' lengths' denominators when all lengths are rational and every constant
    rotation is a signed permutation (DH: cos and sin of each alpha and offset in {0, 1,
    -1}); else None."""
    dens = []
    for joint in model.joints:
        if not joint.prismatic:
            for v in (sympy.cos(joint.offset), sympy.sin(joint.offset)):
                if v not in (0, 1, -1):
                    return None
        lengths = [joint.offset] if joint.prismatic else []
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
def base_parameters(model: RobotModel, kind: str) -> BaseParameters:
    """Rank analysis and grouping of the full regressor ``kind`` of ``model``."""
    full = full_regressor(model, kind)
    names = tuple(map(str, full.p))

    def evaluate(seed):
        return evaluate_full(model, kind, random_inputs(model, full.inputs, SAMPLES[kind], seed))

    return find_base_parameters(evaluate, names, SEEDS, common_denominator(model))


@lru_cache(maxsize=None)
def unavailable(model: RobotModel, kind: str) -> str | None:
    """Why regressor ``kind`` is not generated for ``model``, or None when it is: symbolic
    lengths, or a rank / column decision the samples cannot make with the stated margin
    (:func:`kindyngen.algorithms.base_parameters.check_margin`; seen on real arms with millimetre
    offsets, e.g. the Kinova Jaco 2's joint 2, 1.6 mm off joint 1's axis). The other
    functions are generated all the same."""
    if not supported(model):
        return "symbolic lengths"
    try:
        base_parameters(model, kind)
    except BaseParameterError as exc:
        return f"base parameters undecided ({exc})"
    return None


def undecided_notes(model: RobotModel, only=None) -> list[str]:
    """One line per regressor (of ``only``, default all) left out because its base parameters
    could not be decided (robots with symbolic lengths have none, and say so elsewhere)."""
    return [f"{model.identifier}: regressor {kind} not generated: {unavailable(model, kind)}"
            for kind in KINDS if (only is None or kind in only)
            and unavailable(model, kind) not in (None, "symbolic lengths")]


def supported(model: RobotModel) -> bool:
    """Regressors need numeric DH lengths (the grouping coefficients are found numerically)."""
    return not model.length_symbols


def regressor(model: RobotModel, kind: str, name: str | None = None) -> SymbolicFunction | None:
    """``Y_g(q)``, ``Y_m(q)`` or ``Y(q, qd, qdd)`` on base parameters (output port ``Y``);
    None where :func:`unavailable` says why not."""
    if unavailable(model, kind):
        return None
    full = full_regressor(model, kind)
    base = base_parameters(model, kind)
    rows, cols = len(full.rows), len(base.base)
    stages = Stages()
    exprs = torque_columns(model, full, base.base, stages) if kind == "Y" else full.columns(base.base)
    what = {"Y_g": "gravity torques g", "Y_m": "inertia stack (lower triangle of M, row by row)",
            "Y": "joint torques tau"}[kind]
    unit = {"Y_g": "N m per base parameter", "Y_m": "kg m^2 per base parameter", "Y": "N m per base parameter"}[kind]
    port = Port("Y", (rows, cols), f"regressor of the {what} on the base parameters (row-major; "
                f"columns: {', '.join(base.names)})", unit)
    gx, gy, gz = full.gravity
    conventions = (
        f"Joint space in DH order: q (rad), qd (rad/s), qdd (rad/s^2). Gravity in the base frame: "
        f"({gx:g}, {gy:g}, {gz:g}) m/s^2. Rows: {', '.join(full.row_names)}. "
        f"Columns: the {cols} base parameters (rank of the full {len(base.full_names)}-column regressor), "
        f"named after the barycentric parameter each is led by (m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, "
        f"Izz per link, inertia about the link frame origin in link-frame axes; suffix R: other "
        f"parameters grouped into it); their expressions and the robot's values are in "
        f"base_params.json. Y times those values equals the modelled quantity.")
    return SymbolicFunction(
        name=name or kind, summary=SUMMARIES[kind],
        inputs=full.inputs, outputs=(port,), input_symbols=full.input_symbols, output_exprs=(exprs,),
        conventions=conventions,
        metadata={"params": "none", "base_parameters": base.names}, stages=stages.definitions)


def torque_columns(model: RobotModel, full: FullRegressor, indices, stages: Stages) -> tuple[se.Basic, ...]:
    """Row-major entries of the torque regressor restricted to columns ``indices``: a link
    parameter's column as the torque its unit value causes, carried up the tree
    (:mod:`kindyngen.algorithms.tree_regressors`: nothing differentiated, fewer operations after CSE
    than ``d tau / d p``), an effect coefficient's as :attr:`FullRegressor.effect_columns`."""
    rigid = len(full.p) - len(full.effect_columns)
    wanted = sorted(k for k in indices if k < rigid)
    _, columns = link_parameter_columns(model, frozenset(wanted), stages)
    column = dict(zip(wanted, columns))
    return tuple(column[k][r] if k < rigid else full.effect_columns[k - rigid][r]
                 for r in range(len(full.rows)) for k in indices)


def base_params_document(model: RobotModel) -> dict | None:
    """Content of ``base_params.json``: per regressor the base parameters in column order,
    their expressions in the barycentric symbols and their values for the robot's YAML
    parameters (``Y @ values`` is the modelled quantity), plus rank and condition number."""
    if not supported(model):
        return None
    out = {}
    for kind in KINDS:
        if unavailable(model, kind):
            out[kind] = {"unavailable": unavailable(model, kind)}
            continue
        b = base_parameters(model, kind)
        values = full_values(model, kind)
        out[kind] = {
            "names": list(b.names),
            "expressions": list(b.expression_strings()),
            # exact sums of the description's rationals, rounded once to a double
            "values": [float(v) for v in b.exact_values(values)],
            "rank": b.rank,
            "full_columns": len(b.full_names),
            "exact": b.exact,
        }
    return out

