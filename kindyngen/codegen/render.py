"""Render optimised programs into source text through the jinja2 templates in
``kindyngen/codegen/templates/`` (package data: they travel with an installed package).

One renderer per target language, all fed the same plain context built here: names of
inputs, temporaries and outputs are decided once per language, the printer supplies the
expressions. Text from the user (the robot's name, the description's file name, summaries,
conventions and port descriptions, which name joints, links and frames) enters the context as
:class:`kindyngen.codegen.environment.UserText` and is escaped by the environment of the file
it is printed in: C comments, Python docstrings, MATLAB comments, the CMake comment.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path

import jinja2
import symengine as se

from .. import __version__
from .environment import UserText, blank, environment
from .trig_kernel import (BOUND as TRIG_BOUND, FLOAT_BOUND, FLOAT_MAX_ULP, MAX_ULP as TRIG_MAX_ULP, SPLIT, batch_kernel_c, kernel_c, split_slot,
                          kernel_c_float, kernel_latency)
from ..ik.damped_least_squares import dls_view
from ..algorithms.symbolic import LoopBody
from .optimize import Program, half_angles, kernel_arguments
from .schedule import pressure_order
from .printer import C, C_FLOAT, CASADI, JAX, MATLAB, NUMPY, Dialect
from .render_python_c import render_python_c
from ..model.robot_model import RobotModel
from ..model.user_text import c_comment, cmake_comment, matlab_comment, python_string

BATCH_BLOCK = 64
"""Most configurations per block of a C batch function. A block's sin/cos of the joint angles
and its outputs live in local arrays (outputs written there, then copied out row by row: stores
to port[k*count + i] for several k would need run-time alias checks that stop compilers from
vectorising), so functions with large outputs get smaller blocks."""

BATCH_STACK = 32768
"""Bytes of those local arrays a batch function may use."""

BATCH_MIN_BLOCK = 16
"""Fewest configurations per block worth a local output array; functions whose outputs need
smaller blocks (regressors, hundreds of entries, mostly zeros: their time is the stores) write
outputs in place instead, in blocks of BATCH_BLOCK."""

LOOP_DATAREFS = 1000
"""Most array references (distinct loads, and stores) in a batch block's loop over configurations
that compilers vectorise: gcc gives a loop of more up (its ``loop-max-datarefs-for-datadeps``,
1000 by default). A batch above it runs its configurations one at a time through the single
call instead (``FunctionView.per_state``), which prints the faster program (its print order,
or its lane program): the G1's tau_derivatives (1150 distinct outputs) and fd_derivatives
(3675 outputs, and a lane program), measured in docs/latency.md ("Batches of large outputs")."""

SCALARS = ("double", "float")
"""C scalar types (``generate --scalar``): double (default), or float for single-precision FPUs."""

KERNEL_LANES = 8
"""Single calls with arguments affine in q other than the half joint angles q[k]/2 (those: the
half-angle kernel over q in place, :func:`kindyngen.codegen.optimize.half_angles`), e.g. lwr4's fk_dq with 0.5*(q[0] + q[2]),
run the sincos kernel over the joint angles and those arguments, computed into an array; more
than seven of them are padded with zeros to a multiple of this (AVX-512 lanes). Joint angles
alone are read in place from q, unpadded: the padded copy, stored in pieces and loaded back as
one vector, cost more than the kernel's scalar remainder (lwr4 on Zen 5: jacobian 35.0 -> 31.8
ns, tau 82.6 -> 71.4; docs/latency.md)."""


HALF_KERNEL = "kdg_sincos_half"
"""The C name of the half-angle kernel (sin and cos of x[i]/2), printed where a single call uses it."""


DEMAND_ORDER_OPERATIONS = 1000
"""Single calls of more operations than this (after CSE) are printed in demand order
(:func:`demand_order`). These are throughput-bound, and gcc keeps statements in the order
printed, so temporaries computed long before their use and outputs stored only at the end
fill the registers and spill. Measured in one head-to-head run (docs/latency.md; Zen 5, gcc
12.2, minima): tau_derivatives 1.12x on lwr4 and panda, fd 1.04x / 1.11x, fd_derivatives
1.03x / 1.05x; M, c, tau (300-650 operations) within 2 % either way, so they keep CSE's order."""

PRESSURE_ORDER_OPERATIONS = 3000
"""Single calls of more operations than this are printed in register-pressure order
(:func:`kindyngen.codegen.schedule.pressure_order`) instead of demand order: at each step the
ready statement that frees the most live temporaries. Of lwr4's and panda's functions that
is tau_derivatives and fd_derivatives_no_minv (4100-7100 operations; the next
largest, c_christoffel and S, have at most 2105). Measured in head-to-head runs against demand
order (docs/latency.md, "Register-pressure order for the derivatives"): fd (1100-1300
operations) did not move (0.97-1.01x); tau_derivatives gained (1.0-1.25x) and
fd_derivatives_no_minv (1.02-1.28x); fd_derivatives moved either way in three runs (lwr4
1.09x, 1.00x, 0.67x; panda 0.85x, 1.06x, 1.05x), so it keeps demand order
(PRESSURE_ORDER_EXCLUDED)."""

