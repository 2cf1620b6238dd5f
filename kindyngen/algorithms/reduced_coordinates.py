"""Reduced coordinates: a model whose joints are tied by linear holonomic constraints (mimic
joints, ``q_dep = multiplier * q_ind + offset``) as functions of its independent coordinates
only, derived symbolically (a reduced model, not a projection at run time).

With ``x`` the coordinates of the model without mimics (every joint one,
:meth:`kindyngen.model.robot_model.RobotModel.without_mimics`) and ``y`` the independent ones
(:attr:`~kindyngen.model.robot_model.RobotModel.coordinates`; a floating base's 7 and 6 pass
through unchanged)::

    q_x = phi(q_y) = G q_y + b,    qd_x = G qd_y,    qdd_x = G qdd_y

with G constant (one entry, the multiplier, per row), so there is no ``Gdot qd`` term. By
virtual work the generalised forces of the independent coordinates are ``G^T`` of the full
ones (a joint's torque includes multiplier times the torque of each joint mimicking it), and::

    M_y = G^T M_x G,   g_y = G^T g_x,   c_y = G^T c_x(q_x, G qd_y),   tau_y = G^T tau_x(q_x, G qd_y, G qdd_y)
    J_y = J_x G,       fd: M_y qdd_y = tau_y - c_y - g_y,
    dtau_y/dq_y = G^T dtau_x/dq_x G (likewise qd),   Y_y = G^T Y_x.

Every function is derived on the model without mimics in its own symbols (``q_0 .. q_{n-1}``),
its velocity axes are contracted with G (:meth:`CoordinateMap.contract`; rows and columns alike:
``(G^T A)[a, j] = sum_i G[i, a] A[i, j]``), and then the full symbols are replaced by their
expressions in the independent ones, once, simultaneously (:meth:`CoordinateMap.substitution`),
in the named intermediates and the outputs. Where a full joint follows with multiplier 1 and
offset 0 it reads the same symbol (``cos(q_7)`` is shared); with -1 ``cos(-q_7)`` is
``cos(q_7)``; any other affine argument is one the C computes before its sin/cos kernel.

Closed kinematic loops are the nonlinear case of the same map: ``q_x = phi(q_y)`` solved from
the loop constraints, ``G(q) = dphi/dq_y`` depending on q and ``qdd_x = G qdd_y + Gdot qd_y``
(whose ``G^T M Gdot qd_y`` joins c): :mod:`kindyngen.algorithms.loop_closure` and
``loop_functions`` derive it, passing ``G qd`` and ``G qdd + Gdot qd`` into the recursions.
Loops that are all parallelograms have a constant G and are reduced here, as mimic joints whose
couplings have several terms (:attr:`kindyngen.model.robot_model.Mimic.terms`). What is linear
here: :meth:`CoordinateMap.configuration` (``G q + b``), the velocity map without ``Gdot qd``,
and the derivatives of :mod:`kindyngen.algorithms.reduced_functions` (``d(G^T tau)/dq = G^T
dtau/dq G`` holds only for constant G).

Example: the two pendulums of :mod:`kindyngen.readers.urdf`, the right one following the left with
multiplier -1:

>>> import sympy
>>> from kindyngen.model.robot_model import Mimic
>>> from kindyngen.readers.urdf import parse_urdf, TWO_PENDULUMS
>>> tree = parse_urdf(TWO_PENDULUMS, tree=True)
>>> mimic = replace(tree, joints=(tree.joints[0], replace(tree.joints[1], mimic=Mimic(0, sympy.Integer(-1)))))
>>> cmap = coordinate_map(mimic)
>>> cmap.G
((1,), (-1,))
>>> cmap.substitution()
{q_0: q_0, q_1: -q_0, qd_0: qd_0, qd_1: -qd_0, qdd_0: qdd_0, qdd_1: -qdd_0}
>>> cmap.contract([se.Symbol("a"), se.Symbol("b")], (2,), (0,))
[a - b]
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import symengine as se
import sympy

from ..model.robot_model import FREE_FLYER_NQ, FREE_FLYER_NV, RobotModel
from .symbolic import Port, SymbolicFunction, port_symbols

ZERO = se.Integer(0)
VELOCITY_INPUTS = ("qd", "qdd")     # input ports mapped by G (q by phi)


@dataclass(frozen=True)
class CoordinateMap:
    """``q_x = G q_y + b`` of a model with mimic joints (module text): ``G`` (nv_x x nv_y,
    exact rationals, nested tuples) and ``b`` (per joint of the full model, exact), with the
    model (``model``) and the one the derivations run on (``free``)."""

    model: RobotModel
    free: RobotModel
    G: tuple
    b: tuple

    @property
    def nv_full(self) -> int:
        return self.free.nv

    @property
    def nv(self) -> int:
        return self.model.nv

    def velocity(self, reduced) -> list:
        """``G v`` for reduced velocities (or accelerations) ``v``: the full ones."""
        return [se.Add(*(se.sympify(g) * v for g, v in zip(row, reduced) if g != 0)) for row in self.G]

    def configuration(self, reduced) -> list:
        """The full configuration from the reduced one: a floating base's 7 entries as they
        are, each joint ``multiplier * q_k + offset`` (``G q + b``)."""
        base = FREE_FLYER_NQ if self.model.floating_base else 0
        vbase = FREE_FLYER_NV if self.model.floating_base else 0
        joints = self.velocity([ZERO] * vbase + list(reduced[base:]))[vbase:]
        return list(reduced[:base]) + [q + se.sympify(b) if b != 0 else q for q, b in zip(joints, self.b)]

    def substitution(self, names=("q",) + VELOCITY_INPUTS) -> dict:
        """The full input symbols of ``names`` (``port_symbols``) -> their expressions in the
        reduced ones of the same names: one simultaneous ``xreplace`` with it rewrites a
        derivation of the free model in the independent coordinates (the reduced symbols reuse
        the names ``q_0 ..``; a second pass would corrupt them: apply it once)."""
        out = {}
        for name in names:
            if name == "q":
                full, reduced = port_symbols("q", (self.free.nq,)), port_symbols("q", (self.model.nq,))
                out.update(zip(full, self.configuration(reduced)))
            else:
                full, reduced = port_symbols(name, (self.nv_full,)), port_symbols(name, (self.nv,))
                out.update(zip(full, self.velocity(reduced)))
        return out

    def contract(self, exprs, shape: tuple, axes: tuple) -> list:
        """A row-major array of ``shape`` with each axis in ``axes`` (of length nv_x) contracted
        with G (``G^T`` on rows, ``G`` on columns: the same sum), as a flat list; exact zeros
        skipped (the module's example)."""
        exprs, shape = list(exprs), tuple(shape)
        for axis in axes:
            assert shape[axis] == self.nv_full, f"axis {axis} of {shape} is no velocity axis"
            outer = math.prod(shape[:axis])
            inner = math.prod(shape[axis + 1:])
            out = []
            for o in range(outer):
                for a in range(self.nv):
                    for i in range(inner):
                        terms = [se.sympify(self.G[k][a]) * exprs[(o * shape[axis] + k) * inner + i]
                                 for k in range(self.nv_full) if self.G[k][a] != 0]
                        terms = [t for t in terms if t != 0]
                        out.append(se.Add(*terms) if terms else ZERO)
            exprs, shape = out, shape[:axis] + (self.nv,) + shape[axis + 1:]
        return exprs

    def congruence(self, M) -> list:
        """``G^T M G`` of an nv_x x nv_x nested list, as nested lists."""
        flat = self.contract([e for row in M for e in row], (self.nv_full, self.nv_full), (0, 1))
        return [flat[r * self.nv:(r + 1) * self.nv] for r in range(self.nv)]


@lru_cache(maxsize=16)
def coordinate_map(model: RobotModel) -> CoordinateMap:
    """The map of ``model``'s mimic joints (an identity map without any)."""
    free = model.without_mimics()
    base = FREE_FLYER_NV if model.floating_base else 0
    column = {j: base + k for k, j in enumerate(model.coordinates)}
    rows = [[sympy.Integer(1 if c == r else 0) for c in range(model.nv)] for r in range(base)]
    offsets = []
    for j, joint in enumerate(model.joints):
        row = [sympy.Integer(0)] * model.nv
        if joint.mimic is None:
            row[column[j]] = sympy.Integer(1)
            offsets.append(sympy.Integer(0))
        else:
            for source, multiplier in joint.mimic.sources:
                row[column[source]] += multiplier
            offsets.append(joint.mimic.offset)
        rows.append(row)
    return CoordinateMap(model, free, tuple(tuple(row) for row in rows), tuple(offsets))


def _units(model: RobotModel, free: RobotModel, unit: str) -> str:
    """A unit text of ``free``'s ports re-worded for ``model``'s coordinates (which joints are
    prismatic is said by index among the coordinates)."""
    from .kinematics_conventions import joint_units
    pairs = (("N m", "N"), ("rad/s^2", "m/s^2"), ("rad/s", "m/s"), ("rad", "m"))
    for full, reduced in sorted(((joint_units(free, r, p), joint_units(model, r, p)) for r, p in pairs),
                                key=lambda pair: -len(pair[0])):
        if full != reduced and full in unit:
            unit = unit.replace(full, reduced)
    return unit


def reduced_input(model: RobotModel, port: Port, free: RobotModel) -> Port:
    """An input port of a function of ``free`` (q, qd, qdd, tau: sizes nq_x, nv_x) as ``model``'s;
    ``q`` names the independent joints."""
    if port.name == "q":
        names = ", ".join(joint.name for joint in model.coordinate_joints)
        return replace(port, shape=(model.nq,), unit=_units(model, free, port.unit),
                       description=f"{port.description}; the independent joints {names} (mimic joints follow them)")
    assert port.shape == (free.nv,), f"input {port.name} {port.shape}"
    return replace(port, shape=(model.nv,), unit=_units(model, free, port.unit))


def reduced_output(model: RobotModel, port: Port, axes: tuple, free: RobotModel) -> Port:
    """An output port of a function of ``free`` with its velocity ``axes`` resized to nv_y."""
    shape = tuple(model.nv if k in axes else size for k, size in enumerate(port.shape))
    return replace(port, shape=shape, unit=_units(model, free, port.unit))


def reduce_function(f: SymbolicFunction, model: RobotModel, axes: dict, summary: str = "") -> SymbolicFunction:
    """``f``, a function of ``model.without_mimics()`` in its full symbols, in ``model``'s
    independent coordinates: each output port's velocity ``axes`` (port name -> axis indices)
    contracted with G, then the full symbols of q, qd, qdd substituted in the named
    intermediates and the outputs (module text); ``summary`` is added to f's."""
    assert f.lanes is None and not f.alternatives, f"{f.name}: lanes and alternatives are not reduced"
    cmap = coordinate_map(model)
    outputs = [cmap.contract(exprs, port.shape, axes[port.name]) for port, exprs in zip(f.outputs, f.output_exprs)]
    ports = tuple(reduced_output(model, port, axes[port.name], cmap.free) for port in f.outputs)
    inputs = tuple(reduced_input(model, port, cmap.free) if port.name in ("q",) + VELOCITY_INPUTS else port
                   for port in f.inputs)
    symbols = tuple(port_symbols(port.name, port.shape) if port.name in ("q",) + VELOCITY_INPUTS else syms
                    for port, syms in zip(inputs, f.input_symbols))
    return reduced_function(f, model, inputs, symbols, ports, outputs, summary)


def reduced_function(f: SymbolicFunction, model: RobotModel, inputs, input_symbols, outputs, output_exprs,
                     summary: str = "") -> SymbolicFunction:
    """``f`` with the given ports and outputs (contracted, in full symbols) and its
    intermediates rewritten in the reduced coordinates by the one substitution pass, the mimic
    text in its conventions."""
    sub = coordinate_map(model).substitution()
    stages = tuple((symbol, expr.xreplace(sub)) for symbol, expr in f.stages)
    output_exprs = tuple(tuple(se.sympify(e).xreplace(sub) for e in exprs) for exprs in output_exprs)
    return replace(f, summary=f.summary + (" " + summary if summary else ""), inputs=tuple(inputs),
                   input_symbols=tuple(input_symbols), outputs=tuple(outputs), output_exprs=output_exprs,
                   stages=stages, conventions=f"{f.conventions} {model.mimic_text}".strip())


def elimination_parents(M) -> tuple[int, ...]:
    """Parents for :func:`kindyngen.algorithms.ldlt.tree_ldlt_solve` of a symmetric M whose
    exact-zero pattern is given (the elimination tree of its reverse-order L^T D L): every
    nonzero below the diagonal lies between a coordinate and one of its ancestors, fill-in
    included, so the factor is exact. A tree's M gives the tree; a mimic coupling two branches
    joins them.

    >>> elimination_parents([[1, 1, 1], [1, 1, 0], [1, 0, 1]])
    (-1, 0, 0)
    >>> elimination_parents([[1, 0, 1], [0, 1, 1], [1, 1, 1]])     # 2 couples 0 and 1: fill
    (-1, 0, 1)
    """
    n = len(M)
    above = [{j for j in range(k) if M[k][j] != 0} for k in range(n)]
    parents = [-1] * n
    for k in range(n - 1, -1, -1):
        if above[k]:
            parents[k] = max(above[k])
            above[parents[k]] |= above[k] - {parents[k]}
    return tuple(parents)
