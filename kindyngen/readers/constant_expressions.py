"""Constant expressions written in a description (``pi/2``, ``sqrt(2)/2``, ``0.1 + 0.025``) as exact
sympy numbers, bounded before anything evaluates them.

sympify evaluates its input as Python and computes powers exactly: ``9**9**9**9`` would never
finish, a 20,000-term sum or 100,000 nested brackets exhaust the parser's stack. So an
expression is refused, with the file, the field and the reason, unless it is

* at most :data:`MAX_CHARACTERS` characters with brackets nested at most :data:`MAX_NESTING`
  deep (checked on the text, before Python's parser recurses), and an expression tree at most
  :data:`MAX_DEPTH` deep;
* arithmetic on numbers, ``pi`` and the functions of :data:`FUNCTIONS` only (no attributes,
  subscripts, other names or calls);
* bounded when evaluated in complex doubles first: every sub-expression at most
  :data:`MAGNITUDE` in magnitude, every power of a nonzero base at least 1/MAGNITUDE, and
  exponents (multiplied along nested powers) at most :data:`MAX_EXPONENT` in magnitude, which
  bounds the size of the exact numbers sympy then computes.

Example:

>>> parse_constant("-pi/2", "f.yaml", "alpha")
-pi/2
>>> parse_constant("9**9**9**9", "f.yaml", "alpha")
Traceback (most recent call last):
...
kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'alpha': '9**9**9**9': not finite (beyond the range of a double)
>>> parse_constant("1.0000001**10**5", "f.yaml", "a")
Traceback (most recent call last):
...
kindyngen.model.robot_model.RobotDescriptionError: f.yaml: field 'a': '1.0000001**10**5': the exponent 100000 is beyond +-100 (the exponents of nested powers multiply)
"""
from __future__ import annotations

import ast
import cmath
import math

import sympy

from ..model.robot_model import RobotDescriptionError
from .input_bounds import shown

FUNCTIONS = {"sqrt": sympy.sqrt, "sin": sympy.sin, "cos": sympy.cos, "tan": sympy.tan,
             "asin": sympy.asin, "acos": sympy.acos, "atan": sympy.atan, "atan2": sympy.atan2}
NAMESPACE = {"pi": sympy.pi, **FUNCTIONS}
MAX_CHARACTERS = 200         # pi/2, sqrt(0.1**2 + 0.2**2), atan2(0.0392, 0.9992): tens of characters
MAX_NESTING = 20             # brackets in the text
MAX_DEPTH = 32               # the expression tree (unary minus chains included)
MAX_EXPONENT = 100           # |exponent|, multiplied along nested powers
MAGNITUDE = 1e300            # every sub-expression evaluated in doubles

# Only arithmetic on numbers, pi and the functions above: sympify evaluates its input as
# Python, so anything else (attributes, subscripts, other calls) is refused before it runs.
_NODES = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.UAdd,
          ast.USub, ast.Constant, ast.Name, ast.Load, ast.Call)
# the same functions in complex doubles, for the bounds (atan2 of the real parts: if the
# arguments are not real, sympy finds the value is not either)
_DOUBLE_FUNCTIONS = {"sqrt": cmath.sqrt, "sin": cmath.sin, "cos": cmath.cos, "tan": cmath.tan,
                     "asin": cmath.asin, "acos": cmath.acos, "atan": cmath.atan,
                     "atan2": lambda y, x: complex(math.atan2(y.real, x.real))}
_OPERATIONS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
               ast.Div: lambda a, b: a / b}


def _nesting(text: str) -> int:
    """The deepest nesting of brackets in ``text`` (any kind, unbalanced ones included).

    >>> _nesting("sqrt((1 + 2)*3)"), _nesting("[[[")
    (2, 3)
    """
    depth = deepest = 0
    for char in text:
        if char in "([{":
            depth += 1
            deepest = max(deepest, depth)
        elif char in ")]}":
            depth -= 1
    return deepest


