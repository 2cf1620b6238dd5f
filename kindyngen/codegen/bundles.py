"""Bundles: several generated functions as one call with one CSE over all their outputs.

A controller step calls fk_hom, jacobian, M, g and tau at the same q; called one by one, each
computes the sines and cosines of q (the C sincos kernel) and its own recursion again. A bundle,
``generate --bundle step=fk_hom,jacobian,M,g,tau`` or a description's ``bundles:`` section
(``step: [fk_hom, jacobian, M, g, tau]``), is one generated function ``step`` that returns all
of its members' outputs, in every target (C single and batch, numpy, python_c, CasADi, JAX,
MATLAB), its cost counted like any function's.

Its inputs are the members' inputs by name, in order of first use (``p`` and ``lengths``
last, as every function has them); its outputs are the members' outputs in member order, each
under its own name unless another output or an input of the bundle has that name, then as
``<member>_<name>`` (fd and tau together: ``tau_tau``).

Its program: each member optimised as if generated alone (a member with several routes keeps
the one it would keep alone; a member's lane program is left out: the bundle's C single call
runs the scalar programs), then their straight-line programs concatenated, each sin/cos call
named as a temporary of its own, temporaries renamed apart and every assignment whose
right-hand side an earlier one has merged into it (value numbering, in order, so that what
depends on merged temporaries merges too: the sin/cos of q, the kinematics two members derive
alike, Y's and tau's common Newton-Euler pass), and the whole optimised as one function whose
named intermediates are those assignments (:func:`kindyngen.codegen.optimize.optimize`: one CSE
over all of it, 1-2 % fewer operations than value numbering alone). The C call runs the sincos
kernel once.

The results are the members' up to roundings, not bit for bit: renaming a temporary changes
where symengine puts it among a sum's or product's operands, and with it the order the
printed code adds or multiplies them in (value numbering alone differs as much). Measured on
lwr4 (tests/codegen/test_bundles.py): within 3e-16 of each output's largest entry, the
forward-dynamics derivatives (through M's inverse) within 1.6e-14. Re-deriving the members as
one DAG would share more arithmetic (6 % fewer operations for lwr4's controller step) but makes
symengine's cse of large members (fd with fd_derivatives) take minutes instead of seconds.

>>> problem("step", ("fk_hom", "jacobian", "M"))
>>> problem("M", ("fk_hom", "jacobian")), problem("step", ("fk_hom", "fk_hum"))[:33]
("'M' is a function's name", 'fk_hum is no function (known: fk_')
"""
from __future__ import annotations

import builtins
import keyword
import re
from dataclasses import dataclass, replace
from typing import Callable

import symengine as se

from ..algorithms.symbolic import SymbolicFunction
from ..model.robot_model import RobotDescriptionError, RobotModel
from ..model.user_text import RESERVED, is_identifier
from .catalog import ITERATIVE_NAMES, NAMES, derive_all
from .opcount import OpCount
from .optimize import Program, optimize

MAX_NAME = 30
"""Longest bundle name: ``<robot>_<bundle>`` stays within MATLAB's 63 characters of a function
name for robot identifiers of up to 32 (kindyngen.model.user_text.MAX_IDENTIFIER)."""

LAST_INPUTS = ("p", "lengths")
"""Inputs every function has last, in this order (symbolic parameters, symbolic lengths)."""

# module-level names of the generated Python, JAX and CasADi modules, and the C's other symbols
# (<robot>_<name>_batch, <robot>_rounds_to_nearest): a bundle of such a name would shadow or clash
_GENERATED_NAMES = {"np", "jnp", "ca", "NDOF", "NQ", "NV", "FUNCTIONS", "BUILDERS", "rounds_to_nearest"}


class BundleError(ValueError):
    """A --bundle request that cannot be generated (the description's: RobotDescriptionError)."""


@dataclass(frozen=True)
class Bundle:
    """A requested bundle: its name, its members (catalog function names, in output order) and
    where it was asked for: ``""`` the description's ``bundles:`` section, else the option
    (``"--bundle"``)."""

    name: str
    members: tuple[str, ...]
    option: str = ""

    def error(self, model: RobotModel, reason: str) -> ValueError:
        """The error of this bundle: the description's field, or the option."""
        if self.option:
            return BundleError(f"{self.option} {self.name}: {reason}")
        return RobotDescriptionError(model.source, f"bundles.{self.name}", reason)


