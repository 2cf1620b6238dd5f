"""The reach by the exact-Hessian SQP (kindyngen/control/reach_sqp.py) from three starts: the
measurements behind docs/optimal_control.md's "Exact-Hessian SQP" section, on any arm of
benchmarks/control_robots.py (default the LWR, the issue's reach; limits at the nodes).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.reach_sqp [--robot lwr4] [--out benchmarks/results/reach_sqp.json]

Rows (CPU time by time.process_time, one BLAS thread; medians of --repeats solves):
- from IPOPT's solution (kindyngen.control.reach.ReachNLP) with its gap multipliers (local
  convergence), its plan checked by Pinocchio (benchmarks/control_bench.py plan_check);
- from that solution shifted by one interval with the start at its node 1 (the receding-horizon
  re-solve), against IPOPT's warm re-solve of the same shift;
- cold from the task's start (rest, gravity torques): the filter globalisation with (beta0,
  sigma0) = (1, 0) and (0.1, 1e-2), and the elastic Sl1QP with rho = 5e3.
"""
from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks import control_bench as cb, control_robots as cr  # noqa: E402
from kindyngen.control.reach import ReachNLP  # noqa: E402
from kindyngen.control.reach_sqp import ReachSQP  # noqa: E402
from kindyngen.json_text import strict_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _plain(x):
    return x.tolist() if isinstance(x, np.ndarray) else float(x)


def _row(name, runs):
    r = runs[-1]
    cpu = [x.solve_cpu_s for x in runs]
    return {"variant": name, "status": r.status, "iterations": r.iterations, "solve_cpu_s": float(np.median(cpu)),
            "solve_cpu_s_runs": cpu, "ms_per_iteration": 1e3 * float(np.median(cpu)) / max(r.iterations, 1),
            "objective": r.objective, "kkt": r.kkt, "trace": r.log}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", choices=list(cr.ROBOTS), default="lwr4")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "reach_sqp.json"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--max-iter", type=int, default=80, help="iteration cap of the cold SQP runs")
    args = ap.parse_args(argv)
    model, robot, limits, task = cr.load(args.robot)
    task = replace(task, inner=False)
    doc = {"machine": cb.machine(), "uptime_start": cb.uptime(), "robot": args.robot,
           "problem": f"reach N = {task.N}, T = {task.T} s, limits at the nodes (benchmarks/control_robots.py)",
           "rows": []}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    nlp = ReachNLP(robot, task)
    ref = nlp.solve()
    doc["ipopt"] = {"iterations": ref.iterations, "objective": ref.objective, "solve_cpu_s": ref.solve_cpu_s}
    print(f"ipopt (native): {ref.iterations} iterations, objective {ref.objective:.4f}", flush=True)
    solver = ReachSQP(robot, task, tol_du=1e-5, max_iter=30)
    mu = solver.gap_multipliers(nlp, ref)
    X, U = np.hstack([ref.q, ref.qd]), ref.tau

    # local convergence: from IPOPT's solution and gap multipliers
    runs = [solver.solve(X0=X, U0=U, mu0=mu) for _ in range(args.repeats)]
    row = _row("sqp from IPOPT's solution", runs)
    row["check"] = cb.plan_check(args.robot, model, task, runs[-1])
    doc["rows"].append(row)
    print(row["variant"], row["status"], row["iterations"], f"{row['solve_cpu_s']:.3f}s", row["objective"], flush=True)

    # the warm re-solve: shifted by one interval (the appended interval at rest, gravity torque)
    z, L = nlp.shifted(ref.z), nlp.layout
    Xs = np.array([z[k * L.nw:k * L.nw + L.nx] for k in range(task.N + 1)])
    Us = np.array([z[k * L.nw + L.nx:(k + 1) * L.nw] for k in range(task.N)])
    x1 = Xs[0]
    runs = [solver.solve(x_init=x1, X0=Xs, U0=Us, mu0=np.vstack([mu[1:], mu[-1:]])) for _ in range(args.repeats)]
    row = _row("sqp warm re-solve (shifted by one interval)", runs)
    warm = nlp.build(dict(nlp.options, **{"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                                        "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6}))
    lam_g, lam_x = nlp.shifted_multipliers(ref.lam_g, ref.lam_x)
    r = nlp.solve(x1, z0=z, lam_g0=lam_g, lam_x0=lam_x, solver=warm)
    row["ipopt_warm_resolve"] = {"iterations": r.iterations, "objective": r.objective, "solve_cpu_s": r.solve_cpu_s}
    doc["rows"].append(row)
    print(row["variant"], row["status"], row["iterations"], f"{row['solve_cpu_s']:.3f}s", row["objective"],
          "ipopt:", row["ipopt_warm_resolve"], flush=True)

    # cold, the task's start
    for name, kw in (("sqp cold, filter, beta0 1, sigma0 0", {}),
                     ("sqp cold, filter, beta0 0.1, sigma0 1e-2", {"beta0": 0.1, "sigma0": 1e-2}),
                     ("sqp cold, Sl1QP, rho 5e3", {"rho": 5e3})):
        r = ReachSQP(robot, task, max_iter=args.max_iter, **kw).solve()
        doc["rows"].append(_row(name, [r]))
        print(name, r.status, r.iterations, f"{r.solve_cpu_s:.3f}s", f"f={r.objective:.2f}", r.kkt, flush=True)
        out.write_text(strict_json(doc, indent=1, default=_plain) + "\n")
    doc["uptime_end"] = cb.uptime()
    doc["finished"] = time.strftime("%Y-%m-%d %H:%M:%S")
    out.write_text(strict_json(doc, indent=1, default=_plain) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
