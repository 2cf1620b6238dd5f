"""The reach (start at rest, flange to a goal, at rest after T; minimum h sum |tau|^2 under the
joint limits) on the LWR, the Panda or the UR5 (benchmarks/control_robots.py) by any of
kindyngen.control's solvers, each plan checked by Pinocchio.

    .venv/bin/python examples/ocp_reach.py [--robot lwr4|panda|ur5] [--solver native baseline ...]
                                           [--N 20] [--T 1.0] [--substeps 1] [--out DIR]

Solvers (kindyngen/control/reach.py, reach_sqp.py):
  native           IPOPT on the native stage library (constraints, Jacobian and exact Hessian in C
                   over the generated fd, fd_derivatives, tau), IPOPT's adaptive barrier (the default)
  native-monotone  the same with IPOPT's default (monotone) barrier
  baseline         Opti + IPOPT with fd on MX symbols, IPOPT's defaults: what a new user writes
  sx               IPOPT on the same NLP as one SX graph (CasADi's AD)
  inverse-dynamics the stage accelerations as unknowns tied by the generated tau (SX graph, IPOPT)
  fatrop           fatrop (structure declared by hand) on the SX graph, to tol 1e-4 (its dual
                   residual stalls above that at N = 20: kindyngen.control.reach.solve_fatrop)
  fatrop-inverse-dynamics  fatrop on the inverse-dynamics form's SX graph, to tol 1e-6
  sqp              the exact-Hessian SQP (DAQP on the condensed QP), from the native solution
                   shifted by one interval, the start moved to its node 1 (the receding-horizon
                   re-solve; from the cold start it does not converge)
The LWR's task is the issue's (q0 = (0, .5, 0, -1, 0, 0, 0), goal (0.35, 0.25, 0.55) m, the data
sheet's speeds, torques 176/176/100/100/100/30/30 N m); the Panda's and the UR5's goal is their
start flange moved by a fixed offset.

Pinocchio's checks of each plan (the arm's own Pinocchio model, sharing no code with ours):
plan_step_error (from each node the plan's RK4 steps of pin.aba against the next node),
resim_error (the torques applied to pin.aba with 20 RK4 steps per interval: the discretisation's
own error, at the nodes), the flange's distance from the goal after that re-simulation, and the
limits' excess at the nodes. --out writes ocp.json (one entry per solver: status, iterations,
solve CPU, objective, the checks, t, q, qd, tau) and joints.png of the first solver's plan.

(The example scripts this replaces kept their own copies of the machinery for the LWR alone:
examples/ocp.py --problem lwr4_reach with its formulations, ocp_stages.py, ocp_fd_stages.py
with fd_stages_nlp.c, ocp_fatrop.py, ocp_sqp.py; docs/optimal_control.md maps the old commands.)
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks import control_robots as cr  # noqa: E402
from benchmarks.control_bench import plan_check, resimulation  # noqa: E402
from kindyngen.control import reach  # noqa: E402
from kindyngen.control.integrators import Integrator  # noqa: E402

SOLVERS = ("native", "native-monotone", "baseline", "sx", "inverse-dynamics", "fatrop", "fatrop-inverse-dynamics", "sqp")


class _Parser(argparse.ArgumentParser):
    def error(self, message):        # one error line, exit 2
        print(f"error: {message}", file=sys.stderr)
        raise SystemExit(2)


def solve(name: str, robot, task):
    """One solver's result (a ReachResult, or the SQP's result with the same fields)."""
    if name == "native":
        return reach.ReachNLP(robot, task).solve()
    if name == "native-monotone":
        return reach.ReachNLP(robot, task, adaptive=False).solve()
    if name == "baseline":
        return reach.solve_baseline(robot, task)
    if name == "sx":
        return reach.solve_sx(robot, task)
    if name == "inverse-dynamics":
        return reach.inverse_dynamics_reach(robot, task)
    if name == "fatrop":
        return reach.solve_fatrop(robot, task)
    if name == "fatrop-inverse-dynamics":
        return reach.solve_fatrop(robot, task, formulation="inverse-dynamics")
    from kindyngen.control.reach_sqp import ReachSQP
    task = replace(task, inner=False)
    nlp = reach.ReachNLP(robot, task)
    res = nlp.solve()
    sqp = ReachSQP(robot, task, tol_du=1e-5, max_iter=30)
    mu = sqp.gap_multipliers(nlp, res)
    z, L = nlp.shifted(res.z), nlp.layout
    X = np.array([z[k * L.nw:k * L.nw + L.nx] for k in range(task.N + 1)])
    U = np.array([z[k * L.nw + L.nx:(k + 1) * L.nw] for k in range(task.N)])
    return sqp.solve(x_init=np.concatenate([res.q[1], res.qd[1]]), X0=X, U0=U, mu0=np.vstack([mu[1:], mu[-1:]]))


def plot(res, task, limits, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for j in range(res.q.shape[1]):
        axes[0].plot(res.t, res.q[:, j], "o-", ms=2.5, label=f"q{j + 1}")
        axes[1].plot(res.t, res.qd[:, j] / limits.qd_max[j], "o-", ms=2.5)
        axes[2].step(res.t[:-1], res.tau[:, j] / limits.tau_max[j], where="post")
    axes[0].set_ylabel("q [rad]")
    axes[1].set_ylabel("qd / qd_max")
    axes[2].set_ylabel("tau / tau_max")
    axes[2].set_xlabel("t [s]")
    axes[0].legend(fontsize=7, ncol=7)
    axes[0].set_title(f"reach, N = {task.N}, objective {res.objective:.4f}", fontsize=9)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = _Parser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                 epilog="\n\n".join(__doc__.split("\n\n")[2:]))
    ap.add_argument("--robot", choices=list(cr.ROBOTS), default="lwr4")
    ap.add_argument("--solver", nargs="+", choices=SOLVERS, default=["native"],
                    help="one or more solvers, compared in the order given (CPU time ratio to the first)")
    ap.add_argument("--N", type=int, default=20, help="shooting intervals (default 20)")
    ap.add_argument("--T", type=float, default=1.0, help="duration in s (default 1)")
    ap.add_argument("--substeps", type=int, default=1, help="RK4 steps per interval (default 1)")
    ap.add_argument("--out", help="folder for ocp.json and joints.png (created)")
    args = ap.parse_args(argv)
    if args.N < 2:
        ap.error(f"--N {args.N}: at least 2")
    if args.substeps < 1:
        ap.error(f"--substeps {args.substeps}: at least 1")
    if not args.T > 0:
        ap.error(f"--T {args.T}: must be positive")
    if not cr.available(args.robot):
        ap.error(f"--robot {args.robot}: {cr.ROBOTS[args.robot].description} is not installed")
    model, robot, limits, task = cr.load(args.robot)
    task = replace(task, N=args.N, T=args.T, integrator=Integrator("rk4", args.substeps))
    rows, first = [], None
    for name in args.solver:
        res = solve(name, robot, task)
        check = plan_check(args.robot, model, task, res)
        check.update(resimulation(args.robot, model, task, res))
        first = first or res
        ratio = first.solve_cpu_s / res.solve_cpu_s
        print(f"{name:17s} {res.status:24s} {res.iterations:4d} it {res.solve_cpu_s:8.4f} s CPU  objective "
              f"{res.objective:.4f}  x{1 / ratio:.1f} the first's CPU;  Pinocchio: plan step error "
              f"{check['plan_step_error']:.1e}, goal {check['goal_error_m']:.1e} m, re-simulated {args.N} x 20 RK4 "
              f"steps: {check['resim_error']:.2e}, flange {1e3 * check['resim_goal_error_m']:.2f} mm from the goal")
        rows.append({"solver": name, "status": res.status, "success": res.success, "iterations": res.iterations,
                     "solve_cpu_s": res.solve_cpu_s, "objective": res.objective, **check, "t": res.t.tolist(),
                     "q": res.q.tolist(), "qd": res.qd.tolist(), "tau": res.tau.tolist()})
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        doc = {"robot": args.robot, "q0": list(task.q0), "goal": list(task.goal), "N": task.N, "T": task.T,
               "integrator": task.integrator.tag, "limits": limits.__dict__, "rows": rows}
        (out / "ocp.json").write_text(json.dumps(doc, indent=1, default=float) + "\n")
        plot(first, task, limits, out / "joints.png")
        print(f"wrote {out / 'ocp.json'}, {out / 'joints.png'}")
    return 0 if all(r["success"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
