"""Time-optimal point-to-point motions over any prepared robot: from rest at q0 to rest at qf in
the least time T (plus a small torque regulariser w h sum |tau_k / tau_max|^2), multiple shooting
with the integrator's steps of the generated fd (one SX step mapped over the N intervals of
T / N), joint position and speed limits at the nodes and at the inner substep ends, torques as
bounds; IPOPT. (examples/ocp.py's problem, written for any robot.)

Example (tests/control/test_reach.py runs it on the UR5)::

    res = solve_time_optimal(robot, limits, q0, qf, N=20)       # res["T"], res["q"], res["tau"]
"""
from __future__ import annotations

import time

import numpy as np

from .integrators import Integrator
from .robot import ControlError, ControlRobot, Limits


def solve_time_optimal(robot: ControlRobot, limits: Limits, q0, qf, N: int = 20,
                       integrator: Integrator = Integrator("rk4", 4), weight: float = 1e-2,
                       speed_margin: float = 0.05, T_guess: float = 1.5, T_bounds=(0.05, 10.0),
                       ipopt: dict | None = None) -> dict:
    """Solve; returns status, iterations, solve_cpu_s, T, t, q, qd, tau."""
    import casadi as ca
    n = robot.n
    q0, qf = np.asarray(q0, float), np.asarray(qf, float)
    if len(q0) != n or len(qf) != n:
        raise ControlError(f"q0 and qf need {n} values each")
    lim = limits.backed_off(speed_margin)
    xs, us, hs = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n), ca.SX.sym("h")
    end, inner = integrator.step(robot.fd, n, hs, xs, us)
    outs = [end] + ([ca.horzcat(*inner)] if inner else [])
    step = ca.Function("step", [xs, us, hs], outs)
    T = ca.MX.sym("T")
    X = ca.MX.sym("X", 2 * n, N + 1)
    U = ca.MX.sym("U", n, N)
    mapped = step.map(N)(X[:, :N], U, ca.repmat(T / N, 1, N))
    Xnext = mapped[0] if inner else mapped
    g = [ca.vec(Xnext - X[:, 1:])]
    lbg, ubg = [np.zeros(2 * n * N)], [np.zeros(2 * n * N)]
    xlo = np.concatenate([lim.array("q_lo"), -lim.array("qd_max")])
    xhi = np.concatenate([lim.array("q_hi"), lim.array("qd_max")])
    if inner:
        cnt = len(inner) * N
        g.append(ca.vec(mapped[1]))
        lbg.append(np.tile(xlo, cnt))
        ubg.append(np.tile(xhi, cnt))
    tm = lim.array("tau_max")
    J = T + weight * (T / N) * ca.sumsqr(U / ca.repmat(ca.DM(tm), 1, N))
    V = ca.vertcat(T, ca.vec(X), ca.vec(U))
    Xlo, Xhi = np.tile(xlo[:, None], (1, N + 1)), np.tile(xhi[:, None], (1, N + 1))
    Xlo[:, 0] = Xhi[:, 0] = np.concatenate([q0, np.zeros(n)])
    Xlo[:, -1] = Xhi[:, -1] = np.concatenate([qf, np.zeros(n)])
    lbx = np.concatenate([[T_bounds[0]], Xlo.ravel(order="F"), np.tile(-tm, N)])
    ubx = np.concatenate([[T_bounds[1]], Xhi.ravel(order="F"), np.tile(tm, N)])
    s = np.linspace(0, 1, N + 1)
    Xg = np.zeros((2 * n, N + 1))
    Xg[:n] = q0[:, None] + (qf - q0)[:, None] * s[None, :]
    guess = np.concatenate([[T_guess], Xg.ravel(order="F"), np.zeros(n * N)])
    opts = {"print_time": False, "ipopt.print_level": 0, "ipopt.tol": 1e-8, "ipopt.max_iter": 3000, "ipopt.sb": "yes"}
    opts.update(ipopt or {})
    solver = ca.nlpsol("time_optimal", "ipopt", {"x": V, "f": J, "g": ca.vertcat(*g)}, opts)
    t0, c0 = time.perf_counter(), time.process_time()
    sol = solver(x0=guess, lbx=lbx, ubx=ubx, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    st = solver.stats()
    v = np.array(sol["x"]).ravel()
    Tv = float(v[0])
    Xv = v[1:1 + 2 * n * (N + 1)].reshape(N + 1, 2 * n)
    Uv = v[1 + 2 * n * (N + 1):].reshape(N, n)
    return {"success": bool(st["success"]), "status": st["return_status"], "iterations": int(st["iter_count"]),
            "solve_s": wall, "solve_cpu_s": cpu, "T": Tv, "t": np.linspace(0, Tv, N + 1), "q": Xv[:, :n],
            "qd": Xv[:, n:], "tau": Uv, "integrator": integrator.tag}
