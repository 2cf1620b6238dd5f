"""An SQP with the exact Hessian of the Lagrangian for the LWR reach of examples/ocp_reach.py,
on a condensed dense QP solved by DAQP; measured by benchmarks/reach_sqp.py and
docs/optimal_control.md ("Exact-Hessian SQP"). **It converges from near a solution, not from
the issue's cold start**, and it is not faster than IPOPT on the compiled stages: it is kept
for the exact Hessian of the RK4 step of `fd` (below), checked here against finite differences;
examples/ocp_fd_stages.py writes the same derivation in MX and compiles it for IPOPT.

The problem is fd_rk4's (one explicit RK4 step of the forward dynamics per interval, so its
KKT points are those of the `baseline` and `fd_rk4` NLPs): unknowns the nodes x_1..x_N and
the torques u_0..u_{N-1}, x_0 fixed; gaps d_k = F(x_k, u_k) - x_{k+1} = 0; the flange position
and rest at x_N; |u| <= tau_max; q and qd limits at the nodes 1..N; cost h sum |u_k|^2.

The exact Hessian, cheaply. The Hessian of mu' F(x, u) for the explicit RK4 step of `fd`
compiles to 19 MB of C (not built in 11 min). But RK4 can be written implicitly with the four
stage accelerations a_i as unknowns tied by the inverse dynamics, r_i = tau(q_i, qd_i, a_i) -
u = 0; the stage states y_i = (q_i, qd_i, a_i) and the next node are linear in v = (x, u, a).
Eliminating a by the implicit function theorem gives the reduced Hessian over w = (x, u),

    H_k = sum_i (dy_i/dw)' Hess_y[lam_i' tau](y_i) (dy_i/dw),   dy_i/dw = L_i [I; da/dw],
    da/dw = -R_a^-1 R_w,   lam = -R_a^-T F_a' mu_k,

with R = dr/dv from the generated `tau_derivatives` and mass matrix `M` at the four stages
(a_i from `fd`, so r = 0), F_a the constant dependence of the next node on a. Compiled: the
four forward dynamics with the inverse dynamics' Jacobians there (one call mapped over the
N intervals) and the 21 x 21 Hessian of one Newton-Euler pass (mapped over the 4 N stages);
the elimination is numpy, batched over the intervals; A = dF/dx and B = dF/du come out of
the same elimination. (Checked against finite differences in tests/integration/test_ocp_sqp.py.)

The SQP: the QP of the exact Hessian in (dx, du) condensed to the N n = 140 torque steps
(dX = G dU + c as in examples/mpc_sqp.py), made positive definite when it is not (DAQP needs
that) by mirroring its negative eigenvalues, solved by DAQP with the torque bounds as simple
bounds, the state limits as rows (passed lazily, as in mpc_sqp) and the terminal position
and rest as equalities; the gap multipliers recovered by the backward recursion of the QP's
stationarity. Globalisation, two variants:
  filter (rho None)  where the linearised terminal rows are infeasible under the bounds,
                     only a fraction beta of their violation is asked for; a filter line
                     search (Waechter and Biegler 2006) on (l1 infeasibility, objective);
                     beta0 caps beta and sigma0 I (a proximal term) damps the step, both
                     adapted to the accepted step length;
  sl1qp (rho given)  Fletcher's elastic QP (terminal rows with l1 slacks priced rho) and a
                     line search on the l1 merit f + rho (gaps + terminal rows + limit excess).
Converged when the KKT residuals of the NLP (primal: gaps, terminal rows, limit excess;
dual: the Lagrangian's stationarity in x and u; complementarity) are below tol_pr, tol_du.

Worked example (from IPOPT's solution of fd_rk4 and its gap multipliers it converges in a
few iterations to objective 716.662; from rest, it does not)::

    >>> from ocp_sqp import ReachSQP                                       # doctest: +SKIP
    >>> r = ReachSQP(N=20).solve(X0=X, U0=U, mu0=mu); r["status"]          # doctest: +SKIP
    'converged'
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

import ocp_reach
import ocp_stages


def stage_maps(n: int, h: float):
    """Constant matrices of one implicit RK4 step over v = (q, qd, u, a_1..a_4) (7 n):
    Ly (4, 3n, 7n) with y_i = Ly[i] v the i-th stage state (q_i, qd_i, a_i), Fv (2n, 7n) with
    x_next = Fv v.

    >>> Ly, Fv = stage_maps(1, 0.1); Fv[0]        # q+ = q + h qd + h^2 / 6 (a1 + a2 + a3)
    array([1.        , 0.1       , 0.        , 0.00166667, 0.00166667, 0.00166667,
           0.        ])
    """
    I = np.eye(n)
    nv = 7 * n
    q, qd = np.zeros((n, nv)), np.zeros((n, nv))
    q[:, :n], qd[:, n:2 * n] = I, I
    acc = [np.zeros((n, nv)) for _ in range(4)]
    for i in range(4):
        acc[i][:, (3 + i) * n:(4 + i) * n] = I
    vs = [qd, qd + h / 2 * acc[0], qd + h / 2 * acc[1], qd + h * acc[2]]
    qs = [q, q + h / 2 * vs[0], q + h / 2 * vs[1], q + h * vs[2]]
    Ly = np.array([np.vstack([qs[i], vs[i], acc[i]]) for i in range(4)])
    Fv = np.vstack([q + h / 6 * (vs[0] + 2 * vs[1] + 2 * vs[2] + vs[3]),
                    qd + h / 6 * (acc[0] + 2 * acc[1] + 2 * acc[2] + acc[3])])
    return Ly, Fv


def ipopt_start(res: dict, N: int, n: int):
    """(X, U, mu) of an ocp_reach fd_rk4 result (its g: per interval the gap x_{k+1} - F, the
    row x_0 = p after the first; CasADi's Lagrangian f + lam_g' g): mu_k = -lam_g of the
    gap, the multiplier of F - x_{k+1} used here."""
    lam, gaps, i = res["lam_g"], [], 0
    for k in range(N):
        gaps.append(lam[i:i + 2 * n])
        i += 4 * n if k == 0 else 2 * n
    return np.hstack([res["q"], res["qd"]]), np.array(res["tau"]), -np.array(gaps)


def compiled_functions(funcs: dict, N: int, h: float) -> dict:
    """The C-compiled pieces (examples/ocp_stages.py's compile cache):
    reach_sqp_steps (mapped over N): (x, u) -> (x_next, Y = the four RK4 stage states (3n x 4),
        J = [dtau/dq, dtau/dqd, M] at each stage (n x 4 * 3n));
    reach_sqp_next (mapped over N): (x, u) -> x_next (the line search's rollout);
    reach_sqp_idhess (mapped over 4 N): (y, m) -> Hessian of m' tau(y) over y (3n x 3n);
    reach_sqp_term: (q, goal, m) -> (fk position - goal, its Jacobian, Hessian of m' fk)."""
    n = funcs["robot"].n
    fd, tau, td, Mf = funcs["fd"], funcs["tau"], ca.Function.load(
        str(ocp_reach.ROOT / "generated" / funcs["robot"].name / "casadi" / "tau_derivatives.casadi")), \
        ca.Function.load(str(ocp_reach.ROOT / "generated" / funcs["robot"].name / "casadi" / "M.casadi"))
    x, u = ca.MX.sym("x", 2 * n), ca.MX.sym("u", n)
    q, v = x[:n], x[n:]
    a1 = fd(q, v, u)
    q2, v2 = q + h / 2 * v, v + h / 2 * a1
    a2 = fd(q2, v2, u)
    q3, v3 = q + h / 2 * v2, v + h / 2 * a2
    a3 = fd(q3, v3, u)
    q4, v4 = q + h * v3, v + h * a3
    a4 = fd(q4, v4, u)
    xn = ca.vertcat(q + h / 6 * (v + 2 * v2 + 2 * v3 + v4), v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4))
    stages = [(q, v, a1), (q2, v2, a2), (q3, v3, a3), (q4, v4, a4)]
    Y = ca.horzcat(*[ca.vertcat(*s) for s in stages])
    J = ca.horzcat(*[ca.horzcat(*td(*s), Mf(s[0])) for s in stages])
    step = ca.Function("reach_sqp_step", [x, u], [xn, Y, J], ["x", "u"], ["x_next", "Y", "J"])
    nxt = ca.Function("reach_sqp_next1", [x, u], [xn], ["x", "u"], ["x_next"])
    ys, ms = ca.SX.sym("y", 3 * n), ca.SX.sym("m", n)
    hess = ca.hessian(ca.dot(ms, tau(ys[:n], ys[n:2 * n], ys[2 * n:])), ys)[0]
    idh = ca.Function("reach_sqp_idhess1", [ys, ms], [hess], ["y", "m"], ["H"])
    qs, goal, mp = ca.SX.sym("q", n), ca.SX.sym("goal", 3), ca.SX.sym("m", 3)
    p = funcs["fk_hom"](qs)[:3, 3]
    term = ca.Function("reach_sqp_term", [qs, goal, mp],
                       [p - goal, ca.jacobian(p, qs), ca.hessian(ca.dot(mp, p), qs)[0]],
                       ["q", "goal", "m"], ["t", "Jt", "Ht"])
    fs = [step.map("reach_sqp_steps", "serial", N, [], []), nxt.map("reach_sqp_next", "serial", N, [], []),
          idh.map("reach_sqp_idhess", "serial", 4 * N, [], []), term]
    return ocp_stages.compile_functions(fs, f"reach_sqp_{funcs['robot'].name}_N{N}")


class ReachSQP:
    """Exact-Hessian SQP of the reach (see the module docstring). Parameters: N, the generated
    Functions (ocp_reach.load()), tolerances tol_pr (gaps, terminal rows, limits; rad, rad/s,
    m) and tol_du (stationarity of the Lagrangian and complementarity), max_iter, and the
    globalisation: beta0, sigma0 (filter) or rho (sl1qp)."""

    def __init__(self, N: int = 20, funcs: dict | None = None, tol_pr: float = 1e-9, tol_du: float = 1e-6,
                 max_iter: int = 100, beta0: float = 1.0, sigma0: float = 0.0, rho: float | None = None):
        t0 = time.perf_counter()
        self.funcs = funcs or ocp_reach.load()
        self.setup = ocp_reach.setup_dict(self.funcs, N)
        s = self.setup
        self.n = n = s["n"]
        self.nx, self.N, self.h = 2 * n, N, s["T"] / N
        self.tol_pr, self.tol_du, self.max_iter = tol_pr, tol_du, max_iter
        self.beta0, self.sigma0, self.rho = beta0, sigma0, rho
        self.ext = compiled_functions(self.funcs, N, self.h)
        self.Ly, self.Fv = stage_maps(n, self.h)
        self.tm = np.tile(s["tau_max"], N)
        self.xlo = np.concatenate([s["q_lo"], -s["qd_max"]])
        self.xhi = np.concatenate([s["q_hi"], s["qd_max"]])
        self.build_s = time.perf_counter() - t0

    # ---- one linearisation ---------------------------------------------------------------
    def evaluate(self, X, U):
        """Compiled steps at the nodes X[0..N-1] (N+1 x 2n) and torques U (N x n): F (N x 2n),
        stage states Y (N, 4, 3n) and inverse-dynamics Jacobians J (N, 4, n, 3n)."""
        N, n = self.N, self.n
        F, Y, J = self.ext["reach_sqp_steps"](X[:-1].T, U.T)
        F = np.array(F).T
        Y = np.array(Y).reshape(3 * n, N, 4).transpose(1, 2, 0)
        J = np.array(J).reshape(n, N, 4, 3 * n).transpose(1, 2, 0, 3)
        return F, Y, J

    def eliminate(self, J):
        """From the stage Jacobians J: R_a^-1-based sensitivities. Returns (dY (N, 4, 3n, 3n)
        = dy_i/dw, AB (N, 2n, 3n) = dF/dw, Ra (N, 4n, 4n)) for w = (x, u)."""
        N, n = self.N, self.n
        nw = 3 * n
        R = np.einsum("kiab,ibc->kiac", J, self.Ly).reshape(N, 4 * n, 7 * n)
        for i in range(4):          # r_i = tau(y_i) - u
            R[:, i * n:(i + 1) * n, 2 * n:3 * n] -= np.eye(n)
        Ra, Rw = R[:, :, nw:], R[:, :, :nw]
        Za = -np.linalg.solve(Ra, Rw)                                # (N, 4n, 3n) = da/dw
        Z = np.concatenate([np.broadcast_to(np.eye(nw), (N, nw, nw)), Za], axis=1)   # (N, 7n, 3n)
        dY = np.einsum("iab,kbc->kiac", self.Ly, Z)
        AB = np.einsum("ab,kbc->kac", self.Fv, Z)
        return dY, AB, Ra

    def stage_hessians(self, Y, dY, Ra, mu):
        """The reduced Hessians (N, 3n, 3n) over w = (x_k, u_k) of mu_k' F(x_k, u_k)."""
        N, n = self.N, self.n
        b = -np.einsum("ab,ka->kb", self.Fv[:, 3 * n:], mu)             # -F_a' mu (N, 4n)
        lam = np.linalg.solve(np.transpose(Ra, (0, 2, 1)), b[..., None])[..., 0]
        Hy = self.ext["reach_sqp_idhess"](Y.reshape(4 * N, 3 * n).T, lam.reshape(4 * N, n).T)
        Hy = np.array(Hy).reshape(3 * n, 4 * N, 3 * n).transpose(1, 0, 2).reshape(N, 4, 3 * n, 3 * n)
        return (np.swapaxes(dY, 2, 3) @ (Hy @ dY)).sum(axis=1)

    def terminal(self, xN, goal, mp):
        t, Jp, Hp = self.ext["reach_sqp_term"](xN[:self.n], goal, mp)
        return np.array(t).ravel(), np.array(Jp), np.array(Hp)

    def condense(self, A, B, d):
        """G (N, 2n, N n), c (N, 2n): dx_{k+1} = G[k] dU + c[k] (mpc_sqp.TrackingMPC.condense)."""
        N, nx, n = self.N, self.nx, self.n
        G = np.zeros((N, nx, N * n))
        c = np.zeros((N, nx))
        G[0][:, :n] = B[0]
        c[0] = d[0]
        for k in range(1, N):
            G[k][:, :k * n] = A[k] @ G[k - 1][:, :k * n]
            G[k][:, k * n:(k + 1) * n] = B[k]
            c[k] = A[k] @ c[k - 1] + d[k]
        return G, c

    # ---- merit -----------------------------------------------------------------------------
    def infeasibility(self, X, U, F=None, goal=None):
        """(l1 norm, max norm) of the gaps, the terminal rows and the state-limit excess."""
        goal = self.setup["goal"] if goal is None else goal
        if F is None:
            F = np.array(self.ext["reach_sqp_next"](X[:-1].T, U.T)).T
        t = np.concatenate([self.terminal(X[-1], goal, np.zeros(3))[0], X[-1, self.n:]])
        exc = np.maximum(X[1:] - self.xhi, 0) + np.maximum(self.xlo - X[1:], 0)
        parts = [np.abs(F - X[1:]), np.abs(t), exc]
        return sum(float(p.sum()) for p in parts), max(float(p.max()) for p in parts)

    # ---- the QP ----------------------------------------------------------------------------
    def solve_qp(self, Hc, gc, G, c, X, U, Jt, t, active, screen=0.05, beta=1.0, rho=None):
        """DAQP on the condensed QP: torque bounds simple, the state limits of nodes 1..N rows
        (passed lazily: those near their bound or in `active`, re-solved with any row the
        answer violates), the terminal rows Jt (G[N-1] dU + c[N-1]) = -beta t equalities
        (beta < 1: only a part of the terminal rows' violation removed, see solve()).
        Returns (dU, lam (bounds, state rows, terminal rows), flag, iterations, working set)."""
        import daqp
        N, n, nx = self.N, self.n, self.nx
        nb, ns = N * n, N * nx
        Gs = G.reshape(ns, nb)
        xf = (X[1:] + c).ravel()
        lo, hi = np.tile(self.xlo, N) - xf, np.tile(self.xhi, N) - xf
        At = Jt @ G[-1]
        bt = -beta * t - Jt @ c[-1]
        width = np.tile(self.xhi - self.xlo, N)
        keep = np.minimum(hi, -lo) < screen * width
        if active is not None:
            keep |= active[nb:nb + ns] != 0
        sense_all = np.concatenate([np.zeros(nb + ns, np.int32), np.full(len(bt), 5, np.int32)])
        if active is not None:
            sense_all[:nb + ns] |= ((active[:nb + ns] != 0).astype(np.int32)
                                    | (2 * (active[:nb + ns] < 0)).astype(np.int32))
        nt = len(bt)
        if rho is not None:
            # elastic terminal rows (Fletcher's Sl1QP): At dU - s+ + s- = bt, s+- >= 0 at the
            # price rho (s+ + s-) (and a small curvature, DAQP needs H positive definite), so
            # that the QP is feasible from any point and its terminal multipliers are <= rho
            eps = 1e-6 * max(1.0, float(np.abs(np.diag(Hc)).max()))
            Hq = np.zeros((nb + 2 * nt, nb + 2 * nt))
            Hq[:nb, :nb] = Hc
            Hq[nb:, nb:] = eps * np.eye(2 * nt)
            gq = np.concatenate([gc, np.full(2 * nt, rho)])
            At = np.hstack([At, -np.eye(nt), np.eye(nt)])
            box_hi = np.concatenate([self.tm - U.ravel(), np.full(2 * nt, 1e30)])
            box_lo = np.concatenate([-self.tm - U.ravel(), np.zeros(2 * nt)])
            sense_all = np.concatenate([sense_all[:nb], np.zeros(2 * nt, np.int32), sense_all[nb:]])
            Gpad = np.hstack([Gs, np.zeros((ns, 2 * nt))])
        else:
            Hq, gq, box_hi, box_lo, Gpad = Hc, gc, self.tm - U.ravel(), -self.tm - U.ravel(), Gs
        nbq = len(box_hi)
        iters = 0
        while True:
            rows = np.flatnonzero(keep)
            sel = np.concatenate([np.arange(nbq), nbq + rows, nbq + ns + np.arange(nt)])
            A = np.ascontiguousarray(np.vstack([Gpad[rows], At]))
            z, _, flag, info = daqp.solve(Hq, gq, A, np.concatenate([box_hi, hi[rows], bt]),
                                          np.concatenate([box_lo, lo[rows], bt]), sense_all[sel])
            iters += int(info["iterations"])
            z = np.asarray(z)
            du = z[:nb]
            if flag < 0:
                break
            Gdu = Gs @ du
            missed = ~keep & ((Gdu > hi + 1e-9) | (Gdu < lo - 1e-9))
            if not missed.any():
                break
            keep |= missed
        lamq = np.zeros(nbq + ns + nt)
        lamq[sel] = np.asarray(info["lam"])
        lam = np.concatenate([lamq[:nb], lamq[nbq:]])
        act = np.sign(lam).astype(np.int32)
        act[nb + ns:] = 0
        self.slack_l1 = float(z[nb:].sum()) if rho is not None else (1 - beta) * float(np.abs(t).sum())
        return du, lam, int(flag), iters, act

    @staticmethod
    def regularise_mirror(Hc):
        """Hc made positive definite in place by mirroring its negative eigenvalues (floor
        1e-8 of the largest); returns the shift that was needed (0 if none)."""
        try:
            np.linalg.cholesky(Hc)
            return 0.0
        except np.linalg.LinAlgError:
            w, V = np.linalg.eigh(Hc)
            floor = 1e-8 * max(float(np.abs(w).max()), 1.0)
            Hc[:] = (V * np.maximum(np.abs(w), floor)) @ V.T
            return float(floor - w.min())

    # ---- the SQP ---------------------------------------------------------------------------
    def guess(self):
        s, N = self.setup, self.N
        x0 = np.concatenate([s["q0"], np.zeros(self.n)])
        return np.tile(x0, (N + 1, 1)), np.tile(s["gravity_torque"], (N, 1))

    def solve(self, x_init=None, goal=None, X0=None, U0=None, mu0=None, verbose: bool = False) -> dict:
        """SQP from nodes X0 (N+1 x 2n; X0[0] replaced by x_init if given), torques U0 (N x n)
        and gap multipliers mu0 (N x 2n, of F(x_k, u_k) - x_{k+1}); default: rest at q0 with
        the gravity torques and zero multipliers (the issue's start). Returns ocp_reach's
        result fields plus kkt (the last residuals) and log (one entry per iteration)."""
        t0, c0 = time.perf_counter(), time.process_time()
        s, N, n, nx, h = self.setup, self.N, self.n, self.nx, self.h
        goal = s["goal"] if goal is None else np.asarray(goal)
        Xg, Ug = self.guess()
        X = np.array(Xg if X0 is None else X0, float)
        U = np.clip(np.array(Ug if U0 is None else U0, float), -s["tau_max"], s["tau_max"])
        if x_init is not None:
            X[0] = x_init
        mu, mt, nu, lb = np.zeros((N, nx)), np.zeros(3 + n), np.zeros((N, nx)), np.zeros((N, n))
        if mu0 is not None:
            mu = np.array(mu0, float)
        active, beta_cap, sigma, filt = None, self.beta0, self.sigma0, []
        theta_max = theta_min = 0.0
        it, status, log = 0, "max_iter", []
        F, Y, J = self.evaluate(X, U)
        while True:
            dY, AB, Ra = self.eliminate(J)
            A, B = AB[:, :, :nx], AB[:, :, nx:]
            d = F - X[1:]
            tp, Jp, Hp = self.terminal(X[-1], goal, mt[:3])
            t = np.concatenate([tp, X[-1, n:]])
            Jt = np.zeros((3 + n, nx))
            Jt[:3, :n], Jt[3:, n:] = Jp, np.eye(n)
            # KKT residuals of the NLP at (X, U) with the current multipliers
            r_u = 2 * h * U + np.einsum("kab,ka->kb", B, mu) + lb
            r_x = np.zeros((N, nx))
            r_x[:-1] = np.einsum("kab,ka->kb", A[1:], mu[1:]) - mu[:-1] + nu[:-1]
            r_x[-1] = -mu[-1] + nu[-1] + Jt.T @ mt
            exc = np.maximum(X[1:] - self.xhi, 0) + np.maximum(self.xlo - X[1:], 0)
            pr = max(float(np.abs(d).max()), float(np.abs(t).max()), float(exc.max()))
            du_res = max(float(np.abs(r_u).max()), float(np.abs(r_x).max()))
            slack_x = np.minimum(np.abs(X[1:] - self.xhi), np.abs(X[1:] - self.xlo))
            slack_u = np.minimum(np.abs(U - s["tau_max"]), np.abs(U + s["tau_max"]))
            co = max(float(np.abs(nu * slack_x).max()), float(np.abs(lb * slack_u).max()))
            log.append({"iter": it, "objective": float(h * np.sum(U ** 2)), "inf_pr": pr, "inf_du": du_res,
                        "compl": co})
            if verbose:
                print(f"{it:3d} f={log[-1]['objective']:.6f} pr={pr:.2e} du={du_res:.2e} co={co:.1e}",
                      {k: log[-2][k] for k in ("alpha", "beta", "qp_iterations", "regularisation", "sigma")} if it else "")
            if pr <= self.tol_pr and du_res <= self.tol_du and co <= self.tol_du:
                status = "converged"
                break
            if it >= self.max_iter:
                break
            it += 1
            # the QP: Hessian blocks of the Lagrangian per stage (cost 2 h I on u) and terminal
            Hk = self.stage_hessians(Y, dY, Ra, mu)
            Hk[:, nx:, nx:] += 2 * h * np.eye(n)
            HT = np.zeros((nx, nx))
            HT[:n, :n] = Hp
            G, c = self.condense(A, B, d)
            Gx = np.concatenate([np.zeros((1, nx, N * n)), G[:-1]])       # dx_k = Gx[k] dU + cx[k]
            cx = np.concatenate([np.zeros((1, nx)), c[:-1]])
            Hxx, Hxu, Huu = Hk[:, :nx, :nx], Hk[:, :nx, nx:], Hk[:, nx:, nx:]
            Gf = Gx.reshape(N * nx, N * n)
            Hc = Gf.T @ np.einsum("kab,kbc->kac", Hxx, Gx).reshape(N * nx, N * n)
            cross = np.einsum("kai,kab->ikb", Gx, Hxu).reshape(N * n, N * n)
            Hc += cross + cross.T
            for k in range(N):
                Hc[k * n:(k + 1) * n, k * n:(k + 1) * n] += Huu[k]
            Hc += G[-1].T @ HT @ G[-1]
            gc = 2 * h * U.ravel() + Gf.T @ np.einsum("kab,kb->ka", Hxx, cx).ravel() \
                + np.einsum("kab,ka->kb", Hxu, cx).ravel() + G[-1].T @ (HT @ c[-1])
            Hc = 0.5 * (Hc + Hc.T)
            Hc[np.diag_indices_from(Hc)] += sigma     # proximal term: the step's trust region
            reg = self.regularise_mirror(Hc)
            # far from the goal the linearised terminal rows may be out of reach under the
            # torque and speed bounds (the QP at the start is infeasible): then only a
            # fraction beta of their violation is removed, the largest that is feasible
            betas = tuple(b for b in (1.0, 0.5, 0.25, 0.12, 0.06, 0.03, 0.0) if b <= beta_cap)
            if self.rho is not None:
                betas = (1.0,)
            for j, beta in enumerate(betas):
                dU, lam, flag, qit, act = self.solve_qp(Hc, gc, G, c, X, U, Jt, t, active, beta=beta, rho=self.rho)
                if flag >= 0:
                    break
            if j > 0 and j + 1 < len(betas):   # off the edge of feasibility, where the multipliers blow up
                beta = betas[j + 1]
                dU, lam, flag, qit, act = self.solve_qp(Hc, gc, G, c, X, U, Jt, t, active, beta=beta)
            active = act
            if flag < 0:
                status = f"qp_failed ({flag})"
                break
            D = dU.reshape(N, n)
            dX = (G.reshape(N * nx, N * n) @ dU).reshape(N, nx) + c
            # the QP's multipliers: bounds, state rows, terminal rows; the gaps' by recursion
            lb_q = lam[:N * n].reshape(N, n)
            nu_q = lam[N * n:N * n + N * nx].reshape(N, nx)
            mt_q = lam[N * n + N * nx:]
            dxk = np.concatenate([np.zeros((1, nx)), dX[:-1]])
            mu_q = np.zeros((N, nx))
            mu_q[-1] = nu_q[-1] + Jt.T @ mt_q + HT @ dX[-1]
            for j in range(N - 1, 0, -1):
                mu_q[j - 1] = A[j].T @ mu_q[j] + nu_q[j - 1] + Hxx[j] @ dxk[j] + Hxu[j] @ D[j]
            # filter line search (Waechter and Biegler 2006, without second-order corrections):
            # a trial point is accepted if the filter does not dominate it and it reduces the
            # infeasibility theta or the objective enough; where the step is a descent
            # direction of f and theta is small, the Armijo condition on f instead
            f0 = h * np.sum(U ** 2)
            th0 = self.infeasibility(X, U, F, goal)[0]
            if not filt:
                theta_max, theta_min = 1e4 * max(1.0, th0), 1e-4 * max(1.0, th0)
            gf = 2 * h * float(np.sum(U * D))
            alpha = 1.0
            dphi = gf - (self.rho or 0.0) * (th0 - self.slack_l1)
            while True:
                Xa, Ua = X.copy(), U + alpha * D
                Xa[1:] += alpha * dX
                fa, tha = h * np.sum(Ua ** 2), self.infeasibility(Xa, Ua, None, goal)[0]
                if alpha < 1e-4:
                    break
                if self.rho is not None:     # l1 merit, the penalty of the elastic QP
                    ok = f_type = fa + self.rho * tha <= f0 + self.rho * th0 + 1e-4 * alpha * min(dphi, 0.0)
                    if ok:
                        break
                    alpha *= 0.5
                    continue
                f_type = gf < 0 and alpha * (-gf) ** 2.3 > th0 ** 1.1 and th0 <= theta_min
                ok = tha <= theta_max and not any(tha >= tf and fa >= ff for tf, ff in filt)
                if ok and f_type:
                    ok = fa <= f0 + 1e-4 * alpha * gf
                elif ok:
                    ok = tha <= (1 - 1e-5) * th0 or fa <= f0 - 1e-5 * th0
                if ok:
                    break
                alpha *= 0.5
            if not (f_type and ok):
                filt.append(((1 - 1e-5) * th0, f0 - 1e-5 * th0))
            if alpha == 1.0:
                beta_cap, sigma = min(1.0, 2 * beta_cap), sigma / 4
            else:
                beta_cap, sigma = max(beta_cap / 2, 0.03), min(sigma * 4, 1e6)
            X, U = Xa, np.clip(Ua, -s["tau_max"], s["tau_max"])
            mu += alpha * (mu_q - mu)
            mt += alpha * (mt_q - mt)
            nu += alpha * (nu_q - nu)
            lb += alpha * (lb_q - lb)
            log[-1].update({"alpha": alpha, "beta": beta, "sigma": sigma, "qp_iterations": qit, "regularisation": reg})
            F, Y, J = self.evaluate(X, U)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        obj = float(h * np.sum(U ** 2))
        return {"status": status, "success": status == "converged", "iterations": it, "solve_s": wall,
                "solve_cpu_s": cpu, "build_s": self.build_s, "formulation": "fd_rk4",
                "solver": "sqp_exact (condensed QP, DAQP)", "substeps": 1, "N": N, "T": s["T"],
                "t": np.linspace(0, s["T"], N + 1), "q": X[:, :n], "qd": X[:, n:], "tau": U.copy(),
                "objective": obj, "max_constraint_violation": log[-1]["inf_pr"],
                "kkt": {k: log[-1][k] for k in ("inf_pr", "inf_du", "compl")}, "log": log}
