"""The LWR reach of issue 27 as optimal-control problems built from the generated CasADi
Functions, in several formulations, for examples/ocp.py, examples/mpc.py and
benchmarks/ocp_bench.py.

The problem (robots/lwr4.yaml): start at rest at q0 = (0, 0.5, 0, -1, 0, 0, 0); the flange
position at (0.35, 0.25, 0.55) m and the arm at rest at T = 1 s; |tau| <= (176, 176, 100, 100,
100, 30, 30) N m; joint limits on q and the data-sheet speed limits on qd at the nodes (QD_MAX below); minimise the integral of |tau|^2 with tau
piecewise constant on N = 20 intervals; initial guess: rest at q0 with gravity-compensating
torques.

Formulations (every one integrates the forward dynamics by one classic RK4 step per interval,
so all converge to the same discrete problem):
  baseline   Opti + IPOPT, exact Hessian, `fd` called on MX symbols in an explicit RK4 step
             (what a new user writes; the issue's reference).
  fd_rk4     the same explicit RK4 step of `fd`, in one SX graph, variables and constraints
             ordered stage by stage (x0, u0, x1, u1, ...).
  id_rk4     implicit RK4 with inverse dynamics: the four RK4 stage accelerations a1..a4 are
             decision variables of each interval, tied to the torque by the generated inverse
             dynamics `tau(q_i, qd_i, a_i) = tau_k` at the four RK4 stage states; the stage
             states and the next node are then linear in (x_k, a1..a4). At a solution it is
             exactly the explicit RK4 step of the forward dynamics, but no mass matrix is
             inverted in the NLP and the Hessian is that of the recursive Newton-Euler only.
Solvers: `ipopt` (MUMPS, exact Hessian), `fatrop` (stage structure declared by hand:
structure_detection manual with nx, nu, ng per stage), `sqp` (CasADi's sqpmethod, exact
Hessian, qrqp QP; for warm-started re-solves).

Worked example::

    >>> from ocp_reach import reach_problem                               # doctest: +SKIP
    >>> nlp = reach_problem("id_rk4")                                      # doctest: +SKIP
    >>> r = nlp.solve(); r["status"], round(r["objective"], 3)             # doctest: +SKIP
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

Q0 = np.array([0.0, 0.5, 0.0, -1.0, 0.0, 0.0, 0.0])
GOAL = np.array([0.35, 0.25, 0.55])
TAU_MAX = np.array([176, 176, 100, 100, 100, 30, 30.0])
# KUKA LWR IV+ data-sheet joint speeds (110, 110, 128, 128, 204, 184, 184 deg/s), bounds on qd
# at the nodes. Without them the minimum-torque plan of the statement (N = 20, one RK4
# step per interval) spins the light wrist at up to 385 rad/s and exploits RK4's error: its
# torques applied to Pinocchio's ABA at 20 steps per interval end 164 rad/s and 1.47 m away.
QD_MAX = np.array([110, 110, 128, 128, 204, 184, 184]) * np.pi / 180
HORIZON_S = 1.0
FORMULATIONS = ("baseline", "fd_rk4", "id_rk4")
SOLVERS = ("ipopt", "fatrop", "sqp")


def load(robot_name: str = "lwr4", folder: Path | None = None) -> dict:
    """The robot description and the generated Functions fd, tau, fk_hom."""
    from kindyngen.readers.yaml_description import load_robot
    folder = Path(folder or ROOT / "generated" / robot_name / "casadi")
    funcs = {"robot": load_robot(ROOT / "robots" / f"{robot_name}.yaml")}
    for name in ("fd", "tau", "fk_hom"):
        funcs[name] = ca.Function.load(str(folder / f"{name}.casadi"))
    return funcs


def setup_dict(funcs: dict, N: int = 20, T: float = HORIZON_S) -> dict:
    """Problem data in the form examples/ocp.py's resimulate() reads."""
    robot = funcs["robot"]
    n = robot.n
    return {"problem": "lwr4_reach", "robot": robot, "n": n, "N": N, "T": T, "kind": "reach",
            "q_lo": np.array(robot.lower, float), "q_hi": np.array(robot.upper, float),
            "qd_max": QD_MAX.copy(), "tau_max": TAU_MAX.copy(), "q0": Q0.copy(), "goal": GOAL.copy(),
            "gravity_torque": np.array(funcs["tau"](Q0, np.zeros(n), np.zeros(n))).ravel()}


