"""IPOPT's options for the fd_rk4 reach of examples/ocp_fd_stages.py, chosen by measurement:
fewer iterations on the same NLP (same cost, constraints, N, initial guess, tol 1e-8 and every
other termination option at IPOPT's defaults, as the Opti baseline), the same optimum.

The default (monotone Fiacco-McCormick barrier from mu = 0.1) spends its first 24 of 45
iterations at mu = 0.1, with a restoration phase at iteration 6, before the barrier starts to
fall. IPOPT's adaptive barrier (mu_strategy adaptive: mu chosen anew at every iteration, the
centring parameter minimising a quality function of the linearised KKT error; Nocedal,
Waechter and Waltz 2009) with the
affine-scaling corrector and at most 4 golden-section steps of the quality function search
(default 8) reaches the same KKT point (objective 716.662, |z - z_default| 2e-4) in 23
iterations, at ~0.4 ms more per iteration (the corrector's and the quality function's extra
back-solves with the same factorisation). Its globalisation (obj-constr-filter, which falls
back to the monotone mode when the adaptive one stops making progress) is IPOPT's default.

On 10 goals around the reach's (+-0.1 m, `--goals`), this option set converged on all 10 in 317
iterations in total against 1040 for the default (which stopped infeasible on one goal), ending
at an equal or lower local optimum on every goal. The 4 section steps are N = 20's choice: at
N = 40 FAST takes 69 iterations against 56 for the defaults and 44 with IPOPT's 8 section steps
(at N = 10: 37, 60, 49). What did not pay (docs/optimal_control.md
has the tables): MUMPS's options (pivot tolerance, orderings, scalings), SPRAL, NLP scaling
none, bound_push, mu_init, barrier_tol_factor, the cg-penalty line search, least-squares duals,
mehrotra_algorithm.

    PYTHONPATH=. python examples/ocp_fd_options.py [--rounds 3] [--goals 10]

times the Opti baseline and each option set of SWEEP, interleaved, by CPU time; --goals runs the
robustness check.

Worked example::

    >>> import ocp_fd_stages, ocp_fd_options                                      # doctest: +SKIP
    >>> s = ocp_fd_stages.FdStageReach(20)                                         # doctest: +SKIP
    >>> r = s.solve_ipopt(s.ipopt(ocp_fd_options.FAST))                            # doctest: +SKIP
    >>> r["status"], r["iterations"], round(r["objective"], 3)                     # doctest: +SKIP
    ('Solve_Succeeded', 23, 716.662)
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

FAST = {"ipopt.mu_strategy": "adaptive", "ipopt.mu_oracle": "quality-function", "ipopt.corrector_type": "affine",
        "ipopt.quality_function_max_section_steps": 4}

# what was measured (docs/optimal_control.md, "IPOPT's options for fd_stages"); keys without
# the "ipopt." prefix
SWEEP = {
    "default": {},
    "mu_linear_decrease_factor 0.1": {"mu_linear_decrease_factor": 0.1},
    "mu_init 1e-2": {"mu_init": 1e-2},
    "adaptive (quality-function)": {"mu_strategy": "adaptive"},
    "adaptive loqo": {"mu_strategy": "adaptive", "mu_oracle": "loqo"},
    "adaptive probing": {"mu_strategy": "adaptive", "mu_oracle": "probing"},
    "adaptive + affine corrector": {"mu_strategy": "adaptive", "corrector_type": "affine"},
    "FAST": {k[len("ipopt."):]: v for k, v in FAST.items()},
    "adaptive + affine, never-monotone": {"mu_strategy": "adaptive", "corrector_type": "affine",
                                          "adaptive_mu_globalization": "never-monotone-mode"},
    "FAST + mumps_pivtol 1e-4": dict({k[len("ipopt."):]: v for k, v in FAST.items()}, mumps_pivtol=1e-4),
    "FAST + mumps_pivot_order 0 (AMD)": dict({k[len("ipopt."):]: v for k, v in FAST.items()}, mumps_pivot_order=0),
    "FAST + nlp_scaling none": dict({k[len("ipopt."):]: v for k, v in FAST.items()}, nlp_scaling_method="none"),
}


def _ipopt(opts: dict) -> dict:
    return {k if k.startswith("ipopt.") else "ipopt." + k: v for k, v in opts.items()}


def sweep(rounds: int = 3, sets: dict | None = None, baseline: bool = True, baseline_fast: bool = True) -> dict:
    """Each option set on FdStageReach(20), `rounds` times, interleaved with the Opti baseline
    (default options, and FAST's if baseline_fast); CPU times (time.process_time)."""
    import ocp_fd_stages
    import ocp_reach
    funcs = ocp_reach.load()
    s = ocp_fd_stages.FdStageReach(20, funcs)
    sets = SWEEP if sets is None else sets
    built = {k: s.ipopt(_ipopt(v)) for k, v in sets.items()}
    out = {k: [] for k in sets}
    base, base_fast = [], []
    load0 = os.getloadavg()
    for _ in range(rounds):
        if baseline:
            base.append(ocp_reach.solve_baseline(funcs=funcs))
        if baseline_fast:
            base_fast.append(ocp_reach.solve_baseline(funcs=funcs, ipopt_options=FAST))
        for k in sets:
            out[k].append(s.solve_ipopt(built[k]))
    ref = out[next(iter(out))][-1]["z"]

    def row(runs, z=True):
        c = [r["solve_cpu_s"] for r in runs]
        d = {"status": runs[-1]["status"], "iterations": runs[-1]["iterations"], "objective": runs[-1]["objective"],
             "cpu_min_s": min(c), "cpu_median_s": float(np.median(c)), "cpu_runs_s": c}
        if z:
            d["max_abs_dz_vs_first"] = float(np.abs(runs[-1]["z"] - ref).max())
        return d
    doc = {"loadavg_start": list(load0), "rows": {k: row(v) for k, v in out.items()}}
    if base:
        doc["baseline"] = row(base, False)
    if base_fast:
        doc["baseline_fast"] = row(base_fast, False)
    doc["loadavg_end"] = list(os.getloadavg())
    return doc


def goals(n_goals: int = 10, spread: float = 0.1, sets: dict | None = None, seed: int = 1) -> dict:
    """The reach to n_goals goals (the first the reach's own, the others uniform within +-spread
    m of it), each option set: status, iterations, objective."""
    import ocp_fd_stages
    s = ocp_fd_stages.FdStageReach(20)
    sets = sets or {"default": {}, "FAST": FAST}
    built = {k: s.ipopt(_ipopt(v)) for k, v in sets.items()}
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n_goals):
        goal = s.setup["goal"] + (0.0 if i == 0 else spread) * rng.uniform(-1, 1, 3)
        r = {k: s.solve_ipopt(built[k], goal=goal) for k in sets}
        rows.append({"goal": goal.tolist(), **{k: {"success": v["success"], "iterations": v["iterations"],
                                                   "objective": v["objective"]} for k, v in r.items()}})
    return {"rows": rows, "totals": {k: {"success": sum(r[k]["success"] for r in rows),
                                         "iterations": sum(r[k]["iterations"] for r in rows)} for k in sets}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--goals", type=int, default=0, help="also the robustness check on this many goals")
    ap.add_argument("--out", help="write the JSON here")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    doc = sweep(args.rounds)
    for k, r in doc["rows"].items():
        print(f"{k:36s} {r['status'][:16]:16s} it={r['iterations']:3d} cpu min={1e3 * r['cpu_min_s']:6.1f} ms "
              f"median={1e3 * r['cpu_median_s']:6.1f} ms f={r['objective']:.6f} dz={r['max_abs_dz_vs_first']:.1e}"
              f" x{doc['baseline']['cpu_median_s'] / r['cpu_median_s']:.1f} (medians)")
    for k in ("baseline", "baseline_fast"):
        r = doc[k]
        print(f"{k:36s} {r['status'][:16]:16s} it={r['iterations']:3d} cpu min={r['cpu_min_s']:.3f} s "
              f"median={r['cpu_median_s']:.3f} s f={r['objective']:.6f}")
    if args.goals:
        doc["goals"] = goals(args.goals, sets={"default": {}, "FAST": FAST})
        for g in doc["goals"]["rows"]:
            print(np.round(g["goal"], 3), {k: (v["success"], v["iterations"], round(v["objective"], 3))
                                           for k, v in g.items() if k != "goal"})
        print("totals", doc["goals"]["totals"])
    print(f"load {doc['loadavg_start']} -> {doc['loadavg_end']}, {time.perf_counter() - t0:.0f} s")
    if args.out:
        import json
        with open(args.out, "w") as fh:
            json.dump(doc, fh, indent=1)
            fh.write("\n")


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    main()
