"""The plain data every derivation produces: a named function of named array ports whose
outputs are symengine expressions (a DAG: shared sub-expressions are shared objects).

Example:

>>> import symengine as se
>>> q = port_symbols("q", (2,))
>>> f = SymbolicFunction("sum", "q0 + q1", (Port("q", (2,), "joint angles", "rad"),),
...                      (Port("s", (1,), "sum", "rad"),), (q,), ((q[0] + q[1],),))
>>> f.outputs[0].size
1
"""
from __future__ import annotations

from dataclasses import dataclass, field
from math import prod

import symengine as se


@dataclass(frozen=True)
class Port:
    """One input or output array. ``shape`` is row-major; ``dtype`` "double" or "int"."""

    name: str
    shape: tuple[int, ...]
    description: str
    unit: str = ""
    dtype: str = "double"

    @property
    def size(self) -> int:
        return prod(self.shape)

    def to_json(self) -> dict:
        return {"name": self.name, "shape": list(self.shape), "description": self.description,
                "unit": self.unit, "dtype": self.dtype}


@dataclass(frozen=True)
class SymbolicFunction:
    """A derived function: inputs as flat tuples of symbols, outputs as flat tuples of
    expressions (row-major), plus the text that generated headers carry."""

    name: str
    summary: str
    inputs: tuple[Port, ...]
    outputs: tuple[Port, ...]
    input_symbols: tuple[tuple[se.Symbol, ...], ...]
    output_exprs: tuple[tuple[se.Basic, ...], ...]
    conventions: str = ""
    metadata: dict = field(default_factory=dict, compare=False)
    # named intermediates (symbol, expression), in evaluation order, that outputs and later
    # intermediates refer to: see :class:`Stages`
    stages: tuple[tuple[se.Symbol, se.Basic], ...] = ()
    # other derivations of the same function (routes, named by metadata["route"]):
    # optimisation keeps the one with the fewest operations after CSE
    alternatives: tuple["SymbolicFunction", ...] = ()
    # the same outputs as one program run once per lane (the C prints it as a loop over
    # lanes that compilers vectorise); None: scalar code only
    lanes: "LaneSweep | None" = None
    # the same outputs as loops over a tree's joints (the C single call prints them); None: not
    joint_loops: "JointLoops | None" = None

    def __repr__(self) -> str:
        # the generated repr prints every expression as a tree: a DAG's shared nodes once per
        # use, gigabytes for the derivatives (a failing test's report once ran out of memory)
        ports = lambda ports: ", ".join(f"{p.name}{list(p.shape)}" for p in ports)
        return (f"SymbolicFunction({self.name!r}: ({ports(self.inputs)}) -> ({ports(self.outputs)}), "
                f"{len(self.stages)} stages, {len(self.alternatives)} alternatives, lanes={self.lanes is not None}, "
                f"joint_loops={self.joint_loops is not None})")

    def inlined_outputs(self) -> tuple[tuple[se.Basic, ...], ...]:
        """``output_exprs`` with the named intermediates substituted: expressions of the
        inputs only, to evaluate or differentiate directly (a DAG: nothing is expanded).

        >>> x, s = se.symbols("x s")
        >>> f = SymbolicFunction("f", "", (Port("x", (1,), ""),), (Port("y", (1,), ""),), ((x,),),
        ...                      ((s * s,),), stages=((s, x + 1),))
        >>> f.inlined_outputs()
        (((1 + x)**2,),)
        """
        if not self.stages:
            return self.output_exprs
        values: dict = {}
        for symbol, expr in self.stages:
            values[symbol] = expr.xreplace(values) if values else expr
        return tuple(tuple(e.xreplace(values) for e in exprs) for exprs in self.output_exprs)

    def __post_init__(self):
        for port, syms in zip(self.inputs, self.input_symbols):
            assert len(syms) == port.size, f"{self.name}: input {port.name} has {len(syms)} symbols"
        for port, exprs in zip(self.outputs, self.output_exprs):
            assert len(exprs) == port.size, f"{self.name}: output {port.name} has {len(exprs)} entries"


