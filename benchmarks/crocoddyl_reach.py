"""The LWR reach of examples/ocp_reach.py in Crocoddyl: the peer of benchmarks/ocp_bench.py,
run in its own virtual environment by ocp_bench (which passes the problem's numbers in
--problem and checks the returned plans with the repository's Pinocchio check). The version
set that installs together and loads (mim-solvers 0.1.1 requires pin ~= 3.7.0; the pin 3.7
wheels need urdfdom 4 and tinyxml2 10):

    python3 -m venv .venv-crocoddyl     # ocp_bench's default; or anywhere, then --crocoddyl-venv
    .venv-crocoddyl/bin/pip install crocoddyl==3.0.1.1 pin==3.7.0 mim-solvers==0.1.1 "cmeel-urdfdom<5" "cmeel-tinyxml2<11"
    OPENBLAS_NUM_THREADS=1 .venv/bin/python -m benchmarks.ocp_bench --only-crocoddyl

Newer sets do not work (docs/optimal_control.md, "Crocoddyl"): crocoddyl 3.2.1 + pin 4.1.0 +
mim-solvers 0.3.0 (what pip picks) install, but any frame residual segfaults in calc;
mim-solvers 0.2.0 is linked to libpinocchio *.so.3.8.0 while crocoddyl 3.2.0 needs *.so.3.

Three solves, each printed as one element of "rows" in one JSON line:
  csqp         THE SAME problem as ours, the way a Crocoddyl user writes it: mim-solvers'
               SolverCSQP (SQP, Gauss-Newton Hessian, ADMM QP) with ConstraintModelManager:
               |tau| <= tau_max at every interval, q in the joint limits and |qd| <= qd_max at
               nodes 1..N-1 (inequalities), at the node N q in the limits, qd = 0 and the flange
               translation at the goal (equalities as lb = ub, mim-solvers' way); cost
               ResidualModelControl with weight 2 (Crocoddyl's 1/2 |r|^2 times dt in the RK4
               quadrature = h * sum |tau_k|^2, our objective exactly); IntegratedActionModelRK
               (RK4, piecewise-constant torque, dt = T / N): the same discrete dynamics as our
               fd_rk4. Stopping rule: KKT residual <= 1e-8 (IPOPT's tol), at most --maxiter.
  csqp tol=1e-2 the same solver stopped at KKT <= 1e-2 (where it gets to in tens of iterations).
  boxfddp      a SOFTER problem (the earlier peer row): terminal position (weight 1e5) and speed
               (1e4) as penalties, torque 1, state regulariser 1e-3, torque bounds as control
               bounds (BoxFDDP), no joint or speed limits.
All from the same start and guess (rest at q0, gravity-compensating torques); CPU time
(time.process_time) median of --repeats solves; the warm re-solve from the solution shifted by
one interval (the MPC step) once each.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

# mim-solvers' defaults except filter_size: with the default (1) the filter accepts every full
# step from this start and the gaps grow to 1e6 (measured: 60 iterations, then no step found);
# with 10 it converges to the IPOPT solution's objective
CSQP_OPTIONS = {"filter_size": 10, "max_qp_iters": 1000, "eps_abs": 1e-4, "eps_rel": 0.0}


def build(problem_data, urdf):
    """The Pinocchio model, the three shooting problems and the start (x0, guess)."""
    import crocoddyl
    import pinocchio as pin
    p = {k: np.asarray(v, float) if isinstance(v, list) else v for k, v in problem_data.items()}
    model = pin.buildModelFromUrdf(urdf)
    model.gravity.linear = np.array([0, 0, -9.81])
    fid = model.getFrameId(p["frame"])
    n, N = model.nq, int(p["N"])
    dt = float(p["T"]) / N
    state = crocoddyl.StateMultibody(model)
    act = crocoddyl.ActuationModelFull(state)
    nu = act.nu
    x0 = np.concatenate([p["q0"], np.zeros(n)])

    def residual_state(ref=None):
        return crocoddyl.ResidualModelState(state, np.zeros(2 * n) if ref is None else ref, nu)

    def hard(kind):
        """kind: first (node 0: torque bounds only, the state is the given x0), running, terminal."""
        costs = crocoddyl.CostModelSum(state, nu)
        cons = crocoddyl.ConstraintModelManager(state, nu)
        if kind != "terminal":
            costs.addCost("tau", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state, nu)), 2.0)
            cons.addConstraint("tau", crocoddyl.ConstraintModelResidual(
                state, crocoddyl.ResidualModelControl(state, nu), -p["tau_max"], p["tau_max"]))
        if kind == "running":
            cons.addConstraint("x", crocoddyl.ConstraintModelResidual(
                state, residual_state(), np.concatenate([p["q_lo"], -p["qd_max"]]), np.concatenate([p["q_hi"], p["qd_max"]])))
        if kind == "terminal":
            cons.addConstraint("x", crocoddyl.ConstraintModelResidual(
                state, residual_state(), np.concatenate([p["q_lo"], np.zeros(n)]), np.concatenate([p["q_hi"], np.zeros(n)])))
            cons.addConstraint("p", crocoddyl.ConstraintModelResidual(
                state, crocoddyl.ResidualModelFrameTranslation(state, fid, p["goal"], nu), np.zeros(3), np.zeros(3)))
        return crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, costs, cons)

    def soft(terminal):
        cm = crocoddyl.CostModelSum(state, nu)
        cm.addCost("x", crocoddyl.CostModelResidual(state, residual_state(x0)), 1e-3)
        if terminal:
            cm.addCost("p", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelFrameTranslation(state, fid, p["goal"], nu)), 1e5)
            w = np.concatenate([np.zeros(n), np.ones(n)])
            cm.addCost("v", crocoddyl.CostModelResidual(state, crocoddyl.ActivationModelWeightedQuad(w), residual_state()), 1e4)
        else:
            cm.addCost("u", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state, nu)), 1.0)
        dam = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, cm)
        if not terminal:
            dam.u_lb, dam.u_ub = -p["tau_max"], p["tau_max"]
        return dam

    def rk4(dam):
        return crocoddyl.IntegratedActionModelRK(dam, crocoddyl.RKType.four, dt)

    hard_problem = crocoddyl.ShootingProblem(x0, [rk4(hard("first"))] + [rk4(hard("running"))] * (N - 1),
                                             crocoddyl.IntegratedActionModelEuler(hard("terminal"), 0.0))
    soft_problem = crocoddyl.ShootingProblem(x0, [rk4(soft(False))] * N, crocoddyl.IntegratedActionModelEuler(soft(True), 0.0))
    data = model.createData()
    g = pin.rnea(model, data, p["q0"], np.zeros(n), np.zeros(n))
    return {"model": model, "data": data, "fid": fid, "n": n, "N": N, "dt": dt, "x0": x0, "guess_u": g,
            "hard": hard_problem, "soft": soft_problem, "p": p}


def make_solver(kind, b):
    import crocoddyl
    if kind == "boxfddp":
        return crocoddyl.SolverBoxFDDP(b["soft"])
    import mim_solvers
    s = mim_solvers.SolverCSQP(b["hard"])
    for k, v in CSQP_OPTIONS.items():
        setattr(s, k, v)
    s.termination_tolerance = 1e-2 if kind == "csqp tol=1e-2" else 1e-8
    return s


def solve(kind, b, maxiter, repeats):
    """`repeats` solves from the same start with a fresh solver each; the last one's plan."""
    import pinocchio as pin
    n, N, x0 = b["n"], b["N"], b["x0"]
    cpu, wall = [], []
    for _ in range(repeats):
        solver = make_solver(kind, b)
        solver.problem.x0 = x0
        t0, c0 = time.perf_counter(), time.process_time()
        ok = solver.solve([x0] * (N + 1), [b["guess_u"]] * N, maxiter, False)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    X, U = np.array(solver.xs), np.array(solver.us)
    pin.framesForwardKinematics(b["model"], b["data"], X[-1, :n])
    tip = b["data"].oMf[b["fid"]].translation
    p = b["p"]
    iterations = int(solver.iter)
    kkt = float(solver.KKT) if kind != "boxfddp" else None
    status = ("converged" if ok else "stopped: no acceptable step" if iterations < maxiter
              else f"stopped at maxiter {maxiter}")
    if kind != "boxfddp":
        status += f" (KKT {kkt:.1e} vs tol {solver.termination_tolerance:.0e})"
    row = {"solver": kind, "status": status, "success": bool(ok), "iterations": iterations,
           "solve_cpu_s": float(np.median(cpu)), "solve_cpu_s_runs": cpu, "solve_s": float(np.median(wall)),
           "kkt": kkt, "crocoddyl_cost": float(solver.cost),
           # our objective, evaluated the same way for every row
           "objective": float(b["dt"] * np.sum(U ** 2)),
           "goal_error_m": float(np.linalg.norm(tip - p["goal"])), "final_speed": float(np.abs(X[-1, n:]).max()),
           "limit_excess": {"tau": float(np.max(np.abs(U) - p["tau_max"], initial=0)),
                            "qd_nodes": float(max(np.max(np.abs(X[1:, n:]) - p["qd_max"]), 0)),
                            "q_nodes": float(max(np.max(X[1:, :n] - p["q_hi"]), np.max(p["q_lo"] - X[1:, :n]), 0))},
           "q": X[:, :n].tolist(), "qd": X[:, n:].tolist(), "tau": U.tolist()}
    # warm re-solve from the solution shifted by one interval (the MPC step)
    solver.problem.x0 = X[1]
    c1 = time.process_time()
    solver.solve(list(solver.xs[1:]) + [solver.xs[-1]], list(solver.us[1:]) + [solver.us[-1]], 10, False)
    row["warm_resolve_cpu_s"], row["warm_iterations"] = time.process_time() - c1, int(solver.iter)
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--urdf", required=True)
    ap.add_argument("--problem", required=True,
                    help="JSON: q0, goal, tau_max, qd_max, q_lo, q_hi, N, T, frame (ocp_bench passes examples/ocp_reach.py's)")
    ap.add_argument("--maxiter", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=5, help="solves per row, median CPU time (default 5)")
    args = ap.parse_args()
    import crocoddyl
    import pinocchio as pin
    from importlib import metadata
    b = build(json.loads(args.problem), args.urdf)
    rows = [solve(kind, b, args.maxiter, args.repeats) for kind in ("csqp", "csqp tol=1e-2", "boxfddp")]
    # the distributions' versions (crocoddyl 3.0.1.1's module says 3.0.1) and the modules'
    print(json.dumps({"versions": {d: metadata.version(d) for d in ("crocoddyl", "mim-solvers", "pin")},
                      "crocoddyl": crocoddyl.__version__, "pin": pin.__version__, "csqp_options": CSQP_OPTIONS,
                      "maxiter": args.maxiter, "repeats": args.repeats, "rows": rows}))


if __name__ == "__main__":
    main()
