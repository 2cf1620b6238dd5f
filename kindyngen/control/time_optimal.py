"""Time-optimal point-to-point motions over any prepared robot: from rest at q0 to rest at qf in
the least time T (plus a small torque regulariser w h sum |tau_k / tau_max|^2), multiple shooting
with the integrator's steps of the generated fd over N intervals of h = T / N, joint position and
speed limits (backed off by ``speed_margin``) at the nodes and at the inner substep ends, torques
as bounds; IPOPT. (examples/ocp.py's problem, written for any robot.)

Two routes to the same NLP (variables V = (T, vec X, vec U), the same rows, bounds, cost, guess):

- :class:`TimeOptimalNLP` (``solve_time_optimal(native=True)``, the default): the constraints,
  their Jacobian and the exact Hessian of the Lagrangian from the native time-optimal library
  (kindyngen/control/time_library.c, compiled per robot, N and integrator in about a second):
  the integrator's chain with h a variable, the Hessian from the inverse dynamics' Hessian with
  the terms of h (docs/reference/control.md);
- ``native=False``: one SX step of the integrator mapped over the intervals in an MX NLP, CasADi's
  AD for the derivatives (what examples/ocp.py's mx_map mode writes; the reference the native
  library is checked against).

Example (tests/control/test_time_optimal.py runs it on the UR5 and the Panda)::

    res = solve_time_optimal(robot, limits, q0, qf, N=20)       # res["T"], res["q"], res["tau"]
"""
from __future__ import annotations

import time

import numpy as np

from .integrators import Integrator
from .native import time_optimal_library
from .robot import ControlError, ControlRobot, Limits

IPOPT = {"print_time": False, "ipopt.print_level": 0, "ipopt.tol": 1e-8, "ipopt.max_iter": 3000, "ipopt.sb": "yes"}


class TimeOptimalProblem:
    """The NLP's data: bounds, row bounds, guess, cost weights; the MX graph of the mapped SX step
    (``mx_nlp``) for the reference route."""

    def __init__(self, robot: ControlRobot, limits: Limits, q0, qf, N: int = 20,
                 integrator: Integrator = Integrator("rk4", 4), weight: float = 1e-2, speed_margin: float = 0.05,
                 T_guess: float = 1.5, T_bounds=(0.05, 10.0)):
        n = robot.n
        self.robot, self.N, self.integrator, self.weight = robot, N, integrator, weight
        self.q0, self.qf = np.asarray(q0, float), np.asarray(qf, float)
        if len(self.q0) != n or len(self.qf) != n:
            raise ControlError(f"q0 and qf need {n} values each")
        if int(N) != N or N < 1:
            raise ControlError(f"N = {N}: at least one interval")
        lim = self.limits = limits.backed_off(speed_margin)
        self.tau_max = lim.array("tau_max")
        xlo = np.concatenate([lim.array("q_lo"), -lim.array("qd_max")])
        xhi = np.concatenate([lim.array("q_hi"), lim.array("qd_max")])
        M = integrator.substeps
        self.lbg = np.concatenate([np.zeros(2 * n * N), np.tile(xlo, (M - 1) * N)])
        self.ubg = np.concatenate([np.zeros(2 * n * N), np.tile(xhi, (M - 1) * N)])
        Xlo, Xhi = np.tile(xlo[:, None], (1, N + 1)), np.tile(xhi[:, None], (1, N + 1))
        Xlo[:, 0] = Xhi[:, 0] = np.concatenate([self.q0, np.zeros(n)])
        Xlo[:, -1] = Xhi[:, -1] = np.concatenate([self.qf, np.zeros(n)])
        self.lbx = np.concatenate([[T_bounds[0]], Xlo.ravel(order="F"), np.tile(-self.tau_max, N)])
        self.ubx = np.concatenate([[T_bounds[1]], Xhi.ravel(order="F"), np.tile(self.tau_max, N)])
        s = np.linspace(0, 1, N + 1)
        Xg = np.zeros((2 * n, N + 1))
        Xg[:n] = self.q0[:, None] + (self.qf - self.q0)[:, None] * s[None, :]
        self.guess = np.concatenate([[T_guess], Xg.ravel(order="F"), np.zeros(n * N)])
        self.p = weight / self.tau_max ** 2          # the cost's weights on u_j^2

    def cost(self, V):
        """f = T + h sum_k sum_j p_j u_kj^2 on a CasADi symbol V."""
        import casadi as ca
        n, N = self.robot.n, self.N
        U = ca.reshape(V[1 + 2 * n * (N + 1):], n, N)
        return V[0] + V[0] / N * ca.sumsqr(ca.diag(ca.DM(np.sqrt(self.p))) @ U)

    def mx_nlp(self):
        """The same NLP as one SX step mapped over the intervals in MX (CasADi's AD route)."""
        import casadi as ca
        n, N = self.robot.n, self.N
        xs, us, hs = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n), ca.SX.sym("h")
        end, inner = self.integrator.step(self.robot.fd, n, hs, xs, us)
        step = ca.Function("step", [xs, us, hs], [end] + ([ca.vertcat(*inner)] if inner else []))
        V = ca.MX.sym("V", 1 + 2 * n * (N + 1) + n * N)
        T = V[0]
        X = ca.reshape(V[1:1 + 2 * n * (N + 1)], 2 * n, N + 1)
        U = ca.reshape(V[1 + 2 * n * (N + 1):], n, N)
        mapped = step.map(N)(X[:, :N], U, ca.repmat(T / N, 1, N))
        if inner:
            g = ca.vertcat(ca.vec(mapped[0] - X[:, 1:]), ca.vec(mapped[1]))
        else:
            g = ca.vec(mapped - X[:, 1:])
        return {"x": V, "f": self.cost(V), "g": g}

    def result(self, sol, st, wall, cpu, route) -> dict:
        n, N = self.robot.n, self.N
        v = np.array(sol["x"]).ravel()
        Tv = float(v[0])
        Xv = v[1:1 + 2 * n * (N + 1)].reshape(N + 1, 2 * n)
        Uv = v[1 + 2 * n * (N + 1):].reshape(N, n)
        return {"success": bool(st["success"]), "status": st["return_status"], "iterations": int(st["iter_count"]),
                "solve_s": wall, "solve_cpu_s": cpu, "T": Tv, "t": np.linspace(0, Tv, N + 1), "q": Xv[:, :n],
                "qd": Xv[:, n:], "tau": Uv, "integrator": self.integrator.tag, "route": route,
                "objective": float(sol["f"]), "max_defect": float(np.abs(np.array(sol["g"]).ravel()[:2 * n * N]).max())}


