"""The critical-path count (kindyngen.codegen.opcount) against independent computations: brute-force
path enumeration on small hand-made DAGs, and a walk over the generated C text itself (parsed as
the expression grammar C and Python share), which is what the compiler evaluates."""
import ast
import itertools
import json
import random
import re
from pathlib import Path

import pytest
import symengine as se

from kindyngen.codegen import trig_kernel
from kindyngen.codegen.printer import C
from kindyngen.codegen.opcount import LATENCY, CriticalPath, longest_chain, program_critical_path

ROOT = Path(__file__).resolve().parents[2]


def all_paths_longest(nodes):
    """Longest path by enumerating every path from every node back to a source."""
    deps = {name: d for name, _, d in nodes}
    lat = {name: l for name, l, _ in nodes}

    def paths(name):
        if not deps[name]:
            return [[name]]
        return [p + [name] for d in deps[name] for p in paths(d)]

    best = (0, 0)
    for name in deps:
        for p in paths(name):
            best = max(best, (sum(lat[x] for x in p), sum(lat[x] > 0 for x in p)))
    return best


def test_longest_chain_against_enumeration():
    rng = random.Random(7)
    for trial in range(200):
        n = rng.randint(1, 9)
        nodes = []
        for k in range(n):
            deps = tuple(f"n{j}" for j in range(k) if rng.random() < 0.4)
            nodes.append((f"n{k}", rng.choice([0, 1, 3, 13, 20]), deps))
        want = all_paths_longest(nodes)
        got = longest_chain(nodes)
        assert got.cycles == want[0], (nodes, got, want)


def test_hand_made_programs():
    a, b, c, d, t = se.symbols("a b c d t")
    add, mul, div = LATENCY["add"], LATENCY["mul"], LATENCY["div"]
    # t = a*b (3); out = t + c + d printed c + d + t: (c + d) and t both ready at 3, then + t
    assert program_critical_path([(t, a*b)], [t + c + d]).cycles == mul + add
    # a power inside a product is chained in line (b*b*t is (b*b)*t), which the generated fd
    # exercises below where the first factor is the late one
    assert C.expr(t * b**2, {b: "b", t: "t"}) == "b*b*t"
    assert program_critical_path([(t, a*b*c)], [t * b**2]).cycles == 3 * mul
    # a divisor product and a division
    assert program_critical_path([], [a / (b * c)]).cycles == mul + div
    # integer powers are repeated products: b*b*b
    assert program_critical_path([], [b**3]).cycles == 2 * mul
    # sin of a joint angle served by the kernel: ready at its latency
    q = se.Symbol("q_0")
    served = {se.sin(q)}
    assert program_critical_path([], [se.sin(q) * a], served, {"kernel": 51}).cycles == 51 + mul
    assert program_critical_path([], [se.sin(q) * a]).cycles == LATENCY["call"] + mul


# -- the generated C, walked as text ---------------------------------------------------------

OPS = {ast.Add: "add", ast.Sub: "add", ast.Mult: "mul", ast.Div: "div"}


def c_ready(expr: str, ready: dict, kernel: int) -> int:
    """Cycles until a C expression of the generated code is ready."""
    def visit(node):
        if isinstance(node, ast.BinOp):
            return max(visit(node.left), visit(node.right)) + LATENCY[OPS[type(node.op)]]
        if isinstance(node, ast.UnaryOp):
            return visit(node.operand)                # a sign flip
        if isinstance(node, ast.Constant):
            return 0
        if isinstance(node, ast.Name):
            return ready[node.id]
        if isinstance(node, ast.Subscript):       # q[3] (an input) or sin_q[3] (the kernel)
            return kernel if node.value.id in ("sin_q", "cos_q") else 0
        if isinstance(node, ast.Call):
            kind = "sqrt" if node.func.id == "sqrt" else "call"
            return max(visit(a) for a in node.args) + LATENCY[kind]
        raise TypeError(ast.dump(node))
    return visit(ast.parse(expr, mode="eval").body)


def c_bodies(source: str):
    """{function name: its statement lines} of the single-call functions of a generated .c."""
    out = {}
    for m in re.finditer(r"^void (\w+)\((?!long count)[^)]*\)\n\{\n(.*?)^\}", source, re.S | re.M):
        out[m.group(1)] = m.group(2).splitlines()
    return out


