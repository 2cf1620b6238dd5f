"""Operation counts of expressions, with one rule shared by the printer.

Rule (also in the README):

* ``add``: additions and subtractions. An n-term sum costs n - 1; a term with a negative
  coefficient is a subtraction, not a negation plus an addition. A comparison (IK branch
  tests) costs one ``add``.
* ``mul``: multiplications and divisions. An n-factor product costs n - 1; a numeric factor
  counts as a factor, a factor of -1 does not (it folds into the surrounding sum or flips a
  sign bit); ``x**k`` for integer k >= 2 costs k - 1 (printed as repeated products);
  ``x**-k`` costs k (k - 1 products and one division); a divisor in a product costs the
  same as a factor.
* ``call``: sin, cos, sqrt, atan2, ... one each; ``x**r`` with non-integer r is a call
  (``pow``), except r = 1/2, which is ``sqrt``. A select (``c ? a : b``) is one call.
* Numeric constants (``sqrt(2)/2``, ``pi``) are literals and cost nothing.

"before" counts the expression tree as derived, every shared sub-expression paid at each
occurrence; "after" counts the straight-line program after common-subexpression
elimination, every temporary paid once. The printer (:mod:`kindyngen.codegen.printer`) prints each
node exactly as counted here, using :func:`add_parts` and :func:`mul_parts`.

Example:

>>> import symengine as se
>>> x, y = se.symbols("x y")
>>> tree_count([x*y - 2*x + se.sin(y)**2])
OpCount(add=2, mul=3, call=1)
"""
from __future__ import annotations

from dataclasses import dataclass

import symengine as se


@dataclass(frozen=True)
class OpCount:
    add: int = 0
    mul: int = 0
    call: int = 0

    def __add__(self, other: "OpCount") -> "OpCount":
        return OpCount(self.add + other.add, self.mul + other.mul, self.call + other.call)

    def to_json(self) -> dict:
        return {"add": self.add, "mul": self.mul, "call": self.call}

    @property
    def total(self) -> int:
        return self.add + self.mul + self.call


ZERO = OpCount()
COMPARISONS = (se.StrictLessThan, se.LessThan, se.Equality, se.Unequality)
LOGIC = (se.And, se.Or, se.Not, type(se.true).__mro__[1])  # BooleanAtom: true/false
_NOT_LITERAL = (se.Piecewise,) + COMPARISONS + LOGIC


def is_literal(e: se.Basic) -> bool:
    """A numeric constant, printed as one literal."""
    if e.is_Number:
        return True
    if e.is_Symbol:         # the common case in printed programs: a temporary or an input
        return False
    return not isinstance(e, _NOT_LITERAL) and not _has_symbol(e)


def _has_symbol(e: se.Basic) -> bool:
    """Whether ``e`` contains a symbol, stopping at the first one found (``free_symbols``
    walks the whole sub-DAG at every node: quadratic on the deep DAGs of derivatives)."""
    stack = [e]
    while stack:
        x = stack.pop()
        if x.is_Symbol:
            return True
        stack.extend(x.args)
    return False


def add_parts(e: se.Add, literal=is_literal) -> tuple[float, list[se.Basic]]:
    """(constant term, non-constant terms) of a sum, in symengine's stable order."""
    const = 0.0
    terms = []
    for a in e.args:
        if literal(a):
            const += float(a)
        else:
            terms.append(a)
    return const, terms


def mul_parts(e: se.Mul, literal=is_literal) -> tuple[float, list[se.Basic], list[se.Basic]]:
    """(numeric factor, numerator factors, divisors) of a product.

    A divisor is returned as its positive power: ``x*y**-2`` gives ``(1.0, [x], [y**2])``."""
    coeff = 1.0
    numer, denom = [], []
    for a in e.args:
        if literal(a):
            coeff *= float(a)
        elif isinstance(a, se.Pow) and a.args[1].is_Integer and a.args[1] < 0:
            base, exp = a.args
            denom.append(base if exp == -1 else se.Pow(base, -exp))
        else:
            numer.append(a)
    return coeff, numer, denom


