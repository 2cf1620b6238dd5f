"""MPC of the reach in a closed loop against a Pinocchio plant (benchmarks/control_plant.py: the
arm's own Pinocchio model, RK4 at 1 kHz, sharing no code with the controller), on the LWR, the
Panda or the UR5, with kindyngen.control:

    .venv/bin/python examples/mpc.py [--robot lwr4] [--controller tracking|rti|resolve]
                                     [--disturbance none|noise|payload|push|mass|torque] [--out DIR]

Controllers:
  tracking  the tracking MPC (kindyngen/control/mpc.py: Gauss-Newton SQP on the condensed QP by
            DAQP, limits as rows with an exact penalty, a CPU budget per step) of the reach planned
            with margins (two RK4 steps per interval; 0.3 of every speed, 0.05 rad of every
            position and 0.1 of every torque limit kept free), every 50 ms, and the 1 kHz inner loop
            (kindyngen/control/closed_loop.py: state and disturbance estimates, PD between the
            nodes, the limit guard, fallback to the shifted plan, then the brake);
  rti       the same with one SQP iteration per step (the real-time iteration);
  resolve   the reach itself re-solved by IPOPT on the native library every 50 ms from the
            measured state (the goal at rest at the end of the receding 1 s horizon), warm-started
            from the solution and its constraint and bound multipliers shifted by one interval;
            its first torque held for the interval (no inner loop). --max-iter caps IPOPT's
            iterations (the capped iterate is applied); --no-bound-multipliers warm-starts without
            the bound multipliers (what the warm start was before they were shifted).
Disturbances (tracking, rti): none, noise (1e-4 rad, 1e-3 rad/s), payload (--payload kg at the
flange from 0.5 s; default 5), push (60 N at the flange, 0.4-0.7 s), mass (links 10 % heavier),
torque (80 % of joint --joint's limit, 0.4-0.7 s). resolve: a payload of --payload kg from the start.

Printed and written to DIR/mpc.json: the re-solve's CPU time per step (median, p95, p99, worst),
iterations, the plant's 1 kHz samples past a position, speed or torque limit, the flange's final
distance from the goal; for tracking and rti everything benchmarks/control_bench.py records per
case (the torque steps' admissibility and verdict, the limit guard's samples); DIR/mpc.png.

(Replaces examples/mpc.py's own copies for the LWR: --solver ipopt | stages (the reach re-solve
on the SX graph or the compiled id_rk4 stages), --solver sqp | rti (examples/mpc_sqp.py's tracking
MPC), and examples/mpc_warm_start.py; docs/optimal_control.md maps the old commands.)
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

from benchmarks import control_bench, control_robots as cr  # noqa: E402
from benchmarks.control_plant import Disturbance, PinocchioPlant  # noqa: E402
from kindyngen.control.integrators import Integrator  # noqa: E402
from kindyngen.control.reach import ReachNLP  # noqa: E402

TOL = 1e-6


class _Parser(argparse.ArgumentParser):
    def error(self, message):        # one error line, exit 2
        print(f"error: {message}", file=sys.stderr)
        raise SystemExit(2)


def disturbance(kind: str, limits, joint: int, payload: float) -> Disturbance:
    return {"none": Disturbance(), "noise": Disturbance("noise", noise=(1e-4, 1e-3), seed=1),
            "payload": Disturbance("payload", start=0.5, mass_kg=payload),
            "push": Disturbance("push", start=0.4, duration=0.3, force=(0.0, 60.0, 0.0)),
            "mass": Disturbance("mass_error", mass_scale=1.1),
            "torque": Disturbance("torque", start=0.4, duration=0.3, joint=joint,
                                  torque=0.8 * limits.tau_max[joint])}[kind]


def tracking(args, model, robot, limits, task):
    """control_bench's case: the reach with margins tracked by the MPC and the inner loop."""
    from kindyngen.control.mpc import MPCOptions
    rt = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3, margin_position=0.05,
                 margin_torque=0.1)
    res = ReachNLP(robot, rt).solve()
    if not res.success:
        raise SystemExit(f"the reference reach was not solved: {res.status}")
    ref = {"X": np.hstack([res.q, res.qd]), "U": res.tau, "goal": task.goal}
    options = MPCOptions(max_iter=1 if args.controller == "rti" else 10, budget_s=args.budget_ms * 1e-3)
    dist = disturbance(args.disturbance, limits, args.joint - 1, args.payload)
    return control_bench.mpc_case(args.robot, model, robot, limits, ref, args.disturbance, dist, False,
                                  options=options, duration=args.duration, keep_log=True)


