"""``kindyngen plan``: a reach, or a reach tracked by the MPC in a simulated closed loop, on any
fixed-base arm description (YAML or URDF).

``plan_reach`` prepares the robot (derived once, cached), compiles its native stage library
(once per N, interval and integrator), solves the reach by IPOPT and, for a URDF where
Pinocchio is installed, checks the plan against Pinocchio's own model of the file (its ABA
integrated by the plan's RK4 steps, its flange at the goal). ``track`` re-plans the reach with
margins (0.3 of every speed, 0.05 rad of every position limit) and runs the MPC
(kindyngen/control/mpc.py, closed_loop.py) against a plant: the robot's own generated dynamics
at 1 kHz (RK4), with optional measurement noise and a joint torque step: a demonstration of the
loop, not a verification (benchmarks/control_bench.py runs the Pinocchio plant).

Output folder: ``plan.json`` (the plan, the solver's report, the Pinocchio check) and, with
--track, ``track.json`` (per MPC step CPU time, iterations and mode, the plant's limit
samples, the flange's final distance from the goal).
"""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from .integrators import Integrator
from .reach import ReachNLP, ReachTask
from .robot import ControlError, prepare, read_limits, urdf_limits

OUTPUTS = ("plan.json", "track.json")


def limits_for(model, description: Path, limits_file):
    if limits_file:
        return read_limits(limits_file, model)
    if Path(description).suffix.lower() == ".urdf":
        return urdf_limits(description, model)
    raise ControlError(f"{description}: a YAML description has no speed or torque limits; give them with --limits FILE "
                       "(YAML: velocity: [...], effort: [...], one per joint)")


def pinocchio_check(description: Path, tip, task, res) -> dict:
    """Pinocchio's own model of a URDF: the plan's RK4 steps of its ABA and its flange at the goal."""
    try:
        import pinocchio as pin
    except ImportError:
        return {"skipped": "Pinocchio is not installed"}
    if Path(description).suffix.lower() != ".urdf":
        return {"skipped": "no independent model of a YAML description here (the test suite checks those)"}
    pm = pin.buildModelFromUrdf(str(description))
    if pm.nq != res.q.shape[1]:
        return {"skipped": f"Pinocchio reads {pm.nq} joints from the file, the plan has {res.q.shape[1]} (--base/--tip)"}
    pd = pm.createData()
    n, M = pm.nq, task.integrator.substeps

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
    out = {"plan_step_error": err}
    if tip and pm.existFrame(tip):
        pin.framesForwardKinematics(pm, pd, res.q[-1])
        out["goal_error_m"] = float(np.linalg.norm(pd.oMf[pm.getFrameId(tip)].translation - np.asarray(task.goal)))
    return out


def plan_reach(model, description, args, progress) -> tuple[dict, object, object, object]:
    robot = prepare(model, progress=progress)
    limits = limits_for(model, description, args.limits)
    q0 = tuple(args.q0) if args.q0 is not None else tuple(float(np.clip(0.0, lo, hi)) for lo, hi in
                                                            zip(limits.q_lo, limits.q_hi))
    if len(q0) != robot.n:
        raise ControlError(f"--q0: {len(q0)} values for {robot.n} joints")
    goal = tuple(args.goal) if args.goal is not None else tuple(robot.flange_position(q0) + np.asarray(args.offset))
    task = ReachTask(q0, goal, limits, T=args.T, N=args.N, integrator=Integrator(args.integrator, args.substeps),
                     inner=True, margin_speed=args.speed_margin, margin_position=args.position_margin)
    nlp = ReachNLP(robot, task, progress=progress)
    progress(f"solving the reach ({robot.name}, N = {task.N}, T = {task.T:g} s, {task.integrator.tag})")
    res = nlp.solve()
    from .reach import check_between_nodes
    between = check_between_nodes(nlp.lib.fd, res, limits) if res.success else None
    doc = {"robot": robot.name, "description": str(description), "n": robot.n, "q0": list(q0), "goal": list(goal),
           "T": task.T, "N": task.N, "integrator": task.integrator.tag, "limits": limits.__dict__,
           "margin_speed": task.margin_speed, "margin_position": task.margin_position, **res.as_json(),
           # the plan's torques integrated finely between the nodes by the model: what a margin must cover
           "between_nodes": between,
           "pinocchio": pinocchio_check(description, getattr(args, "tip", None), task, res)}
    progress(f"{res.status}: {res.iterations} iterations, {1e3 * res.solve_cpu_s:.1f} ms CPU, objective "
             f"{res.objective:.4f}" + (f"; between the nodes the speeds pass their limits by up to "
                                       f"{between['speed_excess']:.3g} rad/s (negative: margin left), positions by "
                                       f"{between['position_excess']:.3g} rad" if between else ""))
    if not res.success:
        raise ControlError(f"the reach was not solved ({res.status}): the goal {[round(float(v), 4) for v in goal]} may be out of "
                           f"reach in T = {task.T:g} s within the limits")
    return doc, robot, limits, task


