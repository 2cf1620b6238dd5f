"""Render optimised programs into source text through the jinja2 templates in
``kindyngen/templates/`` (package data: they travel with an installed package).

One renderer per target language, all fed the same plain context built here: names of
inputs, temporaries and outputs are decided once per language, the printer supplies the
expressions.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import jinja2

from . import __version__
from .ik_dls import dls_view
from .optimize import Program
from .printer import C, CASADI, NUMPY, Dialect
from .robot import RobotModel

TEMPLATES = Path(__file__).resolve().parent / "templates"


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


def _environment() -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), keep_trailing_newline=True,
                             trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    env.filters["shape"] = lambda shape: " x ".join(str(s) for s in shape)
    return env


def input_names(program: Program, dialect: Dialect) -> dict:
    """How each input symbol is read: ``q[3]`` in C and CasADi, ``q_3`` (unpacked) in numpy."""
    names = {}
    for port, symbols in zip(program.function.inputs, program.function.input_symbols):
        for k, sym in enumerate(symbols):
            if dialect is NUMPY:
                names[sym] = f"{port.name}_{k}"
            elif dialect is CASADI and len(port.shape) == 2:
                names[sym] = f"{port.name}[{k // port.shape[1]}, {k % port.shape[1]}]"
            else:
                names[sym] = f"{port.name}[{k}]"
    return names


def function_view(program: Program, dialect: Dialect, prefix: str) -> FunctionView:
    f = program.function
    names = input_names(program, dialect)
    used_symbols = set()
    for _, e in program.assignments:
        used_symbols |= e.free_symbols
    for port in program.outputs:
        for e in port:
            used_symbols |= e.free_symbols
    assignments = []
    for sym, expr in program.assignments:
        names[sym] = str(sym)
        assignments.append((str(sym), dialect.expr(expr, names)))
    inputs = tuple(PortView(p.name, p.shape, p.size, p.dtype, p.unit, p.description,
                            used=any(s in used_symbols for s in syms))
                   for p, syms in zip(f.inputs, f.input_symbols))
    outputs = tuple(PortView(p.name, p.shape, p.size, p.dtype, p.unit, p.description,
                             entries=tuple((k, dialect.expr(e, names)) for k, e in enumerate(exprs)))
                    for p, exprs in zip(f.outputs, program.outputs))
    text = " ".join(t for _, t in assignments) + " ".join(t for o in outputs for _, t in o.entries)
    return FunctionView(
        name=f.name, c_symbol=f"{prefix}_{f.name}", summary=f.summary, conventions=f.conventions,
        inputs=inputs, outputs=outputs, assignments=tuple(assignments),
        before=program.before.to_json(), after=program.after.to_json(),
        has_select=("where(" in text or "if_else(" in text or "?" in text),
    )


def _context(model: RobotModel, programs, dialect: Dialect) -> dict:
    return {
        "robot": model.identifier,
        "robot_name": model.name,
        "source": Path(model.source).name,
        "n": model.n,
        "convention": model.convention,
        "gravity": [float(v) for v in model.gravity],
        "version": __version__,
        "functions": [function_view(p, dialect, model.identifier) for p in programs],
        "ik_dls": dls_view(model, programs),  # iterative IK (templates/*/ik_dls.*.j2), or None
    }


def render_c(model: RobotModel, programs) -> dict[str, str]:
    """Header, source and CMakeLists.txt of the C99 library."""
    env, ctx = _environment(), _context(model, programs, C)
    return {f"{model.identifier}.h": env.get_template("c/header.h.j2").render(ctx),
            f"{model.identifier}.c": env.get_template("c/source.c.j2").render(ctx),
            "CMakeLists.txt": env.get_template("c/CMakeLists.txt.j2").render(ctx)}


def render_python(model: RobotModel, programs) -> dict[str, str]:
    env, ctx = _environment(), _context(model, programs, NUMPY)
    return {f"{model.identifier}.py": env.get_template("python/module.py.j2").render(ctx)}


def render_casadi(model: RobotModel, programs) -> dict[str, str]:
    env, ctx = _environment(), _context(model, programs, CASADI)
    return {f"{model.identifier}_casadi.py": env.get_template("casadi/module.py.j2").render(ctx)}


RENDERERS = {"c": render_c, "python": render_python, "casadi": render_casadi}
