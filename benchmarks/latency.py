"""Latency: the critical-path count against measured single-call times, the sincos kernel
alone against its latency bound, and what FMA contraction buys; results/latency.json.

    python -m benchmarks.latency [--robots lwr4 panda] [--rounds 3] [--out DIR]

* ``functions``: every generated C function of each robot, timed per single call in the
  harness of ``make bench`` (benchmarks/c_harness.py), built ``-O3 -march=native`` twice:
  strict (``-ffp-contract=off``, the code exactly as the critical-path count reads it) and
  contracted (``-ffp-contract=fast``, gcc's default outside ISO mode). Beside each time, the
  function's critical path and operation count from ``generated/<robot>/opcounts.json``.
* ``machine_code``: per function, the strict build's object code as gcc emits it (bytes,
  instructions, and instructions with a memory operand: loads and stores of inputs, outputs,
  sin/cos arrays and register spills; x86-64 only, read with objdump).
* ``correlation``: Pearson's r over the functions of a robot between the strict single-call
  time and (a) the critical path in cycles, (b) add + mul + call after CSE, (c) each figure of
  ``machine_code``, and the least-squares fits time = a * cycles + b * operations + c and
  time = a * cycles + b * memory operands + c with their r.
* ``kernel``: kdg_sincos alone on 8 angles (n passed at run time, as the batch calls do) and
  on 7 (``n7``: the split kernel, kdg_sincos_split with n a constant and its libm fix-up behind
  the flag, as lwr4's and panda's single calls run it): latency (the
  next call's angles depend on this call's results) and throughput (independent calls), both
  net of the same harness around an empty kernel of the same memory traffic (for n7 two
  vector loads of x[0..3] and x[3..6] and eight lanes stored: the harness's chain goes through
  memory, and a vector load of scalars just stored waits for the stores; the net of the
  eight-lane empty loop is kept beside it), in cycles of this core (calibrated by a chain
  of dependent multiplications, 3 cycles each on Zen 2-5; a chain of additions is not: 3 cycles
  on Zen 4, 2 on Zen 5), against :func:`kindyngen.codegen.trig_kernel.kernel_latency` with the
  stated table and with Zen 5's 2-cycle addition.

Times are medians over interleaved rounds; CPU-time noise from other processes is reduced by
taking the minimum over repetitions for the kernel. Nothing here asserts on a time.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

from kindyngen.codegen import trig_kernel
from kindyngen.json_text import strict_json
from kindyngen.readers.yaml_description import load_robot

from . import c_harness, compiled, inputs
from .build import BUILD, build
from .common import GENERATED, RESULTS, ROBOTS, machine, manifest, summary

VARIANTS = {"strict": ["-O3", "-march=native", "-ffp-contract=off"],
            "contracted": ["-O3", "-march=native", "-ffp-contract=fast"]}


def log(message: str) -> None:
    print(f"[latency] {message}", file=sys.stderr, flush=True)


def pearson(x, y) -> float:
    """Pearson's correlation coefficient.

    >>> round(pearson([1, 2, 3], [2, 4, 7]), 4)
    0.9934
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    return float(np.corrcoef(x, y)[0, 1])


def fit(columns, y) -> dict:
    """Least squares y ~ columns @ a + c: coefficients and the correlation of fit and y."""
    a = np.column_stack([np.asarray(c, float) for c in columns] + [np.ones(len(y))])
    coef, *_ = np.linalg.lstsq(a, np.asarray(y, float), rcond=None)
    return {"coefficients": [float(v) for v in coef], "r": pearson(a @ coef, y)}


