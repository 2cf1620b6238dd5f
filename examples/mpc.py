"""Closed-loop model-predictive control of the LWR reach (and, with --solver sqp or rti, of a
Panda motion): the receding-horizon problem of
examples/ocp_reach.py re-solved at every control step, warm-started by the shifted solution,
while a plant that shares no code with the generator (Pinocchio's ABA on tests/reference.py's
model, RK4 at 1 kHz) moves the arm.

    .venv/bin/python examples/mpc.py --problem lwr4 --out /tmp/mpc_lwr4 [--steps 30]

Each control step (one shooting interval, h = T / N = 50 ms at N = 20): the planner gets the
measured plant state, re-solves the reach (goal at rest at the end of the horizon, which moves
with time; id_rk4 + IPOPT, warm start from the previous solution shifted by one interval; with
--solver stages on examples/ocp_stages.py's compiled per-interval functions, IPOPT's adaptive
barrier and the shifted constraint and bound multipliers), and the plant integrates the first
torque, held constant, for h at 1 kHz. The first step is the cold solve from rest. A failed
solve applies the previous plan's next torque; with --max-iter K a re-solve stopped after K
IPOPT iterations applies its iterate (examples/mpc_warm_start.py measures what that costs).

With --solver sqp (or rti) the controller is a different one: examples/mpc_sqp.py's tracking
MPC of a planned motion (lwr4: the converged reach, 2 RK4 steps per interval; panda: a
minimum-jerk joint motion), Gauss-Newton SQP with full steps on the condensed dense QP in the
N * 7 torques (DAQP), warm-started from the shifted nodes, torques and working set, iterated
to tol 1e-4 (rti: one iteration per step); the plant carries a payload the MPC does not know
(--payload, default 1 kg at the flange) and the MPC estimates a constant torque disturbance
from each interval's prediction error (--no-estimate to switch off). The speed limits: the LWR
plan keeps --backoff (0.3) of each data-sheet speed free at its nodes, the MPC imposes the
limit at the nodes and at the RK4 substep ends inside each interval (--no-inner-speed: nodes
only), tightened by --speed-margin (default 0). mpc.json then also has the iterations per
step, reference_rms (plant vs the reference), the disturbance, and the plant's largest speed
per joint as a fraction of qd_max (speed_peak_fraction) and its largest excess in rad/s.

    .venv/bin/python examples/mpc.py --problem lwr4 --solver sqp --out /tmp/mpc_lwr4_sqp
    .venv/bin/python examples/mpc.py --problem panda --solver rti --out /tmp/mpc_panda_rti

Output in --out: mpc.json (solve_ms per step, its median, 95th percentile and worst,
iterations, tracking_rms = RMS over steps of |plant state - the plan's predicted next node|
(rad, rad/s), goal error of the flange over time, violations = 1 kHz plant samples beyond a
data-sheet joint, speed or torque limit by more than 1e-6 plus failed solves), mpc.png.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

# One BLAS thread unless the caller says otherwise: a re-solve of a few milliseconds gains nothing
# from a second thread, whose spinning doubled the CPU time per step on the idle 2-core machine
# (LWR sqp: 17.0 ms CPU for 9.5 ms wall); must be set before numpy loads OpenBLAS.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent
ROOT = EXAMPLES.parent
for _p in (str(ROOT), str(EXAMPLES), str(ROOT / "tests")):
    if _p not in sys.path:
        sys.path.insert(0, _p)

PLANT_HZ = 1000
WARM = {"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4, "ipopt.warm_start_bound_push": 1e-6,
        "ipopt.warm_start_mult_bound_push": 1e-6}
# the compiled stages' warm re-solve, chosen by measurement (one shifted re-solve, AMD EPYC):
# the adaptive barrier takes 17 iterations (115 ms CPU) where the monotone one at mu_init 1e-4
# takes 28 (186 ms), at 1e-6 46 and at 1e-8 53; adaptive with mu_init 1e-4, 1e-6 or 1e-8 alike.
# With the bound multipliers shifted too (examples/mpc_warm_start.py) 13-20 iterations; on one
# shifted re-solve the monotone barrier (mu_init 1e-6: 17 iterations, 1e-8: 20), the probing or
# LOQO oracles (13 / 17) and tol 1e-4 with acceptable_tol 1e-3 (12-16 in the loop) were no faster
# in CPU time; ma27 is not in this IPOPT build (Invalid_Option: no HSL library)
WARM_STAGES = dict(WARM, **{"ipopt.mu_strategy": "adaptive", "ipopt.mu_init": 1e-6})


class _Parser(argparse.ArgumentParser):
    def error(self, message):   # one error line, exit 2
        print(f"error: {message}", file=sys.stderr)
        raise SystemExit(2)


def plant(robot, payload_kg: float = 0.0):
    """x, tau, duration -> x after `duration` of RK4 at PLANT_HZ on Pinocchio's ABA; with
    `payload_kg` a point mass at the flange origin that the controller's model does not have."""
    import pinocchio as pin
    from reference import pinocchio_model
    model, data, flange = pinocchio_model(robot)
    if payload_kg:
        fr = model.frames[flange]
        model.appendBodyToJoint(fr.parentJoint, fr.placement.act(pin.Inertia(payload_kg, np.zeros(3), np.zeros((3, 3)))),
                                pin.SE3.Identity())
        data = model.createData()
    n = robot.n
    dt = 1.0 / PLANT_HZ

    def f(x, u):
        return np.concatenate([x[n:], pin.aba(model, data, x[:n], x[n:], u)])

    def step(x, u, duration):
        samples = []
        for _ in range(int(round(duration * PLANT_HZ))):
            k1 = f(x, u)
            k2 = f(x + dt / 2 * k1, u)
            k3 = f(x + dt / 2 * k2, u)
            k4 = f(x + dt * k3, u)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            samples.append(x)
        return x, np.array(samples)

    def tip(q):
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[flange].translation.copy()
    return step, tip


