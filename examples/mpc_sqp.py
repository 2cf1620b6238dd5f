"""A tracking MPC for examples/mpc.py: Gauss-Newton SQP on a condensed dense QP, the RK4 step
of the generated forward dynamics and its Jacobians compiled to C, DAQP as the QP solver.

Why this design (and not the reach re-solve of examples/ocp_stages.py): the re-solve's cost
h sum |tau_k|^2 reaches the motion only through the dynamics, so a Gauss-Newton Hessian drops
second-order terms weighted by multipliers of the size of the torques and its SQP diverges
(docs/optimal_control.md); IPOPT on the exact Hessian cannot go under ~16 ms a call. The
standard MPC design (acados-style) tracks a planned trajectory instead: the cost is a sum of
squares of the deviation from the plan,

    sum_{k=1..N} |W_x,k (x_k - x_ref,k)|^2 + sum_{k=0..N-1} |W_u (u_k - u_ref,k)|^2,

so the Gauss-Newton Hessian J' W J is the exact Hessian of the cost and a good one of the
Lagrangian (the residuals and the multipliers are small near the plan).

Formulation: multiple shooting, condensed. Unknowns: the nodes x_1..x_N and the torques
u_0..u_{N-1} (piecewise constant on N intervals of h); x_0 is the measured state. Hard torque
bounds (simple bounds of the QP); joint position and speed limits at the nodes 1..N, and the
speed limit also at the ends of the RK4 substeps inside every interval (the speeds between the
nodes, whose sensitivities are rows of the same chained RK4 Jacobians), as soft rows (DAQP's
soft constraints, so that a disturbed state a little past a speed limit leaves the QP
feasible; their slack is ~1e-6 of the bound, i.e. they act as hard rows when feasible). One SQP iteration: the compiled, mapped RK4 step gives F_k = F(x_k, u_k),
A_k = dF/dx and B_k = dF/du at every interval; the linearised dynamics with their gaps
d_k = F_k - x_{k+1} are eliminated (condensing: dX = G dU + c, G_{k+1} = A_k G_k + [0 .. B_k
.. 0], c_{k+1} = A_k c_k + d_k), which leaves a dense QP in the N * n torque steps

    min 0.5 dU' (G' Wx G + Wu) dU + (G' Wx (X + c - X_ref) + Wu (U - U_ref))' dU
    s.t. -tau_max - U <= dU <= tau_max - U,  lo - X - c <= G dU <= hi - X - c (soft),
         -vmax - V - cv <= Gv dU <= vmax - V - cv (soft; V the inner substep speeds,
         Gv_k = Av_k G_{k-1} + [0 .. Bv_k .. 0], cv_k = Av_k c_{k-1})

solved by DAQP (dual active set, dense; started from the previous QP's working set, shifted
between control steps). Full steps: U += dU, X += G dU + c (multiple shooting keeps a wrong
torque guess from being amplified over the 1 s horizon, which made the single-shooting
variant of this SQP diverge under a payload). Iterations stop when the largest |du_j| /
tau_max_j and the largest gap are both below `tol`, or after `max_iter`; the real-time
iteration is max_iter = 1.

Sensitivities: the RK4 step (M substeps) is written in MX over the generated `fd` and its
analytic derivatives `fd_derivatives` (dqdd/dq, dqdd/dqd, M^-1), chained through the four
stages; CasADi's map makes the N intervals one call; C code generated once and compiled by
gcc (examples/ocp_stages.py's compile_functions and cache, about 2.5 s).

Worked example::

    >>> import mpc_sqp                                                      # doctest: +SKIP
    >>> funcs = mpc_sqp.load("lwr4")                                       # doctest: +SKIP
    >>> ref = mpc_sqp.reference("lwr4", 20, 2, funcs)                      # doctest: +SKIP
    >>> ctl = mpc_sqp.TrackingMPC(funcs, ref["limits"], ref["X"], ref["U"], ref["h"], 20, substeps=2)  # doctest: +SKIP
    >>> X, U = ctl.initial_guess(0)                                        # doctest: +SKIP
    >>> ctl.solve(ref["x0"], X, U, 0)["converged"]                         # doctest: +SKIP
    True
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def load(robot_name: str) -> dict:
    """The robot description and the generated Functions fd, fd_derivatives, tau."""
    from kindyngen.readers.yaml_description import load_robot
    folder = ROOT / "generated" / robot_name / "casadi"
    funcs = {"robot": load_robot(ROOT / "robots" / f"{robot_name}.yaml")}
    for name in ("fd", "fd_derivatives", "tau", "fk_hom"):
        funcs[name] = ca.Function.load(str(folder / f"{name}.casadi"))
    return funcs


def rk4_step_with_jacobians(fd: ca.Function, fd_derivatives: ca.Function, n: int, h: float,
                            substeps: int = 1) -> ca.Function:
    """(x, u) -> (x_next, A = dx_next/dx, B = dx_next/du, v_inner, Av, Bv) of `substeps` classic
    RK4 steps of xdot = (qd, fd(q, qd, u)) over h, the Jacobians chained from fd_derivatives (no
    AD of the dynamics: the analytic derivatives are generated code like fd). v_inner are the
    joint speeds at the ends of the substeps 1..M-1 inside the interval (n (M - 1) values, empty
    for M = 1), Av, Bv their Jacobians: the rows of the same chained A, B that belong to qd, so
    the speed limit can be imposed between the nodes at no extra dynamics evaluation."""
    x, u = ca.MX.sym("x", 2 * n), ca.MX.sym("u", n)
    hs = h / substeps
    I, Z = ca.MX.eye(n), ca.MX(n, n)

    def f(z):                 # xdot, d xdot / dz, d xdot / du
        q, qd = z[:n], z[n:]
        a = fd(q, qd, u)
        da_dq, da_dqd, minv = fd_derivatives(q, qd, u)
        return ca.vertcat(qd, a), ca.vertcat(ca.horzcat(Z, I), ca.horzcat(da_dq, da_dqd)), ca.vertcat(Z, minv)

    xk, A, B = x, ca.MX.eye(2 * n), ca.MX(2 * n, n)
    inner = []
    for m in range(substeps):
        if m > 0:
            inner.append((xk[n:], A[n:, :], B[n:, :]))
        k1, J1, E1 = f(xk)
        d1x, d1u = J1 @ A, J1 @ B + E1
        k2, J2, E2 = f(xk + hs / 2 * k1)
        d2x, d2u = J2 @ (A + hs / 2 * d1x), J2 @ (B + hs / 2 * d1u) + E2
        k3, J3, E3 = f(xk + hs / 2 * k2)
        d3x, d3u = J3 @ (A + hs / 2 * d2x), J3 @ (B + hs / 2 * d2u) + E3
        k4, J4, E4 = f(xk + hs * k3)
        d4x, d4u = J4 @ (A + hs * d3x), J4 @ (B + hs * d3u) + E4
        xk = xk + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        A = A + hs / 6 * (d1x + 2 * d2x + 2 * d3x + d4x)
        B = B + hs / 6 * (d1u + 2 * d2u + 2 * d3u + d4u)
    v_in = ca.vertcat(*[v for v, _, _ in inner]) if inner else ca.MX(0, 1)
    Av = ca.vertcat(*[a for _, a, _ in inner]) if inner else ca.MX(0, 2 * n)
    Bv = ca.vertcat(*[b for _, _, b in inner]) if inner else ca.MX(0, n)
    return ca.Function("rk4_step_jac", [x, u], [xk, A, B, v_in, Av, Bv], ["x", "u"],
                       ["x_next", "A", "B", "v_inner", "Av", "Bv"])


@dataclass(frozen=True)
class Weights:
    """Scales of the tracking cost: a deviation of sigma_q rad, sigma_qd rad/s or
    sigma_tau * tau_max costs 1; the last node's state terms are `terminal` times heavier."""
    sigma_q: float = 0.01
    sigma_qd: float = 0.1
    sigma_tau: float = 0.1
    terminal: float = 10.0