class ModelPlant:
    """The robot's own generated dynamics at the sample rate (RK4), a joint torque step, noise."""

    def __init__(self, lib, n, noise=(0.0, 0.0), step=None, seed=0):
        self.lib, self.n, self.noise, self.torque_step = lib, n, noise, step
        self.rng = np.random.default_rng(seed)

    def step(self, x, u, dt, t):
        n = self.n
        u = np.array(u, float)
        if self.torque_step and self.torque_step[2] <= t < self.torque_step[2] + self.torque_step[3]:
            u[int(self.torque_step[0]) - 1] += self.torque_step[1]

        def f(z):
            return np.concatenate([z[n:], self.lib.fd(z[:n], z[n:], u)])
        k1 = f(x); k2 = f(x + dt / 2 * k1); k3 = f(x + dt / 2 * k2); k4 = f(x + dt * k3)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def measure(self, x, t):
        if not any(self.noise):
            return x
        n = self.n
        return x + np.concatenate([self.noise[0] * self.rng.standard_normal(n), self.noise[1] * self.rng.standard_normal(n)])


def track(robot, limits, task, args, progress) -> dict:
    from .closed_loop import Controller, simulate
    from .mpc import MPCOptions, TrackingMPC
    if abs(task.h * 1000 - round(task.h * 1000)) > 1e-9:
        raise ControlError(f"--T / --N = {task.h:g} s: with --track the MPC's interval must be a whole number of "
                           "milliseconds (the plant runs at 1 kHz)")
    rt = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3, margin_position=0.05,
                 margin_torque=0.1)
    progress("planning the reference with margins (0.3 of every speed, 0.05 rad of every position limit)")
    ref = ReachNLP(robot, rt, progress=progress).solve()
    if not ref.success:
        raise ControlError(f"the reference reach within the margins was not solved ({ref.status})")
    X, U = np.hstack([ref.q, ref.qd]), ref.tau
    mpc = TrackingMPC(robot, limits, X, U, MPCOptions(N=rt.N, h=rt.h, budget_s=args.budget_ms * 1e-3), progress)
    plant = ModelPlant(mpc.lib, robot.n, tuple(args.noise), args.torque_step)
    ctl = Controller(mpc)
    duration = task.T + args.settle
    progress(f"closed loop: {duration:g} s at 1 kHz, MPC every {1e3 * rt.h:g} ms")
    t0 = time.perf_counter()
    lg = simulate(ctl, plant, X[0].copy(), duration)
    xs = np.array(lg.x)
    n = robot.n
    q, qd = xs[:, :n], xs[:, n:]
    cpu = np.array([s["cpu_ms"] for s in lg.steps[1:]])
    viol = {"q": int(np.sum(np.any((q > limits.array("q_hi") + 1e-6) | (q < limits.array("q_lo") - 1e-6), axis=1))),
            "qd": int(np.sum(np.any(np.abs(qd) > limits.array("qd_max") + 1e-6, axis=1)))}
    goal_err = float(np.linalg.norm(robot.flange_position(q[-1]) - np.asarray(task.goal)))
    doc = {"plant": "the robot's generated dynamics, RK4 at 1 kHz" + (f", noise {list(args.noise)}" if any(args.noise) else "")
           + (f", torque step {list(args.torque_step)} (joint, N m, start s, duration s)" if args.torque_step else ""),
           "duration_s": duration, "mpc_interval_s": rt.h, "violations": viol,
           "resolve_cpu_ms": {"median": float(np.median(cpu)), "p99": float(np.percentile(cpu, 99)), "worst": float(cpu.max())},
           "modes": {m: sum(1 for s in lg.steps if s["mode"] == m) for m in ("mpc", "shifted plan", "brake")},
           "goal_error_final_m": goal_err, "wall_s": time.perf_counter() - t0, "steps": lg.steps}
    progress(f"tracked: re-solve CPU median {doc['resolve_cpu_ms']['median']:.2f} ms, p99 {doc['resolve_cpu_ms']['p99']:.2f} ms; "
             f"limit samples {viol}; flange {1e3 * goal_err:.3f} mm from the goal")
    return doc


def write(folder: Path, plan: dict, tracked: dict | None) -> None:
    (folder / "plan.json").write_text(json.dumps(plan, indent=1) + "\n")
    if tracked is not None:
        (folder / "track.json").write_text(json.dumps(tracked, indent=1) + "\n")
