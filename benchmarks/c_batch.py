"""Throughput of the generated C batch functions (<robot>_<name>_batch, implementation
"c_batch") against single calls of the same library in the same run.

Both are built with -O3 -march=native through the C harness (benchmarks/c_harness.py): the
single calls cycle over N configurations, one call each; the batch driver calls
<name>_batch(N, ...) on the same N configurations in structure-of-arrays layout (entry k of
configuration i at [k*N + i], as the generated header documents). Times are per
configuration, median/min/max over repeats and rounds (the two drivers run interleaved so a
busy machine affects both alike); "ratio" is single median / batch median.

    from benchmarks.c_batch import time_batch
    results = time_batch(GENERATED / "lwr4", model, functions, n=1000)
    # {"fk_hom": {"c_batch": {...ns...}, "c_single": {...}, "ratio": 3.1, "max_error": 0.0}, ...}
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import c_harness, inputs
from .common import summary

IMPL = "c_batch"
FLAGS = ["-O3", "-march=native"]


def _size(port: dict) -> int:
    return int(np.prod(port["shape"]))


def _call(function: dict, batch: bool, n: int) -> str:
    ins = ", ".join(f"{{in{p}}}" for p in range(len(function["inputs"])))
    outs = ", ".join(f"{{out{p}}}" for p in range(len(function["outputs"])))
    if batch:
        return f"{function['c_symbol']}_batch({n}L, {ins}, {outs})"
    return f"{function['c_symbol']}({ins}, {outs})"


def prepare(robot_dir: Path, functions: list[dict], samples: dict, n: int, workdir: Path,
            flags: list[str] = FLAGS, compiler: str = "gcc", sources: list[Path] | None = None,
            tag: str = ""):
    """Build the single-call and the batch driver for ``functions`` (functions.json entries,
    iterative ones are skipped: they have no batch variant) on ``samples`` ({function name:
    {port: (>= n, *shape) array}}, e.g. from benchmarks.inputs.sample). ``sources``: the
    library to link (default: robot_dir/c/<robot>.c; an object file built once serves both
    drivers); ``tag`` tells builds of other flags or compilers apart in the build cache."""
    robot = robot_dir.name
    chosen = [f for f in functions if f.get("kind") != "iterative" and "c" in f.get("languages", ("c",))]
    single, batch = [], []
    for f in chosen:
        arrays = [np.asarray(samples[f["name"]][p["name"]][:n], float).reshape(n, -1) for p in f["inputs"]]
        outputs = [(_size(p), p.get("dtype", "double")) for p in f["outputs"]]
        single.append(c_harness.CFunction(f["name"], _call(f, False, n), arrays, outputs))
        # one "input" row holding all n configurations, transposed to structure-of-arrays
        soa = [np.ascontiguousarray(a.T).reshape(1, -1) for a in arrays]
        batch.append(c_harness.CFunction(f["name"], _call(f, True, n), soa,
                                         [(size * n, dtype) for size, dtype in outputs]))
    c_dir = robot_dir / "c"
    prelude = f'#include "{robot}.h"'
    sources = sources or [c_dir / f"{robot}.c"]
    flags = [*flags, f"-I{c_dir}"]
    return (chosen,
            c_harness.prepare(f"{robot}_c_single{tag}", single, prelude, sources, flags, workdir / "single", compiler),
            c_harness.prepare(f"{robot}_c_batch{tag}", batch, prelude, sources, flags, workdir / "batch", compiler))


def time_batch(robot_dir: Path, model, functions: list[dict], n: int = 1000, repeats: int = 5,
               rounds: int = 3, target_ns: float = 2e6, workdir: Path | None = None,
               python_module=None) -> dict:
    """{function name: {"c_batch": summary ns per configuration, "c_single": summary ns per
    call, "ratio": single / batch (medians), "max_error": largest difference between the
    batch's outputs for configuration 0 and the single call's}} for ``n`` configurations.
    ``python_module``: the generated numpy module, for IK targets (see inputs.sample)."""
    workdir = Path(workdir) if workdir else Path(__file__).resolve().parent / "build" / "c_batch" / robot_dir.name
    samples = {f["name"]: inputs.sample(f, model, n, python_module) for f in functions
               if f.get("kind") != "iterative"}
    chosen, single, batch = prepare(robot_dir, functions, samples, n, workdir)
    times = {"c_single": {}, "c_batch": {}}
    checks = {}
    for _ in range(rounds):
        for impl, prepared in (("c_single", single), ("c_batch", batch)):
            measured, outputs = c_harness.measure(prepared, repeats, target_ns)
            for name, values in measured.items():
                scale = n if impl == "c_batch" else 1     # a batch call does n configurations
                times[impl].setdefault(name, []).extend(v / scale for v in values)
            checks[impl] = outputs
    results = {}
    for f in chosen:
        name = f["name"]
        single_stats, batch_stats = summary(times["c_single"][name]), summary(times["c_batch"][name])
        errors = [np.max(np.abs(b.reshape(_size(p), n)[:, 0] - s), initial=0.0)
                  for p, s, b in zip(f["outputs"], checks["c_single"][name], checks["c_batch"][name])]
        results[name] = {IMPL: batch_stats, "c_single": single_stats,
                         "ratio": single_stats["median_ns"] / batch_stats["median_ns"],
                         "max_error": float(max(errors, default=0.0))}
    return results
