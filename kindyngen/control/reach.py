"""The reach: from a state at rest, bring the flange to a goal position and the arm to rest at
T, minimising h sum |tau_k|^2 under joint position, speed and torque limits. Transcriptions
over any prepared robot:

- :class:`ReachNLP`: multiple shooting on fd, the integrator's steps and their exact
  derivatives from the native stage library (:mod:`kindyngen.control.native`), IPOPT given
  the compiled Jacobian and Hessian (the fast path);
- :func:`sx_reach_nlp`: the same NLP as one CasADi SX graph (the reference the native library
  is checked against), :func:`solve_sx` solves it by IPOPT;
- :func:`inverse_dynamics_reach`: the inverse-dynamics form (the stage accelerations unknowns,
  tied to the torque by the generated ``tau``), IPOPT on the SX graph;
- :func:`solve_fatrop`: fatrop on either SX graph;
- :func:`solve_baseline`: what a new user writes, Opti + IPOPT with ``fd`` on MX symbols.

Limits: torques as bounds; positions and speeds at every node 1..N within the limits backed off
by a stated margin (:attr:`ReachTask.margin_speed`, :attr:`ReachTask.margin_position`), and,
with ``substeps > 1`` and ``inner=True``, at the inner substep ends too (rows of the NLP);
:func:`check_between_nodes` integrates a plan finely to measure what happens between them.

Example (the LWR reach of the issue: data-sheet speeds, its torque limits; derives and compiles
the LWR once, then solves in tens of milliseconds):

    >>> import numpy as np
    >>> from kindyngen.readers.yaml_description import load_robot
    >>> from kindyngen.control.robot import Limits, prepare
    >>> model = load_robot("robots/lwr4.yaml")
    >>> qd_max = tuple(np.radians([110, 110, 128, 128, 204, 184, 184]))
    >>> limits = Limits(tuple(model.lower), tuple(model.upper), qd_max, (176, 176, 100, 100, 100, 30, 30))
    >>> task = ReachTask(q0=(0, .5, 0, -1, 0, 0, 0), goal=(.35, .25, .55), limits=limits)
    >>> res = ReachNLP(prepare(model), task).solve()
    >>> res.success, round(res.objective, 3), res.tau.shape
    (True, 716.662, (20, 7))
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .integrators import Integrator
from .native import stage_library
from .robot import ControlError, ControlRobot, Limits

#: IPOPT's adaptive barrier with the affine corrector: on the LWR reach the same KKT point as
#: the defaults in 23 iterations instead of 45 (docs/optimal_control.md, "IPOPT's options")
FAST = {"ipopt.mu_strategy": "adaptive", "ipopt.mu_oracle": "quality-function", "ipopt.corrector_type": "affine",
        "ipopt.quality_function_max_section_steps": 4}
BASE_OPTIONS = {"print_time": False, "ipopt.print_level": 0, "ipopt.tol": 1e-8, "ipopt.max_iter": 1000,
                "ipopt.sb": "yes"}


@dataclass(frozen=True)
class ReachTask:
    """A reach: start at rest at q0, flange at ``goal`` (m, base frame) and at rest at T.
    ``margin_speed``: fraction of each speed limit the plan keeps free at its nodes (and inner
    rows); ``margin_position``: rad kept from each position limit; ``margin_torque``: fraction of
    each torque limit left unused (for a tracking controller's feedback)."""
    q0: tuple
    goal: tuple
    limits: Limits
    T: float = 1.0
    N: int = 20
    integrator: Integrator = Integrator()
    inner: bool = True
    margin_speed: float = 0.0
    margin_position: float = 0.0
    margin_torque: float = 0.0

    def __post_init__(self):
        if len(self.goal) != 3:
            raise ControlError(f"goal: 3 coordinates (m), got {len(self.goal)}")
        if not self.T > 0:
            raise ControlError(f"T = {self.T}: must be positive")
        if int(self.N) != self.N or self.N < 2:
            raise ControlError(f"N = {self.N}: at least 2 intervals")
        if len(self.q0) != self.limits.n:
            raise ControlError(f"q0 has {len(self.q0)} values for {self.limits.n} joints")
        if not 0 <= self.margin_speed < 1:
            raise ControlError(f"speed margin {self.margin_speed}: must be in [0, 1)")
        lim = self.planned_limits
        q0 = np.asarray(self.q0, float)
        if np.any(q0 < lim.array("q_lo")) or np.any(q0 > lim.array("q_hi")):
            j = int(np.argmax((q0 < lim.array("q_lo")) | (q0 > lim.array("q_hi"))))
            raise ControlError(f"q0: joint {j + 1} at {q0[j]:.4g} rad is outside its limits "
                               f"[{lim.q_lo[j]:.4g}, {lim.q_hi[j]:.4g}] (margin {self.margin_position:g} rad included)")

    @property
    def h(self) -> float:
        return self.T / self.N

    @property
    def planned_limits(self) -> Limits:
        return self.limits.backed_off(self.margin_speed, self.margin_position, self.margin_torque)


@dataclass(frozen=True)
class ReachResult:
    """A solved (or not) reach: nodes t (N + 1), q, qd (N + 1 x n), tau (N x n), the solver's
    report, and the NLP's vectors (z, multipliers) for warm starts."""
    success: bool
    status: str
    iterations: int
    solve_s: float
    solve_cpu_s: float
    objective: float
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    max_constraint_violation: float
    solver: str
    z: np.ndarray = field(repr=False, default=None)
    lam_g: np.ndarray = field(repr=False, default=None)
    lam_x: np.ndarray = field(repr=False, default=None)

    def as_json(self) -> dict:
        return {"success": self.success, "status": self.status, "iterations": self.iterations, "solve_s": self.solve_s,
                "solve_cpu_s": self.solve_cpu_s, "objective": self.objective, "solver": self.solver,
                "max_constraint_violation": self.max_constraint_violation, "t": self.t.tolist(), "q": self.q.tolist(),
                "qd": self.qd.tolist(), "tau": self.tau.tolist()}


def _bounds(task: ReachTask, nu_extra: int = 0):
    """Variable bounds of z = (x_0, u_0, ..., x_N): node 0 free (fixed by x_0 = p, so that a
    measured state a little past a limit leaves a re-solve feasible), torques within their
    limits, nodes 1..N within the planned limits."""
    lim = task.planned_limits
    n, N = lim.n, task.N
    xlo = np.concatenate([lim.array("q_lo"), -lim.array("qd_max")])
    xhi = np.concatenate([lim.array("q_hi"), lim.array("qd_max")])
    tm = np.concatenate([lim.array("tau_max"), np.full(nu_extra, np.inf)])
    free = np.full(2 * n, np.inf)
    lbx = np.concatenate([-free, -tm] + [np.concatenate([xlo, -tm])] * (N - 1) + [xlo])
    ubx = np.concatenate([free, tm] + [np.concatenate([xhi, tm])] * (N - 1) + [xhi])
    return lbx, ubx


def _result(z, n, N, nu, T, status, success, iterations, wall, cpu, g_violation, solver, lam_g=None, lam_x=None):
    st = 2 * n + nu
    X = np.array([z[k * st:k * st + 2 * n] for k in range(N + 1)])
    U = np.array([z[k * st + 2 * n:k * st + 2 * n + n] for k in range(N)])
    h = T / N
    return ReachResult(bool(success), str(status), int(iterations), wall, cpu, float(h * np.sum(U ** 2)),
                       np.linspace(0, T, N + 1), X[:, :n], X[:, n:], U, float(g_violation), solver, z,
                       None if lam_g is None else np.asarray(lam_g), None if lam_x is None else np.asarray(lam_x))


class ReachNLP:
    """The reach on the native stage library, solved by IPOPT (see the module docstring).
    Parameters p = (initial state, goal) so that one built solver re-solves from any state.
    ``adaptive``: IPOPT's adaptive barrier (FAST; False: IPOPT's monotone default), ``ipopt``:
    further options (``ipopt.`` prefixed)."""

    def __init__(self, robot: ControlRobot, task: ReachTask, ipopt: dict | None = None, progress=None,
                 adaptive: bool = True):
        import casadi as ca
        t0 = time.perf_counter()
        self.robot, self.task = robot, task
        if task.limits.n != robot.n:
            raise ControlError(f"limits for {task.limits.n} joints, robot {robot.name} has {robot.n}")
        self.lib = stage_library(robot, task.N, task.h, task.integrator, task.inner, progress)
        L = self.layout = self.lib.layout
        N, h = task.N, task.h
        Z, P = ca.MX.sym("z", L.nz), ca.MX.sym("p", L.nx + 3)
        e = self.lib.externals
        g = e["kdg_nlp_g"](Z, P)
        gj, J = e["kdg_nlp_jac_g"](Z, P)
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", L.ng)
        f = h * sum(ca.sumsqr(Z[k * L.nw + L.nx:k * L.nw + L.nw]) for k in range(N))
        self.nlp = {"x": Z, "p": P, "f": f, "g": g}
        self.f_jac_g = ca.Function("nlp_jac_g", [Z, P], [gj, J], ["x", "p"], ["g", "jac_g_x"])
        self.f_hess = ca.Function("nlp_hess_l", [Z, P, lam_f, lam_g], [e["kdg_nlp_hess"](Z, P, lam_f, lam_g)],
                                  ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        self.f_g = ca.Function("g", [Z, P], [g])
        self.lbx, self.ubx = _bounds(task)
        self.lbg, self.ubg = self.row_bounds()
        opts = dict(BASE_OPTIONS, **(FAST if adaptive else {}))
        opts.update(ipopt or {})
        self.options = opts
        self.solver = self.build(opts)
        self.build_s = time.perf_counter() - t0

    def build(self, options: dict):
        import casadi as ca
        opts = {"jac_g": self.f_jac_g, "hess_lag": self.f_hess, "calc_lam_p": False}
        opts.update(options)
        return ca.nlpsol(f"reach_{self.robot.name}", "ipopt", self.nlp, opts)

    def row_bounds(self):
        """Gap, initial-state and terminal rows equal 0; inner substep states within the planned limits."""
        return _row_bounds(self.task, self.layout)

    def guess(self, x_init=None) -> np.ndarray:
        """Rest at the initial state's configuration with the gravity torque."""
        n, N = self.robot.n, self.task.N
        q = np.asarray(self.task.q0 if x_init is None else x_init[:n], float)
        xr = np.concatenate([q, np.zeros(n)])
        return np.concatenate([np.concatenate([xr, self.robot.gravity_torque(q)])] * N + [xr])

    def shifted(self, z: np.ndarray) -> np.ndarray:
        """Every interval one earlier; the appended one holds the last node with its gravity torque."""
        L, n, N = self.layout, self.robot.n, self.task.N
        xN = z[N * L.nw:]
        return np.concatenate([z[L.nw:N * L.nw], xN, self.robot.gravity_torque(xN[:n]), xN])

    def shifted_multipliers(self, lam_g: np.ndarray, lam_x: np.ndarray):
        """The constraint and bound multipliers moved with :meth:`shifted`: every interval's rows
        and bounds one interval earlier, the appended interval given the last one's; the row
        x_0 = x_init takes the old first gap's multiplier, which carried x_1's stationarity
        (without the multipliers IPOPT's warm start re-raises its barrier for every active
        bound: docs/optimal_control.md, "The warm re-solve's settings")."""
        L, N = self.layout, self.task.N
        rows = [lam_g[L.row_gap(k):L.row_gap(k) + L.nx] for k in range(N)]
        inner = [lam_g[L.row_inner(k):L.row_inner(k) + L.nin] for k in range(N)]
        out = np.array(lam_g, float).copy()
        for k in range(N):
            src = min(k + 1, N - 1)
            out[L.row_gap(k):L.row_gap(k) + L.nx] = rows[src]
            out[L.row_inner(k):L.row_inner(k) + L.nin] = inner[src]
        out[L.nx:2 * L.nx] = rows[0]
        lx = np.concatenate([lam_x[L.nw:N * L.nw], lam_x[(N - 1) * L.nw:N * L.nw], lam_x[N * L.nw:]])
        return out, lx

    def p(self, x_init=None, goal=None) -> np.ndarray:
        n = self.robot.n
        x = np.concatenate([np.asarray(self.task.q0, float), np.zeros(n)]) if x_init is None else np.asarray(x_init, float)
        return np.concatenate([x, np.asarray(self.task.goal if goal is None else goal, float)])

    def solve(self, x_init=None, goal=None, z0=None, lam_g0=None, lam_x0=None, solver=None) -> ReachResult:
        solver = solver or self.solver
        p = self.p(x_init, goal)
        args = {"x0": self.guess(x_init) if z0 is None else z0, "lbx": self.lbx, "ubx": self.ubx, "lbg": self.lbg,
                "ubg": self.ubg, "p": p}
        if lam_g0 is not None:
            args["lam_g0"] = lam_g0
        if lam_x0 is not None:
            args["lam_x0"] = lam_x0
        t0, c0 = time.perf_counter(), time.process_time()
        sol = solver(**args)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        st = solver.stats()
        z = np.array(sol["x"]).ravel()
        g = np.array(sol["g"]).ravel()
        viol = float(max(np.max(g - self.ubg, initial=0), np.max(self.lbg - g, initial=0)))
        return _result(z, self.robot.n, self.task.N, self.robot.n, self.task.T, st["return_status"], st["success"],
                       st["iter_count"], wall, cpu, viol, f"ipopt, native stages ({self.task.integrator.tag})",
                       np.array(sol["lam_g"]).ravel(), np.array(sol["lam_x"]).ravel())


def sx_reach_nlp(robot: ControlRobot, task: ReachTask):
    """The native NLP's g as one SX graph over the generated fd (same variable and row order):
    (z, p, g) SX symbols and expressions, and f."""
    import casadi as ca
    lib_layout = stage_library(robot, task.N, task.h, task.integrator, task.inner).layout
    n, N, L = robot.n, task.N, lib_layout
    Z, P = ca.SX.sym("z", L.nz), ca.SX.sym("p", L.nx + 3)
    g = ca.SX.zeros(L.ng)
    for k in range(N):
        x, u = Z[k * L.nw:k * L.nw + L.nx], Z[k * L.nw + L.nx:(k + 1) * L.nw]
        end, inner = task.integrator.step(robot.fd, n, task.h, x, u)
        g[L.row_gap(k):L.row_gap(k) + L.nx] = Z[(k + 1) * L.nw:(k + 1) * L.nw + L.nx] - end
        if L.nin:
            g[L.row_inner(k):L.row_inner(k) + L.nin] = ca.vertcat(*inner)
    g[L.nx:2 * L.nx] = Z[:L.nx] - P[:L.nx]
    xN = Z[N * L.nw:]
    g[L.ng - 3 - n:] = ca.vertcat(robot.fk_hom(xN[:n])[:3, 3] - P[L.nx:], xN[n:])
    f = task.h * sum(ca.sumsqr(Z[k * L.nw + L.nx:(k + 1) * L.nw]) for k in range(N))
    return Z, P, g, f


def solve_sx(robot: ControlRobot, task: ReachTask, ipopt: dict | None = None) -> ReachResult:
    """IPOPT on :func:`sx_reach_nlp`'s SX graph (CasADi's AD for the derivatives, IPOPT's
    defaults): the native NLP's reference route, the same variables, rows and bounds."""
    import casadi as ca
    Z, P, g, f = sx_reach_nlp(robot, task)
    lib = stage_library(robot, task.N, task.h, task.integrator, task.inner)
    lbg, ubg = _row_bounds(task, lib.layout)
    opts = dict(BASE_OPTIONS, **(ipopt or {}))
    solver = ca.nlpsol("reach_sx", "ipopt", {"x": Z, "p": P, "f": f, "g": g}, opts)
    lbx, ubx = _bounds(task)
    q0 = np.asarray(task.q0, float)
    xr = np.concatenate([q0, np.zeros(robot.n)])
    z0 = np.concatenate([np.concatenate([xr, robot.gravity_torque(q0)])] * task.N + [xr])
    t0, c0 = time.perf_counter(), time.process_time()
    sol = solver(x0=z0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=np.concatenate([xr, np.asarray(task.goal, float)]))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    st = solver.stats()
    gv = np.array(sol["g"]).ravel()
    viol = float(max(np.max(gv - ubg, initial=0), np.max(lbg - gv, initial=0)))
    return _result(np.array(sol["x"]).ravel(), robot.n, task.N, robot.n, task.T, st["return_status"], st["success"],
                   st["iter_count"], wall, cpu, viol, "ipopt (SX graph, CasADi's AD)",
                   np.array(sol["lam_g"]).ravel(), np.array(sol["lam_x"]).ravel())


def _row_bounds(task: ReachTask, L):
    """Row bounds of the native layout L: gaps, x_0 and terminal rows 0, inner states within the planned limits."""
    lim = task.planned_limits
    lbg, ubg = np.zeros(L.ng), np.zeros(L.ng)
    xlo = np.concatenate([lim.array("q_lo"), -lim.array("qd_max")])
    xhi = np.concatenate([lim.array("q_hi"), lim.array("qd_max")])
    for k in range(task.N):
        r = L.row_inner(k)
        if L.nin:
            lbg[r:r + L.nin] = np.tile(xlo, L.nin // L.nx)
            ubg[r:r + L.nin] = np.tile(xhi, L.nin // L.nx)
    return lbg, ubg


def solve_baseline(robot: ControlRobot, task: ReachTask, ipopt: dict | None = None) -> ReachResult:
    """The plain baseline: Opti + IPOPT (exact Hessian, MUMPS, IPOPT's defaults), ``fd`` called
    on MX symbols in the integrator's step, constraints in the order a user writes them; the
    same discrete problem as :class:`ReachNLP` (node limits; inner substep limits when set)."""
    import casadi as ca
    n, N, h = robot.n, task.N, task.h
    lim = task.planned_limits
    opti = ca.Opti()
    X = opti.variable(2 * n, N + 1)
    U = opti.variable(n, N)
    for k in range(N):
        end, inner = task.integrator.step(robot.fd, n, h, X[:, k], U[:, k])
        opti.subject_to(X[:, k + 1] == end)
        if task.inner:
            for xi in inner:
                opti.subject_to(opti.bounded(lim.array("q_lo"), xi[:n], lim.array("q_hi")))
                opti.subject_to(opti.bounded(-lim.array("qd_max"), xi[n:], lim.array("qd_max")))
    opti.subject_to(X[:, 0] == np.concatenate([np.asarray(task.q0, float), np.zeros(n)]))
    for k in range(1, N + 1):
        opti.subject_to(opti.bounded(lim.array("q_lo"), X[:n, k], lim.array("q_hi")))
        opti.subject_to(opti.bounded(-lim.array("qd_max"), X[n:, k], lim.array("qd_max")))
    for k in range(N):
        opti.subject_to(opti.bounded(-lim.array("tau_max"), U[:, k], lim.array("tau_max")))
    opti.subject_to(robot.fk_hom(X[:n, N])[:3, 3] == np.asarray(task.goal, float))
    opti.subject_to(X[n:, N] == 0)
    opti.minimize(h * ca.sumsqr(U))
    q0 = np.asarray(task.q0, float)
    opti.set_initial(X, np.tile(np.concatenate([q0, np.zeros(n)])[:, None], (1, N + 1)))
    opti.set_initial(U, np.tile(robot.gravity_torque(q0)[:, None], (1, N)))
    opts = {"print_level": 0, "tol": 1e-8, "max_iter": 1000, "sb": "yes"}
    opts.update({k[len("ipopt."):] if k.startswith("ipopt.") else k: v for k, v in (ipopt or {}).items()})
    opti.solver("ipopt", {"print_time": False}, opts)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        sol, ok = opti.solve(), True
    except RuntimeError:
        sol, ok = opti.debug, False
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    st = opti.stats()
    Xv, Uv = np.array(sol.value(X)), np.array(sol.value(U)).reshape(n, N)
    z = np.concatenate([np.concatenate([Xv[:, k], Uv[:, k]]) for k in range(N)] + [Xv[:, N]])
    return _result(z, n, N, n, task.T, st["return_status"], ok and st["success"], st["iter_count"], wall, cpu,
                   0.0, "ipopt (Opti, fd on MX)")


def inverse_dynamics_nlp(robot: ControlRobot, task: ReachTask) -> dict:
    """The inverse-dynamics form of the reach as one SX graph: per interval the torque and the
    integrator's stage accelerations are unknowns (u_k = (tau_k, a_0..a_{S-1})), tied by
    tau(q_i, qd_i, a_i) = tau_k at every stage (the stage states and the next node are then linear
    in the unknowns; no mass matrix is inverted). Rows in fatrop's stage layout: per interval the
    gap, the S n inverse-dynamics residuals, the inner substep states (``task.inner``), and at
    interval 0 x_0 - x_init; the terminal rows last. Returns the nlp dict, the bounds, the start
    (rest with the gravity torques), p, and fatrop's structure (nu, ng per stage)."""
    import casadi as ca
    from .integrators import TABLEAUX
    n, N, h = robot.n, task.N, task.h
    A, b = TABLEAUX[task.integrator.method]
    S = task.integrator.stages
    M = task.integrator.substeps
    hs = h / M
    nu = n * (1 + S)
    st = 2 * n + nu
    lim = task.planned_limits
    Z, P = ca.SX.sym("z", (N + 1) * 2 * n + N * nu), ca.SX.sym("p", 2 * n + 3)
    g, lbg, ubg, ng = [], [], [], []
    xlo = np.concatenate([lim.array("q_lo"), -lim.array("qd_max")])
    xhi = np.concatenate([lim.array("q_hi"), lim.array("qd_max")])
    for k in range(N):
        x, u = Z[k * st:k * st + 2 * n], Z[k * st + 2 * n:(k + 1) * st]
        q, v, tk = x[:n], x[n:], u[:n]
        acc = [u[n * (1 + i):n * (2 + i)] for i in range(S)]
        res, inner = [], []
        for m in range(M):
            if m and task.inner:
                inner.append(ca.vertcat(q, v))
            a = acc[m * len(b):(m + 1) * len(b)]
            vs, qs = [], []
            for i in range(len(b)):
                vi, qi = v, q
                for j in range(i):
                    if A[i][j]:
                        vi = vi + hs * float(A[i][j]) * a[j]
                        qi = qi + hs * float(A[i][j]) * vs[j]
                vs.append(vi)
                qs.append(qi)
            res += [robot.tau(qs[i], vs[i], a[i]) - tk for i in range(len(b))]
            q = q + hs * sum(float(b[i]) * vs[i] for i in range(len(b)) if b[i])
            v = v + hs * sum(float(b[i]) * a[i] for i in range(len(b)) if b[i])
        g += [Z[(k + 1) * st:(k + 1) * st + 2 * n] - ca.vertcat(q, v), ca.vertcat(*res), *inner]
        lbg += [np.zeros(2 * n), np.zeros(S * n)] + [xlo] * len(inner)
        ubg += [np.zeros(2 * n), np.zeros(S * n)] + [xhi] * len(inner)
        ng.append(S * n + 2 * n * len(inner))
        if k == 0:
            g.append(Z[:2 * n] - P[:2 * n])
            lbg.append(np.zeros(2 * n))
            ubg.append(np.zeros(2 * n))
            ng[0] += 2 * n
    xN = Z[N * st:]
    g.append(ca.vertcat(robot.fk_hom(xN[:n])[:3, 3] - P[2 * n:], xN[n:]))
    lbg.append(np.zeros(3 + n))
    ubg.append(np.zeros(3 + n))
    f = h * sum(ca.sumsqr(Z[k * st + 2 * n:k * st + 3 * n]) for k in range(N))
    lbx, ubx = _bounds(task, nu - n)
    q0 = np.asarray(task.q0, float)
    xr = np.concatenate([q0, np.zeros(n)])
    z0 = np.concatenate([np.concatenate([xr, robot.gravity_torque(q0), np.zeros(S * n)])] * N + [xr])
    return {"nlp": {"x": Z, "p": P, "f": f, "g": ca.vertcat(*g)}, "lbx": lbx, "ubx": ubx,
            "lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg), "x0": z0,
            "p": np.concatenate([xr, np.asarray(task.goal, float)]), "nu": nu, "ng": ng + [3 + n]}


def _solve_built(solver, d: dict, n: int, task: ReachTask, label: str) -> ReachResult:
    t0, c0 = time.perf_counter(), time.process_time()
    sol = solver(x0=d["x0"], lbx=d["lbx"], ubx=d["ubx"], lbg=d["lbg"], ubg=d["ubg"], p=d["p"])
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    st = solver.stats()
    gv = np.array(sol["g"]).ravel()
    viol = float(max(np.max(gv - d["ubg"], initial=0), np.max(d["lbg"] - gv, initial=0)))
    return _result(np.array(sol["x"]).ravel(), n, task.N, d["nu"], task.T, st.get("return_status", st["success"]),
                   st["success"], st.get("iter_count", -1), wall, cpu, viol, label)


def inverse_dynamics_reach(robot: ControlRobot, task: ReachTask, ipopt: dict | None = None) -> ReachResult:
    """The inverse-dynamics form (:func:`inverse_dynamics_nlp`) solved by IPOPT. At a solution
    it is the explicit step of the forward dynamics."""
    import casadi as ca
    d = inverse_dynamics_nlp(robot, task)
    solver = ca.nlpsol("reach_id", "ipopt", d["nlp"], dict(BASE_OPTIONS, **(ipopt or {})))
    return _solve_built(solver, d, robot.n, task, "ipopt, inverse-dynamics form (SX graph)")


def rollout(step, x0, tau, substeps: int, h: float) -> np.ndarray:
    """States at the nodes of applying ``tau`` (N x n, held per interval) from x0 with ``step(x, u,
    dt)``, ``substeps`` steps per interval (a simulator's integrator, e.g. Pinocchio's ABA by RK4)."""
    xs = [np.asarray(x0, float)]
    for u in np.asarray(tau):
        x = xs[-1]
        for _ in range(substeps):
            x = step(x, u, h / substeps)
        xs.append(x)
    return np.array(xs)


def solve_fatrop(robot: ControlRobot, task: ReachTask, options: dict | None = None,
                 formulation: str = "forward") -> ReachResult:
    """The reach solved by fatrop, CasADi's structure-exploiting interior point (a Riccati
    recursion stage by stage), on an SX graph whose rows are in fatrop's stage layout (per
    interval the gap first, then the stage's rows; the terminal rows last), the structure
    declared by hand. ``formulation``: "forward" (:func:`sx_reach_nlp`, u = tau) or
    "inverse-dynamics" (:func:`inverse_dynamics_nlp`, u = (tau, stage accelerations)).

    Started from a barrier of 1e-2 (from IPOPT's default 0.1 its iterates crept on the LWR reach,
    docs/optimal_control.md). Default tolerance: 1e-4 for the forward form, where fatrop's dual
    residual stalls (UR5 and LWR at N = 20: the primal residual 1e-12, the dual 3.9e-4 falling by
    0.2 % an iteration under an inertia correction of 10^0.5-10^1.3 at every iteration, status 1
    after 300 iterations; the stage-wise Riccati needs each stage's reduced Hessian positive
    definite, which the exact Lagrangian's is not here: it is positive only on the null space of
    the terminal rows, IPOPT's factorisation of the whole KKT system needs only that; at N = 10
    the UR5 converged to 1e-6 in 20 iterations); 1e-6 for the inverse-dynamics form, which
    converges there (the example it was ported from: LWR, 63 iterations)."""
    import casadi as ca
    n, N = robot.n, task.N
    if formulation == "forward":
        Z, P, g, f = sx_reach_nlp(robot, task)
        L = stage_library(robot, task.N, task.h, task.integrator, task.inner).layout
        lbx, ubx = _bounds(task)
        lbg, ubg = _row_bounds(task, L)
        q0 = np.asarray(task.q0, float)
        xr = np.concatenate([q0, np.zeros(n)])
        d = {"nlp": {"x": Z, "p": P, "f": f, "g": g}, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg,
             "x0": np.concatenate([np.concatenate([xr, robot.gravity_torque(q0)])] * N + [xr]),
             "p": np.concatenate([xr, np.asarray(task.goal, float)]), "nu": n,
             "ng": [L.nx + L.nin] + [L.nin] * (N - 1) + [3 + n]}
        tol = 1e-4
    elif formulation == "inverse-dynamics":
        d = inverse_dynamics_nlp(robot, task)
        tol = 1e-6
    else:
        raise ControlError(f"fatrop formulation {formulation!r}: 'forward' or 'inverse-dynamics'")
    opts = {"print_time": False, "structure_detection": "manual", "N": N, "nx": [2 * n] * (N + 1),
            "nu": [d["nu"]] * N + [0], "ng": d["ng"],
            "fatrop.print_level": 0, "fatrop.mu_init": 1e-2, "fatrop.tol": tol, "fatrop.max_iter": 300}
    opts.update(options or {})
    solver = ca.nlpsol("reach_fatrop", "fatrop", d["nlp"], opts)
    return _solve_built(solver, d, n, task, f"fatrop ({formulation} form, SX graph, stage structure by hand)")


def check_between_nodes(accel, res: ReachResult, limits: Limits, samples: int = 50) -> dict:
    """The between-node check: from every node of a plan, its torque held over the interval and
    integrated by RK4 in ``samples`` steps of ``accel(q, qd, tau) -> qdd`` (the library's ``fd``,
    or an independent simulator's); returns the largest excess (negative: the margin left) of
    the positions and speeds over the limits at those samples, in rad and rad/s, and where.

    >>> lim = Limits((-1.0,), (1.0,), (1.0,), (10.0,))
    >>> res = ReachResult(True, "", 0, 0.0, 0.0, 0.0, np.array([0.0, 1.0]), np.array([[0.0], [0.5]]),
    ...                   np.array([[0.0], [0.0]]), np.array([[1.0]]), 0.0, "")
    >>> out = check_between_nodes(lambda q, qd, u: u, res, lim, 10)   # qdd = 1 for 1 s: qd reaches 1
    >>> abs(round(out["speed_excess"], 6)), out["speed_at"]        # at the limit at the interval's end
    (0.0, (0, 10))
    """
    n = res.q.shape[1]
    lo, hi, vmax = limits.array("q_lo"), limits.array("q_hi"), limits.array("qd_max")
    q_ex, v_ex, q_at, v_at = -np.inf, -np.inf, None, None
    T = res.t[-1] - res.t[0]
    N = len(res.tau)
    dt = T / N / samples

    def f(x, u):
        return np.concatenate([x[n:], accel(x[:n], x[n:], u)])
    for k in range(N):
        x = np.concatenate([res.q[k], res.qd[k]])
        for s in range(samples):
            k1 = f(x, res.tau[k])
            k2 = f(x + dt / 2 * k1, res.tau[k])
            k3 = f(x + dt / 2 * k2, res.tau[k])
            k4 = f(x + dt * k3, res.tau[k])
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            qe = float(max(np.max(x[:n] - hi), np.max(lo - x[:n])))
            ve = float(np.max(np.abs(x[n:]) - vmax))
            if qe > q_ex:
                q_ex, q_at = qe, (k, s + 1)
            if ve > v_ex:
                v_ex, v_at = ve, (k, s + 1)
    return {"position_excess": q_ex, "position_at": q_at, "speed_excess": v_ex, "speed_at": v_at,
            "samples_per_interval": samples}
