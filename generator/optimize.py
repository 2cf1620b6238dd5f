"""Common-subexpression elimination: SymbolicFunction -> straight-line Program.

The program is the pair SymPyBotics carries code as: (intermediates, outputs).  CSE runs on
the DAG with symengine, which takes milliseconds where sympy's takes minutes.

Example:

>>> import symengine as se
>>> from generator.symbolic import Port, SymbolicFunction, port_symbols
>>> q = port_symbols("q", (2,))
>>> s = se.sin(q[0] + q[1])
>>> f = SymbolicFunction("f", "", (Port("q", (2,), ""),), (Port("y", (2,), ""),), (q,), ((2*s, s*s),))
>>> p = optimize(f)
>>> len(p.assignments), p.after.call
(1, 1)
"""
from __future__ import annotations

from dataclasses import dataclass

import symengine as se

from .opcount import OpCount, program_count, tree_count
from .symbolic import SymbolicFunction


@dataclass(frozen=True)
class Program:
    """A function as straight-line code: temporaries in evaluation order, then outputs
    (flat, row-major per port) in terms of inputs and temporaries."""

    function: SymbolicFunction
    assignments: tuple[tuple[se.Symbol, se.Basic], ...]
    outputs: tuple[tuple[se.Basic, ...], ...]
    before: OpCount
    after: OpCount


def optimize(function: SymbolicFunction) -> Program:
    """CSE over all outputs of ``function`` together, with temporaries named t0, t1, ..."""
    flat = [e for port in function.output_exprs for e in port]
    replacements, reduced = se.cse(flat)
    rename = {sym: se.Symbol(f"t{k}") for k, (sym, _) in enumerate(replacements)}
    assignments = tuple((rename[sym], expr.xreplace(rename)) for sym, expr in replacements)
    reduced = [e.xreplace(rename) for e in reduced]
    outputs, start = [], 0
    for port in function.outputs:
        outputs.append(tuple(reduced[start:start + port.size]))
        start += port.size
    return Program(
        function=function,
        assignments=assignments,
        outputs=tuple(outputs),
        before=tree_count(flat),
        after=program_count(assignments, reduced),
    )