def own_cost(e: se.Basic, literal=is_literal) -> OpCount:
    """Cost of the node ``e`` itself; its arguments (as returned by :func:`children`) excluded.
    ``literal``: :func:`is_literal` or a memoised twin of it."""
    if literal(e) or e.is_Symbol:
        return ZERO
    if isinstance(e, se.Add):
        const, terms = add_parts(e, literal)
        return OpCount(add=len(terms) - 1 + (const != 0.0))
    if isinstance(e, se.Mul):
        coeff, numer, denom = mul_parts(e, literal)
        factors = len(numer) + (abs(coeff) != 1.0)
        return OpCount(mul=max(factors - 1, 0) + len(denom))
    if isinstance(e, se.Pow):
        exp = e.args[1]
        if exp.is_Integer:
            k = int(exp)
            return OpCount(mul=k - 1) if k >= 2 else OpCount(mul=-k)
        if exp == se.Rational(1, 2):
            return OpCount(call=1)
        if exp == se.Rational(-1, 2):
            return OpCount(call=1, mul=1)
        return OpCount(call=1)
    if isinstance(e, se.Piecewise):
        return OpCount(call=len(e.args) // 2 - 1)
    if isinstance(e, COMPARISONS):
        return OpCount(add=1)
    if isinstance(e, LOGIC):
        return ZERO
    if e.is_Function:
        return OpCount(call=1)
    raise TypeError(f"no cost rule for {type(e).__name__}: {e}")


def children(e: se.Basic, literal=is_literal) -> tuple:
    """The sub-expressions that are evaluated separately (divisors as positive powers)."""
    if literal(e) or e.is_Symbol:
        return ()
    if isinstance(e, se.Add):
        return tuple(add_parts(e, literal)[1])
    if isinstance(e, se.Mul):
        _, numer, denom = mul_parts(e, literal)
        return tuple(numer) + tuple(denom)
    if isinstance(e, se.Pow):
        return (e.args[0],)
    if isinstance(e, se.Piecewise):
        return tuple(a for a in e.args if a != se.true)
    return tuple(e.args)


def tree_count(exprs) -> OpCount:
    """Operations of the expressions as trees (a shared node paid at every occurrence).

    Memoised on the DAG (plain integer triples inside), so tens of millions of operations
    are counted in milliseconds."""
    memo: dict = {}
    literals: dict = {}     # each node's is_literal, asked by its parents' and its own rules

    def literal(e) -> bool:
        known = literals.get(e)
        if known is None:
            known = literals[e] = is_literal(e)
        return known

    def visit(e) -> tuple[int, int, int]:
        hit = memo.get(e)
        if hit is None:
            own = own_cost(e, literal)
            add, mul, call = own.add, own.mul, own.call
            for child in children(e, literal):
                a, m, c = visit(child)
                add, mul, call = add + a, mul + m, call + c
            hit = memo[e] = (add, mul, call)
        return hit

    total = [0, 0, 0]
    for e in exprs:
        for k, v in enumerate(visit(se.sympify(e))):
            total[k] += v
    return OpCount(*total)


def program_count(assignments, outputs) -> OpCount:
    """Operations of a straight-line program: every assignment and output paid once, the
    temporaries it reads being free."""
    return tree_count([expr for _, expr in assignments] + list(outputs))


# -- critical path ---------------------------------------------------------------------------

LATENCY = {"add": 3, "mul": 3, "div": 13, "sqrt": 20, "select": 1, "call": 40, "kernel": 0}
"""Cycles from operands to result per operation kind, for the critical-path count: AMD Zen 4
(family 19h, AMD's Software Optimization Guide): vaddsd/vsubsd 3, vmulsd 3, vdivsd 13,
vsqrtsd 20 (15-21), a blend or sign flip 1. ``call``: a libm call (sin, cos, atan2, ... of an
argument the sincos kernel does not serve), a stated round figure (glibc's sin is 40-60
cycles). ``kernel``: a sin or cos of a joint angle (or of an argument affine in the joint angles, a
half angle) read from the sincos kernel's output, which runs at the start of the function:
its latency is the kernel's own critical path after its last argument
(:data:`kindyngen.codegen.trig_kernel.KERNEL_LATENCY` passed by the caller), 0 here. Strict C99: a*b + c is
a product then a sum (no contraction), and every sum and product is evaluated left to right in
the order the printer writes it."""


@dataclass(frozen=True)
class CriticalPath:
    """The longest chain of dependent operations of a program, in cycles of :data:`LATENCY`,
    and how many operations lie on it."""
    cycles: int
    operations: int

    def to_json(self) -> dict:
        return {"cycles": self.cycles, "operations": self.operations}


def longest_chain(nodes) -> CriticalPath:
    """Longest weighted path of a DAG given as ``(name, latency, dependencies)`` in an order
    where every dependency comes first; a node's result is ready ``latency`` cycles after its
    last dependency's.

    >>> longest_chain([("a", 3, ()), ("b", 13, ("a",)), ("c", 3, ("a",)), ("d", 3, ("b", "c"))])
    CriticalPath(cycles=19, operations=3)
    """
    ready: dict = {}
    for name, latency, deps in nodes:
        t, n = max((ready[d] for d in deps), default=(0, 0))
        ready[name] = (t + latency, n + (latency > 0))
    t, n = max(ready.values(), default=(0, 0))
    return CriticalPath(t, n)


def _printed_terms(terms: list) -> list:
    """The non-constant terms of a sum (:func:`add_parts`) in the order
    :mod:`kindyngen.codegen.printer` writes them (a positive term first)."""
    negative = [isinstance(t, se.Mul) and mul_parts(t)[0] < 0 for t in terms]
    if negative[0] and not all(negative):
        terms.insert(0, terms.pop(negative.index(False)))
    return terms


def _printed_factors(factors) -> list:
    """Factors as the printer chains them: a power ``b**k`` (k >= 2 integer) inside a product
    is ``b*b*...`` in line, k factors of the chain, not a product of its own."""
    out = []
    for f in factors:
        if isinstance(f, se.Pow) and f.args[1].is_Integer and int(f.args[1]) >= 2:
            out += [f.args[0]] * int(f.args[1])
        else:
            out.append(f)
    return out


def program_critical_path(assignments, outputs, served=(), latency=None) -> CriticalPath:
    """Critical path of a straight-line program as printed in C: temporaries ready when their
    expression is, inputs at 0, ``served`` (sin/cos expressions read from the kernel's arrays)
    at ``latency["kernel"]``.

    >>> x, y, z = se.symbols("x y z")
    >>> program_critical_path([], [x*y + z + 1])   # (x*y + z) + 1.0: 3 + 3 + 3
    CriticalPath(cycles=9, operations=3)
    >>> program_critical_path([], [x/(y*z)])       # x/(y*z): 3 + 13
    CriticalPath(cycles=16, operations=2)
    """
    timer = ChainTimer(served, latency)
    for sym, expr in assignments:
        timer.assign(sym, expr)
    t, n = max((timer.ready(e) for e in outputs), default=(0, 0))
    return CriticalPath(t, n)


class ChainTimer:
    """When each expression of a program is ready, as (cycles, operations on the chain), by
    the rules of :func:`program_critical_path`; temporaries are told with :meth:`assign`."""

    def __init__(self, served=(), latency=None):
        self.lat = lat = dict(LATENCY, **(latency or {}))
        self.served = frozenset(served)
        self.memo: dict = {}
        self.kernel = (lat["kernel"], 1 if lat["kernel"] else 0)
        self.literals: dict = {}

    def literal(self, e) -> bool:
        """:func:`is_literal`, memoised (asked of every node by its parents' rules)."""
        known = self.literals.get(e)
        if known is None:
            known = self.literals[e] = is_literal(e)
        return known

    def assign(self, sym, expr) -> None:
        self.memo[sym] = self.ready(expr)

    def ready(self, e):
        lat, memo, served, kernel = self.lat, self.memo, self.served, self.kernel
        visit, literal = self.ready, self.literal
        chain = _chain
        hit = memo.get(e)
        if hit is not None:
            return hit
        if e in served:
            hit = kernel
        elif e.is_Symbol or literal(e):
            hit = (0, 0)
        elif isinstance(e, se.Add):
            const, terms = add_parts(e, literal)
            terms = _printed_terms(terms)
            ready = [visit(t) for t in terms]
            hit = chain(ready[0], [(lat["add"], r) for r in ready[1:]] + ([(lat["add"], (0, 0))] if const else []))
        elif isinstance(e, se.Mul):
            coeff, numer, denom = mul_parts(e, literal)
            numer, denom = _printed_factors(numer), _printed_factors(denom)
            ready = [visit(f) for f in numer]
            if abs(coeff) != 1.0:
                ready.insert(0, (0, 0))
            hit = chain(ready[0], [(lat["mul"], r) for r in ready[1:]]) if ready else (0, 0)
            if denom:
                d = [visit(f) for f in denom]
                hit = chain(hit, [(lat["div"], chain(d[0], [(lat["mul"], r) for r in d[1:]]))])
        elif isinstance(e, se.Pow):
            base, exp = e.args
            b = visit(base)
            if exp.is_Integer and int(exp) >= 2:
                hit = chain(b, [(lat["mul"], (0, 0))] * (int(exp) - 1))
            elif exp.is_Integer:
                hit = chain(chain(b, [(lat["mul"], (0, 0))] * (-int(exp) - 1)), [(lat["div"], (0, 0))])
            elif exp == se.Rational(1, 2):
                hit = chain(b, [(lat["sqrt"], (0, 0))])
            elif exp == se.Rational(-1, 2):
                hit = chain(b, [(lat["sqrt"], (0, 0)), (lat["div"], (0, 0))])
            else:
                hit = chain(b, [(lat["call"], (0, 0))])
        elif isinstance(e, se.Piecewise):
            parts = [visit(a) for a in children(e, literal)]
            hit = chain(max(parts), [(lat["select"], (0, 0))] * (len(e.args) // 2 - 1))
        elif isinstance(e, COMPARISONS):
            hit = chain(max(visit(a) for a in e.args), [(lat["add"], (0, 0))])
        elif isinstance(e, LOGIC):
            hit = max((visit(a) for a in e.args), default=(0, 0))
        elif e.is_Function:
            hit = chain(max(visit(a) for a in e.args), [(lat["call"], (0, 0))])
        else:
            raise TypeError(f"no latency rule for {type(e).__name__}: {e}")
        memo[e] = hit
        return hit


def _chain(start, steps):
    """``steps`` operations in sequence after ``start``, each joining one more operand (ready
    times): ((a op b) op c) ..."""
    t, n = start
    for operand_latency, operand in steps:
        t, n = max((t, n), operand)
        t, n = t + operand_latency, n + 1
    return t, n
