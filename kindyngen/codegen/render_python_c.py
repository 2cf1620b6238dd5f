"""Render the CPython extension that offers a robot's generated C to Python ("python_c").

The extension source ``python_c/<robot>_ext.c`` includes the generated ``../c/<robot>.c`` and
wraps every function of the robot's interface (``functions.json``: whatever functions the
pipeline produced, ``ik_dls`` included) as a Python function with the numpy module's name and
argument order, for one configuration per call at a per-call overhead well under a microsecond.
``kindyngen.runtime.python_c.load`` compiles and imports it.

The renderer reads only the interface document, so the extension of an already generated
robot can be rendered from its ``functions.json`` alone (``render_extension``). Its texts (the
robot's name, summaries, conventions, port descriptions) are user text: C string literals of the
docstrings (:func:`kindyngen.model.user_text.c_string`), a C comment in the file's header.
"""
from __future__ import annotations

import textwrap

from .. import __version__
from .environment import UserText, environment
from .interface import manifest
from ..model.user_text import c_comment, c_string, one_line

# The longest string literal a C99 compiler must accept (5.2.4.1); -pedantic warns beyond it.
C99_STRING_LIMIT = 4095
DOC_WIDTH = 88


class PythonCRenderError(ValueError):
    """An interface the extension cannot offer (a port type the wrapper does not know)."""


def _c_literal_lines(text: str) -> list[str]:
    r"""``text`` as the lines of one C string literal (escaped, one source line per text line).

    >>> print("\n".join(_c_literal_lines('f(q)\n--\nthe "tip"\\ */ ??/')))
    "f(q)\n"
    "--\n"
    "the \"tip\"\\ */ ?\?/"
    """
    # the compiled bytes: the newlines, the rest as c_string writes it (controls visibly)
    size = len("\n".join(one_line(line) for line in text.split("\n")).encode())
    if size > C99_STRING_LIMIT:
        raise PythonCRenderError(f"docstring of {size} bytes exceeds the C99 string limit "
                                 f"{C99_STRING_LIMIT}: {text[:60]!r}...")
    lines = text.split("\n")
    out = []
    for k, line in enumerate(lines):
        body = c_string(line)
        out.append(f'"{body}\\n"' if k < len(lines) - 1 else f'"{body}"')
    return out


def _shape_text(shape) -> str:
    """A shape as Python prints it: ``(7,)``, ``(4, 4)``."""
    return "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"


def _cost_text(opcount: dict) -> str:
    if "after" in opcount:
        a = opcount["after"]
        return f"Cost of the generated C: {a['add']} add, {a['mul']} mul, {a['call']} call."
    if "per_iteration" in opcount:
        t = opcount["per_iteration"]["total"]
        return (f"Cost of the generated C per iteration: {t['add']} add, {t['mul']} mul, {t['call']} call; "
                f"at most {opcount['max_iterations']} iterations.")
    return ""


def _wrap(text: str, indent: str = "") -> str:
    """``text`` filled to DOC_WIDTH, its controls first written visibly (as the C string will)."""
    return textwrap.fill(one_line(text), DOC_WIDTH, subsequent_indent=indent, break_on_hyphens=False)


def _docstring(spec: dict, signature: str, robot: str) -> str:
    """The numpy module's docstring, for one configuration; the first two lines give Python
    the signature (__text_signature__, as Argument Clinic writes it)."""
    parts = [f"{spec['name']}($module, {', '.join(p['name'] for p in spec['inputs'])})\n--\n",
             _wrap(spec["summary"]), "", _wrap(spec["conventions"]), ""]
    for p in spec["inputs"]:
        parts.append(_wrap(f"{p['name']}: {_shape_text(p['shape'])} float64, {p['description']} [{p['unit']}]", "    "))
    for p in spec["outputs"]:
        kind = "int64" if p["dtype"] == "int" else "float64"
        parts.append(_wrap(f"Returns {p['name']}: {_shape_text(p['shape'])} {kind}, {p['description']} "
                           f"[{p['unit']}]", "    "))
    if len(spec["outputs"]) > 1:
        parts.append(f"(a tuple: {', '.join(p['name'] for p in spec['outputs'])})")
    for line in spec.get("status", ()):
        parts.append(_wrap(f"status {line}", "    "))
    parts.append(_wrap(_cost_text(spec["opcount"])))
    parts.append(_wrap(f"One configuration per call, outputs freshly allocated; for batches use the numpy "
                       f"module python/{robot}.py. Same as {signature} there."))
    return "\n".join(parts).rstrip()


