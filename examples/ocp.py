"""Time-optimal point-to-point motions with the generated CasADi Functions, IPOPT, and an
independent check by Pinocchio.

    .venv/bin/python examples/ocp.py --problem two_link --N 100 --out /tmp/ocp_two_link
    .venv/bin/python examples/ocp.py --problem lwr4 --out /tmp/ocp_lwr4
    .venv/bin/python examples/ocp.py --problem panda --out /tmp/ocp_panda

Direct multiple shooting: states x = (q, qd) at N + 1 nodes, torques piecewise constant on
the N intervals, one RK4 step of the generated forward dynamics `fd(q, qd, tau) -> qdd` per
interval (`--substeps` for more), free final time T (h = T / N). Limits on q and qd at the
nodes and on tau (box bounds); start and end states fixed (at rest). Objective: T, plus for
the 7-joint arms a small torque regulariser w * sum_k h |tau_k / tau_max|^2.

Problems:
  two_link  the classic time-optimal two-link problem (Van Willigenburg 1991; TOMLAB/PROPT's
            "Two-link robot"; rockit's two-link example): horizontal plane, q from (0, 0) to
            (1.5, 0) at rest, |tau1| <= 25 N m, |tau2| <= 9 N m, min T. The arm is
            examples/two_link.yaml, generated on the fly into a temporary folder.
  lwr4      KUKA LWR IV+ (robots/lwr4.yaml, the committed generated/lwr4/casadi/*.casadi):
            start and goal configurations from two Cartesian flange poses through the
            generated closed-form IK `ik_hom` (theta3 = 0, the branch valid (status 0) for both
            poses with the shortest joint-space distance).
  panda     Franka Panda (robots/panda.yaml, generated/panda/casadi/*.casadi), two given
            configurations.

--solver native (lwr4, panda): the same NLP solved by kindyngen.control.time_optimal on its
native library (constraints, Jacobian and exact Hessian in C over the generated fd and
fd_derivatives, compiled per robot, N and integrator in a few seconds; formerly --solver stages
with examples/ocp_time_stages.py). The LWR reach (minimum torque, fixed T) that was --problem
lwr4_reach is examples/ocp_reach.py.

Output in --out: ocp.json (status, iterations, solve_s, T, t, q, qd, tau, max_defect,
resim_error, limit checks), joints.png, torques.png.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = Path(__file__).resolve().parent
for _p in (str(ROOT), str(EXAMPLES)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

from kindyngen.readers.yaml_description import load_robot  # noqa: E402

PROBLEMS = ("two_link", "lwr4", "panda")
MODES = ("sx", "mx", "mx_expand", "mx_map")
# Fastest way of using the generated Functions in this NLP (examples/ocp_speed.py,
# examples/results/ocp_speed.json): one SX RK4-step Function with fd inlined, mapped over the
# intervals in an MX NLP. A pure SX NLP (fd called on SX symbols, or expand=True) iterates
# about as fast but takes 10-20 s longer to build on the 7-joint arms (its exact Hessian is
# built over the whole unrolled graph); plain MX call nodes iterate slowest.
DEFAULT_MODE = "mx_map"
VELOCITY_BACKOFF = 0.05   # fraction of each velocity limit kept free (nodes and inner RK4 steps)

# Limits of the 7-joint arms besides the position limits of the robot descriptions.
DEG = np.pi / 180
LIMITS = {
    # KUKA LWR IV+ data sheet: joint speeds 110, 110, 128, 128, 204, 184, 184 deg/s;
    # max torques 176, 176, 100, 100, 100, 38, 38 N m.
    "lwr4": {"qd": np.array([110, 110, 128, 128, 204, 184, 184]) * DEG,
             "tau": np.array([176, 176, 100, 100, 100, 38, 38.0])},
    # Franka Panda (FCI "robot and interface specifications"): qd_max 2.175 (joints 1-4),
    # 2.61 (5-7) rad/s; tau_max 87 (1-4), 12 (5-7) N m.
    "panda": {"qd": np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]),
              "tau": np.array([87, 87, 87, 87, 12, 12, 12.0])},
}


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _pose(p, yaw):
    """Flange pose: tool z axis pointing down, turned by yaw about the base z axis."""
    T = np.eye(4)
    T[:3, :3] = _rot_z(yaw) @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = p
    return T


# Cartesian start and goal poses of the LWR (flange = wrist centre, base at the shoulder).
LWR_POSES = (_pose([0.45, -0.35, 0.25], 0.0), _pose([0.35, 0.45, 0.45], np.pi / 2))
# Panda: the "ready" pose and a second configuration, both inside the limits.
PANDA_Q = (np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]),
           np.array([1.2, 0.3, -0.4, -1.6, 0.5, 2.2, -0.4]))


def load_functions(problem: str, workdir: str | None = None) -> dict:
    """The robot description and the generated Functions of ``problem`` (two_link: generated
    into ``workdir``, a temporary folder by default)."""
    if problem == "two_link":
        from kindyngen.codegen.pipeline import generate
        robot = load_robot(EXAMPLES / "two_link.yaml")
        out = generate(robot, Path(workdir or tempfile.mkdtemp(prefix="kindyngen_two_link_")),
                       languages=("casadi",), progress=False)
        folder = out / "casadi"
    else:
        robot = load_robot(ROOT / "robots" / f"{problem}.yaml")
        folder = ROOT / "generated" / problem / "casadi"
    funcs = {"robot": robot, "folder": str(folder)}
    for name in ("fd", "fk_hom", "ik_hom"):
        path = folder / f"{name}.casadi"
        if path.exists():
            funcs[name] = ca.Function.load(str(path))
    return funcs


def lwr_configurations(ik_hom, poses=LWR_POSES, theta3=0.0):
    """Start and goal from the closed-form IK: the branch with status 0 for both poses that has
    the shortest joint-space distance. Returns (q_start, q_goal, branch)."""
    sols = []
    for T in poses:
        q, status = ik_hom(ca.DM(T), theta3)
        sols.append((np.array(q), np.array(status).ravel().astype(int)))
    best = None
    for b in range(8):
        if sols[0][1][b] == 0 and sols[1][1][b] == 0:
            dist = np.linalg.norm(sols[1][0][b] - sols[0][0][b])
            if best is None or dist < best[0]:
                best = (dist, b)
    if best is None:
        raise RuntimeError(f"no IK branch valid for both poses: statuses {sols[0][1]} {sols[1][1]}")
    b = best[1]
    return sols[0][0][b], sols[1][0][b], b


def problem_setup(problem: str, funcs: dict) -> dict:
    robot = funcs["robot"]
    n = robot.n
    setup = {"problem": problem, "robot": robot, "n": n, "q_lo": np.array(robot.lower, float),
             "q_hi": np.array(robot.upper, float)}
    if problem == "two_link":
        # rockit's timeopt_pathfollowing: line yd(s) = (1.5 s, 1.5 (1 - s)), s in [0, 1], start
        # speed v0 = 1 m/s along it, turned into qd0 through the two-link IK (elbow q2 = acos(c) > 0)
        l1 = l2 = 1.0

        def ik(y):
            c = (y[0] ** 2 + y[1] ** 2 - l1 ** 2 - l2 ** 2) / (2 * l1 * l2)
            q2 = np.arccos(c)
            return np.array([np.arctan2(y[1], y[0]) - np.arctan2(l2 * np.sin(q2), l1 + l2 * c), q2])

        def yd(s_):
            return np.array([1.5 * s_, 1.5 * (1 - s_)])
        sdot0 = 1.0 / np.linalg.norm([1.5, -1.5])
        eps = 1e-6   # central difference of the IK along the line at s = 0 (error ~ 1e-12)
        qd0 = (ik(yd(eps)) - ik(yd(-eps))) / (2 * eps) * sdot0
        setup.update(kind="path", q0=ik(yd(0.0)), qf=ik(yd(1.0)), qd0=qd0, qd_max=np.full(2, np.inf),
                     tau_max=np.array([30.0, 15.0]), weight=0.0, T_guess=1.0, T_bounds=(0.0, np.inf),
                     q_bounds_in_nlp=False, line=((0.0, 1.5), (1.5, 0.0)))
    else:
        if problem == "lwr4":
            q0, qf, branch = lwr_configurations(funcs["ik_hom"])
            setup["ik_branch"] = int(branch)
            setup["poses"] = [T.tolist() for T in LWR_POSES]
        else:
            q0, qf = PANDA_Q
        setup.update(kind="p2p", q0=q0, qf=qf, qd_max=LIMITS[problem]["qd"], tau_max=LIMITS[problem]["tau"],
                     weight=1e-2, T_guess=1.5, T_bounds=(0.05, 10.0), q_bounds_in_nlp=True)
    return setup


def _rk4(rhs, x, u, h, substeps=1, inner=False):
    """`substeps` RK4 steps over h; with inner=True also the states after steps 1..substeps-1."""
    hs = h / substeps
    states = []
    for _ in range(substeps):
        k1 = rhs(x, u)
        k2 = rhs(x + hs / 2 * k1, u)
        k3 = rhs(x + hs / 2 * k2, u)
        k4 = rhs(x + hs * k3, u)
        x = x + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        states.append(x)
    if inner:
        return x, (ca.horzcat(*states[:-1]) if substeps > 1 else None)
    return x


def _robot_rhs(fd, n):
    """x = (q, qd[, s]), u = (tau[, sdot]) -> dx/dt."""
    def rhs(x, u):
        parts = [x[n:2 * n], fd(x[:n], x[n:2 * n], u[:n])]
        if x.shape[0] > 2 * n:
            parts.append(u[n:])
        return ca.vertcat(*parts)
    return rhs


def build_nlp(setup: dict, fd: ca.Function, N: int, mode: str = DEFAULT_MODE, substeps: int = 1,
              fk_hom: ca.Function | None = None):
    """The multiple-shooting NLP. mode: 'sx' (fd called on SX symbols: one SX graph), 'mx' (MX
    graph with a call node of fd per RK4 stage), 'mx_expand' (the same, expanded to SX by
    nlpsol's expand=True), 'mx_map' (one SX RK4-step Function mapped over the N intervals).
    Returns the nlp dict and (nx, nu)."""
    n = setup["n"]
    path = setup["kind"] == "path"
    nx, nu = (2 * n + 1, n + 1) if path else (2 * n, n)
    Sym = ca.SX if mode == "sx" else ca.MX
    T = Sym.sym("T")
    X = Sym.sym("X", nx, N + 1)
    U = Sym.sym("U", nu, N)
    h = T / N
    rhs = _robot_rhs(fd, n)
    inner = substeps > 1
    if mode == "mx_map":
        xs, us, hs = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("h")
        xe, xi = _rk4(rhs, xs, us, hs, substeps, inner=True)
        step = ca.Function("rk4_step", [xs, us, hs], [xe] + ([xi] if inner else []))
        outs = step.map(N)(X[:, :N], U, ca.repmat(h, 1, N))
        Xnext, Xin = (outs[0], outs[1]) if inner else (outs, None)
    else:
        steps = [_rk4(rhs, X[:, k], U[:, k], h, substeps, inner=True) for k in range(N)]
        Xnext = ca.horzcat(*[a for a, _ in steps])
        Xin = ca.horzcat(*[b for _, b in steps]) if inner else None
    g = [ca.vec(Xnext - X[:, 1:])]
    ng_eq = g[0].shape[0]
    # position and velocity limits also on the states inside each interval (RK4 substeps), so
    # that they hold between the nodes, not only at them
    inner_bounds = None
    if inner and setup["kind"] == "p2p":
        g.append(ca.vec(Xin[:2 * n, :]))
        cnt = Xin.shape[1]
        # the velocity bound backed off by VELOCITY_BACKOFF inside the intervals: between the RK4
        # substeps the speed can still rise a little (measured 0.057 rad/s on the LWR at N = 10),
        # and the re-simulated motion must respect the limit, not only the planned samples
        qd_inner = (1.0 - VELOCITY_BACKOFF) * setup["qd_max"]
        inner_bounds = (np.tile(np.concatenate([setup["q_lo"], -qd_inner]), cnt),
                        np.tile(np.concatenate([setup["q_hi"], qd_inner]), cnt))
    if path:   # end effector on the line at every node: fk(q_k) = yd(s_k)
        (xa, ya), (xb, yb) = setup["line"]
        for k in range(N + 1):
            Tk = fk_hom(X[:n, k])
            s_k = X[2 * n, k]
            g.append(ca.vertcat(Tk[0, 3] - (xa + (xb - xa) * s_k), Tk[1, 3] - (ya + (yb - ya) * s_k)))
    g = ca.vertcat(*g)
    J = T
    if setup["weight"]:
        J = J + setup["weight"] * h * ca.sumsqr(U[:n, :] / ca.repmat(ca.DM(setup["tau_max"]), 1, N))
    V = ca.vertcat(T, ca.vec(X), ca.vec(U))
    ng = g.shape[0]
    lbg, ubg = np.zeros(ng), np.zeros(ng)
    if inner_bounds is not None:
        lbg[ng_eq:], ubg[ng_eq:] = inner_bounds
    return {"x": V, "f": J, "g": g}, (nx, nu), (lbg, ubg)


def bounds_and_guess(setup: dict, N: int):
    n = setup["n"]
    inf = np.inf
    qd_max, tau_max = setup["qd_max"], setup["tau_max"]
    if setup["q_bounds_in_nlp"]:
        q_lo, q_hi = setup["q_lo"], setup["q_hi"]
    else:
        q_lo, q_hi = np.full(n, -inf), np.full(n, inf)
    Tlo, Thi = setup["T_bounds"]
    s = np.linspace(0, 1, N + 1)
    if setup["kind"] == "path":
        xlo = np.tile(np.concatenate([q_lo, -qd_max, [-inf]])[:, None], (1, N + 1))
        xhi = np.tile(np.concatenate([q_hi, qd_max, [inf]])[:, None], (1, N + 1))
        xlo[n:2 * n, 0] = xhi[n:2 * n, 0] = setup["qd0"]       # start speed
        xlo[2 * n, 0] = xhi[2 * n, 0] = 0.0                     # s(0) = 0
        xlo[2 * n, -1] = xhi[2 * n, -1] = 1.0                   # s(T) = L = 1
        ulo = np.tile(np.concatenate([-tau_max, [0.0]])[:, None], (1, N))   # sdot >= 0
        uhi = np.tile(np.concatenate([tau_max, [inf]])[:, None], (1, N))
        # rockit's guesses: q = qd = tau = 1, s = t L / T0 on the guessed grid, sdot = 0
        Xg = np.ones((2 * n + 1, N + 1))
        Xg[2 * n] = s
        Ug = np.vstack([np.ones((n, N)), np.zeros((1, N))])
    else:
        # nodes, like the inner RK4 steps, keep VELOCITY_BACKOFF of each velocity limit free
        qd_plan = (1.0 - VELOCITY_BACKOFF) * qd_max
        xlo = np.tile(np.concatenate([q_lo, -qd_plan])[:, None], (1, N + 1))
        xhi = np.tile(np.concatenate([q_hi, qd_plan])[:, None], (1, N + 1))
        x0 = np.concatenate([setup["q0"], np.zeros(n)])
        xf = np.concatenate([setup["qf"], np.zeros(n)])
        xlo[:, 0] = xhi[:, 0] = x0
        xlo[:, -1] = xhi[:, -1] = xf
        ulo = np.tile(-tau_max[:, None], (1, N))
        uhi = np.tile(tau_max[:, None], (1, N))
        Xg = np.zeros((2 * n, N + 1))
        Xg[:n] = setup["q0"][:, None] + (setup["qf"] - setup["q0"])[:, None] * s[None, :]
        Ug = np.zeros((n, N))
    lbx = np.concatenate([[Tlo], xlo.ravel(order="F"), ulo.ravel(order="F")])
    ubx = np.concatenate([[Thi], xhi.ravel(order="F"), uhi.ravel(order="F")])
    guess = np.concatenate([[setup["T_guess"]], Xg.ravel(order="F"), Ug.ravel(order="F")])
    return lbx, ubx, guess


def solve(setup: dict, fd: ca.Function, N: int, mode: str = DEFAULT_MODE, substeps: int = 1,
          ipopt: dict | None = None, verbose: bool = False, fk_hom: ca.Function | None = None) -> dict:
    """Build and solve; returns the solution and solver statistics."""
    t0 = time.perf_counter()
    n = setup["n"]
    nlp, (nx, nu), (lbg, ubg) = build_nlp(setup, fd, N, mode, substeps, fk_hom)
    opts = {"ipopt.print_level": 5 if verbose else 0, "print_time": False,
            "ipopt.max_iter": 3000, "ipopt.tol": 1e-8}
    if mode == "mx_expand":
        opts["expand"] = True
    opts.update(ipopt or {})
    solver = ca.nlpsol("ocp", "ipopt", nlp, opts)
    build_s = time.perf_counter() - t0
    lbx, ubx, guess = bounds_and_guess(setup, N)
    t1, c1 = time.perf_counter(), time.process_time()
    sol = solver(x0=guess, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    solve_s, solve_cpu_s = time.perf_counter() - t1, time.process_time() - c1
    stats = solver.stats()
    v = np.array(sol["x"]).ravel()
    T = float(v[0])
    X = v[1:1 + nx * (N + 1)].reshape((nx, N + 1), order="F")
    U = v[1 + nx * (N + 1):].reshape((nu, N), order="F")
    return {"status": stats["return_status"], "success": bool(stats["success"]),
            "iterations": int(stats["iter_count"]), "solve_s": solve_s, "solve_cpu_s": solve_cpu_s,
            "build_s": build_s, "T": T, "N": N, "mode": mode, "substeps": substeps,
            "t": np.linspace(0, T, N + 1), "q": X[:n].T, "qd": X[n:2 * n].T, "tau": U[:n].T,
            "s": X[2 * n:].T, "sdot": U[n:].T,
            "objective": float(sol["f"]), "max_defect": float(np.abs(np.array(sol["g"])[:N * nx]).max())}


def solve_native(setup: dict, N: int, substeps: int, verbose: bool = False, ipopt: dict | None = None) -> dict:
    """The p2p NLP by kindyngen.control.time_optimal (the robot derived into its cache, the
    native library compiled once per N and integrator), in solve()'s result form."""
    from kindyngen.control.integrators import Integrator
    from kindyngen.control.robot import Limits, prepare
    from kindyngen.control.time_optimal import TimeOptimalNLP
    t0 = time.perf_counter()
    limits = Limits(tuple(setup["q_lo"]), tuple(setup["q_hi"]), tuple(setup["qd_max"]), tuple(setup["tau_max"]))
    nlp = TimeOptimalNLP(prepare(setup["robot"]), limits, setup["q0"], setup["qf"], N=N,
                         integrator=Integrator("rk4", substeps), weight=setup["weight"], speed_margin=VELOCITY_BACKOFF,
                         T_guess=setup["T_guess"], T_bounds=setup["T_bounds"],
                         ipopt=dict(ipopt or {}, **({"ipopt.print_level": 5} if verbose else {})))
    build_s = time.perf_counter() - t0
    r = nlp.solve()
    return {"status": r["status"], "success": r["success"], "iterations": r["iterations"], "solve_s": r["solve_s"],
            "solve_cpu_s": r["solve_cpu_s"], "build_s": build_s, "T": r["T"], "N": N, "mode": "native",
            "substeps": substeps, "t": r["t"], "q": r["q"], "qd": r["qd"], "tau": r["tau"],
            "objective": r["objective"], "max_defect": r["max_defect"]}


def resimulate(setup: dict, res: dict, substeps: int = 20) -> dict:
    """Apply the optimal torques piecewise constant from the initial state and integrate with
    Pinocchio's ABA (tests/reference.py's independent model) and fixed-step RK4, `substeps`
    steps per interval. Returns the state error at the nodes and the limit checks on every
    fine step."""
    import pinocchio as pin
    sys.path.insert(0, str(ROOT / "tests"))
    from reference import pinocchio_model
    model, data, flange = pinocchio_model(setup["robot"])
    n, N, T = setup["n"], res["N"], res["T"]
    h = T / N / substeps

    def f(x, u):
        return np.concatenate([x[n:], pin.aba(model, data, x[:n], x[n:], u)])

    x = np.concatenate([res["q"][0], res["qd"][0]])
    fine = [x.copy()]
    node_err = [0.0]
    for k in range(N):
        u = res["tau"][k]
        for _ in range(substeps):
            k1 = f(x, u)
            k2 = f(x + h / 2 * k1, u)
            k3 = f(x + h / 2 * k2, u)
            k4 = f(x + h * k3, u)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            fine.append(x.copy())
        node_err.append(float(np.abs(x - np.concatenate([res["q"][k + 1], res["qd"][k + 1]])).max()))
    fine = np.array(fine)
    qf, qdf = fine[:, :n], fine[:, n:]

    def excess(values, lo, hi):
        return float(max(0.0, np.max(values - hi), np.max(lo - values)))

    qd_max, tau_max = setup["qd_max"], setup["tau_max"]
    extra = {}
    if setup["kind"] == "path":   # distance of the re-simulated end effector from the line
        (xa, ya), (xb, yb) = setup["line"]
        d = np.array([xb - xa, yb - ya]) / np.hypot(xb - xa, yb - ya)
        dist = []
        for qq in qf:
            pin.framesForwardKinematics(model, data, qq)
            p = data.oMf[flange].translation[:2] - np.array([xa, ya])
            dist.append(abs(p[0] * d[1] - p[1] * d[0]))
        extra["resim_path_deviation"] = float(max(dist))
    return {**extra,
        "resim_error": float(max(node_err)),
        "resim_final_error": node_err[-1],
        "resim_substeps": substeps,
        "t_fine": np.linspace(0, T, N * substeps + 1), "q_fine": qf, "qd_fine": qdf,
        "limit_excess": {
            "q_nodes": excess(res["q"], setup["q_lo"], setup["q_hi"]),
            "qd_nodes": excess(res["qd"], -qd_max, qd_max),
            "tau": excess(res["tau"], -tau_max, tau_max),
            "q_resim": excess(qf, setup["q_lo"], setup["q_hi"]),
            "qd_resim": excess(qdf, -qd_max, qd_max),
        },
    }


def rk4_error_estimate(setup: dict, res: dict, fd: ca.Function) -> float:
    """Global error bound of the planner's integration, estimated from its local errors: the sum
    over intervals of |one RK4 step - 16 RK4 steps| from the planned node (both on `fd`)."""
    n, N = setup["n"], res["N"]
    h = res["T"] / N
    xs, us, hs = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n), ca.SX.sym("h")
    rhs = _robot_rhs(fd, n)
    step = ca.Function("s", [xs, us, hs], [_rk4(rhs, xs, us, hs, res["substeps"])])
    fine = ca.Function("s", [xs, us, hs], [_rk4(rhs, xs, us, hs, 16)])
    X = np.hstack([res["q"], res["qd"]]).T
    a = np.array(step.map(N)(X[:, :N], res["tau"].T, h))
    b = np.array(fine.map(N)(X[:, :N], res["tau"].T, h))
    return float(np.abs(a - b).max(axis=0).sum())