def resolve(args, model, robot, limits, task):
    """The reach re-solved by IPOPT every interval from the measured state, warm-started."""
    nlp = ReachNLP(robot, task)
    warm = {"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6, "ipopt.warm_start_bound_push": 1e-6,
            "ipopt.warm_start_mult_bound_push": 1e-6}
    if args.max_iter:
        warm["ipopt.max_iter"] = args.max_iter
    warm_solver = nlp.build(dict(nlp.options, **warm))
    dist = Disturbance("payload", start=0.0, mass_kg=args.payload) if args.payload else Disturbance()
    plant = PinocchioPlant(args.robot, model, dist)
    n, h = robot.n, task.h
    per = int(round(h * 1000))
    x = np.concatenate([np.asarray(task.q0, float), np.zeros(n)])
    steps = int(round(args.duration / h))
    res, xs, taus, cpu, iters, statuses, tracking_err = None, [], [], [], [], [], []
    for i in range(steps):
        if res is None:
            res = nlp.solve(x)
        else:
            lam_g, lam_x = nlp.shifted_multipliers(res.lam_g, res.lam_x)
            last = res
            res = nlp.solve(x, z0=nlp.shifted(res.z), lam_g0=lam_g,
                            lam_x0=None if args.no_bound_multipliers else lam_x, solver=warm_solver)
            # a capped re-solve hands over its iterate; a failed one the previous plan's next torque
            if not (res.success or res.status == "Maximum_Iterations_Exceeded"):
                res = last
        cpu.append(1e3 * res.solve_cpu_s)
        iters.append(res.iterations)
        statuses.append(res.status)
        u = np.clip(res.tau[0], -limits.array("tau_max"), limits.array("tau_max"))
        for s in range(per):
            x = plant.step(x, u, 1e-3, i * h + s * 1e-3)
            xs.append(x)
            taus.append(u)
        tracking_err.append(float(np.linalg.norm(x - np.concatenate([res.q[1], res.qd[1]]))))
    X = np.array(xs)
    q, qd = X[:, :n], X[:, n:]
    warm_cpu = np.array(cpu[1:])
    return {"case": f"reach re-solved every {1e3 * h:g} ms", "disturbance": dist.__dict__,
            "violations": {"q": int(np.sum(np.any((q > limits.array("q_hi") + TOL) | (q < limits.array("q_lo") - TOL), 1))),
                           "qd": int(np.sum(np.any(np.abs(qd) > limits.array("qd_max") + TOL, 1))),
                           "tau": int(np.sum(np.any(np.abs(np.array(taus)) > limits.array("tau_max") + TOL, 1)))},
            "resolve_cpu_ms": {"median": float(np.median(warm_cpu)), "p95": float(np.percentile(warm_cpu, 95)),
                               "p99": float(np.percentile(warm_cpu, 99)), "worst": float(warm_cpu.max())},
            "first_solve_cpu_ms": cpu[0], "iterations": {"median": float(np.median(iters[1:])), "max": int(max(iters[1:]))},
            "statuses": sorted(set(statuses)), "tracking_rms": float(np.sqrt(np.mean(np.square(tracking_err)))),
            "goal_error_final_mm": 1e3 * float(np.linalg.norm(plant.flange(q[-1]) - np.asarray(task.goal))),
            "cpu_ms": cpu, "log": {"x": X, "tau": np.array(taus)}}


