"""Head to head: the generated C against the traced Pinocchio peer and Pinocchio C++ on a few
functions, in one run, interleaved, minima and medians; results/head_to_head.json.

    python -m benchmarks.head_to_head [--robots lwr4 panda] [--functions jacobian tau ...]
                                      [--candidate NAME=DIR ...] [--rounds 15] [--out FILE]

The focused form of ``make bench`` for a shared machine: only the C entries (``c_native``,
gcc -O3 -march=native), ``pinocchio_casadi_c`` (Pinocchio traced with casadi::SX, CasADi's C,
the same flags; for the derivatives the faster of its two candidates, as in ``make bench``)
and ``pinocchio_cpp``, the same inputs, many short interleaved rounds (a burst of load from a
neighbour lands on one round of every implementation, not on one implementation). Each
figure is reported as the minimum and the median ns per single call over the pooled
repetitions; the ratios t(peer) / t(ours) by both. ``--candidate NAME=DIR`` times another
generated tree (another route of the same functions, compiled the same way) in the same
rounds, so a route is chosen by a measurement against the same peer. The load average before
and after is stored with the machine. Every timed output for input 0 is compared with the
peer's (relative error), so a fast wrong answer shows. Nothing here asserts on a time.
"""
from __future__ import annotations

import argparse
import os
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from kindyngen.json_text import strict_json
from kindyngen.readers.yaml_description import load_robot

from . import compiled, inputs, pinocchio_casadi, pinocchio_cpp
from .build import BUILD
from .common import GENERATED, RESULTS, ROBOTS, machine, manifest