def run(steps: int = 30, N: int = 20, verbose: bool = False, solver: str = "ipopt",
        options: dict | None = None) -> dict:
    """The closed loop; `options` override the warm re-solve's IPOPT options (WARM / WARM_STAGES)."""
    import ocp_reach
    funcs = ocp_reach.load()
    if solver == "stages":
        import ocp_stages
        nlp = ocp_stages.StageReach(N, funcs)
        opts = dict(WARM_STAGES, **(options or {}))
        built = nlp.ipopt(opts)
        # the cold first solve (from rest) is never capped
        built_cold = nlp.ipopt({k: v for k, v in opts.items() if k != "ipopt.max_iter"})

        def solve(x_init, z, lam):   # lam = (constraint, bound) multipliers, both shifted
            return nlp.solve_ipopt(built_cold if z is None else built, x_init=x_init, z0=None if z is None else nlp.shifted(z),
                                   lam_g0=None if lam is None else nlp.shifted_lam(lam[0]),
                                   lam_x0=None if lam is None else nlp.shifted_lam_x(lam[1]))
    else:
        nlp = ocp_reach.reach_problem("id_rk4", "ipopt", N, funcs, options=dict(WARM, **(options or {})))

        def solve(x_init, z, lam):
            return nlp.solve(x_init=x_init, z0=None if z is None else nlp.shifted(z), lam_g0=lam)
    setup = nlp.setup
    n, h = setup["n"], setup["T"] / N
    step, tip = plant(setup["robot"])
    x = np.concatenate([setup["q0"], np.zeros(n)])
    z, lam = None, None
    log = {"solve_ms": [], "solve_cpu_ms": [], "iterations": [], "status": [], "tracking": [], "goal_error_m": [], "tau": [], "t": []}
    violations = {"q": 0, "qd": 0, "tau": 0, "failed_solves": 0}
    u_next = setup["gravity_torque"]
    tol = 1e-6
    for i in range(steps):
        res = solve(x, z, lam)
        log["solve_ms"].append(1e3 * res["solve_s"])
        log["solve_cpu_ms"].append(1e3 * res["solve_cpu_s"])
        log["iterations"].append(res["iterations"])
        log["status"].append(res["status"])
        # a re-solve stopped by a max_iter cap still hands over its iterate (the cap's cost
        # shows in tracking_rms and violations); a first cold solve must converge
        capped = res["status"] == "Maximum_Iterations_Exceeded" and z is not None
        if res["success"] or capped:
            z = res["z"]
            lam = (res["lam_g"], res["lam_x"]) if solver == "stages" else res["lam_g"]
            u = res["tau"][0]
            pred = np.concatenate([res["q"][1], res["qd"][1]])
            u_next = res["tau"][1] if N > 1 else u
        else:
            violations["failed_solves"] += 1
            u, pred = u_next, None
        u = np.clip(u, -setup["tau_max"], setup["tau_max"])   # what a drive does; counted below if it acted
        if np.any(np.abs(res["tau"][0]) > setup["tau_max"] + tol):
            violations["tau"] += 1
        x, samples = step(x, u, h)
        violations["q"] += int(np.sum(np.any((samples[:, :n] > setup["q_hi"] + tol) |
                                             (samples[:, :n] < setup["q_lo"] - tol), axis=1)))
        violations["qd"] += int(np.sum(np.any(np.abs(samples[:, n:]) > setup["qd_max"] + tol, axis=1)))
        log["tracking"].append(float(np.linalg.norm(x - pred)) if pred is not None else float("nan"))
        log["goal_error_m"].append(float(np.linalg.norm(tip(x[:n]) - setup["goal"])))
        log["tau"].append(u.tolist())
        log["t"].append((i + 1) * h)
        if verbose:
            print(f"step {i:3d}: {res['status']:22s} it={res['iterations']:3d} {log['solve_ms'][-1]:8.1f} ms "
                  f"goal {1e3 * log['goal_error_m'][-1]:7.2f} mm", flush=True)
    ms = np.array(log["solve_ms"])
    warm = ms[1:] if len(ms) > 1 else ms
    tr = np.array([v for v in log["tracking"] if np.isfinite(v)])
    return {"problem": "lwr4", "N": N, "h_s": h, "plant_hz": PLANT_HZ, "steps": steps,
            "formulation": "id_rk4",
            "solver": "ipopt (warm start)" + (", compiled stages" if solver == "stages" else ""), **log,
            "solve_ms_cold": float(ms[0]), "solve_ms_median": float(np.median(warm)),
            "solve_ms_p95": float(np.percentile(warm, 95)), "solve_ms_worst": float(warm.max()),
            "solve_cpu_ms_median": float(np.median(np.array(log["solve_cpu_ms"])[1:] if steps > 1 else log["solve_cpu_ms"])),
            "tracking_rms": float(np.sqrt(np.mean(tr ** 2))) if tr.size else float("nan"),
            "goal_error_final_m": log["goal_error_m"][-1],
            "violations": int(sum(violations.values())), "violations_by_kind": violations}