def plot(doc, limits, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    X = np.asarray(doc["log"]["x"])
    n = X.shape[1] // 2
    t = np.arange(1, len(X) + 1) * 1e-3
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for j in range(n):
        axes[0].plot(t, X[:, j], lw=1, label=f"q{j + 1}")
        axes[1].plot(t, X[:, n + j] / limits.qd_max[j], lw=1)
        axes[2].plot(t, np.asarray(doc["log"]["tau"])[:, j] / limits.tau_max[j], lw=1)
    axes[0].set_ylabel("q [rad]")
    axes[1].set_ylabel("qd / qd_max")
    axes[2].set_ylabel("tau / tau_max")
    axes[2].set_xlabel("t [s]")
    axes[0].legend(fontsize=7, ncol=7)
    r = doc["resolve_cpu_ms"]
    axes[0].set_title(f"{doc['case']}: re-solve CPU median {r['median']:.2f} ms, p99 {r['p99']:.2f} ms; limit samples "
                      f"{doc['violations']}", fontsize=9)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = _Parser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                 epilog="\n\n".join(__doc__.split("\n\n")[2:]))
    ap.add_argument("--robot", choices=list(cr.ROBOTS), default="lwr4")
    ap.add_argument("--controller", choices=("tracking", "rti", "resolve"), default="tracking")
    ap.add_argument("--disturbance", choices=("none", "noise", "payload", "push", "mass", "torque"), default="payload")
    ap.add_argument("--joint", type=int, default=2, help="torque: the joint (1-based, default 2)")
    ap.add_argument("--payload", type=float, default=None,
                    help="payload: kg at the flange (default 5 for tracking and rti, 0 for resolve)")
    ap.add_argument("--duration", type=float, default=None, help="s (default 2.5; resolve 1.0)")
    ap.add_argument("--budget-ms", type=float, default=10.0, help="tracking, rti: CPU budget per re-solve (default 10)")
    ap.add_argument("--max-iter", type=int, default=None, help="resolve: cap on IPOPT's iterations per re-solve")
    ap.add_argument("--no-bound-multipliers", action="store_true", help="resolve: warm start without the bound multipliers")
    ap.add_argument("--out", help="folder for mpc.json and mpc.png (created)")
    args = ap.parse_args(argv)
    if not cr.available(args.robot):
        ap.error(f"--robot {args.robot}: {cr.ROBOTS[args.robot].description} is not installed")
    if args.max_iter is not None and args.max_iter < 1:
        ap.error(f"--max-iter {args.max_iter}: at least 1")
    if args.duration is not None and not args.duration > 0:
        ap.error(f"--duration {args.duration}: must be positive")
    if args.payload is not None and args.payload < 0:
        ap.error(f"--payload {args.payload}: at least 0")
    if not args.budget_ms > 0:
        ap.error(f"--budget-ms {args.budget_ms}: must be positive")
    model, robot, limits, task = cr.load(args.robot)
    if not 1 <= args.joint <= robot.n:
        ap.error(f"--joint {args.joint}: 1 to {robot.n}")
    if args.controller == "resolve":
        args.payload = 0.0 if args.payload is None else args.payload
        args.duration = args.duration or 1.0
        t0 = time.perf_counter()
        doc = resolve(args, model, robot, limits, task)
        print(f"{args.robot} reach re-solve: CPU median {doc['resolve_cpu_ms']['median']:.1f} ms, p95 "
              f"{doc['resolve_cpu_ms']['p95']:.1f} ms, worst {doc['resolve_cpu_ms']['worst']:.1f} ms (first "
              f"{doc['first_solve_cpu_ms']:.0f} ms), IPOPT iterations {doc['iterations']}; limit samples "
              f"{doc['violations']}; flange {doc['goal_error_final_mm']:.2f} mm from the goal ({time.perf_counter() - t0:.0f} s)")
    else:
        args.payload = 5.0 if args.payload is None else args.payload
        args.duration = args.duration or 2.5
        doc = tracking(args, model, robot, limits, task)
        print(doc["verdict"])
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        plot(doc, limits, out / "mpc.png")
        doc = {k: v for k, v in doc.items() if k != "log"}
        doc.update(robot=args.robot, controller=args.controller, machine=control_bench.machine(),
                   uptime=control_bench.uptime())
        (out / "mpc.json").write_text(json.dumps(doc, indent=1, default=float) + "\n")
        print(f"wrote {out / 'mpc.json'}, {out / 'mpc.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