DEFAULT_FUNCTIONS = ("fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "tau_derivatives", "fd_derivatives")
OURS = "c_native"
PEER = pinocchio_casadi.IMPL
CPP = "pinocchio_cpp"


def log(message: str) -> None:
    print(f"[head_to_head] {message}", file=sys.stderr, flush=True)


def stats(values) -> dict:
    """Minimum, median and count of per-call times.

    >>> stats([3.0, 1.0, 2.0, 10.0])
    {'min_ns': 1.0, 'median_ns': 2.5, 'n': 4}
    """
    v = np.asarray(values, float)
    return {"min_ns": float(v.min()), "median_ns": float(np.median(v)), "n": int(v.size)}


def relative_error(got, want) -> float | None:
    """Largest |got - want| / (1 + |want|) over the outputs; None when the sizes differ."""
    if len(got) != len(want) or any(np.size(g) != np.size(w) for g, w in zip(got, want)):
        return None
    return max((float(np.max(np.abs(np.ravel(g) - np.ravel(w)) / (1 + np.abs(np.ravel(w)))))
                for g, w in zip(got, want) if np.size(w)), default=0.0)


def robot_run(robot: str, names: list, candidates: dict, rounds: int, K: int, target_ns: float,
              with_peer: bool, with_cpp: bool, workdir: Path) -> dict:
    spec = manifest(GENERATED / robot)
    model = load_robot(ROBOTS / f"{robot}.yaml")
    functions = [f for f in spec["functions"] if f["name"] in names]
    samples = {f["name"]: inputs.sample(f, model, K) for f in functions}
    timers = {}
    for impl, tree in {OURS: GENERATED, **candidates}.items():
        log(f"{robot}: {impl}: building {tree / robot}")
        cand = manifest(tree / robot)
        fs = [f for f in cand["functions"] if f["name"] in names]
        timers[impl] = compiled.generated_c(robot, impl, tree / robot, fs, samples, workdir / impl,
                                            compiled.C_FLAGS[OURS])
    if with_peer:
        log(f"{robot}: {PEER}: tracing, generating C and building")
        timers[PEER] = pinocchio_casadi.timer(model, pinocchio_casadi.build_tracer().path, samples, K, workdir)
    if with_cpp:
        data = inputs.dynamics_inputs(model, K)
        timers[CPP] = compiled.pinocchio(model, functions, data, pinocchio_cpp.build_binary().path, workdir / CPP)
    load_before = os.getloadavg()
    log(f"{robot}: timing {', '.join(timers)} in {rounds} interleaved rounds")
    pooled, outputs = compiled.interleave(timers, 3 * rounds, rounds, target_ns,
                                          lambda impl, exc: log(f"{robot} {impl} failed: {exc}"))
    load_after = os.getloadavg()
    notes = {}
    if PEER in pooled:
        # the minimum over all repetitions picks the derivative candidate, as in make bench
        pooled[PEER], outputs[PEER], notes = pinocchio_casadi.keep_faster(pooled[PEER], outputs[PEER])
    rows = {}
    for name in names:
        row = {impl: stats(pooled[impl][name]) for impl in pooled if name in pooled[impl]}
        if name in notes:
            row[PEER]["note"] = notes[name]
        for impl in [OURS, *candidates]:
            if impl not in row:
                continue
            for peer in (PEER, CPP):
                if peer in row:
                    row.setdefault("ratios", {})[f"{peer}/{impl}"] = {
                        "by_min": row[peer]["min_ns"] / row[impl]["min_ns"],
                        "by_median": row[peer]["median_ns"] / row[impl]["median_ns"]}
            if PEER in outputs and name in outputs[PEER] and name in outputs.get(impl, {}):
                row.setdefault("error_vs_peer", {})[impl] = relative_error(outputs[impl][name], outputs[PEER][name])
            if impl != OURS and name in outputs.get(impl, {}) and name in outputs.get(OURS, {}):
                row.setdefault("error_vs_ours", {})[impl] = relative_error(outputs[impl][name], outputs[OURS][name])
                row.setdefault("ratios", {})[f"{OURS}/{impl}"] = {
                    "by_min": row[OURS]["min_ns"] / row[impl]["min_ns"],
                    "by_median": row[OURS]["median_ns"] / row[impl]["median_ns"]}
        rows[name] = row
    return {"functions": rows, "rounds": rounds, "K": K, "target_ns_per_repetition": target_ns,
            "load_average_before": list(load_before), "load_average_after": list(load_after)}


def table(result: dict) -> str:
    lines = []
    for robot, entry in result["robots"].items():
        lines.append(f"{robot} (load {entry['load_average_before'][0]:.1f} -> {entry['load_average_after'][0]:.1f})")
        for name, row in entry["functions"].items():
            cells = [f"{impl} {s['min_ns']:.1f}/{s['median_ns']:.1f}" for impl, s in row.items()
                     if isinstance(s, dict) and "min_ns" in s]
            ratios = [f"{k} {v['by_min']:.2f}/{v['by_median']:.2f}" for k, v in row.get("ratios", {}).items()]
            lines.append(f"  {name:16s} " + "  ".join(cells) + "  |  " + "  ".join(ratios))
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", nargs="+", default=["lwr4", "panda"])
    parser.add_argument("--functions", nargs="+", default=list(DEFAULT_FUNCTIONS))
    parser.add_argument("--candidate", action="append", default=[], metavar="NAME=DIR",
                        help="another generated tree timed in the same rounds under NAME")
    parser.add_argument("--rounds", type=int, default=15, help="interleaved rounds (3 repetitions each)")
    parser.add_argument("--target-ns", type=float, default=2e6, help="length of one repetition")
    parser.add_argument("--K", type=int, default=200, help="inputs cycled through per function")
    parser.add_argument("--no-cpp", action="store_true", help="without Pinocchio C++")
    parser.add_argument("--no-peer", action="store_true",
                        help="without either Pinocchio (ours against the candidates only)")
    parser.add_argument("--out", type=Path, default=RESULTS / "head_to_head.json")
    args = parser.parse_args(argv)
    for robot in args.robots:
        if manifest(GENERATED / robot) is None or not (ROBOTS / f"{robot}.yaml").exists():
            print(f"error: --robots {robot}: no generated/{robot}/functions.json or robots/{robot}.yaml",
                  file=sys.stderr)
            return 2
    candidates = {}
    for text in args.candidate:
        name, sep, path = text.partition("=")
        if not sep or not (Path(path) / args.robots[0] / "functions.json").exists():
            print(f"error: --candidate {text}: expected NAME=DIR with DIR/<robot>/functions.json", file=sys.stderr)
            return 2
        candidates[name] = Path(path).resolve()
    result = {"machine": machine(), "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
              "flags": " ".join(compiled.C_FLAGS[OURS]), "candidates": {k: str(v) for k, v in candidates.items()},
              "robots": {}}
    for robot in args.robots:
        result["robots"][robot] = robot_run(robot, args.functions, candidates, args.rounds, args.K, args.target_ns,
                                            not args.no_peer, not (args.no_cpp or args.no_peer), BUILD / "head_to_head" / robot)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(strict_json(result, indent=1) + "\n")
    print(table(result))
    log(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
