"""The LWR reach (examples/ocp_reach.py) by the exact-Hessian SQP of examples/ocp_sqp.py from
three starts, and IPOPT's barrier options on the compiled stages (examples/ocp_stages.py):
the measurements behind docs/optimal_control.md's "Exact-Hessian SQP" section.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.reach_sqp [--out benchmarks/results/reach_sqp.json]

Rows (CPU time by time.process_time, one BLAS thread; medians of --repeats solves):
- sqp from IPOPT's fd_rk4 solution with its gap multipliers (local convergence), its plan
  checked by Pinocchio (ocp_reach.check);
- sqp from that solution shifted by one interval (the MPC's warm re-solve), against IPOPT's
  re-solve of fd_rk4 from the same shift;
- sqp cold from the issue's start (rest, gravity torques): filter globalisation with
  (beta0, sigma0) = (1, 0) and (0.1, 1e-2), and the elastic Sl1QP with rho = 5e3;
- IPOPT on the compiled stages (id_rk4) with barrier options (iterations, CPU, objective).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from kindyngen.json_text import strict_json

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))
import ocp_reach  # noqa: E402
import ocp_sqp  # noqa: E402
import ocp_stages  # noqa: E402
from benchmarks.ocp_bench import _machine  # noqa: E402

IPOPT_OPTIONS = {
    "default (monotone, mu_init 0.1)": {},
    "adaptive, quality-function": {"ipopt.mu_strategy": "adaptive"},
    "adaptive, probing": {"ipopt.mu_strategy": "adaptive", "ipopt.mu_oracle": "probing"},
    "adaptive, loqo": {"ipopt.mu_strategy": "adaptive", "ipopt.mu_oracle": "loqo"},
    "adaptive, mu_init 1e-2": {"ipopt.mu_strategy": "adaptive", "ipopt.mu_init": 1e-2},
    "monotone, mu_init 1e-3": {"ipopt.mu_init": 1e-3},
    "monotone, mu_linear_decrease_factor 0.05": {"ipopt.mu_linear_decrease_factor": 0.05},
    "tol 1e-6": {"ipopt.tol": 1e-6},
    "nlp_scaling_method none": {"ipopt.nlp_scaling_method": "none"},
    "bound_push = bound_frac = 1e-4": {"ipopt.bound_push": 1e-4, "ipopt.bound_frac": 1e-4},
}


def _plain(x):
    return x.tolist() if isinstance(x, np.ndarray) else float(x)


def _sqp_row(name, runs):
    r = runs[-1]
    return {"variant": name, "status": r["status"], "iterations": r["iterations"],
            "solve_cpu_s": float(np.median([x["solve_cpu_s"] for x in runs])),
            "solve_cpu_s_runs": [x["solve_cpu_s"] for x in runs],
            "ms_per_iteration": 1e3 * float(np.median([x["solve_cpu_s"] for x in runs])) / max(r["iterations"], 1),
            "objective": r["objective"], "kkt": r["kkt"],
            "trace": [{k: v for k, v in e.items()} for e in r["log"]]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "reach_sqp.json"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--max-iter", type=int, default=80, help="iteration cap of the cold SQP runs")
    args = ap.parse_args(argv)
    doc = {"machine": _machine(), "cores": len(os.sched_getaffinity(0)), "loadavg_start": list(os.getloadavg()),
           "problem": "lwr4_reach N = 20 (examples/ocp_reach.py), fd_rk4's KKT points", "rows": []}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    funcs = ocp_reach.load()
    setup = ocp_reach.setup_dict(funcs)
    N, n = 20, setup["n"]
    nlp = ocp_reach.reach_problem("fd_rk4", "ipopt", funcs=funcs)
    ref = nlp.solve()
    doc["ipopt_fd_rk4"] = {"iterations": ref["iterations"], "objective": ref["objective"],
                           "solve_cpu_s": ref["solve_cpu_s"]}
    print(f"ipopt fd_rk4: {ref['iterations']} iterations, objective {ref['objective']:.4f}", flush=True)
    X, U, mu = ocp_sqp.ipopt_start(ref, N, n)

    def sqp(**kw):
        return ocp_sqp.ReachSQP(N, funcs=funcs, **kw)

    # local convergence: from IPOPT's solution and gap multipliers
    solver = sqp(tol_du=1e-5, max_iter=30)
    runs = [solver.solve(X0=X, U0=U, mu0=mu) for _ in range(args.repeats)]
    row = _sqp_row("sqp from IPOPT's solution", runs)
    row["check"] = {k: v for k, v in ocp_reach.check(setup, runs[-1], funcs).items()
                    if k in ("plan_step_error", "resim_error", "resim_goal_error_m", "limit_excess")}
    doc["rows"].append(row)
    print(row["variant"], row["status"], row["iterations"], f"{row['solve_cpu_s']:.3f}s", row["objective"],
          row["check"], flush=True)

    # the warm re-solve: shifted by one interval (appended interval at rest, gravity torque)
    xN = X[-1]
    g = np.array(funcs["tau"](xN[:n], np.zeros(n), np.zeros(n))).ravel()
    Xs, Us, mus = np.vstack([X[1:], xN]), np.vstack([U[1:], g]), np.vstack([mu[1:], mu[-1:]])
    runs = [solver.solve(x_init=Xs[0], X0=Xs, U0=Us, mu0=mus) for _ in range(args.repeats)]
    row = _sqp_row("sqp warm re-solve (shifted by one interval)", runs)
    resolve = nlp.solve(x_init=Xs[0], z0=nlp.shifted(ref["z"]))
    row["ipopt_fd_rk4_resolve"] = {"iterations": resolve["iterations"], "objective": resolve["objective"],
                                   "solve_cpu_s": resolve["solve_cpu_s"]}
    doc["rows"].append(row)
    print(row["variant"], row["status"], row["iterations"], f"{row['solve_cpu_s']:.3f}s", row["objective"],
          "ipopt:", row["ipopt_fd_rk4_resolve"], flush=True)

    # cold, the start
    for name, kw in (("sqp cold, filter, beta0 1, sigma0 0", {}),
                     ("sqp cold, filter, beta0 0.1, sigma0 1e-2", {"beta0": 0.1, "sigma0": 1e-2}),
                     ("sqp cold, Sl1QP, rho 5e3", {"rho": 5e3})):
        r = sqp(max_iter=args.max_iter, **kw).solve()
        row = _sqp_row(name, [r])
        doc["rows"].append(row)
        print(name, r["status"], r["iterations"], f"{r['solve_cpu_s']:.3f}s", f"f={r['objective']:.2f}", r["kkt"],
              flush=True)
        out.write_text(strict_json(doc, indent=1, default=_plain) + "\n")

    # IPOPT's barrier options on the compiled stages
    stages = ocp_stages.StageReach(N, funcs)
    doc["ipopt_stages_options"] = []
    for name, opts in IPOPT_OPTIONS.items():
        built = stages.ipopt(opts)
        runs = [stages.solve_ipopt(built) for _ in range(args.repeats)]
        r = runs[-1]
        doc["ipopt_stages_options"].append({"options": name, "status": r["status"], "iterations": r["iterations"],
                                            "solve_cpu_s": float(np.median([x["solve_cpu_s"] for x in runs])),
                                            "objective": r["objective"]})
        print(f"ipopt stages {name:42s} {r['status']} it={r['iterations']} "
              f"cpu={doc['ipopt_stages_options'][-1]['solve_cpu_s']:.3f} f={r['objective']:.4f}", flush=True)
    doc["loadavg_end"] = list(os.getloadavg())
    doc["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
    out.write_text(strict_json(doc, indent=1, default=_plain) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