def time_functions(robot: str, generated: Path, rounds: int, K: int, workdir: Path, only=None) -> dict:
    robot_dir = generated / robot
    spec = manifest(robot_dir)
    model = load_robot(ROBOTS / f"{robot}.yaml")
    functions = [f for f in spec["functions"] if only is None or f["name"] in only]
    samples = {f["name"]: inputs.sample(f, model, K) for f in functions}
    timers = {}
    for variant, flags in VARIANTS.items():
        log(f"{robot}: building {variant} ({' '.join(flags)})")
        timers[variant] = compiled.generated_c(robot, f"latency_{variant}", robot_dir, functions, samples,
                                               workdir / variant, flags)
    log(f"{robot}: timing in {rounds} interleaved rounds")
    pooled, _ = compiled.interleave(timers, 3 * rounds, rounds, 5e6,
                                    lambda impl, exc: log(f"{robot} {impl} failed: {exc}"))
    counts = json.loads((robot_dir / "opcounts.json").read_text())
    shape = machine_code(robot_dir / "c" / f"{robot}.c", robot, VARIANTS["strict"], workdir / "shape")
    rows = {}
    for f in functions:
        name = f["name"]
        if name not in counts:          # iterative functions (ik_dls): a cost per iteration instead
            continue
        c = counts[name]
        rows[name] = {"critical_path_cycles": c["critical_path"]["cycles"],
                      "critical_path_operations": c["critical_path"]["operations"],
                      "operations": sum(c["after"].values()),
                      **({"machine_code": shape[name]} if name in shape else {}),
                      **{variant: summary(pooled[variant][name]) for variant in VARIANTS if name in pooled[variant]}}
    return rows