PRESSURE_ORDER_EXCLUDED = ("fd_derivatives",)
"""Functions kept in demand order whatever their size: measured slower in a run (above).

Both orders apply to scalar programs: the derivatives' single calls print their lane programs
(:class:`LaneView`) unless generated with ``--no-lanes``.

Both were measured on chains, and apply to chains only (:attr:`RobotModel.is_chain`): a tree's
single calls keep CSE's order, which follows the derivation's pass over the tree. On the G1
(floating base, 29 joints), ad hoc driver, minima over 5-11 interleaved rounds, CSE's order
against pressure order: M 1.25x faster, fd 1.12x, tau 1.06x, tau_derivatives 1.05x; on solo12
tau 1.14x (against demand order) and tau_derivatives 1.03x, fd 0.96x (docs/latency.md, "Print
order on trees")."""


def demand_order(assignments, outputs) -> list:
    """Statements ``("t", index)`` and ``("out", port, entry)`` in demand order: every output
    entry in turn, right after the temporaries it still needs, each of those right after its
    own (post-order, operands in the order the expression lists them), so a temporary is
    computed close to its first use and an output is stored as soon as it is known.

    >>> import symengine as se
    >>> x, t0, t1, t2 = se.symbols("x t0 t1 t2")
    >>> demand_order([(t0, x + 1), (t1, 2 * x), (t2, t0 * t0)], [(t2 + 1, t1)])
    [('t', 0), ('t', 2), ('out', 0, 0), ('t', 1), ('out', 0, 1)]
    """
    index = {sym: k for k, (sym, _) in enumerate(assignments)}
    needs = [sorted(index[a] for a in e.free_symbols if a in index) for _, e in assignments]
    done, order = set(), []

    def visit(root):
        stack = [(root, False)]
        while stack:
            k, expanded = stack.pop()
            if k in done:
                continue
            if expanded:
                done.add(k)
                order.append(("t", k))
                continue
            stack.append((k, True))
            stack.extend((j, False) for j in reversed(needs[k]) if j not in done)

    for port, exprs in enumerate(outputs):
        for entry, e in enumerate(exprs):
            for k in sorted(index[a] for a in e.free_symbols if a in index):
                visit(k)
            order.append(("out", port, entry))
    return order


@dataclass(frozen=True)
class PortView:
    name: str
    shape: tuple
    size: int
    dtype: str
    unit: str
    description: str
    entries: tuple = ()          # outputs: (flat index, expression text)
    used: bool = True             # inputs: read by the function at all


@dataclass(frozen=True)
class FunctionView:
    name: str
    c_symbol: str
    summary: str
    conventions: str
    inputs: tuple[PortView, ...]
    outputs: tuple[PortView, ...]
    assignments: tuple[tuple[str, str], ...]
    before: dict
    after: dict
    has_select: bool
    critical: dict = None         # longest chain of dependent operations (cycles, operations)
    angles: int = 0               # C: entries of q whose sin/cos come from the sincos kernel ...
    first_angle: int = 0          # ... starting at this one (after a floating base's 7 coordinates)
    arguments: tuple = ()         # C single calls: then these arguments affine in q (C text), e.g. half angles
    lanes: int = 0                # C with arguments: angles padded to a multiple of KERNEL_LANES
    split: bool = False           # C single calls of 4-7 kernel arguments: the split kernel, whose
                                  # arrays of eight hold argument k at trig_kernel.split_slot(k, count)
    half: int = 0                 # C single calls whose kernel arguments are all half joint angles: the
                                  # half-angle kernel over this many entries of q from first_angle, in place
    block: int = 0                # C batch: configurations per block
    in_place: bool = False        # C batch: outputs stored straight into the caller's arrays ...
    constants: tuple = ()         # ... those of constant entries before the loop, (port, dtype, ((entry, text), ...))
    per_state: bool = False       # C batch: one configuration at a time through the single call (LOOP_DATAREFS)
    batch: "FunctionView | None" = None  # C: the same body, printed for the batch variant
    # C single calls in demand order (DEMAND_ORDER_OPERATIONS): ("t", name, text) and
    # ("out", port name, entry, text, dtype) in print order; empty: assignments, then outputs
    statements: tuple = ()
    pressure: bool = False        # C single calls: those statements in pressure order (PRESSURE_ORDER_OPERATIONS)
    lane: "LaneView | None" = None  # C single calls of a lane program: printed instead of the statements
    loops: "JointLoopView | None" = None  # C single calls of joint loops: printed instead of the statements


