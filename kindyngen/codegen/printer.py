"""Print straight-line programs as C, numpy or CasADi expressions.

Each node is printed exactly as :mod:`kindyngen.codegen.opcount` counts it (sums with
subtractions, one literal per product, integer powers as repeated products, divisors
grouped), so the counts in the generated headers are the operations in the code.

Example:

>>> import symengine as se
>>> x, y = se.symbols("x y")
>>> C.expr(x*y - 2*x + se.sin(y)**2, {x: "q[0]", y: "q[1]"})
'sin(q[1])*sin(q[1]) - 2.0*q[0] + q[0]*q[1]'
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import symengine as se

from .float32 import c_float
from .opcount import COMPARISONS, add_parts, is_literal, mul_parts

ATOM, MUL, NEG, ADD, CMP, AND, OR, SELECT = 100, 50, 45, 40, 30, 20, 10, 5


@dataclass(frozen=True)
class Dialect:
    """How one target language spells functions, selects and logic."""

    name: str
    functions: dict
    select: str          # format with c, a, b
    logic_and: str
    logic_or: str
    logic_not: str
    select_is_call: bool  # numpy/casadi selects are calls (no precedence issue)
    booleans: tuple = ("0", "1")  # spelling of (false, true)
    single: bool = False  # C float: constants rounded once from their exact values, f-suffixed
    times: str = "*"              # element-wise product and quotient (MATLAB: .* and ./)
    divide: str = "/"

    def literal(self, value) -> str:
        """A non-negative constant: a float, or (single) its exact value as a Fraction."""
        if self.single:
            return c_float(value)
        text = repr(float(value))
        if text in ("inf", "-inf", "nan"):
            raise ValueError(f"non-finite constant {text} in generated code")
        return text

    def _value(self, literals) -> "float | Fraction":
        """The product of literal nodes: in double the product of their doubles, as the counts
        take it (the value the double code always printed); single: exact."""
        if not self.single:
            value = 1.0
            for a in literals:
                value *= float(a)
            return value
        value = Fraction(1)
        for a in literals:
            value *= _exact(a)
        return value

    def expr(self, e, names: dict) -> str:
        return self._print(se.sympify(e), names)[0]

    # -- recursive printer: returns (text, precedence) -------------------------------
    def _print(self, e, names):
        if e in names:
            return names[e], ATOM
        if e == se.true or e == se.false:
            return self.booleans[e == se.true], ATOM
        if is_literal(e) or e.is_Number:
            v = _exact(e) if self.single else float(e)
            return (self.literal(v), ATOM) if v >= 0 else ("-" + self.literal(-v), NEG)
        if e.is_Symbol:
            raise KeyError(f"symbol {e} has no name in this function")
        if isinstance(e, se.Add):
            return self._add(e, names)
        if isinstance(e, se.Mul):
            return self._mul(e, names)
        if isinstance(e, se.Pow):
            return self._pow(e, names)
        if isinstance(e, se.Piecewise):
            return self._piecewise(e, names)
        if isinstance(e, COMPARISONS):
            op = {se.StrictLessThan: "<", se.LessThan: "<=", se.Equality: "==", se.Unequality: "!="}[type(e)]
            a, b = (self._wrap(x, names, ADD + 1) for x in e.args)
            return f"{a} {op} {b}", CMP
        if isinstance(e, se.And):
            return self._logic(self.logic_and, e.args, names, AND)
        if isinstance(e, se.Or):
            return self._logic(self.logic_or, e.args, names, OR)
        if isinstance(e, se.Not):
            return self.logic_not.format(self._print(e.args[0], names)[0]), ATOM
        if e.is_Function:
            fname = type(e).__name__.lower()
            if fname not in self.functions:
                raise ValueError(f"{self.name}: no spelling for function {fname}")
            args = ", ".join(self._print(a, names)[0] for a in e.args)
            return f"{self.functions[fname]}({args})", ATOM
        raise TypeError(f"{self.name}: cannot print {type(e).__name__}: {e}")

    def _wrap(self, e, names, min_prec):
        text, prec = self._print(e, names)
        return text if prec >= min_prec else f"({text})"

    def _add(self, e, names):
        const, terms = add_parts(e)
        if self.single:
            const = sum((_exact(a) for a in e.args if is_literal(a)), Fraction(0))
        negative = [isinstance(t, se.Mul) and mul_parts(t)[0] < 0 for t in terms]
        if negative[0] and not all(negative):  # lead with a positive term: a - b, not -b + a
            first = negative.index(False)
            terms.insert(0, terms.pop(first))
        parts = []
        for k, term in enumerate(terms):
            negative = isinstance(term, se.Mul) and mul_parts(term)[0] < 0
            body = self._wrap(-term if negative else term, names, ADD if k == 0 else ADD + 1)
            if k == 0:
                parts.append("-" + self._wrap(-term, names, MUL) if negative else body)
            else:
                parts.append(("- " if negative else "+ ") + body)
        if const != 0.0:
            parts.append(("- " if const < 0 else "+ ") + self.literal(abs(const)))
        return " ".join(parts), ADD

    def _mul(self, e, names):
        coeff, numer, denom = mul_parts(e)
        if self.single:
            coeff = self._value([a for a in e.args if is_literal(a)])
        factors = ([self.literal(abs(coeff))] if abs(coeff) != 1 else []) + \
                  [self._wrap(f, names, MUL) for f in numer]
        text = self.times.join(factors) if factors else self.literal(1)
        if denom:
            divisor = self.times.join(self._wrap(d, names, MUL) for d in denom)
            text += self.divide + (divisor if len(denom) == 1 and self._print(denom[0], names)[1] == ATOM else f"({divisor})")
        if coeff < 0:
            return "-" + text, NEG
        return text, MUL

    def _pow(self, e, names):
        base, exp = e.args
        if exp.is_Integer:
            k = int(exp)
            b = self._wrap(base, names, ATOM)
            if k >= 2:
                return self.times.join([b] * k), MUL
            if k <= -1:
                return self.literal(1) + self.divide + (b if k == -1 else "(" + self.times.join([b] * -k) + ")"), MUL
        if exp == se.Rational(1, 2):
            return f"{self.functions['sqrt']}({self._print(base, names)[0]})", ATOM
        if exp == se.Rational(-1, 2):
            return f"{self.literal(1)}{self.divide}{self.functions['sqrt']}({self._print(base, names)[0]})", MUL
        return f"{self.functions['pow']}({self._print(base, names)[0]}, {self._print(exp, names)[0]})", ATOM

    def _piecewise(self, e, names):
        args = list(e.args)
        pairs = [(args[k], args[k + 1]) for k in range(0, len(args), 2)]
        value, cond = pairs[-1]
        if cond != se.true:
            raise ValueError("Piecewise without a final default branch cannot be printed branch-free")
        text = self._print(value, names)[0]
        for value, cond in reversed(pairs[:-1]):
            c = self._print(cond, names)[0]
            text = self.select.format(c=c, a=self._print(value, names)[0], b=text)
        return text, (ATOM if self.select_is_call else SELECT)

    def _logic(self, fmt, args, names, prec):
        texts = [self._wrap(a, names, prec + 1) for a in args]
        out = texts[0]
        for t in texts[1:]:
            out = fmt.format(out, t)
        return out, (ATOM if fmt.endswith(")") else prec)


def _exact(e) -> Fraction:
    """The exact value of a literal node: a rational as it is, a double as the double, any
    other constant (sqrt(2), pi, ...) from 40 significant digits (then rounded once to float).

    >>> _exact(se.Rational(1, 3)), _exact(se.RealDouble(0.5))
    (Fraction(1, 3), Fraction(1, 2))
    """
    if e.is_Rational or e.is_Integer:
        return Fraction(int(e.p), int(e.q)) if e.is_Rational else Fraction(int(e))
    if isinstance(e, se.RealDouble):
        return Fraction(float(e))
    import sympy
    return Fraction(str(sympy.Float(sympy.sympify(e).evalf(40), 40)))


_MATH = ("sin", "cos", "tan", "asin", "acos", "atan", "sqrt", "exp", "log", "tanh")

C = Dialect(
    name="c",
    functions={**{f: f for f in _MATH}, "atan2": "atan2", "abs": "fabs", "max": "fmax",
               "min": "fmin", "pow": "pow"},
    select="({c} ? {a} : {b})", logic_and="{} && {}", logic_or="{} || {}", logic_not="!({})",
    select_is_call=False,
)

C_FLOAT = Dialect(
    name="c",
    functions={**{f: f + "f" for f in _MATH}, "atan2": "atan2f", "abs": "fabsf", "max": "fmaxf",
               "min": "fminf", "pow": "powf"},
    select="({c} ? {a} : {b})", logic_and="{} && {}", logic_or="{} || {}", logic_not="!({})",
    select_is_call=False, single=True,
)
"""C with ``--scalar float``: float literals and the single-precision libm functions."""

NUMPY = Dialect(
    name="numpy",
    functions={**{f: f"np.{f}" for f in ("sin", "cos", "tan", "sqrt", "exp", "log", "tanh")},
               "asin": "np.arcsin", "acos": "np.arccos", "atan": "np.arctan", "atan2": "np.arctan2",
               "abs": "np.abs", "max": "np.maximum", "min": "np.minimum", "pow": "np.power"},
    select="np.where({c}, {a}, {b})", logic_and="np.logical_and({}, {})",
    logic_or="np.logical_or({}, {})", logic_not="np.logical_not({})", select_is_call=True,
    booleans=("False", "True"),
)

CASADI = Dialect(
    name="casadi",
    functions={**{f: f"ca.{f}" for f in _MATH}, "atan2": "ca.atan2", "abs": "ca.fabs",
               "max": "ca.fmax", "min": "ca.fmin", "pow": "ca.power"},
    select="ca.if_else({c}, {a}, {b})", logic_and="ca.logic_and({}, {})",
    logic_or="ca.logic_or({}, {})", logic_not="ca.logic_not({})", select_is_call=True,
)

MATLAB = Dialect(
    name="matlab",
    functions={**{f: f for f in _MATH}, "atan2": "atan2", "abs": "abs", "max": "max",
               "min": "min", "pow": "power"},
    # no conditional expression in MATLAB: the generated .m file defines kdg_select
    # (element-wise, both branches evaluated, like numpy's where)
    select="kdg_select({c}, {a}, {b})", logic_and="{} & {}", logic_or="{} | {}", logic_not="~({})",
    select_is_call=True, booleans=("false", "true"), times=".*", divide="./",
)

JAX = Dialect(
    name="jax",
    functions={f: v.replace("np.", "jnp.") for f, v in NUMPY.functions.items()},
    select="jnp.where({c}, {a}, {b})", logic_and="jnp.logical_and({}, {})",
    logic_or="jnp.logical_or({}, {})", logic_not="jnp.logical_not({})", select_is_call=True,
    booleans=("False", "True"),
)
