"""The control benchmark: the reach and the tracking MPC over three arms (the LWR and the Panda
from their YAML DH tables, the UR5 from example-robot-data's URDF), one command:

    OPENBLAS_NUM_THREADS=1 nice .venv/bin/python -m benchmarks.control_bench [--quick] [--out benchmarks/results/control.json]

Part 1, the reach (kindyngen.control.reach, benchmarks/control_robots.py's tasks: start at rest,
flange to a goal at rest at T = 1 s, N = 20, one RK4 step per interval, data-sheet limits):
- ours: IPOPT on the native stage library (adaptive barrier), cold from rest with the gravity
  torques (median CPU of --repeats), and warm re-solved from the solution and its multipliers
  shifted by one interval with the start moved to its node 1 (the MPC's re-solve);
- the plain baseline in the same run: Opti + IPOPT with fd on MX symbols and IPOPT's defaults
  (what a new user writes); ratio of CPU times;
- Crocoddyl + mim-solvers' CSQP on the same problem (benchmarks/crocoddyl_reach.py, in
  .venv-crocoddyl: see its docstring), and acados' SQP with HPIPM (benchmarks/acados_reach.py,
  in .venv-acados), where those environments exist;
- every plan checked by Pinocchio: from each node the RK4 step of Pinocchio's ABA against the next
  node (plan_step_error), the flange at the goal by Pinocchio's kinematics.

Part 2, the MPC disturbance suite (kindyngen.control.mpc and closed_loop; plant
benchmarks/control_plant.py, Pinocchio at 1 kHz): the reach re-planned with two RK4 substeps,
0.3 of every speed and 0.05 rad of every position limit kept free, tracked for 2.5 s by the MPC
(N = 20, h = 50 ms, Gauss-Newton SQP to 1e-4, budget 10 ms), under each disturbance: none,
measurement noise (1e-4 rad, 1e-3 rad/s), a payload 0 -> 5 kg at 0.5 s, a 60 N push at the flange
for 0.3 s, 10 % heavier links, and for every joint a torque step of 80 % of its limit for 0.3 s.
Recorded per case: 1 kHz plant samples past a position, speed or torque limit (tolerance 1e-6),
peak speeds, the re-solve's CPU time (median, p95, p99, worst), iterations, fallbacks, the
samples the limit guard took over, the flange's distance from the goal at the end, and a
verdict. For torque steps, at the onset and at the release (where the controller's cancelling
torque meets the step's end: a step of the same size the other way), whether any controller
sampling at 1 kHz could keep the speed limits: the step's acceleration from Pinocchio's M^-1,
the speed change of the first millisecond (before any sample can see the step) against the
margin left; where none could, the verdict is "no admissible motion exists; stopped safely"
when no position or torque limit was passed and the speeds came back inside their limits (the
milliseconds it took are recorded), else "NOT stopped safely".

Writes the JSON (with the machine and `uptime` at the start and end) and a plot beside it.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from benchmarks import control_robots as cr  # noqa: E402
from benchmarks.control_plant import Disturbance, PinocchioPlant  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TOL = 1e-6


def machine() -> dict:
    cpu = platform.processor()
    if Path("/proc/cpuinfo").exists():
        cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), cpu)
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version()}


def uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def log(text):
    print(text, file=sys.stderr, flush=True)


def plan_check(name, model, task, res) -> dict:
    """Pinocchio's view of a plan: the RK4 steps of its ABA from each node against the next node,
    the flange at the goal."""
    import pinocchio as pin
    pm, frame = cr.pinocchio_plant_model(name, model)
    pd = pm.createData()
    n = model.n
    M = task.integrator.substeps

    def f(x, u):
        return np.concatenate([x[n:], pin.aba(pm, pd, x[:n], x[n:], u)])
    X = np.hstack([res.q, res.qd])
    err = 0.0
    for k in range(task.N):
        x, dt = X[k], task.h / M
        for _ in range(M):
            k1 = f(x, res.tau[k]); k2 = f(x + dt / 2 * k1, res.tau[k]); k3 = f(x + dt / 2 * k2, res.tau[k])
            k4 = f(x + dt * k3, res.tau[k])
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        err = max(err, float(np.abs(x - X[k + 1]).max()))
    pin.framesForwardKinematics(pm, pd, res.q[-1])
    lim = task.planned_limits
    from kindyngen.control.reach import check_between_nodes
    between = check_between_nodes(lambda q, v, u: pin.aba(pm, pd, q, v, u), res, lim, 20)
    return {"plan_step_error": err, "between_nodes_pinocchio": between, "goal_error_m": float(np.linalg.norm(pd.oMf[frame].translation - np.asarray(task.goal))),
            "final_speed": float(np.abs(res.qd[-1]).max()),
            "limit_excess": {"tau": float(np.max(np.abs(res.tau) - lim.array("tau_max"), initial=0)),
                             "q": float(max(np.max(res.q[1:] - lim.array("q_hi")), np.max(lim.array("q_lo") - res.q[1:]), 0)),
                             "qd": float(max(np.max(np.abs(res.qd[1:]) - lim.array("qd_max")), 0))}}


def resimulation(name, model, task, res, substeps: int = 20) -> dict:
    """The plan's torques applied to Pinocchio's ABA, RK4 with ``substeps`` steps per interval
    (the discretisation's own error): the largest state difference at the nodes, the flange's
    distance from the goal at T."""
    import pinocchio as pin
    from kindyngen.control.reach import rollout
    pm, frame = cr.pinocchio_plant_model(name, model)
    pd = pm.createData()
    n = model.n

    def step(x, u, dt):
        def f(z):
            return np.concatenate([z[n:], pin.aba(pm, pd, z[:n], z[n:], u)])
        k1 = f(x); k2 = f(x + dt / 2 * k1); k3 = f(x + dt / 2 * k2); k4 = f(x + dt * k3)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    X = rollout(step, np.concatenate([res.q[0], res.qd[0]]), res.tau, substeps, task.h)
    pin.framesForwardKinematics(pm, pd, X[-1, :n])
    return {"resim_error": float(np.abs(X - np.hstack([res.q, res.qd])).max()), "resim_substeps": substeps,
            "resim_goal_error_m": float(np.linalg.norm(pd.oMf[frame].translation - np.asarray(task.goal)))}


def reach_rows(name, repeats, baseline_repeats, crocoddyl_venv, acados_venv, quick, peers=True) -> dict:
    from kindyngen.control.reach import ReachNLP, solve_baseline
    model, robot, limits, task = cr.load(name)
    t0 = time.perf_counter()
    nlp = ReachNLP(robot, task, progress=log)
    build_s = time.perf_counter() - t0
    cold = [nlp.solve() for _ in range(repeats)]
    res = cold[-1]
    warm_solver = nlp.build(dict(nlp.options, **{"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                                               "ipopt.warm_start_bound_push": 1e-6,
                                               "ipopt.warm_start_mult_bound_push": 1e-6}))
    warm = []
    lam_g, lam_x = nlp.shifted_multipliers(res.lam_g, res.lam_x)
    for _ in range(repeats):
        x1 = np.concatenate([res.q[1], res.qd[1]])
        warm.append(nlp.solve(x1, z0=nlp.shifted(res.z), lam_g0=lam_g, lam_x0=lam_x, solver=warm_solver))
    base = [solve_baseline(robot, task) for _ in range(baseline_repeats)]
    row = {"robot": name, "n": robot.n, "N": task.N, "T": task.T, "goal": list(task.goal), "q0": list(task.q0),
           "build_s": build_s,
           "ours": {"solver": res.solver, "status": res.status, "iterations": res.iterations,
                    "cold_cpu_s": [r.solve_cpu_s for r in cold], "cold_cpu_s_median": float(np.median([r.solve_cpu_s for r in cold])),
                    "objective": res.objective, **plan_check(name, model, task, res)},
           "warm": {"status": warm[-1].status, "iterations": [r.iterations for r in warm],
                    "cpu_s": [r.solve_cpu_s for r in warm], "cpu_s_median": float(np.median([r.solve_cpu_s for r in warm]))},
           "baseline": {"solver": base[-1].solver, "status": base[-1].status, "iterations": base[-1].iterations,
                        "cold_cpu_s": [b.solve_cpu_s for b in base],
                        "cold_cpu_s_median": float(np.median([b.solve_cpu_s for b in base])),
                        "objective": base[-1].objective, **plan_check(name, model, task, base[-1])}}
    row["speedup_cold"] = row["baseline"]["cold_cpu_s_median"] / row["ours"]["cold_cpu_s_median"]
    log(f"{name} reach: ours {res.iterations} it {1e3 * row['ours']['cold_cpu_s_median']:.1f} ms, warm "
        f"{1e3 * row['warm']['cpu_s_median']:.1f} ms, baseline {row['baseline']['iterations']} it "
        f"{row['baseline']['cold_cpu_s_median']:.2f} s: {row['speedup_cold']:.1f}x; objectives "
        f"{res.objective:.4f} / {row['baseline']['objective']:.4f}; plan step error {row['ours']['plan_step_error']:.1e}")
    if peers:
        row["crocoddyl"] = crocoddyl_rows(name, model, task, crocoddyl_venv, quick)
        row["acados"] = acados_rows(name, model, robot, task, acados_venv, quick)
    return row


def crocoddyl_rows(name, model, task, venv: Path, quick: bool) -> dict:
    py = venv / "bin" / "python"
    if not py.exists():
        return {"error": f"no Crocoddyl environment at {venv} (benchmarks/crocoddyl_reach.py says how to make it)"}
    arm = cr.ROBOTS[name]
    if arm.description.suffix == ".urdf":
        urdf, frame = arm.description, arm.tip
    else:
        sys.path.insert(0, str(ROOT / "examples"))
        from dh_to_urdf import write_urdf
        urdf, frame = write_urdf(model, ROOT / "benchmarks" / "build" / "urdf" / f"{name}.urdf"), "flange"
    lim = task.planned_limits
    problem = {"q0": list(task.q0), "goal": list(task.goal), "tau_max": list(lim.tau_max), "qd_max": list(lim.qd_max),
               "q_lo": list(lim.q_lo), "q_hi": list(lim.q_hi), "N": task.N, "T": task.T, "frame": frame}
    cmd = [str(py), "-X", "faulthandler", str(ROOT / "benchmarks" / "crocoddyl_reach.py"), "--urdf", str(urdf),
           "--problem", json.dumps(problem), "--repeats", "1" if quick else "3", "--maxiter", "100" if quick else "200"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
        return {"error": " | ".join(lines[-3:]) if lines else f"exit {r.returncode}"}
    out = json.loads(r.stdout.strip().splitlines()[-1])
    from kindyngen.control.reach import ReachResult
    rows = []
    for c in out["rows"]:
        res = ReachResult(c["success"], c["status"], c["iterations"], c["solve_s"], c["solve_cpu_s"], c["objective"],
                          np.linspace(0, task.T, task.N + 1), np.array(c["q"]), np.array(c["qd"]), np.array(c["tau"]),
                          0.0, c["solver"])
        row = {k: c[k] for k in ("solver", "status", "iterations", "solve_cpu_s", "objective", "kkt",
                                 "warm_resolve_cpu_s", "warm_iterations")}
        row.update(plan_check(name, model, task, res))
        rows.append(row)
        log(f"{name} crocoddyl {c['solver']}: {c['status']}, {c['iterations']} it, {c['solve_cpu_s']:.3f} s CPU, "
            f"objective {c['objective']:.4f}")
    return {"versions": out["versions"], "rows": rows}


def acados_rows(name, model, robot, task, venv: Path, quick: bool) -> dict:
    """benchmarks/acados_reach.py in its environment (see its docstring), the plan checked here."""
    py = venv / "bin" / "python"
    if not py.exists():
        return {"error": f"no acados environment at {venv} (benchmarks/acados_reach.py says how to make it)"}
    lim = task.planned_limits
    problem = {"q0": list(task.q0), "goal": [float(v) for v in task.goal], "tau_max": list(lim.tau_max),
               "qd_max": list(lim.qd_max), "q_lo": list(lim.q_lo), "q_hi": list(lim.q_hi), "N": task.N, "T": task.T}
    module = robot.folder / "casadi" / f"{robot.name}_casadi.py"
    (ROOT / "benchmarks" / "build").mkdir(parents=True, exist_ok=True)      # acados writes its solver there
    r = subprocess.run([str(py), str(ROOT / "benchmarks" / "acados_reach.py"), "--module", str(module), "--problem",
                        json.dumps(problem), "--repeats", "1" if quick else "3",
                        "--build", str(ROOT / "benchmarks" / "build" / "acados")], capture_output=True, text=True,
                       cwd=str(ROOT / "benchmarks" / "build"))
    if r.returncode != 0:
        lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
        return {"error": " | ".join(lines[-3:]) if lines else f"exit {r.returncode}"}
    out = json.loads(r.stdout.strip().splitlines()[-1])
    c = out["row"]
    from kindyngen.control.reach import ReachResult
    res = ReachResult(c["success"], str(c["status"]), c["iterations"], 0.0, c["solve_cpu_s"], c["objective"],
                      np.linspace(0, task.T, task.N + 1), np.array(c["q"]), np.array(c["qd"]), np.array(c["tau"]), 0.0,
                      "acados")
    row = {k: c[k] for k in ("status", "success", "iterations", "solve_cpu_s", "solve_cpu_s_runs", "objective", "build_s",
                             "built_now")}
    row.update(plan_check(name, model, task, res))
    log(f"{name} acados: status {c['status']}, {c['iterations']} it, {c['solve_cpu_s']:.3f} s CPU, objective "
        f"{c['objective']:.4f} (build {c['build_s']:.0f} s)")
    return {"versions": out["versions"], "options": out["options"], "row": row}


SUITE_T = 2.5


def cases(limits, n, quick) -> list[tuple[str, Disturbance]]:
    out = [("none", Disturbance()), ("noise", Disturbance("noise", noise=(1e-4, 1e-3), seed=1)),
           ("payload 0 -> 5 kg at 0.5 s", Disturbance("payload", start=0.5, mass_kg=5.0)),
           ("push 60 N (y) 0.4-0.7 s", Disturbance("push", start=0.4, duration=0.3, force=(0.0, 60.0, 0.0))),
           ("push 60 N (-z) 0.4-0.7 s", Disturbance("push", start=0.4, duration=0.3, force=(0.0, 0.0, -60.0))),
           ("links 10 % heavier", Disturbance("mass_error", mass_scale=1.1))]
    joints = range(n) if not quick else (1, n - 1)
    for j in joints:
        tq = 0.8 * limits.tau_max[j]
        out.append((f"torque step joint {j + 1}: {tq:g} N m (80 %) 0.4-0.7 s",
                    Disturbance("torque", start=0.4, duration=0.3, joint=j, torque=tq)))
    return out


def admissible(plant, limits, x, joint, torque, when) -> dict:
    """Can any controller sampling at 1 kHz keep the speed limits when a torque step of ``torque``
    N m starts (or ends) on ``joint`` at state x? The command in force during the first
    millisecond was chosen before the step could be seen, so whatever the controller does, the
    step changes the joint speeds by M^-1 e_joint torque (1 ms) against the motion that command
    would have made (M^-1: Pinocchio's, at x); compared with the margin each joint has left under
    its limit at x. (Holding the limit would need a command that already opposed the step before
    it began: a controller that knew it in advance.)"""
    n = plant.n
    Minv = plant.mass_matrix_inverse(x[:n])
    acc = np.abs(Minv[:, joint] * torque)
    dv = acc * 1e-3
    margin = limits.array("qd_max") - np.abs(x[n:])
    worst = int(np.argmax(dv - margin))
    ok = bool(np.all(dv <= margin))
    text = (f"at the {when}: the step accelerates joint {worst + 1} by {acc[worst]:.4g} rad/s^2 (Pinocchio's M^-1); "
            f"in the millisecond before any 1 kHz sample can see it its speed moves by {dv[worst]:.3g} rad/s; "
            f"{margin[worst]:.3g} rad/s were left under its limit")
    return {"when": when, "acceleration_rad_s2": acc.tolist(), "speed_change_first_ms": dv.tolist(),
            "speed_margin": margin.tolist(), "keeps_speed_limits": ok,
            "note": (f"admissible at 1 kHz ({text})" if ok else
                     f"no admissible motion exists: {text}, so no controller that does not know the step in advance "
                     f"keeps it")}


def recovery(t, qd, limits, start, stop) -> float | None:
    """Milliseconds from ``start`` until every speed is back within its limit for the rest of
    [start, stop) (None: not before ``stop``).

    >>> from kindyngen.control.robot import Limits
    >>> lim = Limits((-1.0,), (1.0,), (1.0,), (1.0,))
    >>> t = np.arange(1, 11) * 1e-3; qd = np.array([[0.5], [2.0], [1.5], [0.9]] + [[0.5]] * 6)
    >>> recovery(t, qd, lim, 0.002, 0.01), recovery(t, qd, lim, 0.0, 0.0025)
    (2.0, None)
    """
    over = np.any(np.abs(qd) > limits.array("qd_max") + TOL, axis=1)
    window = np.flatnonzero((t >= start - 1e-9) & (t < stop - 1e-9))
    bad = window[over[window]]
    if bad.size == 0:
        return 0.0
    last = int(bad.max())
    return None if last + 1 > window.max() else float(1e3 * (t[last + 1] - start))


def mpc_case(name, model, robot, limits, ref, label, dist, quick, ref_h: float = 0.05, options=None,
             duration: float = SUITE_T, keep_log: bool = False) -> dict:
    """One case of the suite: the MPC (``options``, default MPCOptions()) tracking ``ref`` for
    ``duration`` s against the Pinocchio plant under ``dist``; with ``keep_log`` the 1 kHz states
    and torques are returned too (under "log")."""
    from kindyngen.control.closed_loop import Controller, simulate
    from kindyngen.control.mpc import MPCOptions, TrackingMPC
    mpc = TrackingMPC(robot, limits, ref["X"], ref["U"], options or MPCOptions())
    plant = PinocchioPlant(name, model, dist)
    ctl = Controller(mpc)
    t0 = time.perf_counter()
    lg = simulate(ctl, plant, ref["X"][0].copy(), duration)
    X, tau = np.array(lg.x), np.array(lg.tau)
    n = model.n
    q, qd = X[:, :n], X[:, n:]
    steps = lg.steps
    cpu = np.array([s["cpu_ms"] for s in steps[1:]])
    viol = {"q": int(np.sum(np.any((q > limits.array("q_hi") + TOL) | (q < limits.array("q_lo") - TOL), axis=1))),
            "qd": int(np.sum(np.any(np.abs(qd) > limits.array("qd_max") + TOL, axis=1))),
            "tau": int(np.sum(np.any(np.abs(tau) > limits.array("tau_max") + TOL, axis=1)))}
    goal_err = float(np.linalg.norm(plant.flange(q[-1]) - np.asarray(ref["goal"])))
    # the MPC's prediction of the state at its next re-solve (its model from the measured state
    # under the plan's first torque) against the plant's (log entry i is the state at (i + 1) ms)
    per = int(round(ref_h * 1000))
    pred_err = [float(np.abs(X[s["step"] * per + per - 1] - np.array(s["predicted_next"])).max())
                for s in steps if "predicted_next" in s and s["step"] * per + per - 1 < len(X)]
    modes = {m: sum(1 for s in steps if s["mode"] == m) for m in ("mpc", "shifted plan", "brake")}
    out = {"case": label, "disturbance": dist.__dict__ | {"duration": None if not np.isfinite(dist.duration) else dist.duration},
           "violations": viol, "speed_peak_fraction": (np.abs(qd).max(0) / limits.array("qd_max")).tolist(),
           "position_margin_min_rad": float(min(np.min(q - limits.array("q_lo")), np.min(limits.array("q_hi") - q))),
           "resolve_cpu_ms": {"median": float(np.median(cpu)), "p95": float(np.percentile(cpu, 95)),
                              "p99": float(np.percentile(cpu, 99)), "worst": float(cpu.max())},
           "first_solve_cpu_ms": steps[0]["cpu_ms"],
           "iterations": {"median": float(np.median([s["iterations"] for s in steps])),
                          "max": int(max(s["iterations"] for s in steps))},
           "statuses": {k: sum(1 for s in steps if s["status"] == k) for k in ("converged", "iterate", "fallback")},
           "late": sum(1 for s in steps if s["late"]), "modes": modes,
           "slack_max": float(max(s["slack"] for s in steps)),
           "goal_error_final_mm": 1e3 * goal_err, "sim_wall_s": time.perf_counter() - t0,
           "prediction_error": {"median": float(np.median(pred_err)), "max": float(np.max(pred_err))} if pred_err else None,
           # the steps past the budget, to see what the time went to
           "slow_steps": [{k: s[k] for k in ("step", "t", "cpu_ms", "iterations", "qp_iterations", "status", "mode")}
                          for s in steps if s["cpu_ms"] > 10.0]}
    guard = np.array(lg.guard)
    out["guard_samples"] = int(np.count_nonzero(guard))
    held = viol["q"] == 0 and viol["qd"] == 0 and viol["tau"] == 0
    out["limits_held"] = held
    out["goal_within_1mm"] = goal_err < 1e-3
    if dist.kind == "torque":
        # the true state at the last sample before the step starts and before it ends (log entry i
        # holds the state at t_i + 1 ms, and the RK4 step ending at the onset already sees the step
        # in its last stage); at the end the controller is cancelling the step, so its removal is
        # a step of the same size the other way
        t = np.arange(len(X)) * 1e-3 + 1e-3
        checks = []
        for when, t0, t1 in (("onset", dist.start, dist.end), ("release", dist.end, duration)):
            k = int(round(t0 * 1000))
            c = admissible(plant, limits, X[k - 2], dist.joint, dist.torque, when)
            c["back_inside_speed_limits_ms"] = recovery(t, qd, limits, t0, t1)
            checks.append(c)
        out["admissibility"] = checks
        inadmissible = not all(c["keeps_speed_limits"] for c in checks)
        back = [c["back_inside_speed_limits_ms"] for c in checks]
        safe = viol["q"] == 0 and viol["tau"] == 0 and all(b is not None for b in back)
        if not inadmissible:
            out["verdict"] = "admissible: " + ("every limit held" if held else "LIMITS NOT HELD")
        elif safe:
            out["verdict"] = (f"no admissible motion exists; stopped safely: back inside the speed limits "
                              f"{back[0]:.0f} ms after the onset and {back[1]:.0f} ms after the release, "
                              f"no position or torque limit passed")
        else:
            out["verdict"] = ("no admissible motion exists; NOT stopped safely: "
                              + ", ".join(f"{k} {v} samples past" for k, v in viol.items() if v and k != "qd")
                              + ("" if all(b is not None for b in back) else ", speeds not back inside"))
    else:
        out["verdict"] = "every limit held" if held else "LIMITS NOT HELD"
    if keep_log:
        out["log"] = {"x": X, "tau": tau}
    log(f"{name} {label}: prediction error {out['prediction_error']['median'] if pred_err else float('nan'):.1e} "
        f"(median), violations {viol}, peak qd {max(out['speed_peak_fraction']):.2f} qd_max, re-solve CPU "
        f"median {out['resolve_cpu_ms']['median']:.2f} p99 {out['resolve_cpu_ms']['p99']:.2f} worst "
        f"{out['resolve_cpu_ms']['worst']:.2f} ms, modes {modes}, goal {1e3 * goal_err:.3f} mm"
        + f"; {out['verdict']}" + "".join(f"; {c['note']}" for c in out.get("admissibility", [])
                                         if not c["keeps_speed_limits"]))
    return out


def mpc_suite(name, quick) -> dict:
    from kindyngen.control.integrators import Integrator
    from kindyngen.control.reach import ReachNLP
    model, robot, limits, task = cr.load(name)
    # the reference leaves the MPC's torque reserve (MPCOptions.reserve) to the inner loop
    rt = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3, margin_position=0.05,
                 margin_torque=0.1)
    res = ReachNLP(robot, rt).solve()
    if not res.success:
        return {"error": f"reference reach: {res.status}"}
    ref = {"X": np.hstack([res.q, res.qd]), "U": res.tau, "goal": task.goal}
    rows = [mpc_case(name, model, robot, limits, ref, label, d, quick) for label, d in cases(limits, robot.n, quick)]
    return {"robot": name, "reference": {"objective": res.objective, "iterations": res.iterations,
                                         "integrator": "rk4 x2", "margin_speed": 0.3, "margin_position_rad": 0.05,
                                         "margin_torque": 0.1},
            "cases": rows}


def plot(doc, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    reach = [r for r in doc["reach"] if "ours" in r]
    names = [r["robot"] for r in reach]
    x = np.arange(len(names))
    axes[0].bar(x - 0.25, [r["ours"]["cold_cpu_s_median"] for r in reach], 0.25, label="ours, cold")
    axes[0].bar(x, [r["warm"]["cpu_s_median"] for r in reach], 0.25, label="ours, warm re-solve")
    axes[0].bar(x + 0.25, [r["baseline"]["cold_cpu_s_median"] for r in reach], 0.25, label="Opti + IPOPT baseline")
    labelled = set()

    def mark(x, y, style, label):
        axes[0].plot(x, y, style, label=None if label in labelled else label)
        labelled.add(label)
    for i, r in enumerate(reach):
        rows = r.get("crocoddyl", {}).get("rows", [])
        if rows:
            ok = rows[0]["status"].startswith("converged")
            mark(i + 0.25, rows[0]["solve_cpu_s"], "k^" if ok else "kx",
                 "Crocoddyl CSQP" + ("" if ok else " (stopped, not converged)"))
        ac = r.get("acados", {}).get("row")
        if ac:
            mark(i + 0.25, ac["solve_cpu_s"], "ms" if ac["success"] else "m+",
                 "acados SQP" + ("" if ac["success"] else " (max iterations)"))
    axes[0].set_yscale("log")
    axes[0].set_xticks(x, names)
    axes[0].set_ylabel("reach solve CPU [s]")
    axes[0].legend(fontsize=8)
    for r in doc["mpc"]:
        if "cases" not in r:
            continue
        p99 = [c["resolve_cpu_ms"]["p99"] for c in r["cases"]]
        axes[1].plot(range(len(p99)), p99, "o-", label=r["robot"])
    axes[1].axhline(10, color="k", ls=":", lw=1)
    axes[1].set_xlabel("disturbance case (JSON order)")
    axes[1].set_ylabel("MPC re-solve CPU p99 [ms]")
    axes[1].legend(fontsize=8)
    fig.suptitle(f"{doc['machine']['cpu']}, load at start: {doc['uptime_start'].split('load average:')[-1].strip()}",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "control.json"),
                    help="the JSON (the plot beside it, .png)")
    ap.add_argument("--quick", action="store_true",
                    help="one solve per row, two torque-step joints per robot, Crocoddyl at 100 iterations")
    ap.add_argument("--robots", nargs="+", default=list(cr.ROBOTS), choices=list(cr.ROBOTS))
    ap.add_argument("--repeats", type=int, default=5, help="solves per reach row, median CPU (default 5)")
    ap.add_argument("--no-reach", action="store_true", help="skip part 1 (the reach)")
    ap.add_argument("--no-mpc", action="store_true", help="skip part 2 (the MPC suite)")
    ap.add_argument("--no-peers", action="store_true", help="skip Crocoddyl and acados")
    ap.add_argument("--crocoddyl-venv", default=str(ROOT / ".venv-crocoddyl"),
                    help="environment with crocoddyl, mim-solvers (benchmarks/crocoddyl_reach.py)")
    ap.add_argument("--acados-venv", default=str(ROOT / ".venv-acados"),
                    help="environment with comma-deps-acados (benchmarks/acados_reach.py; the first run of each "
                         "robot generates and compiles its solver, minutes)")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    doc = {"machine": machine(), "uptime_start": uptime(), "quick": args.quick,
           "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"), "reach": [], "mpc": []}
    import casadi
    doc["versions"] = {"casadi": casadi.__version__}
    for name in args.robots:
        if not cr.available(name):
            doc["reach"].append({"robot": name, "error": f"{cr.ROBOTS[name].description} not installed"})
            continue
        if not args.no_reach:
            doc["reach"].append(reach_rows(name, repeats, 1 if args.quick else 3, Path(args.crocoddyl_venv),
                                           Path(args.acados_venv), args.quick, not args.no_peers))
        if not args.no_mpc:
            doc["mpc"].append(mpc_suite(name, args.quick))
    doc["uptime_end"] = uptime()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    plot(doc, out.with_suffix(".png"))
    log(f"wrote {out} and {out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
