"""IPOPT's options on the reach (kindyngen.control.reach.ReachNLP, the native stage library),
measured: the same NLP (cost, constraints, N, initial guess, tol 1e-8 and every other termination
option at IPOPT's defaults, as the Opti baseline), only how IPOPT moves its barrier changes.

    .venv/bin/python examples/reach_options.py [--robot lwr4] [--rounds 3] [--goals 10] [--out FILE.json]

Each option set of SWEEP is solved --rounds times, interleaved with the plain Opti baseline
(kindyngen.control.reach.solve_baseline) and the baseline given FAST's options; CPU times
(time.process_time), iterations, objective, the largest difference of the solution from the
first set's. --goals also solves the reach to that many goals (the task's and others uniform
within +-0.1 m of it) with IPOPT's defaults and with FAST: how many converge, in how many
iterations, at which objective. FAST (kindyngen.control.reach.FAST, ReachNLP's default) was chosen
this way: docs/optimal_control.md, "IPOPT's options".
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks import control_robots as cr  # noqa: E402
from kindyngen.control.reach import FAST, ReachNLP, solve_baseline  # noqa: E402

SWEEP = {
    "default": {},
    "mu_linear_decrease_factor 0.1": {"ipopt.mu_linear_decrease_factor": 0.1},
    "mu_init 1e-2": {"ipopt.mu_init": 1e-2},
    "adaptive (quality-function)": {"ipopt.mu_strategy": "adaptive"},
    "adaptive loqo": {"ipopt.mu_strategy": "adaptive", "ipopt.mu_oracle": "loqo"},
    "adaptive probing": {"ipopt.mu_strategy": "adaptive", "ipopt.mu_oracle": "probing"},
    "adaptive + affine corrector": {"ipopt.mu_strategy": "adaptive", "ipopt.corrector_type": "affine"},
    "FAST": FAST,
    "adaptive + affine, never-monotone": {"ipopt.mu_strategy": "adaptive", "ipopt.corrector_type": "affine",
                                          "ipopt.adaptive_mu_globalization": "never-monotone-mode"},
    "FAST + mumps_pivtol 1e-4": dict(FAST, **{"ipopt.mumps_pivtol": 1e-4}),
    "FAST + nlp_scaling none": dict(FAST, **{"ipopt.nlp_scaling_method": "none"}),
}


def _row(runs, ref=None):
    c = [r.solve_cpu_s for r in runs]
    out = {"status": runs[-1].status, "iterations": runs[-1].iterations, "objective": runs[-1].objective,
           "cpu_min_s": min(c), "cpu_median_s": float(np.median(c)), "cpu_runs_s": c}
    if ref is not None:
        out["max_abs_dz_vs_first"] = float(np.abs(runs[-1].z - ref).max())
    return out


def sweep(robot, task, rounds: int) -> dict:
    nlps = {k: ReachNLP(robot, task, ipopt=v, adaptive=False) for k, v in SWEEP.items()}
    runs = {k: [] for k in SWEEP}
    base, base_fast = [], []
    load0 = os.getloadavg()
    for _ in range(rounds):
        base.append(solve_baseline(robot, task))
        base_fast.append(solve_baseline(robot, task, FAST))
        for k, nlp in nlps.items():
            runs[k].append(nlp.solve())
    ref = runs["default"][-1].z
    return {"loadavg_start": list(load0), "rows": {k: _row(v, ref) for k, v in runs.items()},
            "baseline": _row(base), "baseline_fast": _row(base_fast), "loadavg_end": list(os.getloadavg())}


def goals(robot, task, count: int, spread: float = 0.1, seed: int = 1) -> dict:
    nlps = {"default": ReachNLP(robot, task, adaptive=False), "FAST": ReachNLP(robot, task)}
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(count):
        goal = np.asarray(task.goal) + (0.0 if i == 0 else spread) * rng.uniform(-1, 1, 3)
        r = {k: nlp.solve(goal=goal) for k, nlp in nlps.items()}
        rows.append({"goal": goal.tolist(), **{k: {"success": v.success, "iterations": v.iterations,
                                                   "objective": v.objective} for k, v in r.items()}})
    return {"rows": rows, "totals": {k: {"success": sum(r[k]["success"] for r in rows),
                                         "iterations": sum(r[k]["iterations"] for r in rows)} for k in nlps}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", choices=list(cr.ROBOTS), default="lwr4")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--goals", type=int, default=0, help="also the robustness check on this many goals")
    ap.add_argument("--out", help="write the JSON here")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    model, robot, limits, task = cr.load(args.robot)
    task = replace(task, inner=False)
    doc = sweep(robot, task, args.rounds)
    base = doc["baseline"]["cpu_median_s"]
    for k, r in list(doc["rows"].items()) + [("baseline", doc["baseline"]), ("baseline with FAST", doc["baseline_fast"])]:
        print(f"{k:36s} {r['status'][:16]:16s} it={r['iterations']:3d} CPU median {1e3 * r['cpu_median_s']:8.1f} ms "
              f"f={r['objective']:.6f} x{base / r['cpu_median_s']:.1f} (medians)")
    if args.goals:
        doc["goals"] = goals(robot, task, args.goals)
        print("goals:", doc["goals"]["totals"])
    print(f"load {doc['loadavg_start']} -> {doc['loadavg_end']}, {time.perf_counter() - t0:.0f} s")
    if args.out:
        Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