@pytest.mark.parametrize("robot", ["lwr4", "panda"])
def test_critical_path_is_the_printed_codes(robot):
    source = (ROOT / "generated" / robot / "c" / f"{robot}.c").read_text()
    counts = json.loads((ROOT / "generated" / robot / "opcounts.json").read_text())
    kernel = trig_kernel.kernel_latency()
    checked = 0
    for symbol, lines in c_bodies(source).items():
        name = symbol[len(robot) + 1:]
        if name not in counts or any("?" in line or "for (" in line for line in lines):
            continue                                  # selects and the DLS loop: not this grammar
        ready, worst, kernel_at = {}, 0, kernel
        for line in lines:
            line = line.strip()
            m = re.match(r"const double angles\[\d+\] = \{(.*)\};$", line)
            if m:        # the kernel's lanes: joint angles, half angles, zeros; it waits for the last
                lanes = ast.parse(f"({m.group(1)},)", mode="eval").body.elts
                kernel_at = kernel + max(c_ready(ast.unparse(a), ready, kernel) for a in lanes)
                continue
            if line.startswith(("kdg_sincos_half(", "if (kdg_sincos_half_split(")):  # half angles of q in place: halved in the kernel
                kernel_at = trig_kernel.kernel_latency(half=True)
                continue
            m = re.match(r"const double (t\d+) = (.*);$", line)
            if m:
                ready[m.group(1)] = c_ready(m.group(2), ready, kernel_at)
                continue
            m = re.match(r"\w+\[\d+\] = (.*);$", line)
            if m:
                worst = max(worst, c_ready(m.group(1), ready, kernel_at))
        assert worst == counts[name]["critical_path"]["cycles"], name
        checked += 1
    assert checked >= 15


def test_kernel_latency_is_its_printed_chain():
    """kernel_latency() against the kernel's C text walked line by line, the half-angle kernel's too."""
    for half in (False, True):
        ready = {}
        for line in trig_kernel.kernel_c(half=half).splitlines():
            m = re.match(r"\s*const double (\w+) = (.*);$", line)
            if m and "?" not in m.group(2):        # xi = x[j] (an input, ready at 0) or 0.5*x[j]
                ready[m.group(1)] = c_ready(m.group(2), ready, 0)
        # the blocks of eight, and both blocks of four of the split kernel (their names suffixed)
        for suffix in ("", "_a", "_b"):
            chain = max(ready["sin_r" + suffix], ready["cos_r" + suffix], ready["q" + suffix] + 2 * LATENCY["add"])
            assert trig_kernel.kernel_latency(half=half) == chain + trig_kernel.SELECTS * LATENCY["select"]


# -- shallower code: reassociation chosen by the count ----------------------------------------

def best_tree(ready, latency):
    """The earliest a sum of operands ready at ``ready`` can be ready, by trying every way of
    joining two of them (exhaustive, small n)."""
    ready = tuple(sorted(ready))
    if len(ready) == 1:
        return ready[0]
    best = None
    for i, j in itertools.combinations(range(len(ready)), 2):
        rest = [r for k, r in enumerate(ready) if k not in (i, j)]
        t = best_tree(rest + [max(ready[i], ready[j]) + latency], latency)
        best = t if best is None else min(best, t)
    return best


def _evaluate(assignments, expr, values):
    """A straight-line program's value at ``values`` (symbol -> float), in plain floats."""
    env = dict(values)
    for sym, e in list(assignments) + [(None, expr)]:
        v = float(e.xreplace({s: se.Float(env[s]) for s in e.free_symbols}))
        if sym is None:
            return v
        env[sym] = v


def test_reassociated_sums_are_optimal_and_equal():
    """Sums of operands ready at different times (chains of 0-4 products): the optimised
    program's critical path is the exhaustive optimum, its operation count that of the sum as
    written, its value the same."""
    from kindyngen.codegen.optimize import optimize
    from kindyngen.algorithms.symbolic import Port, SymbolicFunction
    rng = random.Random(3)
    add, mul = LATENCY["add"], LATENCY["mul"]
    for trial in range(12):
        n = rng.randint(3, 6)
        x = se.symbols(f"x0:{2 * n}")
        depth = [rng.randint(0, 4) for _ in range(n)]
        operands, stages = [], []
        for k in range(n):
            term = x[k]
            for j in range(depth[k]):         # one product per named intermediate
                s = se.Symbol(f"s{k}_{j}")
                stages.append((s, term * x[n + k]))
                term = s
            operands.append(term)
        f = SymbolicFunction("f", "", (Port("x", (2 * n,), ""),), (Port("y", (1,), ""),), (x,),
                             ((se.Add(*operands),),), stages=tuple(stages))
        p = optimize(f)
        assert p.critical.cycles == best_tree([d * mul for d in depth], add), (depth, p.critical)
        assert (p.after.add, p.after.mul) == (n - 1, sum(depth))
        values = {s: rng.uniform(-2, 2) for s in x}
        want = _evaluate(stages, se.Add(*operands), values)
        assert abs(_evaluate(p.assignments, p.outputs[0][0], values) - want) <= 1e-12 * (1 + abs(want))