def _rk4_fd(fd, n, h, substeps=1):
    hs = h / substeps

    def step(x, u):
        f = lambda z: ca.vertcat(z[n:], fd(z[:n], z[n:], u))   # noqa: E731
        for _ in range(substeps):
            k1 = f(x)
            k2 = f(x + hs / 2 * k1)
            k3 = f(x + hs / 2 * k2)
            k4 = f(x + hs * k3)
            x = x + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x
    return step


def _id_rk4_stage(tau, n, h, substeps=1):
    """(x, u = (tau, a_1..a_4M)) -> (next node, inverse-dynamics residuals at the 4 M RK4
    stages of M = substeps RK4 steps): the explicit RK4 steps of fd written implicitly."""
    M = substeps
    hs = h / M
    x, u = ca.SX.sym("x", 2 * n), ca.SX.sym("u", (1 + 4 * M) * n)
    q, v, tk = x[:n], x[n:], u[:n]
    res = []
    for m in range(M):
        a = [u[n * (1 + 4 * m + i):n * (2 + 4 * m + i)] for i in range(4)]
        vs = [v, v + hs / 2 * a[0], v + hs / 2 * a[1], v + hs * a[2]]
        qs = [q, q + hs / 2 * vs[0], q + hs / 2 * vs[1], q + hs * vs[2]]
        res += [tau(qs[i], vs[i], a[i]) - tk for i in range(4)]
        q, v = (q + hs / 6 * (vs[0] + 2 * vs[1] + 2 * vs[2] + vs[3]),
                v + hs / 6 * (a[0] + 2 * a[1] + 2 * a[2] + a[3]))
    return ca.Function("id_rk4_stage", [x, u], [ca.vertcat(q, v), ca.vertcat(*res)], ["x", "u"],
                       ["x_next", "id_residual"])


@dataclass
class ReachNLP:
    """A built solver of the reach, parametrised by the initial state and the goal (so that
    examples/mpc.py re-solves it from each measured state). Variables ordered by stage:
    (x0, u0, x1, u1, ..., xN); u = tau (fd_rk4) or (tau, a1..a4) (id_rk4)."""
    setup: dict
    formulation: str
    solver_name: str
    solver: ca.Function
    nu: int
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    build_s: float
    substeps: int = 1
    last: dict = field(default_factory=dict)

    @property
    def n(self):
        return self.setup["n"]

    def guess(self) -> np.ndarray:
        """Rest at q0 with gravity-compensating torques (accelerations 0)."""
        n, N = self.n, self.setup["N"]
        xr = np.concatenate([self.setup["q0"], np.zeros(n)])
        ur = np.concatenate([self.setup["gravity_torque"], np.zeros(self.nu - n)])
        return np.concatenate([np.concatenate([xr, ur])] * N + [xr])

    def unpack(self, z: np.ndarray):
        n, N, nu = self.n, self.setup["N"], self.nu
        st = 2 * n + nu
        X = np.array([z[k * st:k * st + 2 * n] for k in range(N + 1)])
        U = np.array([z[k * st + 2 * n:(k + 1) * st] for k in range(N)])
        return X, U

    def shifted(self, z: np.ndarray) -> np.ndarray:
        """The warm start of the next receding-horizon step: every stage moved one interval
        earlier, the last interval repeated (its end is at rest at the goal)."""
        st = 2 * self.n + self.nu
        N = self.setup["N"]
        body = z[st:N * st]                       # stages 1..N-1 (x, u)
        last_u = z[(N - 1) * st + 2 * self.n:N * st]
        xN = z[N * st:]
        return np.concatenate([body, xN, last_u, xN])

    def solve(self, x_init=None, goal=None, z0=None, lam_g0=None) -> dict:
        n = self.n
        x_init = np.concatenate([self.setup["q0"], np.zeros(n)]) if x_init is None else np.asarray(x_init)
        goal = self.setup["goal"] if goal is None else np.asarray(goal)
        args = {"x0": self.guess() if z0 is None else z0, "lbx": self.lbx, "ubx": self.ubx,
                "lbg": self.lbg, "ubg": self.ubg, "p": np.concatenate([x_init, goal])}
        if lam_g0 is not None:
            args["lam_g0"] = lam_g0
        t0, c0 = time.perf_counter(), time.process_time()
        sol = self.solver(**args)
        solve_s, solve_cpu_s = time.perf_counter() - t0, time.process_time() - c0
        stats = self.solver.stats()
        z = np.array(sol["x"]).ravel()
        X, U = self.unpack(z)
        N, T = self.setup["N"], self.setup["T"]
        g = np.array(sol["g"]).ravel()
        viol = float(max(np.max(g - self.ubg, initial=0), np.max(self.lbg - g, initial=0)))
        res = {"status": str(stats.get("return_status", stats.get("success"))), "success": bool(stats["success"]),
               "iterations": int(stats.get("iter_count", -1)), "solve_s": solve_s, "solve_cpu_s": solve_cpu_s,
               "build_s": self.build_s,
               "formulation": self.formulation, "solver": self.solver_name, "substeps": self.substeps,
               "N": N, "T": T,
               "t": np.linspace(0, T, N + 1), "q": X[:, :n], "qd": X[:, n:], "tau": U[:, :n],
               "objective": float(sol["f"]), "max_constraint_violation": viol,
               "z": z, "lam_g": np.array(sol["lam_g"]).ravel()}
        self.last = res
        return res


