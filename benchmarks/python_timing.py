"""Per-call timing of Python callables: the generated numpy module one configuration at a
time ("python") and batched ("python_batch", time per configuration), and saved CasADi
Functions called from Python ("casadi").

The same scheme as the C harness: cycle over K precomputed inputs, calibrate the iteration
count to a target duration per repetition, report median/min/max over repetitions.
"""
from __future__ import annotations

import importlib.util
import time
from pathlib import Path

from .common import summary


def load_module(path: Path):
    """Import a generated module from its file (generated/ is not a package)."""
    spec = importlib.util.spec_from_file_location(f"kb_generated_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _loop(fn, args: list, iters: int) -> int:
    K = len(args)
    start = time.perf_counter_ns()
    for i in range(iters):
        fn(*args[i % K])
    return time.perf_counter_ns() - start


def per_call(fn, args: list, repeats: int, target_s: float) -> dict:
    """``args``: one argument tuple per precomputed input."""
    iters = 1
    while True:
        elapsed = _loop(fn, args, iters)
        if elapsed > 0.2 * target_s * 1e9 or iters >= 1 << 24:
            iters = max(1, int(iters * target_s * 1e9 / max(elapsed, 1)))
            break
        iters *= 4
    return summary(_loop(fn, args, iters) / iters for _ in range(repeats))


def per_configuration(fn, batch_args: tuple, count: int, repeats: int) -> dict:
    """One call on a whole batch of ``count`` configurations, time divided by ``count``."""
    fn(*batch_args)  # warm-up: first-touch allocation would otherwise bias repeat 1
    times = []
    for _ in range(repeats):
        start = time.perf_counter_ns()
        fn(*batch_args)
        times.append((time.perf_counter_ns() - start) / count)
    return summary(times)