class TimeOptimalNLP(TimeOptimalProblem):
    """The time-optimal NLP on the native library (module docstring); ``solve()``."""

    def __init__(self, *args, ipopt: dict | None = None, progress=None, **kwargs):
        import casadi as ca
        super().__init__(*args, **kwargs)
        self.lib = time_optimal_library(self.robot, self.N, self.integrator, progress)
        L = self.layout = self.lib.layout
        e = self.lib.externals
        V, P = ca.MX.sym("V", L.nv), ca.MX.sym("p", self.robot.n)
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", L.ng)
        n, N = self.robot.n, self.N
        U = ca.reshape(V[1 + 2 * n * (N + 1):], n, N)
        f = V[0] + V[0] / N * ca.sum1(ca.sum2(U ** 2) * P)
        g = e["topt_nlp_g"](V, P)
        gj, J = e["topt_nlp_jac_g"](V, P)
        self.nlp = {"x": V, "p": P, "f": f, "g": g}
        self.f_jac_g = ca.Function("nlp_jac_g", [V, P], [gj, J], ["x", "p"], ["g", "jac_g_x"])
        self.f_hess = ca.Function("nlp_hess_l", [V, P, lam_f, lam_g], [e["topt_nlp_hess"](V, P, lam_f, lam_g)],
                                  ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        opts = dict(IPOPT, **(ipopt or {}))
        opts.update({"jac_g": self.f_jac_g, "hess_lag": self.f_hess, "calc_lam_p": False})
        self.solver = ca.nlpsol(f"time_optimal_{self.robot.name}", "ipopt", self.nlp, opts)

    def solve(self) -> dict:
        t0, c0 = time.perf_counter(), time.process_time()
        sol = self.solver(x0=self.guess, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg, p=self.p)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        return self.result(sol, self.solver.stats(), wall, cpu, "native")


def solve_time_optimal(robot: ControlRobot, limits: Limits, q0, qf, N: int = 20,
                       integrator: Integrator = Integrator("rk4", 4), weight: float = 1e-2,
                       speed_margin: float = 0.05, T_guess: float = 1.5, T_bounds=(0.05, 10.0),
                       ipopt: dict | None = None, native: bool = True) -> dict:
    """Solve; returns success, status, iterations, solve_cpu_s, T, t, q, qd, tau, objective,
    max_defect (the largest gap) (native: the native library's derivatives; else CasADi's AD of
    the mapped SX step)."""
    kwargs = dict(N=N, integrator=integrator, weight=weight, speed_margin=speed_margin, T_guess=T_guess,
                  T_bounds=T_bounds)
    if native:
        return TimeOptimalNLP(robot, limits, q0, qf, ipopt=ipopt, **kwargs).solve()
    import casadi as ca
    prob = TimeOptimalProblem(robot, limits, q0, qf, **kwargs)
    solver = ca.nlpsol("time_optimal", "ipopt", prob.mx_nlp(), dict(IPOPT, **(ipopt or {})))
    t0, c0 = time.perf_counter(), time.process_time()
    sol = solver(x0=prob.guess, lbx=prob.lbx, ubx=prob.ubx, lbg=prob.lbg, ubg=prob.ubg)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return prob.result(sol, solver.stats(), wall, cpu, "mx_map")