def machine_code(source: Path, robot: str, flags: list, workdir: Path) -> dict:
    """``{function: {"bytes", "instructions", "memory_operands"}}`` of the single-call functions
    of a generated C file compiled by gcc with ``flags`` in the harness's language mode (the
    object the timings run); ``{}`` where objdump cannot read the object or it is not x86-64."""
    workdir.mkdir(parents=True, exist_ok=True)
    obj = workdir / f"{robot}.o"
    try:
        subprocess.run(["gcc", c_harness.C_STD, *flags, "-c", str(source), "-o", str(obj)], check=True, capture_output=True)
        dis = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(obj)], check=True, capture_output=True, text=True).stdout
        table = subprocess.run(["nm", "-S", str(obj)], check=True, capture_output=True, text=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        log(f"{robot}: machine code not read ({exc})")
        return {}
    if "x86-64" not in subprocess.run(["objdump", "-f", str(obj)], capture_output=True, text=True).stdout:
        return {}
    sizes = {p[3]: int(p[1], 16) for p in (line.split() for line in table.splitlines()) if len(p) == 4}
    prefix = f"{robot}_"
    return {sym[len(prefix):]: {"bytes": sizes.get(sym), **body} for sym, body in _bodies(dis).items()
            if sym.startswith(prefix) and not sym.endswith("_batch")}


def _bodies(disassembly: str) -> dict:
    r"""``{symbol: {"instructions", "memory_operands"}}`` of ``objdump -d --no-show-raw-insn`` text
    (AT&T syntax: a memory operand is ``disp(%reg)``), the padding between functions (nop,
    int3) left out.

    >>> text = ("0 <r_f>:\n   0:\tvmulsd 0x8(%rdi),%xmm0,%xmm1\n   5:\tret\n"
    ...         "   6:\tnopw 0x0(%rax,%rax,1)\n")
    >>> _bodies(text)
    {'r_f': {'instructions': 2, 'memory_operands': 1}}
    """
    out, current = {}, None
    for line in disassembly.splitlines():
        head = re.match(r"^[0-9a-f]+ <([^>]+)>:$", line)
        if head:
            current = out.setdefault(head.group(1), {"instructions": 0, "memory_operands": 0})
            continue
        insn = re.match(r"^\s+[0-9a-f]+:\t(?:data16 |cs )*(\S+)", line)
        if current is None or not insn or insn.group(1).startswith("nop") or insn.group(1) == "int3":
            continue
        current["instructions"] += 1
        current["memory_operands"] += "(%" in line
    return out


SMALL = 700
"""Functions of at most this many operations after CSE form the "small" set of the correlation,
where a single call is short enough for latency to matter."""


def correlation(rows: dict) -> dict:
    """Correlations over every function and over the small ones (:data:`SMALL`)."""
    small = {n: r for n, r in rows.items() if r["operations"] <= SMALL}
    return {**_correlation(rows), "small": {"max_operations": SMALL, **_correlation(small)}}


def _correlation(rows: dict) -> dict:
    names = [n for n, r in rows.items() if "strict" in r]
    t = [rows[n]["strict"]["median_ns"] for n in names]
    cycles = [rows[n]["critical_path_cycles"] for n in names]
    ops = [rows[n]["operations"] for n in names]
    out = {"functions": len(names), "r_time_critical_path": pearson(cycles, t),
           "r_time_operations": pearson(ops, t),
           "fit_time_ns_on_cycles_operations": fit([cycles, ops], t)}
    if names and all("machine_code" in rows[n] for n in names):
        code = {k: [rows[n]["machine_code"][k] for n in names] for k in ("bytes", "instructions", "memory_operands")}
        out.update({f"r_time_{k}": pearson(v, t) for k, v in code.items()})
        out["fit_time_ns_on_cycles_memory_operands"] = fit([cycles, code["memory_operands"]], t)
    return out


KERNEL_DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "kernel.h"
__attribute__((noinline)) static void empty(long n, const double *restrict x, double *restrict s, double *restrict c)
{ long i; for (i = 0; i < n; ++i) { s[i] = x[i]; c[i] = x[i]; } }
/* the empty kernel with the split kernel's memory traffic: x[0..3] and x[3..6] loaded as two
   vectors (each spanning scalar stores of the harness's chain, which the store buffer cannot
   forward), eight lanes of s and c stored */
__attribute__((noinline)) static void empty7(long n, const double *restrict x, double *restrict s, double *restrict c)
{ int j; (void)n; for (j = 0; j < 4; ++j) { s[j] = x[j]; c[j] = x[j]; s[4 + j] = x[3 + j]; c[4 + j] = x[3 + j]; } }
__attribute__((noinline)) static void kernel(long n, const double *restrict x, double *restrict s, double *restrict c)
{ kdg_sincos(n, x, s, c); }
/* as a single call of lwr4's or panda's functions calls it: seven angles read in place by the split
   kernel, n a constant (its results fill all eight lanes of s and c: lane 4 repeats lane 3) */
__attribute__((noinline)) static void kernel7(long n, const double *restrict x, double *restrict s, double *restrict c)
{ (void)n; if (kdg_sincos_split(7, x, s, c)) kdg_sincos_split_libm(7, x, s, c); }
static double now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec*1e9 + t.tv_nsec; }
static volatile double sink;
__attribute__((noinline)) static double chain(long n, double d)
{ double x = 1.0; long i; for (i = 0; i < n; ++i) { x = x * d; x = x * d; x = x * d; x = x * d; } return x; }
typedef void (*kern)(long, const double *restrict, double *restrict, double *restrict);
/* the next call's angles depend on this call's sines and cosines (0*v: kept in IEEE arithmetic) */
__attribute__((noinline)) static double latency(kern f, long N)
{
    double x[8] = {0.3, -1.2, 2.1, 0.7, -0.4, 1.9, -2.8, 0.0}, s[8], c[8], t0;
    long i; int j;
    t0 = now();
    for (i = 0; i < N; ++i) { f(8, x, s, c); for (j = 0; j < 8; ++j) x[j] = x[j] + 0.0*(s[j] + c[j]); }
    sink = x[0];
    return (now() - t0)/N;
}
__attribute__((noinline)) static double throughput(kern f, long N)
{
    double x[64], s[64], c[64], acc = 0.0, t0;
    long i; int j;
    for (j = 0; j < 64; ++j) x[j] = 0.1*j - 3.0;
    t0 = now();
    for (i = 0; i < N; ++i) { f(8, x + 8*(i & 7), s + 8*(i & 7), c + 8*(i & 7)); acc += s[8*(i & 7)]; }
    sink = acc;
    return (now() - t0)/N;
}
int main(int argc, char **argv)
{
    const long N = 20000;
    const int R = argc > 1 ? atoi(argv[1]) : 300;
    kern ks[4] = {kernel, empty, kernel7, empty7};
    double lat[4] = {1e9, 1e9, 1e9, 1e9}, thr[4] = {1e9, 1e9, 1e9, 1e9}, mul = 1e9, t0, t;
    int r, k;
    for (r = 0; r < R; ++r) {
        t0 = now(); sink = chain(N, 1.0000001); t = (now() - t0)/(4.0*N); if (t < mul) mul = t;
        for (k = 0; k < 4; ++k) {
            t = latency(ks[k], N); if (t < lat[k]) lat[k] = t;
            t = throughput(ks[k], N); if (t < thr[k]) thr[k] = t;
        }
    }
    printf("%.5f %.4f %.4f %.4f %.4f %.4f %.4f %.4f %.4f\n", mul, lat[0], lat[1], thr[0], thr[1], lat[2], thr[2], lat[3], thr[3]);
    return 0;
}
"""


ZEN5 = {"add": 2}
"""Zen 5's double addition takes 2 cycles (Zen 4's 3; multiplication 3 on both): the kernel's
bound with it beside the bound of the stated table."""


def time_kernel(workdir: Path, repeats: int) -> dict:
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "kernel.h").write_text("#include <math.h>\n" + trig_kernel.kernel_c())
    (workdir / "kernel_driver.c").write_text(KERNEL_DRIVER)
    out = {}
    for variant, flags in VARIANTS.items():
        built = build(f"sincos_kernel_{variant}", "gcc", [workdir / "kernel_driver.c"],
                      ["-std=c99", *flags, f"-I{workdir}"], libs=("-lm",), extra=(workdir / "kernel.h",))
        text = subprocess.run([str(built.path), str(repeats)], capture_output=True, text=True, check=True).stdout
        mul, lat, lat0, thr, thr0, lat7, thr7, lat70, thr70 = (float(v) for v in text.split())
        cycle = mul / 3.0                     # a dependent double multiplication: 3 cycles on Zen 2-5
        out[variant] = {"cycle_ns": cycle, "ghz": 1.0 / cycle,
                        "latency_ns": lat, "latency_empty_ns": lat0,
                        "latency_cycles_net": (lat - lat0) / cycle,
                        "throughput_ns": thr, "throughput_empty_ns": thr0,
                        "throughput_cycles_net": (thr - thr0) / cycle,
                        # net of the empty kernel of the same memory traffic (empty7), and of the
                        # eight-lane empty loop as before the split kernel (of_loop_empty)
                        "n7": {"latency_ns": lat7, "latency_empty_ns": lat70,
                               "latency_cycles_net": (lat7 - lat70) / cycle,
                               "latency_cycles_net_of_loop_empty": (lat7 - lat0) / cycle,
                               "throughput_ns": thr7, "throughput_empty_ns": thr70,
                               "throughput_cycles_net": (thr7 - thr70) / cycle,
                               "throughput_cycles_net_of_loop_empty": (thr7 - thr0) / cycle}}
    bound = trig_kernel.kernel_latency()
    out["bound_cycles"] = bound
    out["bound_cycles_zen5"] = trig_kernel.kernel_latency(ZEN5)
    for key, cycles in (("ratio_to_bound", bound), ("ratio_to_bound_zen5", out["bound_cycles_zen5"])):
        out["strict"][key] = out["strict"]["latency_cycles_net"] / cycles
        out["strict"]["n7"][key] = out["strict"]["n7"]["latency_cycles_net"] / cycles
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["lwr4", "panda"])
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds of the function timing")
    parser.add_argument("--kernel-repeats", type=int, default=300, help="repetitions of the kernel timing")
    parser.add_argument("--no-functions", action="store_true", help="the kernel only")
    parser.add_argument("--functions", nargs="+", help="time only these functions (default: all)")
    parser.add_argument("--no-kernel", action="store_true", help="the functions only")
    parser.add_argument("--generated", type=Path, default=GENERATED)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    result = {"machine": machine(), "variants": VARIANTS}
    workdir = BUILD / "latency"
    if not args.no_kernel:
        log("kernel")
        result["kernel"] = time_kernel(workdir / "kernel", args.kernel_repeats)
    if not args.no_functions:
        result["robots"] = {}
        for robot in args.robots:
            rows = time_functions(robot, args.generated, args.rounds, 200, workdir / robot, args.functions)
            result["robots"][robot] = {"functions": rows, "correlation": correlation(rows)}
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "latency.json"
    path.write_text(strict_json(result, indent=1) + "\n")
    log(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
