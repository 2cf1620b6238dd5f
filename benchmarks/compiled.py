"""The compiled implementations (generated C, CasADi's C, Pinocchio C++) as Timers, and
their interleaved timing.

Each Timer runs its binary once for a given number of repetitions. The machine is shared and
noisy, so instead of timing each implementation in one block (where a burst of load from a
neighbour lands on one implementation and skews its ratio to the others), the binaries are
run in several rounds, one after the other within a round, and the repetitions of all rounds
are pooled.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from . import c_harness, casadi_codegen, pinocchio_cpp

# pinocchio_casadi_c (CasADi's C of Pinocchio traced in SX) gets c_native's flags: the peer
# is compiled exactly as well as the generated code it is compared with.
C_FLAGS = {"c": ["-O3"], "c_native": ["-O3", "-march=native"], "casadi_codegen": ["-O3"],
           "pinocchio_casadi_c": ["-O3", "-march=native"]}


@dataclass
class Timer:
    """``run(repeats) -> ({function: [ns per call]}, raw check output)``;
    ``outputs(raw) -> {function: [row-major output arrays for input 0]}``."""

    run: Callable[[int], tuple[dict, dict]]
    outputs: Callable[[dict], dict]
    build_seconds: float | None = None


def generated_c(robot: str, impl: str, robot_dir: Path, functions: list, samples: dict, workdir: Path,
                flags: list | None = None) -> Timer:
    """The generated C99 of one robot, compiled with the flags of ``impl`` (or ``flags``)."""
    source = robot_dir / "c" / f"{robot}.c"
    if not source.exists():
        raise FileNotFoundError(f"no generated C: {source}")
    targets = []
    for f in functions:
        args = [f"{{in{i}}}" for i in range(len(f["inputs"]))] + [f"{{out{i}}}" for i in range(len(f["outputs"]))]
        arrays = [samples[f["name"]][p["name"]] for p in f["inputs"]]
        targets.append(c_harness.CFunction(
            name=f["name"], call=f"{f['c_symbol']}({', '.join(args)})",
            inputs=[a.reshape(a.shape[0], -1) for a in arrays],
            outputs=[(int(np.prod(p["shape"])), p.get("dtype", "double")) for p in f["outputs"]]))
    prepared = c_harness.prepare(f"{robot}_{impl}", targets, f'#include "{robot}.h"', [source],
                                 flags or C_FLAGS[impl], workdir)
    return Timer(run=lambda repeats, target: c_harness.measure(prepared, repeats, target),
                 outputs=lambda raw: raw, build_seconds=prepared.built.seconds)


def casadi_c(robot: str, robot_dir: Path, functions: list, samples: dict, workdir: Path,
             flags: list | None = None) -> Timer | None:
    """CasADi's own C for the saved Functions (None when there are none), compiled with
    ``flags`` (default its C_FLAGS)."""
    loaded = {f["name"]: casadi_codegen.load(robot_dir, f["name"]) for f in functions}
    loaded = {k: v for k, v in loaded.items() if v is not None}
    if not loaded:
        return None
    stem = f"{robot}_casadi_codegen"
    source, prelude, targets = casadi_codegen.generate(loaded, samples, workdir, stem)
    prepared = c_harness.prepare(stem, targets, prelude, [source], flags or C_FLAGS["casadi_codegen"], workdir)

    def outputs(raw):  # CasADi's non-zeros, column-major -> dense row-major
        return {name: [casadi_codegen.from_casadi_layout(v, loaded[name].sparsity_out(i)) for i, v in enumerate(values)]
                for name, values in raw.items()}
    return Timer(run=lambda repeats, target: c_harness.measure(prepared, repeats, target),
                 outputs=outputs, build_seconds=prepared.built.seconds)


def pinocchio(model, functions: list, data: dict, binary: Path, workdir: Path) -> Timer:
    """Pinocchio's algorithms, reported under the names of the generated functions they
    correspond to (one algorithm may stand for several routes, e.g. M and M_lagrange)."""
    prepared = pinocchio_cpp.prepare(model, data, workdir)
    names = {f["name"]: pinocchio_cpp.algorithm_for(f["name"]) for f in functions}
    names.update({alg: alg for alg in pinocchio_cpp.ALWAYS if alg not in names})

    def run(repeats, target):
        times, checks = pinocchio_cpp.measure(binary, prepared, repeats, target)
        return {name: times[alg] for name, alg in names.items() if alg in times}, checks

    def outputs(raw):  # only where Pinocchio computes the very same array
        out = {}
        for name, alg in names.items():
            if alg in raw and not (alg == "fk" and name != "fk_hom"):
                out[name] = raw[alg]
        return out
    return Timer(run=run, outputs=outputs)


def interleave(timers: dict, repeats: int, rounds: int, target_ns: float, on_error) -> tuple[dict, dict]:
    """Run every timer ``rounds`` times in turn; ({impl: {function: [ns...]}}, {impl: outputs
    of the first round}). A timer that fails is reported through ``on_error`` and dropped."""
    per_round = max(1, math.ceil(repeats / rounds))
    pooled = {impl: {} for impl in timers}
    outputs = {}
    live = dict(timers)
    for r in range(rounds):
        for impl, timer in list(live.items()):
            try:
                times, raw = timer.run(per_round, target_ns)
            except Exception as exc:  # noqa: BLE001 - one binary crashing costs its column only
                on_error(impl, exc)
                del live[impl]
                pooled.pop(impl)
                continue
            for name, values in times.items():
                pooled[impl].setdefault(name, []).extend(values)
            if r == 0:
                outputs[impl] = timer.outputs(raw)
    return pooled, outputs