def machine() -> dict:
    """The CPU model and the load while the loop ran (a shared machine: wall times swing)."""
    import platform
    import subprocess
    cpu = platform.processor()
    if Path("/proc/cpuinfo").exists():
        cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), cpu)
    return {"cpu": cpu, "cores": os.cpu_count(),
            "uptime": subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()}


PAYLOAD_KG = 1.0          # the plant's unmodelled payload at the flange (--solver sqp | rti)
# chosen by measurement (docs/optimal_control.md, the MPC section; LWR, 1 kg payload): the
# payload moves the light wrist up to ~0.22 qd_max past the plan within an interval, so the
# reference plan keeps 0.3 qd_max free (0.1: 159 speed samples over, 0.2: 45, 0.3: none, its
# peak 0.93 qd_max); tightening the MPC's rows instead (0.1, 0.2 with the plan at the limit)
# leaves 260 and 30 samples over, makes the SQP take up to 10 iterations and tracks worse
SPEED_MARGIN = 0.0        # fraction of qd_max the MPC's speed rows keep free (--solver sqp | rti)
REFERENCE_BACKOFF = 0.3   # fraction of qd_max the LWR reference plan keeps free at its nodes


def run_sqp(problem: str = "lwr4", steps: int = 30, N: int = 20, verbose: bool = False, rti: bool = False,
            substeps: int = 2, payload_kg: float = PAYLOAD_KG, tol: float = 1e-4, max_iter: int = 10,
            estimate: bool = True, speed_margin: float = SPEED_MARGIN, backoff: float = REFERENCE_BACKOFF,
            inner_speed: bool = True) -> dict:
    """The closed loop with examples/mpc_sqp.py's tracking MPC (Gauss-Newton SQP, condensed QP,
    DAQP): at every control step the SQP from the shifted torques of the previous step, to
    `tol` (or one iteration with rti=True: the real-time iteration), the plant carrying a
    payload the model does not have; with `estimate` the MPC estimates a constant torque
    disturbance from each interval's prediction error (offset-free MPC, timed with the solve)."""
    import mpc_sqp
    funcs = mpc_sqp.load(problem)
    ref = mpc_sqp.reference(problem, N, substeps, funcs, backoff)
    lim, h, n = ref["limits"], ref["h"], funcs["robot"].n
    ctl = mpc_sqp.TrackingMPC(funcs, lim, ref["X"], ref["U"], h, N, substeps=substeps, tol=tol,
                              max_iter=1 if rti else max_iter, speed_margin=speed_margin, inner_speed=inner_speed)
    step, tip = plant(funcs["robot"], payload_kg)
    x = ref["x0"].copy()
    X, U = ctl.initial_guess(0)
    active = None
    log = {"solve_ms": [], "solve_cpu_ms": [], "iterations": [], "qp_iterations": [], "status": [], "tracking": [],
           "reference_error": [], "goal_error_m": [], "tau": [], "t": []}
    violations = {"q": 0, "qd": 0, "tau": 0, "failed_solves": 0}
    tol_lim = 1e-6
    # the plant's largest speed per joint over all 1 kHz samples, as a fraction of qd_max
    qd_peak = np.zeros(n)
    Nr = len(ref["U"])
    x_prev = u_prev = None
    for i in range(steps):
        t0, c0 = time.perf_counter(), time.process_time()
        if estimate and x_prev is not None:
            ctl.estimate_disturbance(x_prev, u_prev, x)
        est_s, est_cpu_s = time.perf_counter() - t0, time.process_time() - c0
        r = ctl.solve(x, X, U, i, active=active)
        log["solve_ms"].append(1e3 * (r["solve_s"] + est_s))
        log["solve_cpu_ms"].append(1e3 * (r["solve_cpu_s"] + est_cpu_s))
        log["iterations"].append(r["iterations"])
        log["qp_iterations"].append(r["qp_iterations"])
        status = "converged" if r["converged"] else ("rti" if rti and r["success"] else "not converged")
        log["status"].append(status)
        if not r["success"]:
            violations["failed_solves"] += 1
        u = r["U"][0]
        if np.any(np.abs(u) > lim["tau_max"] + tol_lim):
            violations["tau"] += 1
        # the prediction of the applied torque: the plan's first RK4 step from the measured state
        # (at convergence the plan's node 1; capped, the node may still have a gap)
        pred = ctl.linearise(x, r["X"], r["U"])[0][0]
        x_prev, u_prev = x, u
        x, samples = step(x, u, h)
        violations["q"] += int(np.sum(np.any((samples[:, :n] > lim["q_hi"] + tol_lim) |
                                             (samples[:, :n] < lim["q_lo"] - tol_lim), axis=1)))
        violations["qd"] += int(np.sum(np.any(np.abs(samples[:, n:]) > lim["qd_max"] + tol_lim, axis=1)))
        qd_peak = np.maximum(qd_peak, np.abs(samples[:, n:]).max(axis=0) / lim["qd_max"])
        log["tracking"].append(float(np.linalg.norm(x - pred)))
        log["reference_error"].append(float(np.linalg.norm(x - ref["X"][min(i + 1, Nr)])))
        log["goal_error_m"].append(float(np.linalg.norm(tip(x[:n]) - ref["goal"])))
        log["tau"].append(u.tolist())
        log["t"].append((i + 1) * h)
        X, U = ctl.shifted(r["X"], r["U"], i)
        active = ctl.shifted_active(r["active"])
        if verbose:
            print(f"step {i:3d}: {status:13s} it={r['iterations']:2d} qp={r['qp_iterations']} "
                  f"{log['solve_ms'][-1]:7.2f} ms (CPU {log['solve_cpu_ms'][-1]:6.2f}) "
                  f"ref err {log['reference_error'][-1]:.2e} goal {1e3 * log['goal_error_m'][-1]:7.2f} mm", flush=True)
    ms, cpu = np.array(log["solve_ms"]), np.array(log["solve_cpu_ms"])
    warm, warm_cpu = (ms[1:], cpu[1:]) if steps > 1 else (ms, cpu)
    tr, re = np.array(log["tracking"]), np.array(log["reference_error"])
    its = np.array(log["iterations"][1:] if steps > 1 else log["iterations"])
    return {"problem": problem, "N": N, "h_s": h, "plant_hz": PLANT_HZ, "steps": steps,
            "formulation": f"tracking, multiple shooting condensed, RK4 ({substeps} steps per interval) of the generated fd, "
                           "Jacobians from fd_derivatives, compiled C",
            "solver": ("real-time iteration (one Gauss-Newton SQP step)" if rti else
                       f"Gauss-Newton SQP to tol {tol:g} (max |du_j| / tau_max_j), at most {max_iter} iterations")
                      + ", condensed dense QP, DAQP",
            "reference": ref["description"], "reference_solve_s": ref["solve_s"],
            "weights": vars(ctl.weights), "compile_s": ctl.compile_s,
            "disturbance": f"plant payload {payload_kg:g} kg at the flange origin (point mass), not in the MPC's model",
            "disturbance_estimate": ("constant torque offset from each interval's prediction error "
                                     "(d += pinv(B_0) (x_measured - x_predicted))") if estimate else "none",
            "disturbance_estimate_final": ctl.d.tolist(),
            **log,
            "solve_ms_cold": float(ms[0]), "solve_ms_median": float(np.median(warm)),
            "solve_ms_p95": float(np.percentile(warm, 95)), "solve_ms_worst": float(warm.max()),
            "solve_cpu_ms_median": float(np.median(warm_cpu)), "solve_cpu_ms_p95": float(np.percentile(warm_cpu, 95)),
            "solve_cpu_ms_worst": float(warm_cpu.max()),
            "iterations_median": float(np.median(its)), "iterations_max": int(its.max()),
            "tracking_rms": float(np.sqrt(np.mean(tr ** 2))),
            "reference_rms": float(np.sqrt(np.mean(re ** 2))),
            "goal_error_final_m": log["goal_error_m"][-1],
            "violations": int(sum(violations.values())), "violations_by_kind": violations,
            "violation_tolerance": f"a plant sample counts when past a data-sheet limit by more than {tol_lim:g} "
                                   "(rad, rad/s, N m)",
            "speed_peak_fraction": qd_peak.tolist(),
            "speed_excess_max_rad_s": float(np.max((qd_peak - 1.0) * lim["qd_max"])),
            "speed_margin": speed_margin, "reference_backoff": backoff if problem == "lwr4" else None,
            "inner_speed_rows": bool(inner_speed and substeps > 1)}