@dataclass(frozen=True)
class LaneSweep:
    """Outputs that are one program evaluated in lanes l = 0, 1, ... which differ only in the
    values of its ``seeds``: lane l reads seed k as ``values[l][k]`` (the C prints numbers only,
    as a constant table; code that pads the lanes to a vector width gives the extra lanes 0 and
    discards them) and its ``exprs[m]`` is
    output entry ``offset + l * stride`` of port ``port`` for ``places[m] = (port, offset,
    stride)``. Outputs of ports no place names are computed once, outside the lanes, from the
    function's ``output_exprs``. ``stages``: named intermediates (symbol, expression) that
    seed values and lane expressions read, computed once before the lanes.

    The adjoint sweeps of the dynamics' derivatives are such a program: seeded with a row of
    the identity, a lane carries the gradient of the joint torques weighted by that row
    (``tau_derivatives``) or by the row of ``-M^-1`` it solves from M's factor first
    (``fd_derivatives``), so one lane gives one row of the Jacobian, and every lane does the
    same arithmetic.

    >>> import symengine as se
    >>> x, s = se.symbols("x s")
    >>> sweep = LaneSweep(seeds=(s,), values=((1,), (x,)), exprs=(s * x,), places=((0, 0, 1),))
    >>> [sweep.lane_value(0, l) for l in range(2)]
    [x, x**2]
    """

    seeds: tuple
    values: tuple
    exprs: tuple
    places: tuple
    stages: tuple = ()

    def __repr__(self) -> str:
        # expressions stay out of the repr: see SymbolicFunction.__repr__
        return (f"LaneSweep({len(self.values)} lanes, {len(self.seeds)} seeds, {len(self.exprs)} expressions, "
                f"{len(self.stages)} stages)")

    def lane_value(self, m: int, lane: int):
        """Lane expression m in lane ``lane``, seeds and stages substituted."""
        values = dict(zip(self.seeds, (se.sympify(v) for v in self.values[lane])))
        staged: dict = {}
        for symbol, expr in self.stages:
            staged[symbol] = expr.xreplace(staged) if staged else expr
        values = {k: v.xreplace(staged) for k, v in values.items()}
        return self.exprs[m].xreplace(values).xreplace(staged)


@dataclass(frozen=True)
class LoopBody:
    """One program a loop over a tree's joints runs per iteration (see :class:`JointLoops`):
    ``function`` has the one input port ``lane``; input k reads ``sources[k]`` and output
    entry m goes to ``places[m]``, each ``(array, row, row_index, column, column_index)``:
    entry ``(row + row_index) * stride + column + column_index`` of ``array`` (one of the
    loops' arrays, stride the lanes, or an output port of the caller, stride its columns),
    the indices "i", "j" (the loop's) or "" (none).

    >>> LoopBody.address(("dtau_dq", 6, "i", 6, "j"), 35)
    '(6 + i)*35 + 6 + j'
    """

    function: "SymbolicFunction"
    sources: tuple
    places: tuple

    @staticmethod
    def address(place: tuple, stride: int) -> str:
        _, row, row_index, column, column_index = place
        line = f"({row} + {row_index})" if row_index else str(row)
        start = f"{line}*{stride}" if line != "0" else ""
        rest = " + ".join(str(x) for x in (column, column_index) if x not in (0, ""))
        return " + ".join(x for x in (start, rest) if x) or "0"


@dataclass(frozen=True)
class JointLoops:
    """A tree function's outputs as loops over its joints (the C single call of the
    world-frame ``tau_derivatives`` prints them; docs/latency.md, "Joint loops"): the work
    per joint, and per pair of joints, is the same arithmetic on different data, which
    straight-line code repeats and a loop runs vectorised across joints.

    In order: ``once`` (a function of the caller's inputs) fills the arrays ``kdg_w`` (rows
    of ``lanes`` entries: joint j of row r at ``r*lanes + j``; the lanes past ``joints`` are
    zero) and, with a floating base, ``kdg_root``, ``kdg_base``; ``body`` per lane fills
    ``kdg_c``; each joint's ``kdg_c`` entries are added to its parent's, leaves first
    (``parents``; a joint on the root to ``kdg_root``, with a floating base), so lane j holds
    the sums over j's subtree; ``columns`` per lane fills ``kdg_t``; the caller's outputs are
    zeroed, then ``joint`` runs per joint j, ``lower`` per pair (i, j) with i in j's subtree
    (``j <= i < ends[j]``: depth-first order makes a subtree contiguous), ``upper`` per pair
    with j in i's strict subtree, ``row`` per joint i, and ``root`` once. ``table``: rows of
    per-joint constants (exact numbers, ``lanes`` each) that sources name as "table"; a
    missing piece is None."""

    joints: int
    lanes: int
    parents: tuple
    ends: tuple
    table: tuple
    once: "SymbolicFunction"
    body: LoopBody
    columns: LoopBody
    joint: "LoopBody | None"
    lower: LoopBody
    upper: LoopBody
    row: "LoopBody | None"
    root: "LoopBody | None"

    PIECES = ("body", "columns", "joint", "lower", "upper", "row", "root")

    def __repr__(self) -> str:
        return f"JointLoops({self.joints} joints in {self.lanes} lanes)"

    def pieces(self) -> tuple:
        """(name, LoopBody) of the loop pieces there are, in order."""
        return tuple((name, getattr(self, name)) for name in self.PIECES if getattr(self, name) is not None)

    def runs(self, name: str) -> int:
        """How often a call runs piece ``name``: per lane, per joint, per pair or once.

        >>> loops = JointLoops(3, 8, (-1, 0, 0), (3, 2, 3), (), None, *(None,) * 7)
        >>> [loops.runs(name) for name in JointLoops.PIECES]
        [8, 8, 3, 5, 2, 3, 1]
        """
        ends = self.ends
        return {"body": self.lanes, "columns": self.lanes, "joint": self.joints, "row": self.joints, "root": 1,
                "lower": sum(e - j for j, e in enumerate(ends)),
                "upper": sum(e - j - 1 for j, e in enumerate(ends))}[name]