def plot(setup: dict, res: dict, sim: dict, out: Path) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = setup["n"]
    files = []
    fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for j in range(n):
        color = f"C{j}"
        axes[0].plot(res["t"], res["q"][:, j], "o", ms=2.5, color=color)
        axes[0].plot(sim["t_fine"], sim["q_fine"][:, j], "-", lw=1, color=color, label=f"q{j + 1}")
        axes[1].plot(res["t"], res["qd"][:, j], "o", ms=2.5, color=color)
        axes[1].plot(sim["t_fine"], sim["qd_fine"][:, j], "-", lw=1, color=color, label=f"qd{j + 1}")
        if np.isfinite(setup["qd_max"][j]):
            for s in (-1, 1):
                axes[1].axhline(s * setup["qd_max"][j], color=color, ls=":", lw=0.8)
    axes[0].set_ylabel("q [rad]")
    axes[1].set_ylabel("qd [rad/s]")
    axes[1].set_xlabel("t [s]")
    axes[0].set_title(f"{setup['problem']}: T = {res['T']:.4f} s, N = {res['N']} "
                      "(dots: planned nodes, lines: Pinocchio re-simulation)")
    for ax in axes:
        ax.legend(fontsize=7, ncol=min(n, 7))
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "joints.png", dpi=110)
    plt.close(fig)
    files.append("joints.png")
    fig, ax = plt.subplots(figsize=(9, 4))
    tt = np.append(res["t"][:-1], res["t"][-1])
    for j in range(n):
        color = f"C{j}"
        ax.step(tt, np.append(res["tau"][:, j], res["tau"][-1, j]), where="post", color=color,
                lw=1.2, label=f"tau{j + 1}")
        for s in (-1, 1):
            ax.axhline(s * setup["tau_max"][j], color=color, ls=":", lw=0.8)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("tau [N m]")
    ax.set_title(f"{setup['problem']}: torques (piecewise constant), dotted: limits")
    ax.legend(fontsize=7, ncol=min(n, 7))
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "torques.png", dpi=110)
    plt.close(fig)
    files.append("torques.png")
    return files


