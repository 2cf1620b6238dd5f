"""Time C functions per call: write a C driver around them, compile it with the code under
test, run it (as often as the caller likes), parse its output.

The driver reads K precomputed inputs per function from a binary file, calls the function
in a loop cycling over them (k = 0..K-1, 0..), sums the first output entry of every call and
stores the sum in a volatile sink so the calls cannot be optimised away, and prints the
per-call time of every repetition (CLOCK_MONOTONIC). The code under test is a
separate translation unit (no -flto), so it is not inlined into the loop: each call is a
real call, as from a user's program. The driver also prints every output for input 0, so
the caller can confirm the call is wired correctly before trusting its time.
"""
from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .build import Built, build


@dataclass
class CFunction:
    """One function to time.

    ``call`` is a C expression with ``{in0}, {in1}, ...`` for the current input pointers and
    ``{out0}, ...`` for the output buffers; ``inputs`` are (K, size) arrays already in the
    callee's memory layout; ``outputs`` are (buffer length, "double" | "int")."""

    name: str
    call: str
    inputs: list
    outputs: list


_MAIN = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static volatile double kb_sink;

static double kb_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e9 + ts.tv_nsec;
}

static double *kb_read(const char *path, long count)
{
    double *buffer = malloc(sizeof(double) * (count > 0 ? count : 1));
    FILE *f = fopen(path, "rb");
    if (!buffer || !f || (long)fread(buffer, sizeof(double), count, f) != count) {
        fprintf(stderr, "cannot read %ld doubles from %s\n", count, path);
        exit(1);
    }
    fclose(f);
    return buffer;
}

/* Calibrate the iteration count once so that a repetition lasts about target_ns, then
   time `repeats` repetitions and print each one's time per call (Python pools them over
   interleaved runs of several drivers). */
static void kb_measure(const char *name, double (*loop)(long, long), long K, int repeats,
                       double target_ns)
{
    long iters = 16;
    for (;;) {
        double t0 = kb_now_ns();
        kb_sink = kb_sink + loop(iters, K);
        double dt = kb_now_ns() - t0;
        if (dt > 0.2 * target_ns || iters > (1L << 30)) {
            iters = (long)(iters * target_ns / (dt > 1.0 ? dt : 1.0));
            if (iters < 1) iters = 1;
            break;
        }
        iters *= 4;
    }
    printf("time %s", name);
    for (int r = 0; r < repeats; ++r) {
        double t0 = kb_now_ns();
        kb_sink = kb_sink + loop(iters, K);
        printf(" %.3f", (kb_now_ns() - t0) / iters);  /* stdout is buffered: no I/O in the timing */
    }
    printf("\n");
}
"""


def driver_source(functions: list[CFunction], prelude: str) -> str:
    parts = [prelude, _MAIN]
    for f_index, f in enumerate(functions):
        ins = [f"kb_in_{f_index}_{p}" for p in range(len(f.inputs))]
        outs = [f"kb_out_{f_index}_{p}" for p in range(len(f.outputs))]
        for var in ins:
            parts.append(f"static double *{var};")
        for var, (size, dtype) in zip(outs, f.outputs):
            parts.append(f"static {'int' if dtype == 'int' else 'double'} {var}[{max(size, 1)}];")
        current = {f"in{p}": f"({var} + k * {arr.shape[1]})" for p, (var, arr) in enumerate(zip(ins, f.inputs))}
        current.update({f"out{p}": var for p, var in enumerate(outs)})
        first = f"(double){outs[0]}[0]" if outs else "0.0"
        parts.append(f"""
static double kb_loop_{f_index}(long iters, long K)
{{
    double acc = 0.0;
    long k = 0;
    for (long i = 0; i < iters; ++i) {{
        {f.call.format(**current)};
        acc += {first};
        if (++k == K) k = 0;
    }}
    return acc;
}}""")
    parts.append("""