def plot(doc, out: Path) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    t = np.array(doc["t"])
    axes[0].semilogy(t, np.array(doc["goal_error_m"]) * 1e3)
    axes[0].set_ylabel("flange to goal [mm]")
    axes[1].plot(t, doc["solve_ms"], "o-", ms=3, label="wall")
    axes[1].plot(t, doc["solve_cpu_ms"], "s-", ms=3, label="CPU")
    axes[1].legend(fontsize=8)
    axes[1].set_yscale("log")
    axes[1].set_ylabel("solve [ms]")
    tau = np.array(doc["tau"])
    for j in range(tau.shape[1]):
        axes[2].step(t - doc["h_s"], tau[:, j], where="post", label=f"tau{j + 1}")
    axes[2].set_ylabel("tau [N m]")
    axes[2].set_xlabel("t [s]")
    axes[2].legend(fontsize=7, ncol=7)
    what = "LWR reach" if doc["problem"] == "lwr4" else doc["problem"]
    axes[0].set_title(f"MPC ({doc['solver'].split(' (')[0].split(',')[0]}), {what}, N = {doc['N']}, plant Pinocchio "
                      f"ABA + RK4 at {doc['plant_hz']} Hz: median solve {doc['solve_ms_median']:.1f} ms wall, "
                      f"{doc['solve_cpu_ms_median']:.1f} ms CPU", fontsize=9)
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "mpc.png", dpi=110)
    plt.close(fig)
    return "mpc.png"