@dataclass(frozen=True)
class LaneView:
    """What the C template prints of a :class:`kindyngen.codegen.optimize.LaneProgram`."""

    count: int                    # lanes of the loop
    used: int                     # lanes whose results are stored
    seeds: int                    # seeds per lane
    statements: tuple             # once: ("t", name, text), ("out", port, entry, text, dtype)
    seed_table: tuple             # rows (per seed) of lane texts, padding lanes 0
    lane_statements: tuple        # per lane, in print order: ("t", name, text), ("out", m, text): lane output m
    lane_outputs: int             # lane outputs per lane
    copies: tuple                 # (port, m, offset, stride): port[offset + lane*stride] = out[m][lane]
    uniform: dict
    per_lane: dict
    executed: dict
    critical: dict


@dataclass(frozen=True)
class JointLoopView:
    """What the C template prints of a :class:`kindyngen.codegen.optimize.JointLoopProgram`:
    per piece its statements, ("t", name, text) or ("out", target, text)."""

    joints: int
    lanes: int
    sizes: tuple                  # (array, entries) of the local arrays
    table: tuple                  # rows of constants (texts), lanes each
    ends: tuple
    once: tuple
    body: tuple
    edges: tuple                  # (joint, parent) leaves first: the subtree sums
    root_joints: tuple            # joints whose sums go into kdg_root
    sum_rows: int
    columns: tuple
    zeroed: tuple                 # output ports zeroed before the entries
    nv: int
    joint: tuple
    lower: tuple
    upper: tuple
    row: tuple
    root: tuple
    parts: dict
    executed: dict


def _index(k: int, shape) -> str:
    """The row-major multi-index of flat entry k, as numpy subscripts.

    >>> _index(7, (2, 2, 3))
    '1, 0, 1'
    """
    out = []
    for size in reversed(shape):
        out.append(k % size)
        k //= size
    return ", ".join(str(i) for i in reversed(out))


def _matlab_index(k: int, shape) -> str:
    """The MATLAB (1-based) subscripts of row-major flat entry k: a matrix entry is addressed
    as written, row then column, whatever the memory order.

    >>> _matlab_index(5, (4, 4)), _matlab_index(2, (7,))
    ('2, 2', '3')
    """
    return ", ".join(str(int(i) + 1) for i in _index(k, shape).split(", "))


def _environment(escape) -> jinja2.Environment:
    """The templates' environment for files whose user text ``escape`` makes data."""
    env = environment(escape)
    env.filters["shape"] = lambda shape: " x ".join(str(s) for s in shape)
    env.filters["index"] = _index
    env.filters["mindex"] = _matlab_index
    env.filters["mshape"] = lambda port: " x ".join(str(s) for s in port.shape)
    return env


def input_names(program: Program, dialect: Dialect) -> dict:
    """How each input symbol is read: ``q[3]`` in C and CasADi, ``q_3`` (unpacked) in numpy,
    JAX and MATLAB."""
    names = {}
    for port, symbols in zip(program.function.inputs, program.function.input_symbols):
        for k, sym in enumerate(symbols):
            if dialect in (NUMPY, JAX, MATLAB):
                names[sym] = f"{port.name}_{k}"
            elif dialect is CASADI and len(port.shape) == 2:
                names[sym] = f"{port.name}[{k // port.shape[1]}, {k % port.shape[1]}]"
            else:
                names[sym] = f"{port.name}[{k}]"
    return names