int main(int argc, char **argv)
{
    if (argc != 5) { fprintf(stderr, "usage: %s DIR K REPEATS TARGET_NS\\n", argv[0]); return 2; }
    const char *dir = argv[1];
    long K = atol(argv[2]);
    int repeats = atoi(argv[3]);
    double target_ns = atof(argv[4]);
    char path[4096];
    (void)path;""")
    for f_index, f in enumerate(functions):
        for p, arr in enumerate(f.inputs):
            parts.append(f'    snprintf(path, sizeof path, "%s/in_{f_index}_{p}.bin", dir);')
            parts.append(f"    kb_in_{f_index}_{p} = kb_read(path, K * {arr.shape[1]});")
    for f_index, f in enumerate(functions):
        parts.append(f'    kb_measure("{f.name}", kb_loop_{f_index}, K, repeats, target_ns);')
    # Outputs for input 0, printed with full precision for the wiring check.
    for f_index, f in enumerate(functions):
        parts.append(f"    kb_sink = kb_sink + kb_loop_{f_index}(1, K);")
        for p, (size, dtype) in enumerate(f.outputs):
            fmt, cast = ('" %d"', "") if dtype == "int" else ('" %.17g"', "")
            parts.append(f'    printf("check {f.name} {p}");'
                         f" for (int j = 0; j < {size}; ++j) printf({fmt}, {cast}kb_out_{f_index}_{p}[j]);"
                         ' printf("\\n");')
    parts.append("    return kb_sink == 12345.678 ? 3 : 0;  /* read the sink */\n}\n")
    return "\n".join(parts)


@dataclass
class Prepared:
    """A built driver and its input files, ready to be run any number of times."""

    binary: Path
    data: Path
    K: int
    built: Built


C_STD = "-std=gnu99"
"""The language mode every C implementation of the benchmarks is built in, ours and the peers'
alike. In GNU mode gcc contracts products into sums (``-ffp-contract=fast``) unless the flags
say otherwise, so the timings include fused multiply-adds on both sides (docs/latency.md)."""


def prepare(name: str, functions: list[CFunction], prelude: str, sources: list[Path], flags: list[str],
            workdir: Path, compiler: str = "gcc") -> Prepared:
    """Write and build the driver for ``functions`` with ``sources`` and ``flags`` (by
    ``compiler``), and write their inputs."""
    workdir.mkdir(parents=True, exist_ok=True)
    driver = workdir / f"{name}_driver.c"
    driver.write_text(driver_source(functions, prelude))
    include = sorted({f"-I{Path(s).parent}" for s in sources})
    built = build(name, compiler, [driver, *sources], [C_STD, *flags, *include], libs=("-lm",),
                  extra=tuple(p for s in sources for p in Path(s).parent.glob("*.h")))
    K = functions[0].inputs[0].shape[0] if functions and functions[0].inputs else 1
    data = workdir / f"{name}_inputs"
    data.mkdir(exist_ok=True)
    for f_index, f in enumerate(functions):
        assert all(arr.shape[0] == K for arr in f.inputs), "all functions share K"
        for p, arr in enumerate(f.inputs):
            np.ascontiguousarray(arr, dtype=np.float64).tofile(data / f"in_{f_index}_{p}.bin")
    return Prepared(built.path, data, K, built)


def measure(prepared: Prepared, repeats: int, target_ns: float) -> tuple[dict, dict]:
    """Run the driver once: ({function: [ns per call, one per repetition]},
    {function: [output arrays for input 0]})."""
    out = subprocess.run([str(prepared.binary), str(prepared.data), str(prepared.K), str(repeats),
                          str(target_ns)], capture_output=True, text=True, check=True)
    return parse(out.stdout)


def parse(stdout: str) -> tuple[dict, dict]:
    """"time NAME t1 ... tR" and "check NAME PORT v..." lines (also Pinocchio's format)."""
    times, checks = {}, {}
    for line in stdout.splitlines():
        parts = line.split()
        if parts and parts[0] == "time":
            times[parts[1]] = [float(v) for v in parts[2:]]
        elif parts and parts[0] == "check":
            checks.setdefault(parts[1], []).append(np.array([float(v) for v in parts[3:]]))
    return times, checks