class Stages:
    """The named intermediates of a recursive derivation (velocities, forces, articulated
    inertias of each body). Handing CSE many small expressions over named symbols instead of
    one DAG whose sub-expressions are shared across many outputs keeps CSE near-linear in the
    size of the algorithm: symengine's cse is superlinear in the sharing of a large DAG.

    ``cut`` names an expression unless it is a number, a symbol or a constant (those stay
    inline, so exact zeros and constants still fold).

    >>> import symengine as se
    >>> stages = Stages()
    >>> a, b = se.symbols("a b")
    >>> x = stages.cut(a * b + 1)
    >>> stages.cut(a), stages.cut(se.Integer(0)), x
    (a, 0, _s0)
    >>> stages.definitions
    ((_s0, 1 + a*b),)
    """

    def __init__(self, prefix: str = "_s"):
        self._definitions: list = []
        self._prefix = prefix         # another prefix: intermediates joined to another function's

    def cut(self, expr):
        expr = se.sympify(expr)
        if expr.is_Number or expr.is_Symbol or not expr.free_symbols:
            return expr
        if isinstance(expr, se.Mul) and len(expr.args) == 2 and expr.args[0].is_Number \
                and expr.args[1].is_Symbol:
            return expr          # c * s: one multiplication wherever it is used
        symbol = se.Symbol(f"{self._prefix}{len(self._definitions)}")
        self._definitions.append((symbol, expr))
        return symbol

    def cut_all(self, exprs) -> list:
        return [self.cut(e) for e in exprs]

    @property
    def definitions(self) -> tuple:
        return tuple(self._definitions)

    def substitute(self, mapping: dict, start: int = 0) -> None:
        """Rewrite the definitions from ``start`` on by one simultaneous ``xreplace`` with
        ``mapping`` (a derivation in other coordinates:
        :mod:`kindyngen.algorithms.reduced_coordinates`).

        >>> stages = Stages()
        >>> a, b = se.symbols("a b")
        >>> _ = stages.cut(a * b + 1)
        >>> stages.substitute({a: b, b: a}); stages.definitions
        ((_s0, 1 + a*b),)
        """
        self._definitions[start:] = [(s, e.xreplace(mapping)) for s, e in self._definitions[start:]]


def naming(stages: Stages | None):
    """``stages.cut``, or the identity when a derivation runs without named intermediates.

    >>> naming(None)(se.Symbol("x") + 1)
    1 + x
    """
    return stages.cut if stages is not None else _unnamed


def _unnamed(expr):
    return expr


def port_symbols(name: str, shape: tuple[int, ...]) -> tuple[se.Symbol, ...]:
    """Flat, row-major symbols for an input port; names cannot clash with CSE temporaries.

    >>> port_symbols("q", (3,))
    (q_0, q_1, q_2)
    """
    return tuple(se.Symbol(f"{name}_{k}") for k in range(prod(shape)))


def flatten(matrix) -> tuple[se.Basic, ...]:
    """Row-major entries of a symengine matrix (or nested list)."""
    if hasattr(matrix, "tolist"):
        matrix = matrix.tolist()
    out = []
    for row in matrix:
        out.extend(row if isinstance(row, (list, tuple)) else [row])
    return tuple(se.sympify(e) for e in out)
