"""Common-subexpression elimination: SymbolicFunction -> straight-line Program.

The program is the pair SymPyBotics carries code as: (intermediates, outputs).  CSE runs on
the DAG with symengine, which takes milliseconds where sympy's takes minutes.

Example:

>>> import symengine as se
>>> from kindyngen.algorithms.symbolic import Port, SymbolicFunction, port_symbols
>>> q = port_symbols("q", (2,))
>>> s = se.sin(q[0] + q[1])
>>> f = SymbolicFunction("f", "", (Port("q", (2,), ""),), (Port("y", (2,), ""),), (q,), ((2*s, s*s),))
>>> p = optimize(f)
>>> len(p.assignments), p.after.call
(1, 1)
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import symengine as se

from .trig_kernel import kernel_latency
import heapq

from .opcount import ChainTimer, CriticalPath, OpCount, program_count, program_critical_path, tree_count
from ..algorithms.symbolic import SymbolicFunction


CSE_CHUNK = 4096
"""Expressions per symengine ``cse`` call on a function with named intermediates. cse's time
grows about quadratically with the number of expressions even when each is small, so longer
lists are reduced in consecutive chunks of this many, in derivation order; what later chunks
share with earlier ones they share through the named intermediates. Measured by
``python -m benchmarks.tree_scaling --cse-only`` (``results/tree_scaling.json``, "cse"): a
chain's M of 40, 80 and 120 joints (4.3k, 16.4k and 36.1k expressions) optimised in 0.87,
5.7 and 22.3 s CPU with one cse call, in 1.1, 4.9 and 10.3 s in chunks, for 0.1-0.9 % more
operations; on the G1 (every function, both fd routes) chunks of 4096 give 62973 add + mul,
2048 give 63301 and 1024 give 63858, none faster. Every staged function of the G1 fits one
chunk. Functions without intermediates are one DAG whose expressions are not small: one cse
call."""


@dataclass(frozen=True)
class Program:
    """A function as straight-line code: temporaries in evaluation order, then outputs
    (flat, row-major per port) in terms of inputs and temporaries."""

    function: SymbolicFunction
    assignments: tuple[tuple[se.Symbol, se.Basic], ...]
    outputs: tuple[tuple[se.Basic, ...], ...]
    before: OpCount
    after: OpCount
    # (route, operations after CSE) of every route that was optimised, chosen one included
    routes: tuple[tuple[str, OpCount], ...] = ()
    # longest chain of dependent operations of the C as printed, sin/cos of q from the kernel
    critical: CriticalPath = CriticalPath(0, 0)
    # the C single call's lane program (function.lanes), or None: the C prints this program
    lanes: "LaneProgram | None" = None
    # the C single call's joint loops (function.joint_loops), or None: the C prints them
    joint_loops: "JointLoopProgram | None" = None

    def __repr__(self) -> str:
        # expressions stay out of the repr (see SymbolicFunction.__repr__)
        return (f"Program({self.function.name!r}: {len(self.assignments)} temporaries, after CSE {self.after.add} add "
                f"{self.after.mul} mul {self.after.call} call, lanes={self.lanes!r})")


LANE_WIDTH = 4
"""Lanes of a lane program are padded to a multiple of this: four doubles fill an AVX2 vector
(two SSE2 or NEON vectors, half an AVX-512 one), so the loop over lanes vectorises without a
scalar remainder; lwr4's and panda's seven joints give eight lanes, the eighth discarded."""


@dataclass(frozen=True)
class LaneProgram:
    """A :class:`kindyngen.algorithms.symbolic.LaneSweep` as code: ``assignments`` and the
    ``outputs`` of the ports no lane fills (None for the ports the lanes fill) computed once,
    then the seed ``values[l][k]`` of the ``used`` lanes (reduced expressions), then, per lane,
    ``lane_assignments`` and ``lane_outputs`` (``places[m]`` says where lane output m goes).
    ``count``: lanes printed, ``used`` (the lanes kept) padded to :data:`LANE_WIDTH`. Operations executed:
    ``uniform + count * lane``."""

    count: int
    used: int
    assignments: tuple
    outputs: tuple
    seeds: tuple
    values: tuple
    lane_assignments: tuple
    lane_outputs: tuple
    places: tuple
    uniform: OpCount
    lane: OpCount
    critical: CriticalPath

    def __repr__(self) -> str:
        # expressions stay out of the repr (see SymbolicFunction.__repr__)
        return (f"LaneProgram({self.count} lanes ({self.used} used), {len(self.assignments)} temporaries once, "
                f"{len(self.lane_assignments)} per lane)")

    @property
    def executed(self) -> OpCount:
        """Operations a call executes, padding lanes included."""
        return OpCount(self.uniform.add + self.count * self.lane.add, self.uniform.mul + self.count * self.lane.mul,
                       self.uniform.call + self.count * self.lane.call)

    def to_json(self) -> dict:
        return {"lanes": self.count, "used": self.used, "uniform": self.uniform.to_json(),
                "per_lane": self.lane.to_json(), "executed": self.executed.to_json(),
                "critical_path": self.critical.to_json()}


@dataclass(frozen=True)
class JointLoopProgram:
    """:class:`kindyngen.algorithms.symbolic.JointLoops` as code: ``once`` and each loop piece
    (``pieces``: (name, Program)) optimised alone, the pieces with their lane inputs.
    Operations executed: each piece's count times its runs (``JointLoops.runs``), and the
    subtree sums, one addition per entry of ``kdg_c`` per joint with a parent (or on a floating
    base's root)."""

    loops: "JointLoops"
    once: Program
    pieces: tuple

    def __repr__(self) -> str:
        return f"JointLoopProgram({self.loops!r})"

    @property
    def sums(self) -> int:
        """Additions of the subtree sums."""
        loops = self.loops
        into = sum(1 for p in loops.parents if p >= 0 or loops.root is not None)
        return into * loops.body.function.outputs[0].size

    def parts(self) -> dict:
        """{piece: (operations per run, runs)}, in the order a call runs them."""
        out = {"once": (self.once.after, 1)}
        for name, program in self.pieces:
            out[name] = (program.after, self.loops.runs(name))
            if name == "body":
                out["sums"] = (OpCount(add=self.sums), 1)
        return out

    @property
    def executed(self) -> OpCount:
        total = OpCount()
        for count, runs in self.parts().values():
            total = total + OpCount(count.add * runs, count.mul * runs, count.call * runs)
        return total

    def to_json(self) -> dict:
        return {"joints": self.loops.joints, "lanes": self.loops.lanes,
                "parts": {name: {**count.to_json(), "runs": runs} for name, (count, runs) in self.parts().items()},
                "executed": self.executed.to_json()}


JOINT_LOOPS_RATIO = 2.5
"""A C single call runs its joint loops when they execute at most this many times the
operations (add + mul) of the scalar program, else the scalar program. tau_derivatives,
gcc 12 -O3 -march=native on Zen 5 (docs/latency.md, "Joint loops"), executed / scalar
operations -> speed against the scalar program: two pendulums on a body 10.6 -> 0.42x, the
mobile slider tree 3.5 -> 0.82x, solo12 with a fixed body 3.02 -> 1.05x, floating 2.06 -> 1.76x,
tests/algorithms/test_tree_joint_loops.py's three branches fixed 2.03 -> 1.92x, floating 1.68 ->
1.94x, the G1 1.38 -> 2.13x, Talos 1.29 -> 2.09x; after it was set: bolt 2.11 -> 1.64x, go2 2.00 ->
1.70x, human 1.42 -> 2.39x.
Counts are integers: the choice is the same on every machine."""


def _paying(loops: JointLoopProgram, scalar: OpCount) -> "JointLoopProgram | None":
    """``loops`` if they pay against the scalar program's count (:data:`JOINT_LOOPS_RATIO`), else None."""
    executed = loops.executed
    return loops if executed.add + executed.mul <= JOINT_LOOPS_RATIO * (scalar.add + scalar.mul) else None


def optimize_joint_loops(loops) -> JointLoopProgram:
    """``loops.once`` and each piece of ``loops`` (:class:`kindyngen.algorithms.symbolic.JointLoops`)
    through :func:`optimize`."""
    return JointLoopProgram(loops=loops, once=optimize(loops.once),
                            pieces=tuple((name, optimize(body.function)) for name, body in loops.pieces()))


def optimize(function: SymbolicFunction, report=None) -> Program:
    """CSE over all outputs of ``function`` together, with temporaries named t0, t1, ...

    A function with named intermediates (``function.stages``) is reduced as one list of its
    intermediates' and outputs' expressions; the intermediates become temporaries like CSE's
    own. Its count before CSE counts each intermediate once (the algorithm as derived).

    A function with ``alternatives`` is optimised by every route, and the route with the
    fewest additions and multiplications after CSE (the first one on a tie) is kept; its
    summary says what the others cost.

    ``report`` (optional) is called with the name of each phase as it starts ("CSE", "CSE
    chunk 2/3", "lane program", "critical path", a route's name first): the progress line of a
    long optimisation."""
    report = report or _silent
    if function.alternatives:
        return _cheapest((replace(function, alternatives=()),) + function.alternatives, report)
    flat = [e for port in function.output_exprs for e in port]
    staged = [e for _, e in function.stages]
    report(f"CSE of {len(staged) + len(flat)} expressions")
    replacements, reduced = _cse(staged + flat, report) if function.stages else se.cse(flat)
    if function.stages:
        replacements, reduced = _merged(replacements, function.stages, reduced)
    rename = {sym: se.Symbol(f"t{k}") for k, (sym, _) in enumerate(replacements)}
    assignments = tuple((rename[sym], _renamed(expr, rename)) for sym, expr in replacements)
    reduced = [_renamed(e, rename) for e in reduced]
    assignments, reduced = _hoist_power_bases(assignments, reduced)
    assignments = _live(assignments, reduced)
    report("critical path")
    assignments, reduced = _shallower(function, assignments, reduced)
    outputs, start = [], 0
    for port in function.outputs:
        outputs.append(tuple(reduced[start:start + port.size]))
        start += port.size
    critical = critical_path(function, assignments, reduced)
    after = program_count(assignments, reduced)
    if function.lanes is not None:
        report("lane program")
    if function.joint_loops is not None:
        report("joint loops")
    return Program(
        function=function,
        assignments=assignments,
        outputs=tuple(outputs),
        before=tree_count(staged + flat),
        after=after,
        critical=critical,
        lanes=optimize_lanes(function, report) if function.lanes is not None else None,
        joint_loops=(_paying(optimize_joint_loops(function.joint_loops), after)
                     if function.joint_loops is not None else None),
    )


def _silent(phase: str) -> None:
    """No progress report."""


def optimize_lanes(function: SymbolicFunction, report=None) -> LaneProgram:
    """CSE over the lane sweep's stages, the outputs outside the lanes, the seed values and the
    lane expressions together; every temporary that reads a seed (or such a temporary) is a
    lane temporary, the rest are computed once. The critical path is the longest over the used
    lanes, each lane's seeds assigned their values.

    >>> from kindyngen.algorithms.symbolic import LaneSweep, Port, port_symbols
    >>> x, s = port_symbols("x", (1,)), se.Symbol("s")
    >>> sweep = LaneSweep(seeds=(s,), values=((x[0] + 1,), (2,)), exprs=(s * (x[0] + 1) ** 2,), places=((0, 0, 1),))
    >>> f = SymbolicFunction("f", "", (Port("x", (1,), ""),), (Port("y", (2,), ""),), (x,),
    ...                      (((x[0] + 1) ** 3, 2 * (x[0] + 1) ** 2),), lanes=sweep)
    >>> p = optimize_lanes(f)
    >>> p.count, p.used, p.assignments, p.values, p.lane_outputs
    (4, 2, ((t0, 1 + x_0),), ((t0,), (2,)), (s*t0**2,))
    """
    sweep = function.lanes
    n_seeds, used = len(sweep.seeds), len(sweep.values)
    filled = {port for port, _, _ in sweep.places}
    uniform_exprs = [e for p, port in enumerate(function.output_exprs) if p not in filled for e in port]
    seed_exprs = [se.sympify(v) for row in sweep.values for v in row]
    flat = uniform_exprs + seed_exprs + list(sweep.exprs)
    if sweep.stages:
        replacements, reduced = _cse([e for _, e in sweep.stages] + flat, report or _silent, "lane program ")
        replacements, reduced = _merged(replacements, sweep.stages, reduced)
    else:
        replacements, reduced = se.cse(flat)
    rename = {sym: se.Symbol(f"t{k}") for k, (sym, _) in enumerate(replacements)}
    assignments = tuple((rename[sym], _renamed(expr, rename)) for sym, expr in replacements)
    reduced = [_renamed(e, rename) for e in reduced]
    assignments, reduced = _hoist_power_bases(assignments, reduced)
    assignments = _live(assignments, reduced)
    varying = set(sweep.seeds)
    for sym, expr in assignments:
        if expr.free_symbols & varying:
            varying.add(sym)
    once = tuple((sym, e) for sym, e in assignments if sym not in varying)
    per_lane = tuple((sym, e) for sym, e in assignments if sym in varying)
    n_uniform, n_seed_values = len(uniform_exprs), len(seed_exprs)
    uniform_out, seed_out = reduced[:n_uniform], reduced[n_uniform:n_uniform + n_seed_values]
    lane_out = tuple(reduced[n_uniform + n_seed_values:])
    outputs, start = [], 0
    for p, port in enumerate(function.outputs):
        if p in filled:
            outputs.append(None)
        else:
            outputs.append(tuple(uniform_out[start:start + port.size]))
            start += port.size
    values = tuple(tuple(seed_out[l * n_seeds:(l + 1) * n_seeds]) for l in range(used))
    critical = max((critical_path(function, once + tuple(zip(sweep.seeds, values[l])) + per_lane,
                                  list(uniform_out) + list(lane_out)) for l in range(used)),
                   key=lambda c: (c.cycles, c.operations))
    return LaneProgram(
        count=-(-used // LANE_WIDTH) * LANE_WIDTH, used=used, assignments=once, outputs=tuple(outputs),
        seeds=tuple(sweep.seeds), values=values, lane_assignments=per_lane, lane_outputs=lane_out,
        places=tuple(sweep.places),
        uniform=program_count(once, list(uniform_out) + [v for v in seed_out if not v.is_Number]),
        lane=program_count(per_lane, lane_out), critical=critical)


def _served(function: SymbolicFunction) -> set:
    """The sin/cos the C sincos kernel serves as entries of the ``q`` port."""
    names = [p.name for p in function.inputs]
    served = set()
    if "q" in names:
        for sym in function.input_symbols[names.index("q")]:
            served |= {se.sin(sym), se.cos(sym)}
    return served


def kernel_arguments(function: SymbolicFunction, assignments, outputs) -> dict:
    """The sin/cos of the program, as printed, whose argument is affine in ``q`` without being
    an entry of it (the half angles of the dual-quaternion functions, 0.5*(q[2] + q[0]), ...),
    each with that argument written in ``q`` alone: the C computes these arguments before the
    sincos kernel and runs it over them too. Affine, because such an argument costs a few adds
    and muls ahead of the kernel; anything else stays a libm call.

    >>> from kindyngen.algorithms.symbolic import Port
    >>> q, t = se.symbols("q_0 q_1"), se.Symbol("t0")
    >>> f = SymbolicFunction("f", "", (Port("q", (2,), ""),), (Port("y", (1,), ""),), (q,), ((0,),))
    >>> kernel_arguments(f, ((t, (q[0] + q[1])/2),), [se.sin(t) + se.cos(q[0]) + se.sin(q[0]*q[1])])
    {sin(t0): (1/2)*(q_0 + q_1)}
    """
    names = [p.name for p in function.inputs]
    if "q" not in names:
        return {}
    q = set(function.input_symbols[names.index("q")])
    define = dict(assignments)
    known: dict = {}

    def affine(e):
        """``e`` in terms of q alone when it is affine in q, else None."""
        if e.is_Number or e in q:
            return e
        if e.is_Symbol:
            if e not in known:
                known[e] = affine(define[e]) if e in define else None
            return known[e]
        if isinstance(e, se.Add):
            parts = [affine(a) for a in e.args]
            return None if any(p is None for p in parts) else se.Add(*parts)
        if isinstance(e, se.Mul):
            numbers = [a for a in e.args if a.is_Number]
            rest = [a for a in e.args if not a.is_Number]
            inner = affine(rest[0]) if len(rest) == 1 else None
            return None if inner is None else se.Mul(*numbers, inner)
        return None

    served = {}
    for e in [e for _, e in assignments] + list(outputs):
        for call in sorted(e.atoms(se.sin, se.cos), key=str):
            if call not in served and call.args[0] not in q:
                argument = affine(call.args[0])
                if argument is not None and not argument.is_Number:
                    served[call] = argument
    return served


def _kernel_wait(served: dict, assignments) -> int:
    """Cycles until the sincos kernel's results are ready: the kernel's latency after its last
    argument (:func:`kernel_arguments`) is computed."""
    timer = ChainTimer()
    return kernel_latency() + max((timer.ready(a)[0] for a in served.values()), default=0)


def _shallower(function: SymbolicFunction, assignments, outputs):
    """The program with its sums and products reassociated where that shortens the critical
    path, or the program unchanged. Every sum or product of three or more operands whose
    operands are ready at different times is evaluated by joining the two earliest-ready
    operands first (Huffman's rule, which minimises the time the result is ready for operands
    of given ready times and one latency per join), the joins named as new temporaries; a node
    is rewritten only where that makes it ready earlier than in the printed left-to-right order.
    The number of operations is unchanged (n - 1 joins either way), so the count decides on the
    critical path alone, and the whole rewrite is kept only when the function's critical path
    is shorter and its add/mul/call count equal. Ready times are integers of the latency table:
    the choice is exact, the same on every CPU."""
    extra = kernel_arguments(function, assignments, outputs)
    served, wait = _served(function) | set(extra), {"kernel": _kernel_wait(extra, assignments)}
    timer = ChainTimer(served, wait)
    used = [int(str(sym)[1:]) for sym, _ in assignments if str(sym)[1:].isdigit()]
    counter = [max(used, default=-1) + 1]
    program: list = []

    def temporary(expr):
        sym = se.Symbol(f"t{counter[0]}")
        counter[0] += 1
        program.append((sym, expr))
        timer.assign(sym, expr)
        return sym

    def joined(operands, join):
        """``operands`` (exprs) joined by ``join`` (se.Add or se.Mul) earliest first; the last
        join is returned unnamed."""
        heap = [(timer.ready(x)[0], k, x) for k, x in enumerate(operands)]
        heapq.heapify(heap)
        k = len(heap)
        while len(heap) > 2:
            (_, _, a), (_, _, b) = heapq.heappop(heap), heapq.heappop(heap)
            t = temporary(join(a, b))
            heapq.heappush(heap, (timer.ready(t)[0], k, t))
            k += 1
        return join(heap[0][2], heap[1][2])

    def rebuild(e):
        if e.is_Symbol or e.is_Number or not e.args or timer.literal(e) or e in timer.served:
            return e
        if isinstance(e, se.Add):
            operands = [a if timer.literal(a) else rebuild(a) for a in e.args]
            return _earlier(se.Add(*operands), operands, se.Add)
        if isinstance(e, se.Mul):
            if any(isinstance(a, se.Pow) for a in e.args):    # divisors, powers printed in line
                return se.Mul(*[rebuild(a) for a in e.args])
            operands = [a if timer.literal(a) else rebuild(a) for a in e.args]
            sign = 1
            if se.Integer(-1) in operands:                     # a sign, not a factor
                operands.remove(se.Integer(-1))
                sign = -1
            return _earlier(se.Mul(*operands) * sign, operands, se.Mul, sign)
        return e

    def _earlier(plain, operands, join, sign=1):
        if len(operands) < 3:
            return plain
        mark = len(program)
        before = timer.ready(plain)[0]
        new = joined(operands, join)
        new = -new if sign < 0 else new
        if timer.ready(new)[0] < before:
            return new
        del program[mark:]                          # not earlier: the node as printed
        return plain

    for sym, expr in assignments:
        new = rebuild(expr)
        program.append((sym, new))
        timer.assign(sym, new)
    new_outputs = [rebuild(e) for e in outputs]
    old_path = program_critical_path(assignments, outputs, served, wait)
    new_path = program_critical_path(program, new_outputs, served, wait)
    if new_path.cycles < old_path.cycles and program_count(program, new_outputs) == program_count(assignments, outputs):
        return tuple(program), new_outputs
    return assignments, outputs


def critical_path(function: SymbolicFunction, assignments, outputs) -> CriticalPath:
    """The program's critical path as generated with ``--trig kernel``: sin and cos of an entry
    of the ``q`` port or of an argument affine in q (:func:`kernel_arguments`) come from the
    sincos kernel (:func:`kindyngen.codegen.trig_kernel.kernel_latency` cycles after its last
    argument is ready), every other call from libm."""
    extra = kernel_arguments(function, assignments, outputs)
    return program_critical_path(assignments, outputs, _served(function) | set(extra),
                                 {"kernel": _kernel_wait(extra, assignments)})


def _cse(exprs, report=_silent, what: str = ""):
    """symengine's cse, on at most CSE_CHUNK expressions at a time (each chunk's temporaries
    renamed apart). Chunked, every sin/cos is first named once for all chunks, so that no call
    is evaluated twice; ``report`` hears of each chunk as it starts."""
    work = [k for k, expr in enumerate(exprs) if not (expr.is_Symbol or expr.is_Number)]
    if len(work) < len(exprs):          # symbols and numbers (most of M's entries) pass through
        replacements, reduced = _cse([exprs[k] for k in work], report, what)
        out = list(exprs)
        for k, expr in zip(work, reduced):
            out[k] = expr
        return replacements, out
    if len(exprs) <= CSE_CHUNK:
        return se.cse(exprs)
    calls: dict = {}
    for expr in exprs:
        for call in sorted(expr.atoms(se.sin, se.cos), key=str):
            calls.setdefault(call, se.Symbol(f"_f{len(calls)}"))
    replacements = [(symbol, call) for call, symbol in calls.items()]
    exprs = [_renamed_calls(expr, calls) for expr in exprs]
    reduced = []
    chunks = -(-len(exprs) // CSE_CHUNK)
    for chunk, start in enumerate(range(0, len(exprs), CSE_CHUNK)):
        report(f"{what}CSE chunk {chunk + 1}/{chunks}")
        part, part_reduced = se.cse(exprs[start:start + CSE_CHUNK])
        rename = {sym: se.Symbol(f"_x{chunk}_{k}") for k, (sym, _) in enumerate(part)}
        replacements += [(rename[sym], _renamed(expr, rename)) for sym, expr in part]
        reduced += [_renamed(expr, rename) for expr in part_reduced]
    return replacements, reduced


def _renamed_calls(expr, calls):
    """``expr`` with its sin/cos calls replaced by their symbols in ``calls``."""
    found = expr.atoms(se.sin, se.cos)
    return expr.xreplace({c: calls[c] for c in found}) if found else expr


IN_PLACE_BOUND = (11, 10)
"""A route whose every sin/cos argument is a joint angle or half of one (the C sincos kernel
reads them in place from q) is kept over a cheaper route with other arguments (affine in q:
the C computes them into an array, whose pieces the kernel's vector loads cannot take from the
store buffer) when it costs at most 11/10 of that route's additions + multiplications. Measured
(docs/latency.md, "Sums of half angles"): lwr4's and panda's fk_dq by the in-place route, 6 % and
4 % more operations, 1.24x and 1.34x faster single calls (both with the split kernel)."""


def half_angles(function, served: dict) -> dict:
    """``{call: k}`` when every one of the ``served`` sin/cos (:func:`kernel_arguments`: those the kernel
    would serve beside the joint angles) has the half joint angle q[k]/2 as its argument, else
    ``{}``. Such a single call runs the half-angle kernel (``trig_kernel.kernel_c(half=True)``)
    over q read in place: bit for bit the values of the kernel over a copy of the halves,
    without the copy, whose pieces the store buffer cannot forward to the kernel's vector load
    (docs/latency.md, "Half angles read in place").

    >>> from kindyngen.algorithms.symbolic import Port
    >>> q = se.symbols("q_0 q_1")
    >>> f = SymbolicFunction("f", "", (Port("q", (2,), ""),), (Port("y", (1,), ""),), (q,), ((0,),))
    >>> half_angles(f, {se.sin(q[1] / 2): q[1] / 2, se.cos(q[0] / 2): q[0] / 2})
    {sin((1/2)*q_1): 1, cos((1/2)*q_0): 0}
    >>> half_angles(f, {se.sin(q[1] / 2): q[1] / 2, se.cos((q[0] + q[1]) / 2): (q[0] + q[1]) / 2})
    {}
    """
    if not served:
        return {}
    q = function.input_symbols[[p.name for p in function.inputs].index("q")]
    index = {se.Rational(1, 2) * sym: k for k, sym in enumerate(q)}
    halves = {call: index.get(argument) for call, argument in served.items()}
    return halves if None not in halves.values() else {}


def reads_q_in_place(program: Program) -> bool:
    """Whether every sin/cos of ``program`` has a joint angle or half of one as its argument
    (:func:`half_angles` of its :func:`kernel_arguments`, or none of those).

    >>> from kindyngen.algorithms.symbolic import Port, port_symbols
    >>> q = port_symbols("q", (2,))
    >>> f = SymbolicFunction("f", "", (Port("q", (2,), ""),), (Port("y", (1,), ""),), (q,), ((se.sin(q[0] / 2),),))
    >>> reads_q_in_place(optimize(f)), reads_q_in_place(optimize(replace(f, output_exprs=((se.sin(q[0] + q[1]),),))))
    (True, False)
    """
    served = kernel_arguments(program.function, program.assignments, [e for port in program.outputs for e in port])
    return not served or bool(half_angles(program.function, served))


def _cheapest(routes, report=_silent) -> Program:
    """The program of the route with the fewest additions + multiplications after CSE (the first
    on a tie), or of the cheapest route that reads q in place (:data:`IN_PLACE_BOUND`)."""
    programs = []
    for k, route in enumerate(routes):
        name = route.metadata.get("route", route.name)
        programs.append(optimize(route, lambda phase: report(f"route {k + 1}/{len(routes)} ({name}): {phase}")))
    ops = [p.after.add + p.after.mul for p in programs]
    best = min(range(len(programs)), key=lambda k: (ops[k], k))
    counted = tuple((p.function.metadata.get("route", p.function.name), p.after) for p in programs)
    routes_text = "; ".join(f"{name} {count.add} + {count.mul}" for name, count in counted) + "."
    text = "Route chosen by the fewest additions + multiplications after CSE: " + routes_text
    # the other routes are read only where the cheapest computes kernel arguments (fk_dq's sums)
    in_place = [] if reads_q_in_place(programs[best]) else [
        k for k in range(len(programs)) if k != best and reads_q_in_place(programs[k])]
    if in_place:
        kept = min(in_place, key=lambda k: (ops[k], k))
        numerator, denominator = IN_PLACE_BOUND
        if ops[kept] * denominator <= ops[best] * numerator:
            best = kept
            text = (f"Route chosen as the cheapest whose sin/cos arguments are joint angles or their halves (the C "
                    f"kernel reads them in place) within {numerator}/{denominator} of the fewest additions + "
                    f"multiplications after CSE: " + routes_text)
    chosen = programs[best]
    return replace(chosen, function=replace(chosen.function, summary=f"{chosen.function.summary} {text}"),
                   routes=counted)


def _merged(replacements, stages, reduced):
    """CSE's replacements and the reduced intermediates as one list of assignments in an
    order that defines every symbol before its use (depth first, in the intermediates' order),
    and the reduced outputs. An intermediate that CSE reduced to a symbol or a number is not
    assigned but substituted."""
    definitions = dict(replacements)
    alias = {}
    for (symbol, _), expr in zip(stages, reduced):
        if expr.is_Symbol or expr.is_Number:
            alias[symbol] = expr
        else:
            definitions[symbol] = expr

    def resolve(sym):
        while sym in alias:
            sym = alias[sym]
        return sym

    if alias:
        resolved = {s: resolve(s) for s in alias}
        definitions = {s: _renamed(e, resolved) for s, e in definitions.items()}
        reduced = [_renamed(e, resolved) for e in reduced]
    order, placed = [], set()
    for root in [s for s, _ in stages] + [s for s, _ in replacements]:
        if root in placed or root not in definitions:
            continue
        stack = [(root, False)]
        while stack:                 # iterative post-order: chains of intermediates are long
            sym, expanded = stack.pop()
            if sym in placed:
                continue
            if expanded:
                placed.add(sym)
                order.append((sym, definitions[sym]))
                continue
            stack.append((sym, True))
            deps = [d for d in definitions[sym].free_symbols if d in definitions and d not in placed]
            stack.extend((d, False) for d in sorted(deps, key=str, reverse=True))
    return order, reduced[len(stages):]


def _renamed(expr, rename):
    """``expr.xreplace(rename)`` with only the symbols ``expr`` holds: xreplace converts its
    whole mapping at every call, quadratic in the number of temporaries."""
    return expr.xreplace({s: rename[s] for s in expr.free_symbols if s in rename})


def _live(assignments, outputs):
    """Drop temporaries no output depends on (symengine's cse can leave a replacement whose
    only uses it later folded into a larger one)."""
    needed = set()
    for e in outputs:
        needed |= e.free_symbols
    kept = []
    for sym, expr in reversed(assignments):
        if sym in needed:
            kept.append((sym, expr))
            needed |= expr.free_symbols
    return tuple(reversed(kept))


_REBUILD = {se.StrictLessThan: se.Lt, se.LessThan: se.Le, se.Equality: se.Eq,
            se.Unequality: se.Ne, se.And: se.And, se.Or: se.Or, se.Not: se.Not}


def _hoist_power_bases(assignments, outputs):
    """Give every compound base of an integer power its own temporary, so that ``b**3``
    prints as ``t*t*t`` and ``b`` is evaluated once, as counted."""
    counter = [len(assignments)]
    hoisted: dict = {}
    program: list = []

    def visit(e, pending):
        if e.is_Symbol or e.is_Number or not e.args:
            return e
        if isinstance(e, se.Pow) and e.args[1].is_Integer and abs(int(e.args[1])) >= 2 \
                and not e.args[0].is_Symbol and e.args[0].free_symbols:
            base = visit(e.args[0], pending)
            if base not in hoisted:
                sym = se.Symbol(f"t{counter[0]}")
                counter[0] += 1
                hoisted[base] = sym
                pending.append((sym, base))
            return se.Pow(hoisted[base], e.args[1])
        new_args = [visit(a, pending) for a in e.args]
        if all(a is b for a, b in zip(new_args, e.args)):
            return e
        if isinstance(e, se.Piecewise):
            return se.Piecewise(*zip(new_args[0::2], new_args[1::2]))
        return _REBUILD.get(type(e), lambda *a: e.func(*a))(*new_args)

    for sym, expr in assignments:
        pending: list = []
        expr = visit(expr, pending)
        program.extend(pending)
        program.append((sym, expr))
    new_outputs = []
    for expr in outputs:
        pending = []
        new_outputs.append(visit(expr, pending))
        program.extend(pending)
    return tuple(program), new_outputs
