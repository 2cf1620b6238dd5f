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

    def __post_init__(self):
        for port, syms in zip(self.inputs, self.input_symbols):
            assert len(syms) == port.size, f"{self.name}: input {port.name} has {len(syms)} symbols"
        for port, exprs in zip(self.outputs, self.output_exprs):
            assert len(exprs) == port.size, f"{self.name}: output {port.name} has {len(exprs)} entries"


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