def _function_view(spec: dict, robot: str) -> dict:
    for p in spec["inputs"]:
        if p["dtype"] != "double":
            raise PythonCRenderError(f"{spec['name']}: input {p['name']} has dtype {p['dtype']}; only double "
                                     f"inputs are wrapped")
    for p in spec["outputs"]:
        if p["dtype"] not in ("double", "int"):
            raise PythonCRenderError(f"{spec['name']}: output {p['name']} has dtype {p['dtype']}; only double "
                                     f"and int outputs are wrapped")
    if not spec["inputs"] or not spec["outputs"]:
        raise PythonCRenderError(f"{spec['name']}: a function without inputs or outputs cannot be wrapped")
    names = [p["name"] for p in spec["inputs"]]
    signature = f"{spec['name']}({', '.join(names)})"

    def port(index, p):
        size = 1
        for s in p["shape"]:
            size *= s
        return {"name": p["name"], "index": index, "shape": list(p["shape"]), "ndim": len(p["shape"]), "size": size,
                "shape_text": _shape_text(p["shape"]), "is_int": p["dtype"] == "int"}

    return {"name": spec["name"], "c_symbol": spec["c_symbol"], "signature": signature,
            "inputs": [port(k, p) for k, p in enumerate(spec["inputs"])],
            "outputs": [port(k, p) for k, p in enumerate(spec["outputs"])],
            "doc": _c_literal_lines(_docstring(spec, signature, robot))}


def _gravity_frame(interface: dict) -> str:
    """Where gravity is given: the world for a floating base (nq != nv), else the base."""
    return "world" if interface.get("nq", interface["n"]) != interface.get("nv", interface["n"]) else "base"


def _module_doc(interface: dict) -> str:
    robot = interface["robot"]
    names = [f["name"] for f in interface["functions"] if "c" in f.get("languages", ("c",))]
    what = interface.get("structure") or f'{interface["n"]} joints, {interface["convention"]} convention'
    gravity = ", ".join(repr(g) for g in interface["gravity"])
    text = (f'The generated C of the robot "{interface["name"]}" ({what}) for single calls from Python, '
            f'generated by KinDynGen {__version__}. Each function takes one configuration (float64 arrays '
            f'of exactly the port shapes; other sequences are converted) and returns fresh numpy arrays, a '
            f'tuple for several outputs: the names, arguments and results of the numpy module '
            f'python/{robot}.py, which remains the way to evaluate batches. Row-major arrays, angles in rad, '
            f'lengths in m, SI units; '
            f'gravity in the {_gravity_frame(interface)} frame ({gravity}) m/s^2. '
            f'Functions: {", ".join(names)}.')
    return _wrap(text)


def render_extension(interface: dict) -> dict[str, str]:
    """The extension source from a robot's interface document (the content of functions.json)."""
    robot = interface["robot"]
    functions = [_function_view(f, robot) for f in interface["functions"]
                 if "c" in f.get("languages", ("c",))]        # only what exists in the generated C
    ctx = {"robot": robot, "module": f"{robot}_ext", "robot_name": UserText(interface["name"]), "n": interface["n"],
           "convention": interface["convention"], "gravity": [repr(float(g)) for g in interface["gravity"]],
           "structure": interface.get("structure"), "gravity_frame": _gravity_frame(interface),
           "version": __version__, "functions": functions, "module_doc": _c_literal_lines(_module_doc(interface))}
    return {f"{robot}_ext.c": environment(c_comment).get_template("python_c/extension.c.j2").render(ctx)}


def render_python_c(model, programs, ik_dls: bool = True) -> dict[str, str]:
    """The extension source of ``model``'s optimised ``programs`` (render.RENDERERS entry);
    ``ik_dls``: whether the iterative IK is wrapped (where it applies)."""
    # the renderer reads no top-level entry but robot, name, n, convention, gravity, functions and
    # a tree's structure, nq and nv:
    # "params" (and how the C computes sin/cos) are in the ports and the C already
    return render_extension(manifest(model, programs, params="numeric", ik_dls=ik_dls))
