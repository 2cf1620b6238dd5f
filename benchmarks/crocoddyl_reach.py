"""The LWR reach in Crocoddyl (FDDP, Pinocchio's analytic derivatives): the peer of
benchmarks/ocp_bench.py, run in its own virtual environment (Crocoddyl 3.2.1 from the
registry crashes against pin 4.1; this set loads):

    python -m venv .venv-crocoddyl
    .venv-crocoddyl/bin/pip install crocoddyl==3.0.1 pin==3.4.0 "cmeel-urdfdom<5" "cmeel-tinyxml2<11"
    .venv-crocoddyl/bin/python benchmarks/crocoddyl_reach.py --urdf examples/results/urdf/lwr4.urdf

A penalty formulation, not the hard-constrained NLP of examples/ocp_reach.py: the flange
position (weight 1e5) and the joint speeds (1e4) at T are terminal costs, torque 1 (the
integral of |tau|^2 up to the factor dt), state regulariser 1e-3; torque bounds as control
bounds (BoxFDDP), no joint or speed limits. Same N = 20, dt = 0.05 s, RK4, same start and guess
(rest, gravity torques). Prints one JSON line.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--urdf", required=True)
    ap.add_argument("--maxiter", type=int, default=200)
    args = ap.parse_args()
    import crocoddyl
    import pinocchio as pin
    model = pin.buildModelFromUrdf(args.urdf)
    model.gravity.linear = np.array([0, 0, -9.81])
    fid = model.getFrameId("flange")
    n, N, dt = model.nq, 20, 0.05
    q0 = np.array([0.0, 0.5, 0.0, -1.0, 0.0, 0.0, 0.0])
    goal = np.array([0.35, 0.25, 0.55])
    tau_max = np.array([176, 176, 100, 100, 100, 30, 30.0])
    state = crocoddyl.StateMultibody(model)
    act = crocoddyl.ActuationModelFull(state)

    def costs(terminal):
        cm = crocoddyl.CostModelSum(state, act.nu)
        cm.addCost("x", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelState(state, np.concatenate([q0, np.zeros(n)]), act.nu)), 1e-3)
        if terminal:
            cm.addCost("p", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelFrameTranslation(state, fid, goal, act.nu)), 1e5)
            w = np.concatenate([np.zeros(n), np.ones(n)])
            cm.addCost("v", crocoddyl.CostModelResidual(state, crocoddyl.ActivationModelWeightedQuad(w),
                                                        crocoddyl.ResidualModelState(state, np.zeros(2 * n), act.nu)), 1e4)
        else:
            cm.addCost("u", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state, act.nu)), 1.0)
        return cm

    run = crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, costs(False))
    run.u_lb, run.u_ub = -tau_max, tau_max
    running = crocoddyl.IntegratedActionModelRK(run, crocoddyl.RKType.four, dt)
    terminal = crocoddyl.IntegratedActionModelEuler(crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, costs(True)), 0.0)
    x0 = np.concatenate([q0, np.zeros(n)])
    problem = crocoddyl.ShootingProblem(x0, [running] * N, terminal)
    data = model.createData()
    g = pin.rnea(model, data, q0, np.zeros(n), np.zeros(n))
    solver = crocoddyl.SolverBoxFDDP(problem)
    xs, us = [x0] * (N + 1), [g] * N
    t0, c0 = time.perf_counter(), time.process_time()
    solver.solve(xs, us, args.maxiter, False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    iterations = int(solver.iter)
    X = np.array(solver.xs)
    pin.framesForwardKinematics(model, data, X[-1, :n])
    tip = data.oMf[fid].translation
    # warm re-solve from the solution shifted by one interval (the MPC step)
    problem.x0 = X[1]
    xs_w = list(solver.xs[1:]) + [solver.xs[-1]]
    us_w = list(solver.us[1:]) + [solver.us[-1]]
    c1 = time.process_time()
    solver.solve(xs_w, us_w, 10, False)
    warm_cpu, warm_iterations = time.process_time() - c1, int(solver.iter)
    print(json.dumps({"crocoddyl": crocoddyl.__version__, "pin": pin.__version__, "iterations": iterations,
                      "solve_s": wall, "solve_cpu_s": cpu, "goal_error_m": float(np.linalg.norm(tip - goal)),
                      "final_speed": float(np.abs(X[-1, n:]).max()), "cost": float(solver.cost),
                      "warm_resolve_cpu_s": warm_cpu, "warm_iterations": warm_iterations, "formulation": "penalty (terminal position 1e5, speed 1e4, "
                      "torque 1, state 1e-3), BoxFDDP, RK4, torque bounds only"}))


if __name__ == "__main__":
    main()