def run(problem: str, N: int, mode: str = DEFAULT_MODE, substeps: int = 1, resim_substeps: int = 20,
        verbose: bool = False, workdir: str | None = None, solver: str = "ipopt") -> tuple[dict, dict, dict]:
    """Solve and check. solver 'ipopt': the NLP of build_nlp in `mode`; 'native': the same NLP
    by kindyngen.control.time_optimal on its native library (p2p problems only; `mode` does not
    apply)."""
    funcs = load_functions(problem, workdir)
    setup = problem_setup(problem, funcs)
    if solver == "native":
        res = solve_native(setup, N, substeps, verbose)
    else:
        res = solve(setup, funcs["fd"], N, mode, substeps, verbose=verbose, fk_hom=funcs["fk_hom"])
    sim = resimulate(setup, res, resim_substeps)
    res["rk4_error_estimate"] = rk4_error_estimate(setup, res, funcs["fd"])
    return setup, res, sim


def to_json(setup: dict, res: dict, sim: dict) -> dict:
    doc = {k: res[k] for k in ("status", "success", "iterations", "solve_s", "solve_cpu_s", "build_s", "T", "N",
                                "mode", "substeps", "objective", "max_defect", "rk4_error_estimate")}
    if "compile_s" in res:
        doc["compile_s"] = res["compile_s"]
    doc.update({k: sim[k] for k in ("resim_error", "resim_final_error", "resim_substeps", "limit_excess",
                                    "resim_path_deviation") if k in sim})
    doc["time_per_iteration_s"] = res["solve_s"] / max(res["iterations"], 1)
    doc["cpu_per_iteration_s"] = res["solve_cpu_s"] / max(res["iterations"], 1)
    doc["problem"] = setup["problem"]
    doc["limits"] = {"q_lower": setup["q_lo"].tolist(), "q_upper": setup["q_hi"].tolist(),
                     "qd_max": [None if not np.isfinite(v) else float(v) for v in setup["qd_max"]],
                     "tau_max": setup["tau_max"].tolist()}
    doc["torque_regulariser_weight"] = setup["weight"]
    doc["q_start"], doc["q_goal"] = setup["q0"].tolist(), setup["qf"].tolist()
    for key in ("ik_branch", "poses"):
        if key in setup:
            doc[key] = setup[key]
    doc["t"] = res["t"].tolist()
    doc["q"] = res["q"].tolist()
    doc["qd"] = res["qd"].tolist()
    doc["tau"] = res["tau"].tolist()
    return doc