def problem(name: str, members) -> str | None:
    """Why ``name`` with ``members`` cannot be a bundle (None: it can): a name of the identifier
    rule (ASCII letters, digits, ``_``, a letter first; at most MAX_NAME characters) that is no
    function's name, no Python keyword or builtin, no name the generated modules define and no
    batch variant's; at least two members, each a derived function of the catalog, none twice."""
    if not is_identifier(name) or len(name) > MAX_NAME:
        return (f"the name {name!r} must be ASCII letters, digits and _ with a letter first, "
                f"at most {MAX_NAME} characters")
    if name in NAMES or name in ITERATIVE_NAMES:
        return f"{name!r} is a function's name"
    if name.endswith("_batch") or name in _GENERATED_NAMES:
        return f"{name!r} is a name of the generated code (a batch variant or a module's own)"
    if keyword.iskeyword(name) or keyword.issoftkeyword(name) or name in dir(builtins) or name.lower() in RESERVED:
        return f"{name!r} is reserved in a generated language (a keyword, builtin or library name)"
    members = tuple(members)
    if len(members) < 2:
        return "a bundle needs at least two functions"
    for member in members:
        if member in ITERATIVE_NAMES:
            return f"{member} is iterative (it calls fk_hom and jacobian in a loop): it cannot be bundled"
        if member not in NAMES:
            return f"{member} is no function (known: {', '.join(NAMES)})"
    repeated = sorted({m for m in members if members.count(m) > 1})
    if repeated:
        return f"{', '.join(repeated)} given twice"
    return None


def parse_option(text: str) -> Bundle:
    """``--bundle NAME=f,g,...`` as a Bundle; ValueError with the reason if it is not one.

    >>> parse_option("step=fk_hom, jacobian,M")
    Bundle(name='step', members=('fk_hom', 'jacobian', 'M'), option='--bundle')
    """
    name, sep, rest = text.partition("=")
    if not sep:
        raise ValueError(f"expected NAME=FUNCTION,FUNCTION,..., got {text!r}")
    bundle = Bundle(name.strip(), tuple(m.strip() for m in rest.split(",") if m.strip()), "--bundle")
    reason = problem(bundle.name, bundle.members)
    if reason:
        raise ValueError(f"{bundle.name}: {reason}")
    return bundle


def requested(model: RobotModel, extra=()) -> tuple[Bundle, ...]:
    """The bundles to generate for ``model``: its description's, then ``extra`` (--bundle), each
    checked (:func:`problem`) and no two of one name; the error names the field or the option."""
    bundles = tuple(Bundle(name, tuple(members)) for name, members in model.bundles) + tuple(extra)
    seen = set()
    for bundle in bundles:
        reason = problem(bundle.name, bundle.members)
        if reason is None and bundle.name in seen:
            reason = "a bundle of this name is already asked for (in the description or by --bundle)"
        if reason:
            raise bundle.error(model, reason)
        seen.add(bundle.name)
    return bundles


def bundle_programs(model: RobotModel, bundles, programs, params: str = "numeric", scalar: str = "double",
                    step: Callable[[str], None] | None = None) -> list[Program]:
    """The program of each bundle, from the members' ``programs`` (those generated anyway) or
    members derived and optimised here; ``step(name)`` after each (progress)."""
    known = {p.function.name: p for p in programs}
    out = []
    for bundle in bundles:
        missing = [m for m in bundle.members if m not in known]
        if missing:
            for function in derive_all(model, params, set(missing), scalar):
                known[function.name] = optimize(function)
        absent = [m for m in bundle.members if m not in known]
        if absent:
            raise bundle.error(model, f"{', '.join(absent)} does not apply to {model.name} "
                                      "(see the function table: chain-only, flange-only or LWR-type IK functions)")
        out.append(bundle_program(bundle.name, [known[m] for m in bundle.members]))
        if step is not None:
            step(bundle.name)
    return out


def bundle_program(name: str, members: list[Program]) -> Program:
    """One Program computing every output of the ``members`` (optimised programs): see the
    module text. Its count before CSE is the members' as derived, summed.

    >>> from kindyngen.algorithms.symbolic import Port, port_symbols
    >>> q = port_symbols("q", (2,))
    >>> f = SymbolicFunction("f", "F.", (Port("q", (2,), ""),), (Port("y", (1,), ""),), (q,), ((se.sin(q[0]) * q[1],),))
    >>> g = SymbolicFunction("g", "G.", (Port("q", (2,), ""),), (Port("y", (1,), ""),), (q,), ((se.sin(q[0]) + 1,),))
    >>> b = bundle_program("fg", [optimize(f), optimize(g)])
    >>> [p.name for p in b.function.outputs], b.after, b.function.metadata["members"]
    (['f_y', 'g_y'], OpCount(add=1, mul=1, call=1), ('f', 'g'))
    """
    function = bundle_function(name, members)
    return replace(optimize(function), before=_sum(p.before for p in members))


