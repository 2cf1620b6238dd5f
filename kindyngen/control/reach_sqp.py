"""The reach (kindyngen/control/reach.py's ReachTask) by an SQP with the exact Hessian of the
Lagrangian, on a condensed dense QP solved by DAQP, over any prepared robot and horizon: the
integrator's steps, their Jacobians and the interval Hessians from the native stage library
(kindyngen/control/native.py: ``linearise``, ``hessians``, ``terminal``), the rest numpy.

**It converges from near a solution, not from the cold start**, and it is not faster than
IPOPT on the same library (docs/optimal_control.md, "Exact-Hessian SQP": from IPOPT's solution
it converges in a few iterations; from the solution shifted by one interval it creeps, because
the condensed Hessian is strongly indefinite where the active rows leave no curvature for
DAQP to use; cold, the first QPs are infeasible under the torque and speed bounds).

The problem is ReachNLP's with the limits at the nodes (inner rows are not handled:
``task.inner`` with substeps > 1 is refused): unknowns the nodes x_1..x_N and the torques
u_0..u_{N-1}, x_0 fixed; gaps d_k = F(x_k, u_k) - x_{k+1} = 0; the flange position and rest at
x_N; |u| <= tau_max; q and qd limits at the nodes 1..N; cost h sum |u_k|^2.

One iteration: the QP in (dx, du) with the exact Hessian blocks (3n x 3n per interval, the
terminal 2n x 2n), condensed (dX = G dU + c); mirrored where it is indefinite (DAQP needs a
positive definite Hessian: negative eigenvalues flipped, floor 1e-8 of the largest); DAQP with
the torque bounds as simple bounds, the node limits as rows passed lazily (those near their
bound or active; a violated row left out is added and the QP solved again) and the terminal
rows as equalities; the gap multipliers from the backward recursion of the QP's stationarity.
Globalisation, two variants:

- filter (``rho`` None): where the linearised terminal rows are infeasible under the bounds
  only a fraction beta of their violation is asked for; a filter line search (Waechter and
  Biegler 2006) on (l1 infeasibility, objective); ``beta0`` caps beta and ``sigma0`` I (a
  proximal term) damps the step, both adapted to the accepted step length;
- sl1qp (``rho`` given): Fletcher's elastic QP (terminal rows with l1 slacks priced rho) and a
  line search on the l1 merit f + rho (gaps + terminal rows + limit excess).

Converged when the NLP's KKT residuals (primal: gaps, terminal rows, limit excess; dual: the
Lagrangian's stationarity in x and u; complementarity) are below ``tol_pr`` and ``tol_du``.

Example (from IPOPT's solution and its gap multipliers; tests/control/test_reach_sqp.py)::

    nlp = ReachNLP(robot, task); res = nlp.solve()
    sqp = ReachSQP(robot, replace(task, inner=False))
    out = sqp.solve(X0=np.hstack([res.q, res.qd]), U0=res.tau, mu0=sqp.gap_multipliers(nlp, res))
    out.success, out.objective          # True, res.objective to 1e-6
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .native import stage_library
from .robot import ControlError, ControlRobot

#: the elastic QP's slack variables: DAQP's "no bound"
INF = 1e30


@dataclass(frozen=True)
class SQPResult:
    """The SQP's end point (nodes q, qd: N + 1 x n, torques tau: N x n), its status
    ('converged', 'max_iter', 'qp_failed (flag)'), the last KKT residuals and one log entry per
    iteration (objective, inf_pr, inf_du, compl, alpha, beta, sigma, qp_iterations,
    regularisation)."""
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
    kkt: dict
    log: list = field(repr=False, default_factory=list)


class ReachSQP:
    """Exact-Hessian SQP of a reach (module docstring). ``tol_pr`` (gaps, terminal rows, limits;
    rad, rad/s, m), ``tol_du`` (stationarity and complementarity), ``max_iter``; globalisation
    ``beta0``, ``sigma0`` (filter) or ``rho`` (sl1qp)."""

    def __init__(self, robot: ControlRobot, task, tol_pr: float = 1e-9, tol_du: float = 1e-6, max_iter: int = 100,
                 beta0: float = 1.0, sigma0: float = 0.0, rho: float | None = None, progress=None):
        t0 = time.perf_counter()
        if task.inner and task.integrator.substeps > 1:
            raise ControlError("the exact-Hessian SQP holds the limits at the nodes only: pose the task with inner=False")
        if task.limits.n != robot.n:
            raise ControlError(f"limits for {task.limits.n} joints, robot {robot.name} has {robot.n}")
        self.robot, self.task = robot, task
        self.lib = stage_library(robot, task.N, task.h, task.integrator, False, progress)
        self.n = n = robot.n
        self.nx, self.N, self.h = 2 * n, task.N, task.h
        self.M = task.integrator.substeps
        self.tol_pr, self.tol_du, self.max_iter = tol_pr, tol_du, max_iter
        self.beta0, self.sigma0, self.rho = beta0, sigma0, rho
        lim = task.planned_limits
        self.tau_max = lim.array("tau_max")
        self.tm = np.tile(self.tau_max, task.N)
        self.xlo = np.concatenate([lim.array("q_lo"), -lim.array("qd_max")])
        self.xhi = np.concatenate([lim.array("q_hi"), lim.array("qd_max")])
        self.slack_l1 = 0.0
        self.build_s = time.perf_counter() - t0

    # ---- one linearisation ---------------------------------------------------------------
    def evaluate(self, X, U):
        """F (N x 2n), A (N x 2n x 2n), B (N x 2n x n) at the nodes X[0..N-1] and torques U."""
        F, A, B, _, _ = self.lib.linearise(X[0], X[1:], U)
        return F, A, B

    def rollout_ends(self, X, U):
        """F at the nodes (values only: the line search's trial points)."""
        return np.array([self.lib.step(X[k], U[k]) for k in range(self.N)])

    def stage_hessians(self, X, U, mu):
        """Per interval the Hessian over (x_k, u_k) of mu_k' F(x_k, u_k) (N x 3n x 3n)."""
        MU = np.zeros((self.N, self.M, self.nx))
        MU[:, -1] = mu
        return self.lib.hessians(X[0], X[1:], U, MU)

    def terminal(self, xN, goal, mt):
        """(t = (flange position - goal, qd), its Jacobian Jt, the Hessian of mt' t)."""
        return self.lib.terminal(xN, goal, mt)

    def condense(self, A, B, d):
        """G (N, 2n, N n), c (N, 2n): dx_{k+1} = G[k] dU + c[k]."""
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

    def gap_multipliers(self, nlp, res) -> np.ndarray:
        """mu (N x 2n), the multipliers of F(x_k, u_k) - x_{k+1}, from a ReachNLP solve of the
        same task (its rows are x_{k+1} - F: mu = -lam_g there)."""
        L = nlp.layout
        return -np.array([res.lam_g[L.row_gap(k):L.row_gap(k) + L.nx] for k in range(self.N)])

    # ---- merit -----------------------------------------------------------------------------
    def infeasibility(self, X, U, F=None, goal=None):
        """(l1 norm, max norm) of the gaps, the terminal rows and the state-limit excess."""
        goal = np.asarray(self.task.goal if goal is None else goal, float)
        if F is None:
            F = self.rollout_ends(X, U)
        t = self.terminal(X[-1], goal, np.zeros(3 + self.n))[0]
        exc = np.maximum(X[1:] - self.xhi, 0) + np.maximum(self.xlo - X[1:], 0)
        parts = [np.abs(F - X[1:]), np.abs(t), exc]
        return sum(float(p.sum()) for p in parts), max(float(p.max()) for p in parts)

    # ---- the QP ----------------------------------------------------------------------------
    def solve_qp(self, Hc, gc, G, c, X, U, Jt, t, active, screen=0.05, beta=1.0, rho=None):
        """DAQP on the condensed QP: torque bounds simple, the state limits of nodes 1..N rows
        (lazily), the terminal rows Jt (G[N-1] dU + c[N-1]) = -beta t equalities (elastic, with
        slacks priced rho, when rho is given). Returns (dU, lam (bounds, state rows, terminal
        rows), flag, iterations, working set)."""
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
            # price rho (and a small curvature: DAQP needs H positive definite), so that the QP
            # is feasible from any point and its terminal multipliers are at most rho
            eps = 1e-6 * max(1.0, float(np.abs(np.diag(Hc)).max()))
            Hq = np.zeros((nb + 2 * nt, nb + 2 * nt))
            Hq[:nb, :nb] = Hc
            Hq[nb:, nb:] = eps * np.eye(2 * nt)
            gq = np.concatenate([gc, np.full(2 * nt, rho)])
            At = np.hstack([At, -np.eye(nt), np.eye(nt)])
            box_hi = np.concatenate([self.tm - U.ravel(), np.full(2 * nt, INF)])
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
        1e-8 of the largest); returns the shift that was needed (0 if none).

        >>> H = np.diag([2.0, -1.0]); ReachSQP.regularise_mirror(H) > 0, np.diag(H).tolist()
        (True, [2.0, 1.0])
        """
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
        """Rest at q0 with the gravity torques (the cold start)."""
        q0 = np.asarray(self.task.q0, float)
        x0 = np.concatenate([q0, np.zeros(self.n)])
        return np.tile(x0, (self.N + 1, 1)), np.tile(self.robot.gravity_torque(q0), (self.N, 1))

    def solve(self, x_init=None, goal=None, X0=None, U0=None, mu0=None, verbose: bool = False) -> SQPResult:
        """SQP from nodes X0 (N+1 x 2n; X0[0] replaced by x_init if given), torques U0 (N x n)
        and gap multipliers mu0 (N x 2n, of F(x_k, u_k) - x_{k+1}); default: rest at q0 with the
        gravity torques and zero multipliers (the cold start). BLAS runs on one thread (the
        matrices are 140 x 140: a second thread doubles the CPU time on a shared machine)."""
        from threadpoolctl import threadpool_limits
        with threadpool_limits(1):
            return self._solve(x_init, goal, X0, U0, mu0, verbose)

    def _solve(self, x_init, goal, X0, U0, mu0, verbose):
        t0, c0 = time.perf_counter(), time.process_time()
        N, n, nx, h = self.N, self.n, self.nx, self.h
        goal = np.asarray(self.task.goal if goal is None else goal, float)
        Xg, Ug = self.guess()
        X = np.array(Xg if X0 is None else X0, float)
        U = np.clip(np.array(Ug if U0 is None else U0, float), -self.tau_max, self.tau_max)
        if x_init is not None:
            X[0] = x_init
        mu, mt, nu, lb = np.zeros((N, nx)), np.zeros(3 + n), np.zeros((N, nx)), np.zeros((N, n))
        if mu0 is not None:
            mu = np.array(mu0, float)
        active, beta_cap, sigma, filt = None, self.beta0, self.sigma0, []
        theta_max = theta_min = 0.0
        it, status, log = 0, "max_iter", []
        F, A, B = self.evaluate(X, U)
        while True:
            d = F - X[1:]
            t, Jt, HT = self.terminal(X[-1], goal, mt)
            # KKT residuals of the NLP at (X, U) with the current multipliers
            r_u = 2 * h * U + np.einsum("kab,ka->kb", B, mu) + lb
            r_x = np.zeros((N, nx))
            r_x[:-1] = np.einsum("kab,ka->kb", A[1:], mu[1:]) - mu[:-1] + nu[:-1]
            r_x[-1] = -mu[-1] + nu[-1] + Jt.T @ mt
            exc = np.maximum(X[1:] - self.xhi, 0) + np.maximum(self.xlo - X[1:], 0)
            pr = max(float(np.abs(d).max()), float(np.abs(t).max()), float(exc.max()))
            du_res = max(float(np.abs(r_u).max()), float(np.abs(r_x).max()))
            slack_x = np.minimum(np.abs(X[1:] - self.xhi), np.abs(X[1:] - self.xlo))
            slack_u = np.minimum(np.abs(U - self.tau_max), np.abs(U + self.tau_max))
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
            Hk = self.stage_hessians(X, U, mu)
            Hk[:, nx:, nx:] += 2 * h * np.eye(n)
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
            # torque and speed bounds: then only a fraction beta of their violation is removed,
            # the largest that is feasible
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
            # infeasibility theta or the objective enough; where the step is a descent direction
            # of f and theta is small, the Armijo condition on f instead
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
            X, U = Xa, np.clip(Ua, -self.tau_max, self.tau_max)
            mu += alpha * (mu_q - mu)
            mt += alpha * (mt_q - mt)
            nu += alpha * (nu_q - nu)
            lb += alpha * (lb_q - lb)
            log[-1].update({"alpha": alpha, "beta": beta, "sigma": sigma, "qp_iterations": qit, "regularisation": reg})
            F, A, B = self.evaluate(X, U)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        T = self.task.T
        return SQPResult(status == "converged", status, it, wall, cpu, float(h * np.sum(U ** 2)), np.linspace(0, T, N + 1),
                         X[:, :n].copy(), X[:, n:].copy(), U.copy(),
                         {k: log[-1][k] for k in ("inf_pr", "inf_du", "compl")}, log)
