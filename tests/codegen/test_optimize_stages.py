"""Named intermediates (``SymbolicFunction.stages``) and alternative routes in ``optimize``.

A staged function must give the same values as the same function written without names (each
intermediate substituted), its program must define every temporary before use, and of several
routes the one with fewer additions + multiplications after CSE is kept. Values are computed
by substituting numbers into the symengine expressions directly, independent of the program.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import symengine as se

from kindyngen.codegen.optimize import optimize
from kindyngen.algorithms.symbolic import Port, Stages, SymbolicFunction, port_symbols


def run_program(program, inputs) -> np.ndarray:
    """The program's outputs at ``inputs``, executing its assignments in order (a temporary
    used before it is assigned leaves a symbol behind and fails the float conversion)."""
    values = {s: se.RealDouble(float(v)) for syms, arr in zip(program.function.input_symbols, inputs)
              for s, v in zip(syms, arr)}
    for symbol, expr in program.assignments:
        values[symbol] = expr.xreplace(values)
    return np.array([float(e.xreplace(values)) for port in program.outputs for e in port])


def direct(function, inputs) -> np.ndarray:
    """The function's outputs with its intermediates substituted one by one (no CSE)."""
    values = {s: se.RealDouble(float(v)) for syms, arr in zip(function.input_symbols, inputs)
              for s, v in zip(syms, arr)}
    for symbol, expr in function.stages:
        values[symbol] = expr.xreplace(values)
    return np.array([float(e.xreplace(values)) for port in function.output_exprs for e in port])


def chain_function(n: int, stages: Stages | None):
    """A recursion like a kinematic chain's: (c, s) rotated by every q_k, with products and
    sums that repeat across steps (CSE material), each step named if ``stages`` is given."""
    q = port_symbols("q", (n,))
    name = stages.cut if stages is not None else (lambda e: e)
    x, y, acc = se.Integer(1), se.Integer(0), []
    for k in range(n):
        c, s = se.cos(q[k]), se.sin(q[k])
        x, y = name(c * x - s * y), name(s * x + c * y)
        acc.append(name(x * y + 2 * (c * x - s * y) + s * s))
    outputs = (tuple(acc) + (x, y, se.Add(*acc)),)
    return SymbolicFunction("f", "test", (Port("q", (n,), ""),), (Port("y", (n + 3,), ""),), (q,), outputs,
                            stages=stages.definitions if stages is not None else ())


def test_staged_program_equals_the_unstaged_function():
    rng = np.random.default_rng(7)
    stages = Stages()
    staged = chain_function(9, stages)
    plain = chain_function(9, None)
    assert len(staged.stages) > 9 and not plain.stages
    program = optimize(staged)
    for _ in range(5):
        q = rng.uniform(-3, 3, 9)
        expected = direct(plain, (q,))
        assert np.allclose(direct(staged, (q,)), expected, rtol=1e-13, atol=1e-13)
        assert np.allclose(run_program(program, (q,)), expected, rtol=1e-12, atol=1e-12)
    # every temporary is assigned once, before any use
    defined = {s for syms in staged.input_symbols for s in syms}
    for symbol, expr in program.assignments:
        assert expr.free_symbols <= defined, f"{symbol} uses {expr.free_symbols - defined} before assignment"
        assert symbol not in defined
        defined.add(symbol)
    assert all(str(s).startswith("t") for s, _ in program.assignments)


def test_intermediates_that_cse_merges_become_one_temporary():
    a, b, c = se.symbols("a_0 a_1 a_2")
    stages = Stages()
    first, second = stages.cut(a * b + c), stages.cut(a * b + c)       # the same value twice
    third = stages.cut(first * second + a)
    f = SymbolicFunction("g", "", (Port("a", (3,), ""),), (Port("y", (2,), ""),), ((a, b, c),),
                         ((third, first - second),), stages=stages.definitions)
    program = optimize(f)
    assert program.outputs[0][1] == 0                   # first - second folds once they are one symbol
    assert float(run_program(program, ((2.0, 3.0, 5.0),))[0]) == pytest.approx(11.0 * 11.0 + 2.0)
    assert program.after.mul == 2 and program.after.add == 2


def test_cut_keeps_numbers_symbols_and_scaled_symbols_inline():
    x = se.Symbol("x")
    stages = Stages()
    assert stages.cut(se.Integer(3)) == 3 and stages.cut(x) == x and stages.cut(-x) == -x
    assert stages.cut(se.sqrt(2)) == se.sqrt(2)                  # constants stay exact and inline
    assert stages.definitions == ()


def test_the_route_with_fewer_operations_is_kept_and_named():
    q = port_symbols("q", (2,))
    s = se.sin(q[0]) * q[1]
    costly = SymbolicFunction("h", "costly.", (Port("q", (2,), ""),), (Port("y", (1,), ""),), (q,),
                              ((s * s * s + s * s + s,),), metadata={"route": "expanded"})
    cheap = replace(costly, summary="cheap.", output_exprs=(((s + 1) * s * s + s,),), metadata={"route": "Horner"})
    for first, second in ((costly, cheap), (cheap, costly)):
        program = optimize(replace(first, alternatives=(second,)))
        assert program.function.summary.startswith("cheap.")
        counts = dict(program.routes)
        assert set(counts) == {"expanded", "Horner"}
        assert counts["Horner"].add + counts["Horner"].mul < counts["expanded"].add + counts["expanded"].mul
        assert program.after == counts["Horner"]
        assert "Route chosen by the fewest additions + multiplications after CSE" in program.function.summary
        assert np.isclose(run_program(program, ((0.3, 1.7),))[0], direct(costly, ((0.3, 1.7),))[0])
    tie = optimize(replace(costly, alternatives=(replace(costly, summary="second.", metadata={"route": "copy"}),)))
    assert tie.function.summary.startswith("costly.")      # on a tie, the first route


def test_long_staged_lists_are_reduced_in_chunks_without_repeating_calls(monkeypatch):
    """Beyond CSE_CHUNK expressions CSE runs chunk by chunk: the values stay, every sin/cos is
    still evaluated once, and the operations grow only by what chunks could have shared."""
    import kindyngen.codegen.optimize as optimize_module
    rng = np.random.default_rng(3)
    whole = optimize(chain_function(12, Stages()))
    monkeypatch.setattr(optimize_module, "CSE_CHUNK", 7)
    staged = chain_function(12, Stages())
    assert len(staged.stages) + 15 > 3 * 7                  # several chunks
    chunked = optimize(staged)
    assert chunked.after.call == whole.after.call == 24
    assert whole.after.add + whole.after.mul <= chunked.after.add + chunked.after.mul
    plain = chain_function(12, None)
    for _ in range(3):
        q = rng.uniform(-3, 3, 12)
        assert np.allclose(run_program(chunked, (q,)), direct(plain, (q,)), rtol=1e-12, atol=1e-12)
