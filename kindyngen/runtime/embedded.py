"""The generated C on emulated Cortex-M microcontrollers: build, run, measure.

A harness (one C file written here) calls every single-call function of a generated robot
folder on fixed inputs, prints each output's bits over semihosting, then times REPS calls of
each with the SysTick counter. It is cross-compiled with arm-none-eabi-gcc against the
startup file and linker script in ``kindyngen/codegen/templates/embedded/`` and run on QEMU:

* ``m4f``: ``mps2-an386``, Cortex-M4F, ``-mfpu=fpv4-sp-d16`` (single-precision FPU): float C;
* ``m7``: ``mps2-an500``, Cortex-M7, ``-mfpu=fpv5-d16`` (double-precision FPU): double C.

Figures per function: flash = the size of its ``.text.<symbol>`` section (``-ffunction-sections``,
``-O2``); stack = its frame from ``-fstack-usage`` plus the frame of the sincos kernel when
that is not inlined (libm calls, reached only for |q| beyond the kernel's bound, not counted);
instructions = executed instructions per call on the emulated core: QEMU's ``-icount shift=0``
advances its virtual clock 1 ns per instruction, the boards' SysTick runs at 25 MHz on it,
so one tick is 40 instructions; REPS calls are timed and the same loop around an empty
function subtracted (resolution 40 / REPS instructions).

``python -m kindyngen.runtime.embedded GENERATED_DIR TARGET`` prints the figures as JSON.
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..json_text import strict_json

HERE = Path(__file__).resolve().parents[1] / "codegen" / "templates" / "embedded"
REPS = 20
TICK_INSTRUCTIONS = 40      # 25 MHz SysTick over the 1 GHz virtual clock of -icount shift=0
CC = "arm-none-eabi-gcc"
QEMU = "qemu-system-arm"


@dataclass(frozen=True)
class Target:
    name: str
    board: str
    cpu_flags: tuple
    scalar: str


TARGETS = {
    "m4f": Target("m4f", "mps2-an386", ("-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"), "float"),
    "m7": Target("m7", "mps2-an500", ("-mcpu=cortex-m7", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv5-d16"), "double"),
}
C_FLAGS = ("-std=c99", "-O2", "-fno-schedule-insns", "-ffunction-sections", "-fdata-sections", "-Wall", "-Wextra", "-Wdouble-promotion")


class EmbeddedError(RuntimeError):
    """The cross build or the emulated run failed."""


def missing_tools() -> str | None:
    """Why the embedded harness cannot run here (None: it can)."""
    for tool in (CC, QEMU):
        if shutil.which(tool) is None:
            return f"{tool} not found (Debian: apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm)"
    return None


def fixed_inputs(manifest: dict, host_lib, lower, upper, seed: int = 7) -> dict:
    """``{function: {input: array}}``: one state per function, within the limits (poses from
    the host's fk of random angles), rounded to the C's scalar type."""
    from types import SimpleNamespace
    from .float_accuracy import random_inputs
    model = SimpleNamespace(lower=lower, upper=upper)     # all random_inputs reads of a model
    rng = np.random.default_rng(seed)
    real = np.float32 if manifest.get("c_scalar") == "float" else np.float64
    out = {}
    for spec in manifest["functions"]:
        if "c" not in spec.get("languages", ("c",)):
            continue
        inputs = random_inputs(model, host_lib, spec, rng, 1)
        out[spec["name"]] = {k: np.asarray(v[0], dtype=real) for k, v in inputs.items()}
    return out


def _main(scalar: str, body: list) -> list:
    """A harness's main(): SysTick started, ``body`` (the calls and their timed loops), then
    the empty function's loop ("ticks - ...") and "done"."""
    return (["", "int main(void)", "{", "    uint32_t start;", "    int r;", f"    static {scalar} a[1], b[1];",
             "    SYST_RVR = 0xFFFFFFu;", "    SYST_CVR = 0u;", "    SYST_CSR = 5u;   /* enable, processor clock */"]
            + body
            + ["    start = SYST_CVR;", f"    for (r = 0; r < {REPS}; ++r) {{", "        kdg_empty(a, b);", "    }",
               '    printf("ticks - %lu\\n", (unsigned long)elapsed(start));', '    printf("done\\n");',
               "    return 0;", "}", ""])


def _literal(value, real) -> str:
    if real is np.float32:
        return f"{float(value).hex()}f"
    return float(value).hex()


def harness_source(manifest: dict, inputs: dict) -> str:
    """The C harness: per function, outputs as hex words ("out <fn> <port> <word> ..."), then
    "ticks <fn> <ticks of REPS calls>"; an empty function's loop last ("ticks - ...")."""
    robot = manifest["robot"]
    single = manifest.get("c_scalar") == "float"
    scalar, real = ("float", np.float32) if single else ("double", np.float64)
    lines = ["/* KinDynGen embedded harness (kindyngen/runtime/embedded.py): generated, do not edit. */",
             "#include <stdint.h>", "#include <stdio.h>", "#include <string.h>", f'#include "{robot}.h"', "",
             "#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)",
             "#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)",
             "#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)", "",
             f"void kdg_empty(const {scalar} *a, {scalar} *b);", "",
             f"static void print_words(const char *fn, const char *port, const void *data, unsigned bytes)",
             "{", "    const uint32_t *w = (const uint32_t *)data;", "    unsigned i;",
             '    printf("out %s %s", fn, port);', "    for (i = 0; i < bytes / 4u; ++i) {",
             '        printf(" %08lx", (unsigned long)w[i]);', "    }", '    printf("\\n");', "}", "",
             "static uint32_t elapsed(uint32_t start)", "{",
             "    return (start - SYST_CVR) & 0xFFFFFFu;   /* SysTick counts down, 24 bits */", "}", ""]
    body = []
    for spec in manifest["functions"]:
        name = spec["name"]
        if name not in inputs:
            continue
        args = []
        for port in spec["inputs"]:
            values = ", ".join(_literal(v, real) for v in np.ravel(inputs[name][port["name"]]))
            var = f"in_{name}_{port['name']}"
            lines.append(f"static const {scalar} {var}[{max(1, int(np.prod(port['shape'])))}] = {{{values}}};")
            args.append(var)
        for port in spec["outputs"]:
            ctype = "int" if port["dtype"] == "int" else scalar
            var = f"out_{name}_{port['name']}"
            lines.append(f"static {ctype} {var}[{int(np.prod(port['shape']))}];")
            args.append(var)
        call = f"{spec['c_symbol']}({', '.join(args)})"
        body += [f"    {call};"]
        body += [f'    print_words("{name}", "{p["name"]}", out_{name}_{p["name"]}, sizeof out_{name}_{p["name"]});'
                 for p in spec["outputs"]]
        body += ["    start = SYST_CVR;", f"    for (r = 0; r < {REPS}; ++r) {{", f"        {call};", "    }",
                 f'    printf("ticks {name} %lu\\n", (unsigned long)elapsed(start));']
    return "\n".join(lines + _main(scalar, body))


def empty_source(scalar: str) -> str:
    """The empty function of the harness's baseline loop, in its own file (not inlined)."""
    return (f"void kdg_empty(const {scalar} *a, {scalar} *b);\n"
            f"void kdg_empty(const {scalar} *a, {scalar} *b)\n{{\n    (void)a;\n    (void)b;\n}}\n")


def _run(cmd, what: str, timeout: float = 600):
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        raise EmbeddedError(f"{what} failed ({done.returncode}): {' '.join(map(str, cmd))}\n{done.stderr[-3000:]}")
    return done


def build_library(c_dir: Path, robot: str, target: Target, work: Path) -> Path:
    """The robot's C compiled for ``target`` (object, with its .su stack-usage file)."""
    work.mkdir(parents=True, exist_ok=True)
    obj = work / f"{robot}.o"
    _run([CC, *target.cpu_flags, *C_FLAGS, "-fstack-usage", "-c", c_dir / f"{robot}.c", "-o", obj],
         f"cross-compiling {robot}.c for {target.name}")
    return obj


def section_sizes(obj: Path) -> dict:
    """``{function symbol: bytes of .text.<symbol>}`` from the object's section headers."""
    out = _run(["arm-none-eabi-readelf", "-S", "-W", obj], "readelf").stdout
    sizes = {}
    for m in re.finditer(r"\]\s+\.text\.(\S+)\s+PROGBITS\s+\S+\s+\S+\s+([0-9a-f]+)", out):
        sizes[m.group(1)] = int(m.group(2), 16)
    return sizes


def stack_usage(su: Path) -> dict:
    """``{function: bytes}`` from gcc's -fstack-usage file."""
    out = {}
    for line in su.read_text().splitlines():
        where, size, _kind = line.split("\t")
        out[where.rsplit(":", 1)[-1]] = int(size)
    return out


def undefined_symbols(obj: Path) -> list[str]:
    out = _run(["arm-none-eabi-nm", "-u", obj], "nm").stdout
    return sorted({line.split()[-1] for line in out.splitlines() if line.strip()})


def build_and_run(generated_dir: Path, target: Target, work: Path, inputs: dict) -> dict:
    """Cross-build the library and the harness for ``target``, run it on QEMU; returns
    ``{"outputs": {fn: {port: array}}, "instructions": {fn: n}, "flash": {fn: bytes},
    "stack": {fn: bytes}, "undefined": [symbols the library's object needs], "linked": [symbols
    the harness image defines]}``."""
    generated_dir = Path(generated_dir)
    manifest = json.loads((generated_dir / "functions.json").read_text())
    robot = manifest["robot"]
    scalar = manifest.get("c_scalar", "double")
    if scalar != target.scalar:
        raise EmbeddedError(f"{target.name} runs {target.scalar} C; {generated_dir} is {scalar}")
    c_dir = generated_dir / "c"
    obj = build_library(c_dir, robot, target, work)
    (work / "harness.c").write_text(harness_source(manifest, inputs))
    (work / "empty.c").write_text(empty_source(scalar))
    elf = work / "harness.elf"
    _run([CC, *target.cpu_flags, *C_FLAGS[:3], "-ffunction-sections", "-fdata-sections", "-Wl,--gc-sections",
          "--specs=rdimon.specs", "-nostartfiles", "-T", HERE / "mps2.ld", "-I", c_dir,
          HERE / "startup.c", work / "harness.c", work / "empty.c", obj, "-lm", "-o", elf],
         f"linking the {target.name} harness")
    done = _run([QEMU, "-M", target.board, "-nographic", "-monitor", "none", "-serial", "none",
                 "-semihosting-config", "enable=on,target=native", "-icount", "shift=0", "-kernel", elf],
                f"running the harness on {target.board}", timeout=300)
    lines = done.stdout.splitlines()
    if "done" not in lines:
        raise EmbeddedError(f"the {target.board} harness stopped early:\n{done.stdout[-2000:]}")
    real = np.float32 if scalar == "float" else np.float64
    outputs, ticks = {}, {}
    specs = {f["name"]: f for f in manifest["functions"]}
    for line in lines:
        parts = line.split()
        if parts[0] == "out":
            fn, port, words = parts[1], parts[2], np.array([int(w, 16) for w in parts[3:]], dtype=np.uint32)
            dtype = next(p["dtype"] for p in specs[fn]["outputs"] if p["name"] == port)
            values = words.view(np.int32) if dtype == "int" else words.view(real)
            outputs.setdefault(fn, {})[port] = values.copy()
        elif parts[0] == "ticks":
            ticks[parts[1]] = int(parts[2])
    base = ticks.pop("-")
    instructions = {fn: round((t - base) * TICK_INSTRUCTIONS / REPS) for fn, t in ticks.items()}
    sizes, frames = section_sizes(obj), stack_usage(obj.with_suffix(".su"))
    kernel = max((v for k, v in frames.items() if k.startswith("kdg_sincos")), default=0)
    flash, stack = {}, {}
    for fn in ticks:
        symbol = specs[fn]["c_symbol"]
        flash[fn] = sizes.get(symbol)
        stack[fn] = frames.get(symbol, 0) + (kernel if any(k.startswith("kdg_sincos") for k in sizes) else 0)
    batch_stack = {k[len(robot) + 1:]: v for k, v in frames.items() if k.endswith("_batch")}
    return {"outputs": outputs, "instructions": instructions, "flash": flash, "stack": stack,
            "batch_stack": batch_stack, "undefined": undefined_symbols(obj), "linked": defined_symbols(elf)}


def _float_literal(value) -> str:
    """A float's C99 spelling, infinities and NaN by <math.h>'s macros.

    >>> _float_literal(0.1), _float_literal(float("-inf")), _float_literal(float("nan"))
    ('0x1.99999a0000000p-4f', '-INFINITY', 'NAN')
    """
    value = float(np.float32(value))
    if np.isnan(value):
        return "NAN"
    if np.isinf(value):
        return "-INFINITY" if value < 0 else "INFINITY"
    return f"{value.hex()}f"


def kernel_source(arguments: dict) -> str:
    """A harness of the float sincos kernel alone (``kindyngen.codegen.trig_kernel.kernel_c_float``):
    per named argument list, its sin and cos as hex words ("out <name> sin|cos <word> ..."),
    then "ticks <name> <ticks of REPS calls>"; an empty function's loop last ("ticks - ...").
    The kernel is called through a function of the harness's own file, as a generated
    function calls it."""
    from ..codegen.trig_kernel import kernel_c_float
    lines = ["/* KinDynGen float kernel harness (kindyngen/runtime/embedded.py): generated, do not edit. */",
             "#include <math.h>", "#include <stdint.h>", "#include <stdio.h>", "",
             "#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)",
             "#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)",
             "#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)", "",
             kernel_c_float(),
             "void kdg_kernel_call(long n, const float *x, float *s, float *c);",
             "void kdg_kernel_call(long n, const float *x, float *s, float *c)", "{",
             "    kdg_sincosf(n, x, s, c);", "}", "",
             "void kdg_empty(const float *a, float *b);", "",
             "static void print_words(const char *name, const char *what, const float *data, long n)", "{",
             "    long i;", '    printf("out %s %s", name, what);', "    for (i = 0; i < n; ++i) {",
             "        union { float f; uint32_t u; } v;", "        v.f = data[i];",
             '        printf(" %08lx", (unsigned long)v.u);', "    }", '    printf("\\n");', "}", "",
             "static uint32_t elapsed(uint32_t start)", "{", "    return (start - SYST_CVR) & 0xFFFFFFu;", "}", ""]
    body = []
    for k, (name, values) in enumerate(arguments.items()):
        n = len(values)
        words = ", ".join(_float_literal(v) for v in values)
        lines.append(f"static const float x{k}[{n}] = {{{words}}};")
        lines.append(f"static float s{k}[{n}], c{k}[{n}];")
        body += [f"    kdg_kernel_call({n}, x{k}, s{k}, c{k});",
                 f'    print_words("{name}", "sin", s{k}, {n});', f'    print_words("{name}", "cos", c{k}, {n});',
                 "    start = SYST_CVR;", f"    for (r = 0; r < {REPS}; ++r) {{",
                 f"        kdg_kernel_call({n}, x{k}, s{k}, c{k});", "    }",
                 f'    printf("ticks {name} %lu\\n", (unsigned long)elapsed(start));']
    return "\n".join(lines + _main("float", body))


def kernel_figures(arguments: dict, work: Path) -> dict:
    """The float sincos kernel on the Cortex-M4F board (QEMU) for each named argument list:
    ``{"sin": {name: float32 array}, "cos": {...}, "instructions": {name: per call},
    "symbols": [every symbol the linked image defines]}`` (the last says whether newlib's
    sinf/cosf were linked)."""
    target = TARGETS["m4f"]
    bad = [name for name in arguments if not re.fullmatch(r"[A-Za-z0-9_.+-]+", name)]
    if bad:
        raise ValueError(f"argument list names must be single words (they are printed and parsed): {bad}")
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    (work / "kernel_harness.c").write_text(kernel_source(arguments))
    (work / "empty.c").write_text(empty_source("float"))
    elf = work / "kernel.elf"
    _run([CC, *target.cpu_flags, *C_FLAGS, "-Werror", "-Wl,--gc-sections", "--specs=rdimon.specs", "-nostartfiles",
          "-T", HERE / "mps2.ld", HERE / "startup.c", work / "kernel_harness.c", work / "empty.c", "-lm", "-o", elf],
         "linking the M4F kernel harness")
    done = _run([QEMU, "-M", target.board, "-nographic", "-monitor", "none", "-serial", "none",
                 "-semihosting-config", "enable=on,target=native", "-icount", "shift=0", "-kernel", elf],
                f"running the kernel harness on {target.board}", timeout=300)
    lines = done.stdout.splitlines()
    if "done" not in lines:
        raise EmbeddedError(f"the {target.board} kernel harness stopped early:\n{done.stdout[-2000:]}")
    out, ticks = {"sin": {}, "cos": {}}, {}
    for line in lines:
        parts = line.split()
        if parts[0] == "out":
            out[parts[2]][parts[1]] = np.array([int(w, 16) for w in parts[3:]], dtype=np.uint32).view(np.float32)
        elif parts[0] == "ticks":
            ticks[parts[1]] = int(parts[2])
    base = ticks.pop("-")
    out["instructions"] = {name: round((t - base) * TICK_INSTRUCTIONS / REPS) for name, t in ticks.items()}
    out["symbols"] = defined_symbols(elf)
    return out


def defined_symbols(elf: Path) -> list[str]:
    """Every symbol a linked image defines (``nm --defined-only``): what was linked in."""
    out = _run(["arm-none-eabi-nm", "--defined-only", elf], "nm").stdout
    return sorted({line.split()[-1] for line in out.splitlines() if line.strip()})


def host_outputs(generated_dir: Path, inputs: dict) -> dict:
    """The same calls on the host (eval's C library, strict C99)."""
    from .evaluate import load_generated
    lib = load_generated(generated_dir, "c")
    return {fn: lib.call(fn, args) for fn, args in inputs.items()}


def libm_calls(generated_dir: Path) -> dict:
    """``{function: sorted libm functions it calls}`` besides sqrt and fabs (correctly rounded on
    every IEEE target) and the sincos kernel: the functions whose results may differ in the last
    bits between the host's libm and newlib."""
    manifest = json.loads((Path(generated_dir) / "functions.json").read_text())
    source = (Path(generated_dir) / "c" / f"{manifest['robot']}.c").read_text()
    out = {}
    for spec in manifest["functions"]:
        m = re.search(r"\nvoid " + re.escape(spec["c_symbol"]) + r"\(.*?\n}\n", source, re.S)
        if not m:
            continue
        calls = set(re.findall(r"\b(sinf?|cosf?|tanf?|asinf?|acosf?|atanf?|atan2f?|expf?|logf?|powf?|tanhf?)\(", m.group(0)))
        out[spec["name"]] = sorted(calls)
    return out


def figures(generated_dir: Path, target_name: str, work: Path, lower=None, upper=None) -> dict:
    """Build, run and compare one generated folder on one target (see the module docstring):
    build_and_run's result plus "inputs" (the fixed inputs), "host" (the same calls on the host)
    and "libm" (libm_calls).
    Joint angles of the fixed inputs: within ``lower``/``upper`` (default +-1 rad)."""
    from .evaluate import load_generated
    generated_dir = Path(generated_dir)
    manifest = json.loads((generated_dir / "functions.json").read_text())
    # the coordinates the functions take: a tree with mimic joints or closed by loops has fewer
    # than its joints ("nq"); loop_solve closes a tree's other joints from them
    n = manifest.get("nq", manifest["n"])
    lower = np.full(n, -1.0) if lower is None else np.asarray(lower, float)
    upper = np.full(n, 1.0) if upper is None else np.asarray(upper, float)
    inputs = fixed_inputs(manifest, load_generated(generated_dir, "c"), lower, upper)
    result = build_and_run(generated_dir, TARGETS[target_name], Path(work), inputs)
    result["inputs"] = inputs
    result["host"] = host_outputs(generated_dir, inputs)
    result["libm"] = libm_calls(generated_dir)
    return result


def agreement(result: dict) -> dict:
    """``{function: "bit-exact" | largest |board - host| relative to the host output's largest
    entry}``: how the board's outputs compare with the host's, over all output ports."""
    out = {}
    for fn, ports in result["outputs"].items():
        exact, worst = True, 0.0
        for port, board in ports.items():
            host = np.ravel(result["host"][fn][port]).astype(board.dtype)
            if np.array_equal(host, board):
                continue
            exact = False
            scale = max(float(np.max(np.abs(host))), np.finfo(float).tiny)
            worst = max(worst, float(np.max(np.abs(host.astype(float) - board.astype(float)))) / scale)
        out[fn] = "bit-exact" if exact else float(f"{worst:.1e}")
    return out


def markdown(result: dict, robot: str, target: Target) -> str:
    """The per-function table of one run."""
    lines = [f"# {robot} on {target.board} ({target.name}, {target.scalar} C)", "",
             f"Flags: {' '.join(target.cpu_flags + C_FLAGS)}; instructions executed per call "
             f"(QEMU -icount, SysTick, {REPS} calls); agreement with the host's C on the same inputs.", "",
             "| function | flash bytes | stack bytes | instructions | vs host |", "|---|---|---|---|---|"]
    agree = agreement(result)
    for fn in result["flash"]:
        lines.append(f"| {fn} | {result['flash'][fn]} | {result['stack'][fn]} | {result['instructions'][fn]} | "
                     f"{agree[fn]} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    import argparse
    import tempfile
    from .evaluate import EvaluationError
    parser = argparse.ArgumentParser(prog="python -m kindyngen.runtime.embedded", description=(
        "Cross-build a generated robot folder's C for an emulated Cortex-M board, run every function "
        "there (QEMU) and print its flash, stack and instruction figures as JSON. m4f: mps2-an386, "
        "float C (generate --scalar float); m7: mps2-an500, double C."))
    parser.add_argument("generated_dir", metavar="GENERATED_DIR", help="e.g. firmware/lwr4 (generate --no-batch)")
    parser.add_argument("target", choices=sorted(TARGETS))
    parser.add_argument("--write", action="store_true",
                        help="also write GENERATED_DIR/embedded_<target>.json and .md (the figures, the table)")
    args = parser.parse_args(argv)
    reason = missing_tools()
    try:
        if reason:
            raise EmbeddedError(reason)
        with tempfile.TemporaryDirectory() as tmp:
            r = figures(Path(args.generated_dir), args.target, Path(tmp))
    except (EmbeddedError, EvaluationError, OSError) as exc:
        print(f"error: {args.generated_dir}: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    document = {k: r[k] for k in ("flash", "stack", "instructions", "batch_stack", "undefined")}
    document["vs_host"] = agreement(r)
    text = strict_json(document, indent=1) + "\n"
    print(text, end="")
    if args.write:
        folder = Path(args.generated_dir)
        robot = json.loads((folder / "functions.json").read_text())["robot"]
        (folder / f"embedded_{args.target}.json").write_text(text)
        (folder / f"embedded_{args.target}.md").write_text(markdown(r, robot, TARGETS[args.target]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