def reach_problem(formulation: str = "id_rk4", solver: str = "ipopt", N: int = 20, funcs: dict | None = None,
                  options: dict | None = None, verbose: bool = False, substeps: int = 1,
                  qd_bound: np.ndarray | None = None) -> ReachNLP:
    """Build the reach NLP (stage-ordered, SX) for formulation fd_rk4 or id_rk4; `qd_bound`:
    the speed bound at the nodes (default QD_MAX, the data sheet; examples/mpc_sqp.py plans
    below it so that its tracking MPC has room under the limit)."""
    if formulation not in ("fd_rk4", "id_rk4"):
        raise ValueError(f"formulation {formulation!r}: reach_problem builds fd_rk4 or id_rk4 (baseline: solve_baseline)")
    if solver not in SOLVERS:
        raise ValueError(f"solver {solver!r}: one of {', '.join(SOLVERS)}")
    t0 = time.perf_counter()
    funcs = funcs or load()
    setup = setup_dict(funcs, N)
    n, T = setup["n"], setup["T"]
    h = T / N
    M = substeps
    nu = n if formulation == "fd_rk4" else (1 + 4 * M) * n
    ng_path = 0 if formulation == "fd_rk4" else 4 * M * n
    st = 2 * n + nu
    Z = ca.SX.sym("z", (N + 1) * 2 * n + N * nu)
    P = ca.SX.sym("p", 2 * n + 3)           # initial state, goal position
    X = [Z[k * st:k * st + 2 * n] for k in range(N + 1)]
    U = [Z[k * st + 2 * n:(k + 1) * st] for k in range(N)]
    if formulation == "fd_rk4":
        xs, us = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n)
        step = ca.Function("fd_rk4_step", [xs, us], [_rk4_fd(funcs["fd"], n, h, M)(xs, us)])
        stage = lambda x, u: (step(x, u), None)   # noqa: E731
    else:
        f = _id_rk4_stage(funcs["tau"], n, h, M)
        stage = lambda x, u: tuple(f(x, u))        # noqa: E731
    g, lbg = [], []
    # fatrop's stage layout: per stage k the gap x_{k+1} - F(x_k, u_k) first, then the path
    # constraints of stage k (the initial state at k = 0); the terminal constraints last
    for k in range(N):
        nxt, res = stage(X[k], U[k])
        g.append(X[k + 1] - nxt)
        lbg.append(np.zeros(2 * n))
        if res is not None:
            g.append(res)
            lbg.append(np.zeros(ng_path))
        if k == 0:
            g.append(X[0] - P[:2 * n])
            lbg.append(np.zeros(2 * n))
    tip = funcs["fk_hom"](X[N][:n])[:3, 3]
    g.append(ca.vertcat(tip - P[2 * n:], X[N][n:]))
    lbg.append(np.zeros(3 + n))
    lbg = np.concatenate(lbg)
    J = h * sum(ca.sumsqr(U[k][:n]) for k in range(N))
    vb = QD_MAX if qd_bound is None else np.asarray(qd_bound, float)
    xlo, xhi = np.concatenate([setup["q_lo"], -vb]), np.concatenate([setup["q_hi"], vb])
    ulo = np.concatenate([-TAU_MAX, np.full(nu - n, -np.inf)])
    uhi = np.concatenate([TAU_MAX, np.full(nu - n, np.inf)])
    # node 0 is the measured state (fixed by the constraint x0 = p): no bounds there, so that
    # a plant state a little beyond a speed limit (between nodes) leaves the re-solve feasible
    free = np.full(2 * n, np.inf)
    lbx = np.concatenate([-free, ulo] + [np.concatenate([xlo, ulo])] * (N - 1) + [xlo])
    ubx = np.concatenate([free, uhi] + [np.concatenate([xhi, uhi])] * (N - 1) + [xhi])
    nlp = {"x": Z, "p": P, "f": J, "g": ca.vertcat(*g)}
    opts = {"print_time": False}
    if solver == "ipopt":
        opts.update({"ipopt.print_level": 5 if verbose else 0, "ipopt.tol": 1e-8, "ipopt.max_iter": 1000,
                     "ipopt.sb": "yes"})
        name = "ipopt"
    elif solver == "fatrop":
        opts.update({"structure_detection": "manual", "N": N, "nx": [2 * n] * (N + 1), "nu": [nu] * N + [0],
                     "ng": [ng_path + 2 * n] + [ng_path] * (N - 1) + [3 + n],
                     "fatrop.print_level": 10 if verbose else 0, "fatrop.tol": 1e-8, "fatrop.max_iter": 1000})
        name = "fatrop"
    else:
        opts.update({"qpsol": "qrqp", "hessian_approximation": "exact", "max_iter": 50, "tol_pr": 1e-8,
                     "tol_du": 1e-6, "print_header": False, "print_iteration": verbose,
                     "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False,
                                       "error_on_fail": False},
                     "error_on_fail": False})
        name = "sqpmethod"
    opts.update(options or {})
    built = ca.nlpsol(f"reach_{formulation}_{solver}", name, nlp, opts)
    return ReachNLP(setup, formulation, solver, built, nu, lbx, ubx, lbg, lbg.copy(), time.perf_counter() - t0, M)