class _Parser(argparse.ArgumentParser):
    def error(self, message):   # one error line, exit 2 (no usage block)
        print(f"error: {message}", file=sys.stderr)
        raise SystemExit(2)


def main(argv=None) -> int:
    ap = _Parser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[2:]))
    ap.add_argument("--problem", choices=PROBLEMS, required=True)
    ap.add_argument("--N", type=int, default=None, help="shooting intervals (default 100 for two_link, 20 otherwise)")
    ap.add_argument("--out", required=True, help="output folder (created)")
    ap.add_argument("--mode", choices=MODES, default=DEFAULT_MODE,
                    help=f"how the generated Functions enter the NLP (default {DEFAULT_MODE})")
    ap.add_argument("--substeps", type=int, default=None,
                    help="RK4 steps per interval in the NLP; limits on q, qd are imposed on the inner steps too "
                         "(default 1 for two_link, 4 otherwise)")
    ap.add_argument("--resim-substeps", type=int, default=20, help="RK4 steps per interval of the re-simulation")
    ap.add_argument("--verbose", action="store_true", help="IPOPT's iteration log")
    ap.add_argument("--solver", choices=("ipopt", "native"), default="ipopt",
                    help="ipopt: the NLP of --mode with CasADi's derivatives (default); native (lwr4, panda): the "
                         "same NLP by kindyngen.control.time_optimal, its Jacobian and exact Hessian from a C "
                         "library over the generated fd and fd_derivatives (compiled once per robot, N and "
                         "integrator; --mode does not apply)")
    args = ap.parse_args(argv)
    if args.N is not None and args.N < 1:
        ap.error(f"--N {args.N}: must be at least 1")
    if args.substeps is not None and args.substeps < 1:
        ap.error(f"--substeps {args.substeps}: must be at least 1")
    if args.solver == "native" and args.problem == "two_link":
        ap.error("--solver native: --problem two_link (the path problem) takes ipopt")
    N = args.N or (100 if args.problem == "two_link" else 20)
    args.substeps = args.substeps or (1 if args.problem == "two_link" else 4)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    setup, res, sim = run(args.problem, N, args.mode, args.substeps, args.resim_substeps, args.verbose,
                          solver=args.solver)
    doc = to_json(setup, res, sim)
    doc["plots"] = plot(setup, res, sim, out)
    (out / "ocp.json").write_text(json.dumps(doc, indent=1) + "\n")
    lim = sim["limit_excess"]
    print(f"{args.problem}: {res['status']}, T = {res['T']:.9f} s, N = {N}, {res['iterations']} iterations, "
          f"solve {res['solve_s']:.3f} s wall, {res['solve_cpu_s']:.3f} s CPU "
          f"({1e3 * doc['cpu_per_iteration_s']:.2f} ms CPU/iteration), build {res['build_s']:.2f} s")
    print(f"  max defect {res['max_defect']:.2e}, re-simulation error {sim['resim_error']:.2e} "
          f"(RK4 error estimate {res['rk4_error_estimate']:.2e}), limit excess "
          + ", ".join(f"{k} {v:.1e}" for k, v in lim.items()))
    print(f"  wrote {out / 'ocp.json'}, {', '.join(str(out / p) for p in doc['plots'])}")
    return 0 if res["success"] else 1


if __name__ == "__main__":
    sys.exit(main())