def kernel_angles(program: Program) -> tuple[int, int]:
    """Which sines/cosines the C sincos kernel computes: ``(first, count)``, the entries
    ``q[first:]``, or (0, 0) when no sin or cos has an entry of the ``q`` port exactly as its
    argument (arguments affine in q, e.g. sin(q_1/2), take the lanes after these:
    :func:`kindyngen.codegen.optimize.kernel_arguments`). Leading entries that are no such
    argument (a floating base's position and quaternion) are left out where that saves a
    group of KERNEL_LANES lanes, else the kernel starts at q[0]."""
    f = program.function
    if "q" not in [p.name for p in f.inputs]:
        return 0, 0
    q = f.input_symbols[[p.name for p in f.inputs].index("q")]
    index = {sym: k for k, sym in enumerate(q)}
    used = set()
    for e in [e for _, e in program.assignments] + [e for port in program.outputs for e in port]:
        used |= {index[a.args[0]] for a in e.atoms(se.sin, se.cos) if a.args[0] in index}
    if not used:
        return 0, 0
    first = min(used)
    if -(-(len(q) - first) // KERNEL_LANES) == -(-len(q) // KERNEL_LANES):
        first = 0
    return first, len(q) - first


def _live_beside_kernel(program: Program, served) -> set:
    """The temporaries still read once the ``served`` sin/cos are read from the kernel's arrays:
    a half angle t0 = 0.5*q[1] read only by sin(t0) and cos(t0) is computed in the kernel's
    arguments instead, and not printed (an unused variable is a warning)."""
    served = {call: se.Symbol(f"_served{k}") for k, call in enumerate(served)}
    reads = {sym: _reads(expr, served) for sym, expr in program.assignments}
    live = set().union(*[_reads(e, served) for port in program.outputs for e in port])
    for sym, _ in reversed(program.assignments):
        if sym in live:
            live |= reads[sym]
    return live


def _reads(expr, served) -> set:
    calls = expr.atoms(se.sin, se.cos) & set(served)
    return (expr.xreplace({c: served[c] for c in calls}) if calls else expr).free_symbols


def _batch_block(angles: int, outputs: int) -> tuple[int, bool]:
    """(configurations per block, outputs in place): the largest power of two up to BATCH_BLOCK
    whose local arrays fit BATCH_STACK bytes, or BATCH_BLOCK in place when that is below
    BATCH_MIN_BLOCK."""
    block = BATCH_BLOCK
    while block >= BATCH_MIN_BLOCK and 8 * block * (2 * angles + outputs) > BATCH_STACK:
        block //= 2
    return (block, False) if block >= BATCH_MIN_BLOCK else (BATCH_BLOCK, True)


def function_view(program: Program, dialect: Dialect, prefix: str, trig: str = "libm",
                  batch: bool = False, lanes: bool = True, chain: bool = True) -> FunctionView:
    """What the templates print of one function. C: ``trig="kernel"`` reads sin/cos of joint
    angles from the arrays sin_q/cos_q the kernel fills; ``batch`` prints inputs and outputs of
    configuration start + j of a structure-of-arrays batch (entry k at ``port[k*count + start + j]``,
    sin/cos at ``sin_q[k][j]``; output entry k goes to ``out_<port>[k][j]``) and always reads sin/cos
    of joint angles from those arrays; ``chain``: a chain's large single calls print in demand or
    pressure order, a tree's in CSE's (PRESSURE_ORDER_EXCLUDED)."""
    f = program.function
    names = input_names(program, dialect)
    if batch:
        names = {sym: f"{port.name}[{k}*count + start + j]"
                 for port, symbols in zip(f.inputs, f.input_symbols) for k, sym in enumerate(symbols)}
    first, angles = kernel_angles(program) if (trig == "kernel" or batch) else (0, 0)
    served = _served(program) if trig == "kernel" else {}
    halves = half_angles(f, served) if not angles and not batch and dialect.name == "c" and not dialect.single else {}
    half, arguments = 0, []
    if halves:
        first = min(halves.values())
        half = len(f.input_symbols[[p.name for p in f.inputs].index("q")]) - first
        split = _splits(half, dialect, batch)
        for call, k in halves.items():
            names[call] = f"{'sin' if isinstance(call, se.sin) else 'cos'}_q[{_slot(k - first, half, split)}]"
    else:
        arguments = _kernel_argument_names(served, dialect, names)
        split = _splits(angles + len(arguments), dialect, batch)
        _name_kernel_results(f, served, names, first, angles, arguments, batch, split)
    # a batch block's arrays: sin/cos of every lane, the arguments, the outputs
    block, in_place = (_batch_block(angles + len(arguments), sum(p.size for p in f.outputs) + len(arguments))
                       if batch else (0, False))
    used_symbols = set()
    for _, e in program.assignments:
        used_symbols |= e.free_symbols
    for port in program.outputs:
        for e in port:
            used_symbols |= e.free_symbols
    live = (_live_beside_kernel(program, [c for c in names if isinstance(c, (se.sin, se.cos))])
            if arguments or half else None)
    assignments = []
    printed = {}
    for sym, expr in program.assignments:
        names[sym] = str(sym)
        if live is None or sym in live:
            assignments.append((str(sym), dialect.expr(expr, names)))
            printed[sym] = assignments[-1]
    inputs = tuple(PortView(p.name, p.shape, p.size, "float" if dialect.single and p.dtype == "double" else p.dtype,
                            UserText(p.unit), UserText(p.description),
                            used=any(s in used_symbols for s in syms))
                   for p, syms in zip(f.inputs, f.input_symbols))
    outputs = tuple(PortView(p.name, p.shape, p.size, "float" if dialect.single and p.dtype == "double" else p.dtype,
                             UserText(p.unit), UserText(p.description),
                             entries=tuple((k, dialect.expr(e, names)) for k, e in enumerate(exprs)))
                    for p, exprs in zip(f.outputs, program.outputs))
    constants, per_state = (), False
    if batch:
        # constant entries (a tree's structural zeros) of a batch storing in place, or running the
        # single call, are filled for the block before the loop over its configurations, in runs of
        # consecutive entries; the loop stores only the others: fewer array references
        # (LOOP_DATAREFS), fewer strided stores per configuration
        varying = tuple(replace(p, entries=tuple(kt for kt, e in zip(p.entries, exprs) if not e.is_Number))
                        for p, exprs in zip(outputs, program.outputs))
        per_state = (_array_references(assignments, varying if in_place else outputs) > LOOP_DATAREFS
                     and 8 * sum(p.size for p in (*f.inputs, *f.outputs)) <= BATCH_STACK)
        if in_place or per_state:
            constants = tuple((p.name, p.dtype, tuple(kt for kt, e in zip(p.entries, exprs) if e.is_Number))
                              for p, exprs in zip(outputs, program.outputs) if any(e.is_Number for e in exprs))
            outputs = varying
    lane = loops = None
    if dialect.name == "c" and not batch and lanes and program.lanes is not None:
        lane, first, angles, arguments = _lane_view(program, dialect, trig)
        split = _splits(angles + len(arguments), dialect, batch)
    if dialect.name == "c" and not batch and lanes and program.joint_loops is not None:
        loops, first, angles, arguments = _joint_loop_view(program, dialect, trig)
        split = _splits(angles + len(arguments), dialect, batch)
    statements = ()
    pressure = False
    # the scalar program's print order, for single calls that do not print a lane program
    if (dialect.name == "c" and not batch and lane is None and loops is None and chain
            and program.after.add + program.after.mul > DEMAND_ORDER_OPERATIONS):
        kept = [(sym, e) for sym, e in program.assignments if sym in printed]
        pressure = (program.after.add + program.after.mul > PRESSURE_ORDER_OPERATIONS
                    and f.name not in PRESSURE_ORDER_EXCLUDED)
        statements = tuple(("t", *printed[kept[k[1]][0]]) if k[0] == "t"
                           else ("out", outputs[k[1]].name, k[2], outputs[k[1]].entries[k[2]][1], outputs[k[1]].dtype)
                           for k in (pressure_order if pressure else demand_order)(kept, program.outputs))
    text = " ".join(t for _, t in assignments) + " ".join(t for o in outputs for _, t in o.entries)
    return FunctionView(
        name=f.name, c_symbol=f"{prefix}_{f.name}", summary=UserText(f.summary), conventions=UserText(f.conventions),
        inputs=inputs, outputs=outputs, assignments=tuple(assignments),
        before=program.before.to_json(), after=program.after.to_json(),
        has_select=("where(" in text or "if_else(" in text or "kdg_select(" in text or "?" in text),
        critical=program.critical.to_json(),
        angles=0 if per_state else angles,
        first_angle=first,
        arguments=() if per_state else tuple(arguments),
        lanes=(angles + len(arguments)) if split else -(-(angles + len(arguments)) // KERNEL_LANES) * KERNEL_LANES,
        split=split,
        half=half,
        block=block,
        in_place=in_place,
        constants=constants,
        per_state=per_state,
        batch=function_view(program, dialect, prefix, trig, batch=True) if dialect.name == "c" and not batch else None,
        statements=statements,
        pressure=pressure,
        lane=lane,
        loops=loops,
    )


def _array_references(assignments, outputs) -> int:
    """The array references of a batch block's loop body as printed: distinct entries read
    (``q[3*count + start + j]``, ``sin_q[2][j]``) and one store per output entry it prints.

    >>> _array_references([("t0", "q[0*count + start + j]*sin_q[1][j]"), ("t1", "t0*q[0*count + start + j]")],
    ...                   [PortView("y", (2,), 2, "double", "", "", entries=((0, "t1"), (1, "cos_q[1][j]")))])
    5
    """
    texts = [t for _, t in assignments] + [t for p in outputs for _, t in p.entries]
    reads = {m for t in texts for m in _ARRAY_ENTRY.findall(t)}
    return len(reads) + sum(len(p.entries) for p in outputs)


_ARRAY_ENTRY = re.compile(r"\b[A-Za-z_]\w*\[[^\[\]]*\](?:\[[^\[\]]*\])?")


def _served(program: Program) -> dict:
    """The program's sin/cos with arguments affine in q (:func:`kindyngen.codegen.optimize.kernel_arguments`)."""
    return kernel_arguments(program.function, program.assignments, [e for p in program.outputs for e in p])


def _kernel_argument_names(served: dict, dialect: Dialect, names: dict) -> list:
    """The C texts of the ``served`` sin/cos arguments affine in q (half angles, joint offsets),
    which take the kernel's lanes after its joint angles, in order of first use."""
    arguments, seen = [], set()
    for argument in served.values():
        if argument not in seen:
            seen.add(argument)
            arguments.append(dialect.expr(argument, names))
    return arguments


def _splits(count: int, dialect: Dialect, batch: bool) -> bool:
    """Whether a call of the double C kernel on ``count`` arguments is the split kernel: single
    calls of four to seven (trig_kernel.SPLIT; batches and float C run the loop over blocks)."""
    return dialect.name == "c" and not dialect.single and not batch and count in SPLIT


def _slot(lane: int, count: int, split: bool) -> int:
    """Where the kernel leaves the sin/cos of its argument ``lane`` of ``count``."""
    return split_slot(lane, count) if split else lane


def _name_kernel_results(f, served: dict, names: dict, first: int, angles: int, arguments: list,
                         batch: bool, split: bool) -> None:
    """``names`` learns where the kernel leaves sin/cos of the joint angles q[first:first + angles]
    (lanes 0..angles-1) and of the ``served`` arguments (the lanes after them, in order of first
    use, as :func:`_kernel_argument_names` lists them): ``sin_q[lane]`` of a single call
    (:func:`_slot`), ``sin_q[lane][j]`` of configuration j of a batch block."""
    count = angles + len(arguments)

    def where(lane):
        return f"[{lane}][j]" if batch else f"[{_slot(lane, count, split)}]"

    if angles:
        q = f.input_symbols[[p.name for p in f.inputs].index("q")]
        for k, sym in enumerate(q[first:]):
            names[se.sin(sym)], names[se.cos(sym)] = f"sin_q{where(k)}", f"cos_q{where(k)}"
    lane = {}
    for call, argument in served.items():
        lane.setdefault(argument, angles + len(lane))
        names[call] = f"{'sin' if isinstance(call, se.sin) else 'cos'}_q{where(lane[argument])}"


def _kernel_served(program: Program, names: dict, dialect: Dialect, trig: str) -> tuple:
    """(first kernel angle, kernel angles, kernel arguments, temporaries live beside the kernel or
    None) of a single call whose sin/cos ``program`` has: the kernel's results named in ``names``."""
    first, angles = kernel_angles(program) if trig == "kernel" else (0, 0)
    served = _served(program) if trig == "kernel" else {}
    arguments = _kernel_argument_names(served, dialect, names)
    split = _splits(angles + len(arguments), dialect, False)
    _name_kernel_results(program.function, served, names, first, angles, arguments, False, split)
    live = _live_beside_kernel(program, [c for c in names if isinstance(c, (se.sin, se.cos))]) if arguments else None
    return first, angles, arguments, live


def _lane_view(program: Program, dialect: Dialect, trig: str) -> tuple:
    """(LaneView, first kernel angle, kernel angles, kernel arguments) of the program's lane program: seed k of
    the current lane reads ``kdg_seed[k][kdg_lane]``, lane output m is stored in
    ``kdg_lane_out[m][kdg_lane]``."""
    lp = program.lanes
    f = program.function
    names = input_names(program, dialect)
    everything = replace(program, assignments=lp.assignments + lp.lane_assignments,
                         outputs=(tuple(e for port in lp.outputs if port is not None for e in port)
                                  + tuple(v for row in lp.values for v in row) + lp.lane_outputs,))
    first, angles, arguments, live = _kernel_served(everything, names, dialect, trig)
    for k, seed in enumerate(lp.seeds):
        names[seed] = f"kdg_seed[{k}][kdg_lane]"
    printed = {}
    for sym, expr in lp.assignments:
        names[sym] = str(sym)
        if live is None or sym in live:
            printed[sym] = ("t", str(sym), dialect.expr(expr, names))
    # the statements once in CSE's order: demand and pressure order measured no faster there
    # (docs/latency.md, "Lane programs")
    statements = list(printed.values()) + [("out", port.name, entry, dialect.expr(e, names), port.dtype)
                                           for port, exprs in zip(f.outputs, lp.outputs)
                                           for entry, e in enumerate(exprs or ())]
    values = [[lp.values[l][k] if l < lp.used else se.Integer(0) for l in range(lp.count)] for k in range(len(lp.seeds))]
    if not all(v.is_Number for row in values for v in row):
        # clang 14 does not vectorise the loop over a seed table filled at run time
        raise ValueError(f"{f.name}: the C prints lane programs with constant seeds only")
    seed_table = tuple(tuple(dialect.expr(v, names) for v in row) for row in values)
    texts = []
    for sym, expr in lp.lane_assignments:
        names[sym] = str(sym)
        texts.append((str(sym), dialect.expr(expr, names)))
    stores = [(m, dialect.expr(e, names)) for m, e in enumerate(lp.lane_outputs)]
    # the loop's body in register-pressure order (schedule.pressure_order): 3-8 % faster than
    # CSE's order (docs/latency.md, "Lane programs")
    order = pressure_order(list(lp.lane_assignments), [lp.lane_outputs])
    lane_statements = tuple(("t", *texts[k[1]]) if k[0] == "t" else ("out", *stores[k[2]]) for k in order)
    view = LaneView(
        count=lp.count, used=lp.used, seeds=len(lp.seeds), statements=tuple(statements), seed_table=seed_table,
        lane_statements=lane_statements, lane_outputs=len(stores),
        copies=tuple((f.outputs[port].name, m, offset, stride) for m, (port, offset, stride) in enumerate(lp.places)),
        uniform=lp.uniform.to_json(), per_lane=lp.lane.to_json(), executed=lp.executed.to_json(),
        critical=lp.critical.to_json())
    return view, first, angles, arguments


PIECE_PREFIX = {"body": "b", "columns": "c", "joint": "j", "lower": "l", "upper": "u", "row": "r", "root": "o"}


def _joint_loop_view(program: Program, dialect: Dialect, trig: str) -> tuple:
    """(JointLoopView, first kernel angle, kernel angles, kernel arguments) of the program's joint
    loops: the once piece reads the caller's inputs and the sincos kernel, each loop piece its
    lane inputs from the arrays its sources name (:class:`kindyngen.algorithms.symbolic.LoopBody`),
    its temporaries prefixed by the piece's initial (its own CSE numbers them from t0 too)."""
    jp = program.joint_loops
    loops = jp.loops
    once = jp.once
    names = input_names(once, dialect)
    first, angles, arguments, live = _kernel_served(once, names, dialect, trig)
    statements = []
    for sym, expr in once.assignments:
        names[sym] = str(sym)
        if live is None or sym in live:
            statements.append(("t", str(sym), dialect.expr(expr, names)))
    for port, exprs in zip(once.function.outputs, once.outputs):
        statements += [("out", f"{port.name}[{k}]", dialect.expr(e, names)) for k, e in enumerate(exprs)]
    nv = program.function.outputs[0].shape[1]
    strides = {p.name: nv for p in program.function.outputs}

    def where(place):
        return f"{place[0]}[{LoopBody.address(place, strides.get(place[0], loops.lanes))}]"

    def piece(key: str, body, code: Program) -> tuple:
        local = {sym: where(src) for sym, src in zip(body.function.input_symbols[0], body.sources)}
        out = []
        for sym, expr in code.assignments:
            local[sym] = f"{PIECE_PREFIX[key]}{sym}"
            out.append(("t", local[sym], dialect.expr(expr, local)))
        out += [("out", where(place), dialect.expr(e, local)) for place, e in zip(body.places, code.outputs[0])]
        return tuple(out)

    printed = {key: () for key in loops.PIECES}
    printed.update((key, piece(key, body, code)) for (key, body), (_, code) in zip(loops.pieces(), jp.pieces))

    base = loops.root is not None
    rows = loops.body.function.outputs[0].size
    sizes = [("kdg_w", once.function.outputs[0].size), ("kdg_c", rows * loops.lanes),
             ("kdg_t", loops.columns.function.outputs[0].size * loops.lanes)]
    if base:
        sizes += [(p.name, p.size) for p in once.function.outputs[1:]]
    view = JointLoopView(
        joints=loops.joints, lanes=loops.lanes, sizes=tuple(sizes),
        table=tuple(tuple(dialect.expr(v, {}) for v in row) for row in loops.table), ends=loops.ends,
        once=tuple(statements), body=printed["body"],
        edges=tuple((j, p) for j, p in reversed(list(enumerate(loops.parents))) if p >= 0),
        root_joints=tuple(j for j, p in enumerate(loops.parents) if p < 0 and base), sum_rows=rows,
        columns=printed["columns"], zeroed=tuple(p.name for p in program.function.outputs), nv=nv,
        joint=printed["joint"], lower=printed["lower"], upper=printed["upper"], row=printed["row"],
        root=printed["root"],
        parts={k: {**c.to_json(), "runs": r} for k, (c, r) in jp.parts().items()}, executed=jp.executed.to_json())
    return view, first, angles, arguments


def _context(model: RobotModel, programs, dialect: Dialect, trig: str = "libm", lanes: bool = True,
             ik_dls: bool = True) -> dict:
    return {
        "robot": model.identifier,
        "robot_name": UserText(model.name),
        "source": UserText(Path(model.source).name),
        "n": model.nv,                           # velocity coordinates (a floating base: 6 + joints)
        "nq": model.nq,
        "convention": model.convention,
        "structure": model.structure_text,       # a tree says what it is; an arm: None
        "gravity": [float(v) for v in model.gravity],
        "version": __version__,
        "functions": [function_view(p, dialect, model.identifier, trig, lanes=lanes, chain=model.is_chain)
                      for p in programs],
        "trig": trig,
        "trig_bound": TRIG_BOUND,
        "trig_max_ulp": TRIG_MAX_ULP,
        "kernel_latency": kernel_latency(),
        "batch_block": BATCH_BLOCK,
        "batch_stack": BATCH_STACK,
        "loop_datarefs": LOOP_DATAREFS,
        # iterative IK (templates/*/ik_dls.*.j2) where asked for (--functions) and applicable, else None
        "ik_dls": dls_view(model, programs) if ik_dls else None,
    }


def render_c(model: RobotModel, programs, trig: str = "kernel", scalar: str = "double",
             batch: bool = True, float_error: dict | None = None, lanes: bool = True,
             ik_dls: bool = True) -> dict[str, str]:
    """Header, source and CMakeLists.txt of the C99 library; ``trig``: see kindyngen/codegen/trig_kernel.py;
    ``scalar``: one of SCALARS (float: no ik_dls, whose tolerances are double's); ``batch``:
    whether the <name>_batch variants are written; ``lanes``: single calls of functions with a
    lane program print it (a loop over lanes that compilers vectorise), else their scalar
    program (fewer operations, for targets without vector units); ``ik_dls``: whether the
    iterative IK is written (where it applies)."""
    single = scalar == "float"
    env, ctx = _environment(c_comment), _context(model, programs, C_FLOAT if single else C, trig, lanes, ik_dls)
    ctx.update(scalar=scalar, batch=batch, zero="0.0f" if single else "0.0",
               sincos="kdg_sincosf" if single else "kdg_sincos", sincos_half=HALF_KERNEL,
               sincos_batch="kdg_sincosf" if single else "kdg_sincos_batch",
               libm_sin="sinf" if single else "sin", libm_cos="cosf" if single else "cos",
               float_trig_bound=FLOAT_BOUND, float_trig_max_ulp=FLOAT_MAX_ULP,
               sincos_kernel=_float_kernel(ctx["functions"], batch) if single else _kernels(ctx["functions"], batch),
               float_error={name: e.text() for name, e in (float_error or {}).items()},
               independent=batch and any(f.batch.in_place and not f.batch.per_state for f in ctx["functions"]))
    if single:
        ctx["ik_dls"] = None
    return {f"{model.identifier}.h": env.get_template("c/header.h.j2").render(ctx),
            f"{model.identifier}.c": env.get_template("c/source.c.j2").render(ctx),
            "CMakeLists.txt": _environment(cmake_comment).get_template("c/CMakeLists.txt.j2").render(ctx)}


def _float_kernel(functions, batch: bool) -> str:
    """The float sincos kernel where a single call or a batch variant calls it, else nothing (a
    static function no call uses is a compiler warning: a float library of ik_hom alone)."""
    used = any(f.half or f.angles or f.arguments for f in functions) or (
        batch and any(f.batch.angles or f.batch.arguments for f in functions))
    return kernel_c_float() if used else ""


def _kernels(functions, batch: bool) -> str:
    """The double sincos kernels the functions call, and only those (a static function no call
    uses is a compiler warning): the loop over blocks where a single call of eight or more
    arguments runs it, the split kernel where a single call of four to seven does (the loop
    over blocks calls it too), each for the plain and for the half-angle kernel; the batch
    variants' one loop over a block's arguments (:func:`batch_kernel_c`) where one runs it."""
    text = []
    for name, half in (("kdg_sincos", False), (HALF_KERNEL, True)):
        calls = [f for f in functions if bool(f.half) == half and (f.half or f.angles or f.arguments)]
        loop = any(not f.split for f in calls)
        if loop or calls:
            text.append(kernel_c(name, half=half, blocks=loop))
    if batch and any(f.batch.angles or f.batch.arguments for f in functions):
        text.append(batch_kernel_c("kdg_sincos"))
    return "\n".join(text)


def render_python(model: RobotModel, programs, ik_dls: bool = True) -> dict[str, str]:
    env, ctx = _environment(python_string), _context(model, programs, NUMPY, ik_dls=ik_dls)
    return {f"{model.identifier}.py": env.get_template("python/module.py.j2").render(ctx)}


def render_casadi(model: RobotModel, programs, escape=python_string, ik_dls: bool = True) -> dict[str, str]:
    """The module of CasADi Function builders; ``escape``: how it prints user text (see
    :func:`casadi_builders`); ``ik_dls``: whether the iterative IK is written (where it applies)."""
    env, ctx = _environment(escape), _context(model, programs, CASADI, ik_dls=ik_dls)
    return {f"{model.identifier}_casadi.py": env.get_template("casadi/module.py.j2").render(ctx)}


def casadi_builders(model: RobotModel, programs, ik_dls: bool = True) -> str:
    """The CasADi module without any user text (every UserText printed as nothing): the code the
    pipeline runs to save the .casadi files, which therefore never runs a character of the
    description. Its Functions are those of the written module (names, inputs, outputs and
    expressions are not user text)."""
    return next(iter(render_casadi(model, programs, escape=blank, ik_dls=ik_dls).values()))


def render_jax(model: RobotModel, programs, ik_dls: bool = False) -> dict[str, str]:
    """A module of pure jax.numpy functions (jit, vmap, grad apply); the iterative ik_dls is
    left out whatever ``ik_dls`` says (its loop and restarts are host code in the numpy module)."""
    env, ctx = _environment(python_string), _context(model, programs, JAX)
    return {f"{model.identifier}_jax.py": env.get_template("jax/module.py.j2").render(ctx)}


def render_matlab(model: RobotModel, programs, ik_dls: bool = False) -> dict[str, str]:
    """One .m function per generated function, ``<robot>_<name>.m`` (vectorised over a trailing
    batch dimension), a MEX gateway around the generated C and the .m that builds it; the
    iterative ik_dls is left out whatever ``ik_dls`` says."""
    env, ctx = _environment(matlab_comment), _context(model, programs, MATLAB)
    ctx["mex"] = f"{model.identifier}_mex"
    # the gateway's matrix reader, only where an input is a matrix (an unused static function is a warning)
    ctx["matrix_inputs"] = any(len(p.shape) == 2 for f in ctx["functions"] for p in f.inputs)
    files = {f"{f.c_symbol}.m": env.get_template("matlab/function.m.j2").render(ctx, f=f) for f in ctx["functions"]}
    files[f"{ctx['mex']}.c"] = _environment(c_comment).get_template("matlab/mex.c.j2").render(ctx)
    files[f"{model.identifier}_build_mex.m"] = env.get_template("matlab/build_mex.m.j2").render(ctx)
    return files


RENDERERS = {"c": render_c, "python": render_python, "casadi": render_casadi, "python_c": render_python_c,
             "jax": render_jax, "matlab": render_matlab}