def solve_baseline(N: int = 20, funcs: dict | None = None, verbose: bool = False, substeps: int = 1,
                   ipopt_options: dict | None = None) -> dict:
    """The issue's reference: Opti + IPOPT (exact Hessian, MUMPS), fd called on MX symbols in
    an explicit RK4 step per interval, constraints in the order a user writes them.
    ipopt_options (keys with or without "ipopt."): added to IPOPT's, e.g. examples/ocp_fd_options.FAST
    to compare like with like; the issue's baseline is without."""
    t0 = time.perf_counter()
    funcs = funcs or load()
    setup = setup_dict(funcs, N)
    n, T = setup["n"], setup["T"]
    h = T / N
    opti = ca.Opti()
    X = opti.variable(2 * n, N + 1)
    U = opti.variable(n, N)
    step = _rk4_fd(funcs["fd"], n, h, substeps)
    for k in range(N):
        opti.subject_to(X[:, k + 1] == step(X[:, k], U[:, k]))
    opti.subject_to(X[:, 0] == np.concatenate([setup["q0"], np.zeros(n)]))
    for k in range(1, N + 1):
        opti.subject_to(opti.bounded(setup["q_lo"], X[:n, k], setup["q_hi"]))
        opti.subject_to(opti.bounded(-QD_MAX, X[n:, k], QD_MAX))
    for k in range(N):
        opti.subject_to(opti.bounded(-TAU_MAX, U[:, k], TAU_MAX))
    opti.subject_to(funcs["fk_hom"](X[:n, N])[:3, 3] == setup["goal"])
    opti.subject_to(X[n:, N] == 0)
    opti.minimize(h * ca.sumsqr(U))
    opti.set_initial(X, np.tile(np.concatenate([setup["q0"], np.zeros(n)])[:, None], (1, N + 1)))
    opti.set_initial(U, np.tile(setup["gravity_torque"][:, None], (1, N)))
    ipopt = {"print_level": 5 if verbose else 0, "tol": 1e-8, "max_iter": 1000, "sb": "yes"}
    ipopt.update({k[len("ipopt."):] if k.startswith("ipopt.") else k: v for k, v in (ipopt_options or {}).items()})
    opti.solver("ipopt", {"print_time": False}, ipopt)
    build_s = time.perf_counter() - t0
    t1, c1 = time.perf_counter(), time.process_time()
    try:
        sol = opti.solve()
        ok = True
    except RuntimeError:
        sol = opti.debug
        ok = False
    solve_s, solve_cpu_s = time.perf_counter() - t1, time.process_time() - c1
    stats = opti.stats()
    Xv, Uv = np.array(sol.value(X)), np.array(sol.value(U)).reshape(n, N)
    return {"status": stats["return_status"], "success": ok and bool(stats["success"]),
            "iterations": int(stats["iter_count"]), "solve_s": solve_s, "solve_cpu_s": solve_cpu_s, "build_s": build_s,
            "formulation": "baseline", "solver": "ipopt (Opti)", "substeps": substeps, "N": N, "T": T, "t": np.linspace(0, T, N + 1),
            "q": Xv[:n].T, "qd": Xv[n:].T, "tau": Uv.T, "objective": float(sol.value(opti.f))}