class TrackingMPC:
    """Receding-horizon tracking of a reference (Xref: nodes 0..Nr, Uref: intervals 0..Nr-1,
    on the grid h; held at its last node with Uhold = the torque that holds it beyond the end)
    by Gauss-Newton SQP (see the module docstring). `limits`: q_lo, q_hi, qd_max, tau_max.

    The speed limit is imposed at the nodes and at the M - 1 substep ends inside every interval
    (`inner_speed`), tightened to (1 - speed_margin) qd_max: the plant runs at 1 kHz and an
    unmodelled payload moves it off the prediction within the interval, so a plan at the
    data-sheet limit passes it (examples/mpc.py counts the plant's samples)."""

    def __init__(self, funcs: dict, limits: dict, Xref, Uref, h: float, N: int, weights: Weights = Weights(),
                 substeps: int = 1, tol: float = 1e-4, max_iter: int = 10, Uhold=None,
                 speed_margin: float = 0.0, inner_speed: bool = True):
        import ocp_stages
        self.n = n = funcs["robot"].n
        self.nx, self.N, self.h, self.tol, self.max_iter = 2 * n, N, h, tol, max_iter
        self.Xref, self.Uref = np.asarray(Xref, float), np.asarray(Uref, float)
        qN = self.Xref[-1, :n]
        self.Uhold = (np.array(funcs["tau"](qN, np.zeros(n), np.zeros(n))).ravel() if Uhold is None
                      else np.asarray(Uhold, float))
        self.tau_max = np.asarray(limits["tau_max"], float)
        self.speed_margin = speed_margin
        self.vmax = (1.0 - speed_margin) * np.asarray(limits["qd_max"], float)
        self.xlo = np.concatenate([limits["q_lo"], -self.vmax])
        self.xhi = np.concatenate([limits["q_hi"], self.vmax])
        # speed rows inside each interval: n per substep end 1..M-1 (none for M = 1)
        self.nv = n * (substeps - 1) if inner_speed else 0
        self.weights, self.substeps = weights, substeps
        wx = np.concatenate([np.full(n, weights.sigma_q ** -2), np.full(n, weights.sigma_qd ** -2)])
        self.wx = np.tile(wx, N)
        self.wx[-self.nx:] *= weights.terminal
        self.wu = np.tile((weights.sigma_tau * self.tau_max) ** -2, N)
        step = rk4_step_with_jacobians(funcs["fd"], funcs["fd_derivatives"], n, h, substeps)
        steps = step.map("rk4_steps_jac", "serial", N, [], [])
        t0 = time.perf_counter()
        stem = f"mpc_{funcs['robot'].name}_N{N}_M{substeps}_h{round(h * 1e6)}us"
        ext = ocp_stages.compile_functions([steps, step], stem)
        self.steps, self.step = ext["rk4_steps_jac"], ext["rk4_step_jac"]
        # the torque the model adds to the commanded one (the estimated disturbance, see
        # estimate_disturbance): zero unless the loop estimates it
        self.d = np.zeros(n)
        self.compile_s = time.perf_counter() - t0
        nrows = N * (self.nx + self.nv)
        self.sense = np.concatenate([np.zeros(N * n), np.full(nrows, 8)]).astype(np.int32)   # 8: soft row

    # ---- reference over the horizon ----------------------------------------------------
    def reference_window(self, i: int):
        """Xref at the nodes i+1..i+N and Uref on the intervals i..i+N-1 (held after the end)."""
        Nr = len(self.Uref)
        idx = np.minimum(np.arange(i + 1, i + self.N + 1), Nr)
        U = np.array([self.Uref[j] if j < Nr else self.Uhold for j in range(i, i + self.N)])
        return self.Xref[idx], U

    def initial_guess(self, i: int):
        """(X, U) = the reference over the horizon of step i (the first step's start)."""
        Xr, Ur = self.reference_window(i)
        return Xr.copy(), Ur.copy()

    def shifted(self, X: np.ndarray, U: np.ndarray, i: int):
        """The warm start of step i + 1 from the solution (X, U) of step i: every node and
        torque one interval earlier; the appended interval repeats the last node and takes the
        reference torque there (its gap closes in the next iterations)."""
        return np.vstack([X[1:], X[-1:]]), np.vstack([U[1:], self.reference_window(i + 1)[1][-1:]])

    # ---- one linearisation -------------------------------------------------------------
    def linearise(self, x0, X, U):
        """The RK4 steps F_k = F(x_k, u_k) from the nodes (x0, X[0..N-2]) with U (N x n), and
        their Jacobians A (N x 2n x 2n), B (N x 2n x n); the inner substep speeds V (N x nv)
        and their Jacobians Av (N x nv x 2n), Bv (N x nv x n) (nv = n (M - 1))."""
        N, nx, n = self.N, self.nx, self.n
        F, A, B, V, Av, Bv = self.steps(np.vstack([x0, X[:-1]]).T, (U + self.d).T)
        F = np.array(F).T
        A = np.array(A).reshape(nx, N, nx).transpose(1, 0, 2)
        B = np.array(B).reshape(nx, N, n).transpose(1, 0, 2)
        nv = self.nv
        if nv:
            V = np.array(V).T
            Av = np.array(Av).reshape(nv, N, nx).transpose(1, 0, 2)
            Bv = np.array(Bv).reshape(nv, N, n).transpose(1, 0, 2)
        else:
            V, Av, Bv = np.zeros((N, 0)), np.zeros((N, 0, nx)), np.zeros((N, 0, n))
        return F, A, B, V, Av, Bv

    def condense(self, A, B, d):
        """G (N 2n x N n), c (N 2n): dX = G dU + c from dx_{k+1} = A_k dx_k + B_k du_k + d_k,
        dx_0 = 0 (the measured state); d_k = F_k - x_{k+1} are the gaps."""
        N, nx, n = self.N, self.nx, self.n
        G = np.zeros((N, nx, N * n))
        c = np.zeros((N, nx))
        G[0][:, :n] = B[0]
        c[0] = d[0]
        for k in range(1, N):
            G[k][:, :k * n] = A[k] @ G[k - 1][:, :k * n]
            G[k][:, k * n:(k + 1) * n] = B[k]
            c[k] = A[k] @ c[k - 1] + d[k]
        return G.reshape(N * nx, N * n), c.ravel()

    def condense_inner(self, Av, Bv, G, c):
        """Gv (N nv x N n), cv (N nv): the linearised inner substep speeds dv_k = Gv_k dU + cv_k
        from dv_k = Av_k dx_k + Bv_k du_k with dx_k = G_{k-1} dU + c_{k-1} (dx_0 = 0)."""
        N, nx, n, nv = self.N, self.nx, self.n, self.nv
        Gv = np.zeros((N, nv, N * n))
        cv = np.zeros((N, nv))
        if nv:
            G3, c2 = G.reshape(N, nx, N * n), c.reshape(N, nx)
            Gv[0][:, :n] = Bv[0]
            for k in range(1, N):
                Gv[k][:, :k * n] = Av[k] @ G3[k - 1][:, :k * n]
                Gv[k][:, k * n:(k + 1) * n] = Bv[k]
                cv[k] = Av[k] @ c2[k - 1]
        return Gv.reshape(N * nv, N * n), cv.ravel()

    def qp(self, x0, X, U, i):
        """The condensed QP of the Gauss-Newton step at (X, U): H, g, the state-row matrix G,
        the offset c, the bounds (box on dU, rows on G dU: row_lo, row_hi), the inner speed rows
        (Gv dU within v_lo, v_hi) and the linearisation (F, A, B, d, V, Av, Bv)."""
        Xr, Ur = self.reference_window(i)
        F, A, B, V, Av, Bv = self.linearise(x0, X, U)
        d = F - X
        G, c = self.condense(A, B, d)
        Gv, cv = self.condense_inner(Av, Bv, G, c)
        vf = V.ravel() + cv
        vm = np.tile(self.vmax, (self.substeps - 1) * self.N) if self.nv else np.zeros(0)
        e = (X - Xr).ravel() + c
        du_ref = (U - Ur).ravel()
        WG = self.wx[:, None] * G
        H = G.T @ WG
        H[np.diag_indices_from(H)] += self.wu
        g = WG.T @ e + self.wu * du_ref
        tm = np.tile(self.tau_max, self.N)
        Uf, xf = U.ravel(), X.ravel() + c
        return {"H": H, "g": g, "G": G, "c": c, "box_lo": -tm - Uf, "box_hi": tm - Uf,
                "row_lo": np.tile(self.xlo, self.N) - xf, "row_hi": np.tile(self.xhi, self.N) - xf,
                "Gv": Gv, "cv": cv, "v_lo": -vm - vf, "v_hi": vm - vf,
                "F": F, "A": A, "B": B, "d": d, "V": V, "Av": Av, "Bv": Bv, "Xr": Xr, "Ur": Ur}

    def solve_qp(self, q, active=None, screen: float = 0.03):
        """DAQP on the condensed QP; `active` (the working set of a previous QP, as returned
        here: +1 upper, -1 lower, 0 inactive per constraint) starts DAQP's active set.

        The state rows go in lazily: DAQP's setup multiplies every row by the inverse
        Cholesky factor of H (420 rows x 140 columns at N = 20, most of its time), so only the
        rows within `screen` of their range (a fraction of hi - lo) from their bound at the
        linearisation, or active in `active`, are passed; a row left out that the solution
        violates is added and the QP solved again, so the result is that of the full QP.
        Returns (du, exit flag, DAQP iterations summed over the passes, working set)."""
        import daqp
        nb = self.N * self.n
        lo, hi = np.concatenate([q["row_lo"], q["v_lo"]]), np.concatenate([q["row_hi"], q["v_hi"]])
        C = np.vstack([q["G"], q["Gv"]])
        width = np.concatenate([np.tile(self.xhi - self.xlo, self.N), np.tile(2 * self.vmax, len(q["v_lo"]) // self.n)])
        keep = np.minimum(hi, -lo) < screen * width
        if active is not None:
            keep |= active[nb:] != 0
        sense_all = self.sense.copy()
        if active is not None:      # DAQP's sense bits: 1 active, 2 at the lower bound
            sense_all |= (active != 0).astype(np.int32) | (2 * (active < 0)).astype(np.int32)
        iters = 0
        while True:
            rows = np.flatnonzero(keep)
            sel = np.concatenate([np.arange(nb), nb + rows])
            du, _, flag, info = daqp.solve(q["H"], q["g"], np.ascontiguousarray(C[rows]),
                                           np.concatenate([q["box_hi"], hi[rows]]),
                                           np.concatenate([q["box_lo"], lo[rows]]), sense_all[sel])
            iters += int(info["iterations"])
            du = np.asarray(du)
            if flag < 0:
                break
            Gdu = C @ du
            missed = ~keep & ((Gdu > hi + 1e-9) | (Gdu < lo - 1e-9))
            if not missed.any():
                break
            keep |= missed
        act = np.zeros(nb + len(hi), np.int32)
        act[sel] = np.sign(np.asarray(info["lam"])).astype(np.int32)
        return du, int(flag), iters, act

    def shifted_active(self, active):
        """The working set moved one interval earlier with shifted(); the appended interval
        gets the last one's."""
        if active is None:
            return None
        N, n, nx, nv = self.N, self.n, self.nx, self.nv
        box = active[:N * n].reshape(N, n)
        rows = active[N * n:N * (n + nx)].reshape(N, nx)
        inner = active[N * (n + nx):].reshape(N, nv)
        return np.concatenate([np.vstack([a[1:], a[-1:]]).ravel() for a in (box, rows, inner)])

    def estimate_disturbance(self, x_prev, u, x_meas, gain: float = 1.0) -> np.ndarray:
        """Offset-free MPC: the constant torque disturbance that explains the last interval.
        The model's step from x_prev with u + d missed the measured x_meas by e; the
        least-squares torque change with B e-matching, d += gain * pinv(B) e, is what the
        model adds to the commanded torque from now on (an unmodelled payload acts like a
        slowly varying torque). Returns d."""
        F, _, B = self.step(x_prev, u + self.d)[:3]
        e = np.asarray(x_meas) - np.array(F).ravel()
        self.d = self.d + gain * np.linalg.lstsq(np.array(B), e, rcond=None)[0]
        return self.d

    # ---- SQP -------------------------------------------------------------------------
    def solve(self, x0, X0, U0, i: int, max_iter: int | None = None, active=None) -> dict:
        """Gauss-Newton SQP with full steps from (X0, U0) (nodes 1..N, torques 0..N-1) for the
        measured state x0 at step i (`active`: a working set to start the first QP from, each
        further QP starts from the previous one's); stops when the largest |du_j| / tau_max_j and the largest
        gap |F_k - x_{k+1}| (rad, rad/s) are both below tol, or after max_iter iterations."""
        max_iter = self.max_iter if max_iter is None else max_iter
        t0, c0 = time.perf_counter(), time.process_time()
        X, U = np.array(X0, float), np.clip(np.array(U0, float), -self.tau_max, self.tau_max)
        x0 = np.asarray(x0, float)
        it, qp_iters, flags, step, gap = 0, [], [], np.inf, np.inf
        converged = failed = False
        while it < max_iter:
            q = self.qp(x0, X, U, i)
            gap = float(np.abs(q["d"]).max())
            du, flag, qi, active = self.solve_qp(q, active)
            qp_iters.append(qi)
            flags.append(flag)
            it += 1
            if flag < 0 or not np.all(np.isfinite(du)):   # DAQP failed: keep the iterate
                failed = True
                break
            D = du.reshape(self.N, self.n)
            step = float(np.max(np.abs(D) / self.tau_max))
            U = np.clip(U + D, -self.tau_max, self.tau_max)
            X = X + (q["G"] @ du + q["c"]).reshape(self.N, self.nx)
            if step <= self.tol and gap <= self.tol:
                converged = True
                break
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        return {"U": U, "X": X, "active": active, "iterations": it, "qp_iterations": qp_iters, "qp_flags": flags,
                "last_step": step, "last_gap": gap, "converged": converged,
                "success": not failed and bool(np.all(np.isfinite(X))),
                "solve_s": wall, "solve_cpu_s": cpu}


# ---- the references the loop tracks (examples/mpc.py --solver sqp | rti) ---------------------
PANDA_T_S = 1.2      # joint 1 moves 1.2 rad: its minimum-jerk peak speed 1.875 * 1.2 / 1.2 s = 1.875 rad/s < 2.175


def reference(problem: str, N: int, substeps: int, funcs: dict, backoff: float = 0.0) -> dict:
    """The trajectory to track on the grid h = 1 s / N, with the limits of the problem.

    lwr4: the converged LWR reach of examples/ocp_reach.py (id_rk4 + IPOPT, `substeps` RK4 steps
    per interval, the same discretisation as the MPC's prediction so that the plan is a
    trajectory of the MPC's model; with one step per 50 ms interval the plan lives on RK4's
    error: rolled out at two steps it is 0.15 rad / rad/s off). N intervals over 1 s; its
    node speeds bounded by (1 - backoff) qd_max (the limits returned are the data sheet's: the
    plan at them leaves its tracking MPC no room for a disturbance). `backoff` is ignored for
    panda, whose motion peaks at 0.86 qd_max (joint 1).
    panda: a minimum-jerk joint motion over PANDA_T_S from examples/ocp.py's two Panda
    configurations (q, qd at the nodes), its torque on each interval the generated inverse
    dynamics at the interval's midpoint (not an exact trajectory of the discrete model: the
    MPC's tracking absorbs the difference); the data-sheet limits of examples/ocp.py."""
    n = funcs["robot"].n
    if problem == "lwr4":
        import ocp_reach
        nlp = ocp_reach.reach_problem("id_rk4", "ipopt", N, ocp_reach.load(), substeps=substeps,
                                      qd_bound=(1.0 - backoff) * ocp_reach.QD_MAX)
        res = nlp.solve()
        if not res["success"]:
            raise RuntimeError(f"the reach reference did not converge: {res['status']}")
        s = nlp.setup
        return {"X": np.hstack([res["q"], res["qd"]]), "U": res["tau"], "h": s["T"] / N,
                "limits": {k: s[k] for k in ("q_lo", "q_hi", "qd_max", "tau_max")}, "goal": s["goal"],
                "x0": np.concatenate([s["q0"], np.zeros(n)]),
                "description": f"the converged LWR reach (examples/ocp_reach.py, id_rk4 + IPOPT, N = {N}, "
                               f"{substeps} RK4 step(s) per interval, node speeds within {1 - backoff:g} qd_max), "
                               f"objective {res['objective']:.4f}",
                "solve_s": res["solve_s"]}
    import ocp
    h = 1.0 / N
    Nr = int(round(PANDA_T_S / h))
    q0, qf = ocp.PANDA_Q
    d = qf - q0

    def mj(t):     # minimum-jerk position, speed, acceleration
        s = np.clip(t / PANDA_T_S, 0.0, 1.0)
        p = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5
        v = (30 * s ** 2 - 60 * s ** 3 + 30 * s ** 4) / PANDA_T_S
        a = (60 * s - 180 * s ** 2 + 120 * s ** 3) / PANDA_T_S ** 2
        return q0 + p * d, v * d, a * d
    X = np.array([np.concatenate(mj(k * h)[:2]) for k in range(Nr + 1)])
    U = np.array([np.array(funcs["tau"](*mj((k + 0.5) * h))).ravel() for k in range(Nr)])
    robot = funcs["robot"]
    lim = {"q_lo": np.array(robot.lower, float), "q_hi": np.array(robot.upper, float),
           "qd_max": ocp.LIMITS["panda"]["qd"], "tau_max": ocp.LIMITS["panda"]["tau"]}
    fk = np.array(funcs["fk_hom"](qf)).reshape(4, 4)
    return {"X": X, "U": U, "h": h, "limits": lim, "goal": fk[:3, 3], "x0": X[0],
            "description": f"minimum-jerk joint motion of the Panda from {q0.tolist()} to {qf.tolist()} in "
                           f"{PANDA_T_S} s, torques by the generated inverse dynamics at the interval midpoints",
            "solve_s": 0.0}