def _tree_depth(tree: ast.AST) -> int:
    """The depth of an expression tree, without recursion."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return deepest


def check_expression(text: str, source: str, field: str) -> ast.Expression:
    """The expression tree of ``text``, refused (see the module text) unless it is bounded
    arithmetic in numbers, pi and :data:`FUNCTIONS`."""
    def refuse(reason: str) -> RobotDescriptionError:
        return RobotDescriptionError(source, field, f"{shown(text)}: {reason}")

    if len(text) > MAX_CHARACTERS:
        raise refuse(f"{len(text)} characters, more than the {MAX_CHARACTERS} an expression may have")
    if _nesting(text) > MAX_NESTING:
        raise refuse(f"brackets nested {_nesting(text)} deep, more than {MAX_NESTING}")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, ValueError, MemoryError, RecursionError) as exc:
        raise RobotDescriptionError(source, field, f"cannot parse {shown(text)} as a number") from exc
    if _tree_depth(tree) > MAX_DEPTH:
        raise refuse(f"nested {_tree_depth(tree)} operations deep, more than {MAX_DEPTH}")
    for node in ast.walk(tree):
        if not isinstance(node, _NODES):
            raise RobotDescriptionError(source, field, f"cannot parse {shown(text)} as a number")
        if isinstance(node, ast.Constant) and (isinstance(node.value, bool)
                                               or not isinstance(node.value, (int, float))):
            raise RobotDescriptionError(source, field, f"cannot parse {shown(text)} as a number")
        if isinstance(node, ast.Name) and node.id not in NAMESPACE:
            raise RobotDescriptionError(
                source, field, f"{shown(text)} is not a real constant (unknown name {node.id!r}; "
                f"allowed: {', '.join(sorted(NAMESPACE))})")
        if isinstance(node, ast.Call) and (node.keywords or not isinstance(node.func, ast.Name)
                                           or node.func.id not in FUNCTIONS):
            raise RobotDescriptionError(source, field, f"cannot parse {shown(text)} as a number")
    _bounded(tree.body, refuse)
    return tree


def _bounded(node: ast.AST, refuse) -> tuple[complex, float]:
    """(value in complex doubles, exponent weight) of a checked expression node, refusing a
    sub-expression beyond :data:`MAGNITUDE`, a power of a nonzero base below 1/MAGNITUDE, or
    an exponent weight (the product of the exponents a literal is raised to) beyond
    :data:`MAX_EXPONENT`. Recursive: the depth is bounded by :data:`MAX_DEPTH`."""
    weight = 1.0
    try:
        if isinstance(node, ast.Constant):
            value = complex(node.value)
        elif isinstance(node, ast.Name):
            value = complex(math.pi)
        elif isinstance(node, ast.UnaryOp):
            value, weight = _bounded(node.operand, refuse)
            value = -value if isinstance(node.op, ast.USub) else value
        elif isinstance(node, ast.Call):
            arguments = [_bounded(argument, refuse) for argument in node.args]
            weight = max((w for _, w in arguments), default=1.0)
            value = complex(_DOUBLE_FUNCTIONS[node.func.id](*(v for v, _ in arguments)))
        else:
            (left, left_weight), (right, right_weight) = _bounded(node.left, refuse), _bounded(node.right, refuse)
            if isinstance(node.op, ast.Pow):
                value = left ** right
                weight = left_weight * max(1.0, abs(right))
                if weight > MAX_EXPONENT:     # a finite power whose exact value could be huge
                    raise refuse(f"the exponent {weight:.9g} is beyond +-{MAX_EXPONENT} (the exponents "
                                 f"of nested powers multiply)")
                if left != 0 and abs(value) < 1 / MAGNITUDE:
                    raise refuse(f"a power below {1 / MAGNITUDE:g} in magnitude")
            else:
                weight = max(left_weight, right_weight)
                value = _OPERATIONS[type(node.op)](left, right)
    except RobotDescriptionError:           # a refusal below (a ValueError too)
        raise
    except ZeroDivisionError:
        raise refuse("divides by zero") from None
    except OverflowError:
        raise refuse("not finite (beyond the range of a double)") from None
    except (TypeError, ValueError):         # a function given the wrong number of arguments
        raise refuse("cannot parse as a number") from None
    if not cmath.isfinite(value):
        raise refuse("not finite (beyond the range of a double)")
    if abs(value) > MAGNITUDE:
        raise refuse(f"a value beyond {MAGNITUDE:g} in magnitude")
    return value, weight


def parse_constant(text: str, source: str, field: str) -> sympy.Expr:
    """A real constant expression, exact (decimals as the rationals written).

    >>> parse_constant("sqrt(2)/2", "f.yaml", "axis[0]"), parse_constant("0.1 + 0.025", "f.yaml", "a")
    (sqrt(2)/2, 1/8)
    """
    check_expression(text, source, field)
    try:
        expr = sympy.sympify(text, locals=NAMESPACE, rational=True)
    except Exception as exc:  # sympify raises many kinds (SympifyError, TypeError, ...)
        raise RobotDescriptionError(source, field, f"cannot parse {shown(text)} as a number") from exc
    if not isinstance(expr, sympy.Expr) or not expr.is_number or not expr.is_real:
        raise RobotDescriptionError(source, field, f"{shown(text)} is not a real constant")
    try:
        finite = math.isfinite(float(expr))
    except (OverflowError, TypeError, ValueError):
        finite = False
    if not finite:
        raise RobotDescriptionError(source, field, f"expected a finite number, got {shown(text)}")
    return expr