def check(setup: dict, res: dict, funcs: dict, resim_substeps: int = 20) -> dict:
    """Independent check of a solution: the torques applied piecewise constant to Pinocchio's
    ABA (tests/reference.py's model, RK4 with `resim_substeps` steps per interval), the
    re-simulated flange position and velocity at T, and the limits."""
    sys.path.insert(0, str(ROOT / "examples"))
    import ocp
    import pinocchio as pin
    sys.path.insert(0, str(ROOT / "tests"))
    from reference import pinocchio_model
    sim = ocp.resimulate(setup, res, resim_substeps)
    model, data, flange = pinocchio_model(setup["robot"])
    # the plan's own discretisation re-done by Pinocchio: from every planned node, the
    # planner's RK4 steps (res["substeps"] per interval) of pin.aba; the largest difference
    # from the next planned node says whether the plan satisfies its discrete dynamics
    n, N, M = setup["n"], res["N"], res.get("substeps", 1)
    hs = res["T"] / N / M

    def f(x, u):
        return np.concatenate([x[n:], pin.aba(model, data, x[:n], x[n:], u)])
    step_err = 0.0
    for k in range(N):
        x = np.concatenate([res["q"][k], res["qd"][k]])
        u = res["tau"][k]
        for _ in range(M):
            k1 = f(x, u)
            k2 = f(x + hs / 2 * k1, u)
            k3 = f(x + hs / 2 * k2, u)
            k4 = f(x + hs * k3, u)
            x = x + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        step_err = max(step_err, float(np.abs(x - np.concatenate([res["q"][k + 1], res["qd"][k + 1]])).max()))
    sim["plan_step_error"] = step_err
    qT = sim["q_fine"][-1]
    pin.framesForwardKinematics(model, data, qT)
    sim["resim_goal_error_m"] = float(np.linalg.norm(data.oMf[flange].translation - setup["goal"]))
    sim["resim_final_speed"] = float(np.abs(sim["qd_fine"][-1]).max())
    return sim