def bundle_function(name: str, members: list[Program]) -> SymbolicFunction:
    """The SymbolicFunction of a bundle of optimised ``members``: their assignments, each
    sin/cos call named as an assignment of its own first, merged by value numbering, as its
    named intermediates (_b0, _b1, ... in order), their outputs (in those) as its outputs."""
    inputs, symbols = _inputs([p.function for p in members])
    by_name = {port.name: syms for port, syms in zip(inputs, symbols)}
    taken = {port.name for port in inputs}
    counts: dict = {}
    for p in members:
        for port in p.function.outputs:
            counts[port.name] = counts.get(port.name, 0) + 1
    stages, canonical, outputs, ports = [], {}, [], []

    def number(expr):
        """The temporary holding ``expr``: an earlier one with the same right-hand side, else a new one."""
        if expr not in canonical:
            canonical[expr] = se.Symbol(f"_b{len(stages)}")
            stages.append((canonical[expr], expr))
        return canonical[expr]

    def named_calls(expr):
        """``expr`` with each sin/cos call read from its temporary (the C kernel serves them wherever
        they are written; named, equal calls of two members merge)."""
        calls = sorted(expr.atoms(se.sin, se.cos), key=str)
        return expr.xreplace({c: number(c) for c in calls}) if calls and not _is_call(expr) else expr

    for p in members:
        f = p.function
        rename = {}
        for port, syms in zip(f.inputs, f.input_symbols):
            rename.update({a: b for a, b in zip(syms, by_name[port.name]) if a != b})
        for sym, expr in p.assignments:
            rename[sym] = number(named_calls(_renamed(expr, rename)))
        for port, exprs in zip(f.outputs, p.outputs):
            port_name = port.name if counts[port.name] == 1 and port.name not in taken else f"{f.name}_{port.name}"
            if port_name in {q.name for q in ports} or port_name in taken:
                raise ValueError(f"bundle {name}: two outputs named {port_name}")
            ports.append(replace(port, name=port_name))
            outputs.append(tuple(named_calls(_renamed(e, rename)) for e in exprs))
    names = [p.function.name for p in members]
    return SymbolicFunction(
        name=name, summary=_summary(names, members), inputs=inputs, outputs=tuple(ports), input_symbols=symbols,
        output_exprs=tuple(outputs), conventions=_conventions(members), stages=tuple(stages),
        metadata={"members": tuple(names), "members_after": _sum(p.after for p in members)})


def _is_call(expr) -> bool:
    return isinstance(expr, (se.sin, se.cos))


def _inputs(functions) -> tuple[tuple, tuple]:
    """The union of the functions' inputs by name (the first function's symbols), in order of
    first use with LAST_INPUTS last; a name with two shapes is an error."""
    ports, symbols, shapes = [], [], {}
    for f in functions:
        for port, syms in zip(f.inputs, f.input_symbols):
            if port.name in shapes:
                if shapes[port.name] != port.shape:
                    raise ValueError(f"input {port.name} has shapes {shapes[port.name]} and {port.shape}")
                continue
            shapes[port.name] = port.shape
            ports.append(port)
            symbols.append(syms)
    order = sorted(range(len(ports)), key=lambda k: (LAST_INPUTS.index(ports[k].name) + 1
                                                     if ports[k].name in LAST_INPUTS else 0, k))
    return tuple(ports[k] for k in order), tuple(symbols[k] for k in order)


def _renamed(expr, rename):
    found = [s for s in expr.free_symbols if s in rename]
    return expr.xreplace({s: rename[s] for s in found}) if found else expr


def _sum(counts) -> OpCount:
    total = OpCount()
    for c in counts:
        total = total + c
    return total


def _summary(names, members) -> str:
    parts = _sum(p.after for p in members)
    return (f"Bundle of {', '.join(names)}: their outputs from one call, in this order, with one CSE over "
            f"all of them (the sin/cos of q once, shared intermediates). Called one by one they cost "
            f"{parts.add} add, {parts.mul} mul, {parts.call} call.")


def _conventions(members) -> str:
    """Each member's summary, then the members' conventions, each sentence once (fk_hom's
    frames are jacobian's too).

    >>> from kindyngen.algorithms.symbolic import Port
    >>> f = SymbolicFunction("f", "F.", (), (), (), (), conventions="Frames: a. Units: SI.")
    >>> g = SymbolicFunction("g", "G.", (), (), (), (), conventions="Frames: a. Axes: b.")
    >>> _conventions([Program(f, (), (), OpCount(), OpCount()), Program(g, (), (), OpCount(), OpCount())])
    'f: F. g: G. Frames: a. Units: SI. Axes: b.'
    """
    texts = [f"{p.function.name}: {p.function.summary}" for p in members]
    sentences: list = []
    for p in members:
        for sentence in re.split(r"(?<=\.)\s+", p.function.conventions.strip()):
            if sentence and sentence not in sentences:
                sentences.append(sentence)
    return " ".join(texts + sentences)