def main(argv=None) -> int:
    ap = _Parser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                 epilog="\n\n".join(__doc__.split("\n\n")[2:]))
    ap.add_argument("--problem", choices=("lwr4", "panda"), required=True,
                    help="lwr4: the LWR reach; panda: a Panda joint motion (--solver sqp or rti only)")
    ap.add_argument("--out", required=True, help="output folder (created)")
    ap.add_argument("--steps", type=int, default=30, help="control steps (default 30, 1.5 s)")
    ap.add_argument("--N", type=int, default=20, help="shooting intervals of the 1 s horizon (default 20)")
    ap.add_argument("--solver", choices=("ipopt", "stages", "sqp", "rti"), default="ipopt",
                    help="ipopt: the reach re-solved by IPOPT on the SX graph (examples/ocp_reach.py); "
                         "stages: IPOPT with the per-interval functions compiled to C (examples/ocp_stages.py; "
                         "the first run compiles for minutes, later runs load the cache); sqp: tracking MPC "
                         "of the planned motion, Gauss-Newton SQP on a condensed QP (examples/mpc_sqp.py) to "
                         "convergence; rti: the same, one SQP iteration per step (real-time iteration)")
    ap.add_argument("--payload", type=float, default=PAYLOAD_KG,
                    help=f"sqp, rti: the plant's payload at the flange in kg, unknown to the MPC (default {PAYLOAD_KG:g})")
    ap.add_argument("--no-estimate", action="store_true",
                    help="sqp, rti: no disturbance estimate (default: the MPC estimates a constant torque offset)")
    ap.add_argument("--speed-margin", type=float, default=SPEED_MARGIN,
                    help="sqp, rti: fraction of each speed limit the MPC's speed rows (nodes and inner substeps) "
                         f"keep free (default {SPEED_MARGIN:g})")
    ap.add_argument("--backoff", type=float, default=REFERENCE_BACKOFF,
                    help="sqp, rti, lwr4: fraction of each speed limit the reference reach plan keeps free at its "
                         f"nodes (default {REFERENCE_BACKOFF:g})")
    ap.add_argument("--no-inner-speed", action="store_true",
                    help="sqp, rti: speed rows at the nodes only (default: also at the RK4 substep ends inside "
                         "each interval)")
    ap.add_argument("--substeps", type=int, default=2,
                    help="sqp, rti: RK4 steps per interval in the MPC's prediction and the reference (default 2)")
    ap.add_argument("--max-iter", type=int, default=None,
                    help="cap on IPOPT's iterations per warm re-solve (the capped iterate is applied; "
                         "default: none, every re-solve converges to tol 1e-8)")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args(argv)
    if args.steps < 1:
        ap.error(f"--steps {args.steps}: must be at least 1")
    if args.N < 2:
        ap.error(f"--N {args.N}: must be at least 2")
    if args.max_iter is not None and args.max_iter < 1:
        ap.error(f"--max-iter {args.max_iter}: must be at least 1")
    if args.problem == "panda" and args.solver in ("ipopt", "stages"):
        ap.error(f"--solver {args.solver}: the reach re-solve exists for --problem lwr4 only (panda: sqp or rti)")
    if args.payload < 0:
        ap.error(f"--payload {args.payload}: must be at least 0")
    for name in ("speed_margin", "backoff"):
        if not 0 <= getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} {getattr(args, name)}: must be in [0, 1)")
    if args.substeps < 1:
        ap.error(f"--substeps {args.substeps}: must be at least 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.solver in ("sqp", "rti"):
        doc = run_sqp(args.problem, args.steps, args.N, args.verbose, args.solver == "rti", args.substeps,
                      args.payload, max_iter=10 if args.max_iter is None else args.max_iter,
                      estimate=not args.no_estimate, speed_margin=args.speed_margin, backoff=args.backoff,
                      inner_speed=not args.no_inner_speed)
    else:
        doc = run(args.steps, args.N, args.verbose, args.solver,
                  None if args.max_iter is None else {"ipopt.max_iter": args.max_iter})
    doc["max_iter"] = args.max_iter
    doc["machine"] = machine()
    doc["plots"] = [plot(doc, out)]
    (out / "mpc.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(f"{args.problem} MPC ({args.solver}): {args.steps} steps, re-solve median {doc['solve_ms_median']:.1f} ms, p95 "
          f"{doc['solve_ms_p95']:.1f} ms, worst {doc['solve_ms_worst']:.1f} ms (cold {doc['solve_ms_cold']:.0f} ms); "
          f"tracking rms {doc['tracking_rms']:.2e}; flange {1e3 * doc['goal_error_final_m']:.2f} mm from the goal; "
          f"violations {doc['violations']} {doc['violations_by_kind']}")
    print(f"  wrote {out / 'mpc.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
