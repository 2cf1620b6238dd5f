"""Tracking MPC over any prepared robot: Gauss-Newton SQP on a condensed dense QP (DAQP), the
integrator's steps and their Jacobians from the native stage library, the joint limits as
rows softened by an exact penalty, and a per-step time budget with a fallback.

The problem at step i, from the measured state x_0 (multiple shooting, condensed):

    min  sum_{k=1..N} |W_x,k (x_k - xref_{i+k})|^2 + sum_{k<N} |W_u (u_k - uref_{i+k} + d)|^2 + rho t
    s.t. x_{k+1} = F(x_k, u_k + d)   (the integrator over h, d the estimated torque disturbance)
         |u_k| <= (1 - reserve) tau_max                      (simple bounds)
         q_lo - t <= q_k <= q_hi + t, |qd_k| <= qd_max + t    (nodes 1..N, and the inner substep
                                                               ends: limits between the nodes)
         t >= 0

The slack t (one for the whole horizon, in rad and rad/s) with the linear cost rho is an exact
L-infinity penalty: for rho above the sum of the limit rows' multipliers the solution is the
hard-constrained one whenever that exists (t = 0), and where a disturbance has put the state
where no plan can hold every limit, the QP stays feasible and violates them least. The
``reserve`` keeps a fraction of every torque limit for the inner loop's feedback
(kindyngen/control/closed_loop.py).

Each SQP iteration: the native library's ``linearise`` gives F_k, A_k, B_k (and the inner
states with their Jacobians); the gaps are condensed (dX = G dU + c), the QP in (dU, t) is
solved by DAQP warm-started from the previous working set, with the limit rows passed lazily
(those near their bound or active; a violated row left out is added and the QP solved again);
full steps. Converged when max |du_j| / tau_max_j and the largest gap are below ``tol``.
Budget: the SQP stops before an iteration that would end past ``budget_s`` of CPU time (the
real-time iteration is max_iter = 1); a step with no usable iterate, or one that ran past the
budget, reports ``fallback`` and the caller applies the previous plan shifted.

Example (Xref, Uref a plan of the reach, e.g. kindyngen.control.reach.ReachNLP(...).solve()'s
np.hstack([q, qd]) and tau; tests/control/test_mpc.py runs it)::

    mpc = TrackingMPC(robot, limits, Xref, Uref, MPCOptions(N=20, h=0.05))
    sol = mpc.solve(x0, 0, *mpc.initial_guess(0))      # sol.status: 'converged'; sol.U[0] to apply
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .integrators import Integrator
from .native import stage_library
from .robot import ControlError, ControlRobot, Limits

INF = 1e30          # DAQP's "no bound"


@dataclass(frozen=True)
class MPCOptions:
    """N intervals of h seconds, integrated by ``integrator``; cost scales sigma_* (a deviation of
    sigma_q rad, sigma_qd rad/s or sigma_tau tau_max costs 1; the last node ``terminal`` times
    that: 1, measured: with 10 the Panda under a 10 % mass error swung slowly by 4-20 mm about the
    goal, its SQP never converged in 30 iterations, with 1 it settles to 0.03 mm in 3); ``max_iter`` SQP iterations (1: real-time iteration) to ``tol``; ``budget_s`` CPU
    seconds per step; ``reserve`` of each torque limit kept for the inner loop; ``penalty``:
    rho of the exact penalty, per rad (rad/s) of the worst limit excess, relative to the
    largest state weight."""
    N: int = 20
    h: float = 0.05
    integrator: Integrator = Integrator("rk4", 2)
    inner: bool = True
    sigma_q: float = 0.01
    sigma_qd: float = 0.1
    sigma_tau: float = 0.1
    terminal: float = 1.0
    max_iter: int = 10
    tol: float = 1e-4
    budget_s: float = 0.010
    reserve: float = 0.1
    penalty: float = 100.0
    screen: float = 0.05
    qp_iter_limit: int = 200
    speed_margin: float = 0.05
    position_margin: float = 0.02

    def __post_init__(self):
        if int(self.N) != self.N or self.N < 2:
            raise ControlError(f"MPC N = {self.N}: at least 2 intervals")
        if not self.h > 0 or not self.budget_s > 0:
            raise ControlError("MPC h and budget_s must be positive")
        if not 0 <= self.reserve < 1:
            raise ControlError(f"MPC torque reserve {self.reserve}: must be in [0, 1)")
        if int(self.max_iter) != self.max_iter or self.max_iter < 1:
            raise ControlError(f"MPC max_iter {self.max_iter}: at least 1")


@dataclass
class Solution:
    """One MPC step: the plan (X: nodes 1..N, U: torques 0..N-1), its working set, and the report."""
    X: np.ndarray
    U: np.ndarray
    active: np.ndarray | None
    status: str                # converged | iterate (budget or max_iter) | fallback
    iterations: int
    qp_iterations: list
    cpu_s: float
    wall_s: float
    slack: float
    gap: float
    step: float
    late: bool = False
    notes: list = field(default_factory=list)


class TrackingMPC:
    """Receding-horizon tracking of Xref (nodes 0..Nr on the grid h) and Uref (intervals
    0..Nr-1), holding the last node with its gravity torque beyond the end."""

    def __init__(self, robot: ControlRobot, limits: Limits, Xref, Uref, options: MPCOptions = MPCOptions(),
                 progress=None):
        o = self.options = options
        self.robot, self.limits = robot, limits
        n = self.n = robot.n
        self.nx, self.N, self.h = 2 * n, o.N, o.h
        self.Xref, self.Uref = np.asarray(Xref, float), np.asarray(Uref, float)
        if self.Xref.shape[1] != 2 * n or self.Uref.shape[1] != n or len(self.Xref) != len(self.Uref) + 1:
            raise ControlError(f"reference: Xref (Nr + 1 x {2 * n}) and Uref (Nr x {n}) expected, got "
                               f"{self.Xref.shape} and {self.Uref.shape}")
        self.Uhold = robot.gravity_torque(self.Xref[-1, :n])
        self.lib = stage_library(robot, o.N, o.h, o.integrator, o.inner, progress)
        self.nin = self.lib.layout.nin
        self.tau_max = limits.array("tau_max")
        self.u_max = (1.0 - o.reserve) * self.tau_max
        # the rows hold the limits backed off by a stated margin: between the nodes and the inner
        # substep ends, and under a disturbance the inner loop is still correcting, the plant
        # moves a little past what the plan does (measured: up to 5 % of a speed limit)
        planned = limits.backed_off(o.speed_margin, o.position_margin)
        self.xlo = np.concatenate([planned.array("q_lo"), -planned.array("qd_max")])
        self.xhi = np.concatenate([planned.array("q_hi"), planned.array("qd_max")])
        wx = np.concatenate([np.full(n, o.sigma_q ** -2), np.full(n, o.sigma_qd ** -2)])
        self.wx = np.tile(wx, o.N)
        self.wx[-self.nx:] *= o.terminal
        self.wu = np.tile((o.sigma_tau * self.tau_max) ** -2, o.N)
        self.rho = o.penalty * float(self.wx.max())
        self.d = np.zeros(n)       # the torque disturbance the model adds to the command

    # ---- reference ------------------------------------------------------------------------
    def reference_window(self, i: int):
        Nr = len(self.Uref)
        idx = np.minimum(np.arange(i + 1, i + self.N + 1), Nr)
        U = np.array([self.Uref[j] if j < Nr else self.Uhold for j in range(i, i + self.N)])
        return self.Xref[idx], U

    def initial_guess(self, i: int):
        """The reference window, its torques less the disturbance estimate (under d, Uref - d is
        what moves the model along the reference)."""
        Xr, Ur = self.reference_window(i)
        return Xr.copy(), Ur - self.d

    def shifted(self, X, U, i: int):
        """The warm start of step i + 1 from step i's plan: one interval earlier, the appended
        interval repeating the last node with the reference torque less the disturbance
        estimate (with the reference torque itself, the LWR under a 5 kg payload started every
        re-solve with a gap of 5-6 rad/s at the last node and needed 4 SQP iterations, not 2)."""
        return np.vstack([X[1:], X[-1:]]), np.vstack([U[1:], self.reference_window(i + 1)[1][-1:] - self.d])

    # ---- the QP --------------------------------------------------------------------------
    def qp(self, x0, X, U, i):
        N, nx, n, nin = self.N, self.nx, self.n, self.nin
        Xr, Ur = self.reference_window(i)
        F, A, B, XI, AXI = self.lib.linearise(x0, X, U, self.d)
        d = F - X
        G = np.zeros((N, nx, N * n))
        c = np.zeros((N, nx))
        G[0][:, :n] = B[0]
        c[0] = d[0]
        for k in range(1, N):
            G[k][:, :k * n] = A[k] @ G[k - 1][:, :k * n]
            G[k][:, k * n:(k + 1) * n] = B[k]
            c[k] = A[k] @ c[k - 1] + d[k]
        rows_G = [G.reshape(N * nx, N * n)]
        rows_c = [c.ravel()]
        vals = [X.ravel()]
        lo, hi = [np.tile(self.xlo, N)], [np.tile(self.xhi, N)]
        if nin:
            # inner states: d xi_k = AXI_k [dx_k; du_k], dx_k = G_{k-1} dU + c_{k-1} (dx_0 = 0)
            Gi = np.zeros((N, nin, N * n))
            ci = np.zeros((N, nin))
            Ax, Au = AXI[:, :, :nx], AXI[:, :, nx:]
            Gi[0][:, :n] = Au[0]
            for k in range(1, N):
                Gi[k][:, :k * n] = Ax[k] @ G[k - 1][:, :k * n]
                Gi[k][:, k * n:(k + 1) * n] = Au[k]
                ci[k] = Ax[k] @ c[k - 1]
            rows_G.append(Gi.reshape(N * nin, N * n))
            rows_c.append(ci.ravel())
            vals.append(XI.ravel())
            lo.append(np.tile(self.xlo, N * nin // nx))
            hi.append(np.tile(self.xhi, N * nin // nx))
        Gall, call, vall = np.vstack(rows_G), np.concatenate(rows_c), np.concatenate(vals)
        e = (X - Xr).ravel() + c.ravel()
        WG = self.wx[:, None] * rows_G[0]
        H = rows_G[0].T @ WG
        H[np.diag_indices_from(H)] += self.wu
        # offset-free: the torque that holds the reference under the estimated disturbance is
        # Uref - d, so that is what the torque term tracks (tracking Uref itself would trade a
        # steady position error against the torque that cancels d)
        g = WG.T @ e + self.wu * (U - Ur + self.d).ravel()
        um = np.tile(self.u_max, N)
        Uf = U.ravel()
        base = vall + call
        return {"H": H, "g": g, "C": Gall, "row_lo": np.concatenate(lo) - base, "row_hi": np.concatenate(hi) - base,
                "box_lo": -um - Uf, "box_hi": um - Uf, "G": rows_G[0], "c": c.ravel(), "gap": d}

    def solve_qp(self, q, active=None, time_limit: float = 0.0):
        """DAQP on the QP in (dU, t) with the limit rows one-sided and lazy (module docstring).
        Returns (dU, t, exit flag, DAQP iterations, working set over [dU, t, rows])."""
        import daqp
        nb = self.N * self.n
        C, lo, hi = q["C"], q["row_lo"], q["row_hi"]
        m = len(lo)
        width = hi - lo
        screen = self.options.screen * width
        keep_lo = -lo < screen       # the linearisation point is near the lower bound
        keep_hi = hi < screen
        if active is not None and len(active) == nb + 1 + 2 * m:
            keep_lo |= active[nb + 1:nb + 1 + m] != 0
            keep_hi |= active[nb + 1 + m:] != 0
        # DAQP on the Jacobi-scaled variables v = dU / D: the condensed Hessian's diagonal spans
        # eleven decades on the Panda (its light wrist against the terminal weights), and DAQP then
        # wanders for hundreds of iterations to a solution it finds in two after the scaling
        D = 1.0 / np.sqrt(np.diag(q["H"]))
        C = C * D[None, :]
        H = np.zeros((nb + 1, nb + 1))
        H[:nb, :nb] = q["H"] * D[:, None] * D[None, :]
        # t's curvature keeps H positive definite; it does not spoil exactness (the penalty's
        # slope at t = 0 is rho whatever the curvature)
        H[nb, nb] = 1.0
        f = np.concatenate([q["g"] * D, [self.rho]])
        iters = 0
        while True:
            il, ih = np.flatnonzero(keep_lo), np.flatnonzero(keep_hi)
            A = np.vstack([np.hstack([C[il], np.ones((len(il), 1))]), np.hstack([C[ih], -np.ones((len(ih), 1))])])
            bu = np.concatenate([q["box_hi"] / D, [INF], np.full(len(il), INF), hi[ih]])
            bl = np.concatenate([q["box_lo"] / D, [0.0], lo[il], np.full(len(ih), -INF)])
            sense = np.zeros(nb + 1 + len(il) + len(ih), dtype=np.int32)
            if active is not None and len(active) == nb + 1 + 2 * m:
                prev = np.concatenate([active[:nb + 1], active[nb + 1:nb + 1 + m][il], active[nb + 1 + m:][ih]])
                sense |= (prev != 0).astype(np.int32) | (2 * (prev < 0)).astype(np.int32)
            A = np.ascontiguousarray(A) if len(A) else np.zeros((0, nb + 1))
            # one cap on DAQP's iterations for the whole step (the lazy rows' re-solves and a cold
            # restart share it): it bounds the QP's time where the active set changes most
            left = max(self.options.qp_iter_limit - iters, 1)
            x, _, flag, info = daqp.solve(H, f, A, bu, bl, sense, iter_limit=left, time_limit=time_limit)
            iters += int(info["iterations"])
            # the shifted working set did not fit (infeasible, cycling, overdetermined): start cold;
            # not after the iteration cap (-4), which bounds the step's time
            if flag in (-1, -2, -6) and sense.any() and iters < self.options.qp_iter_limit:
                x, _, flag, info = daqp.solve(H, f, A, bu, bl, np.zeros_like(sense),
                                              iter_limit=self.options.qp_iter_limit - iters, time_limit=time_limit)
                iters += int(info["iterations"])
            x = np.asarray(x)
            if flag < 0 or not np.all(np.isfinite(x)):
                return np.zeros(nb), 0.0, int(flag), iters, None
            du, t = x[:nb] * D, max(float(x[nb]), 0.0)
            v = q["C"] @ du
            missed_lo = ~keep_lo & (v + t < lo - 1e-9)
            missed_hi = ~keep_hi & (v - t > hi + 1e-9)
            if not (missed_lo.any() or missed_hi.any()):
                break
            keep_lo |= missed_lo
            keep_hi |= missed_hi
        lam = np.sign(np.asarray(info["lam"])).astype(np.int32)
        act = np.zeros(nb + 1 + 2 * m, np.int32)
        act[:nb + 1] = lam[:nb + 1]
        act[nb + 1 + il] = lam[nb + 1:nb + 1 + len(il)]
        act[nb + 1 + m + ih] = lam[nb + 1 + len(il):]
        return du, t, int(flag), iters, act

    def shifted_active(self, active):
        if active is None:
            return None
        N, n = self.N, self.n
        m = (len(active) - N * n - 1) // 2
        per = m // N
        box = active[:N * n].reshape(N, n)
        lo = active[N * n + 1:N * n + 1 + m]
        hi = active[N * n + 1 + m:]

        def shift_rows(r):
            # node rows then inner rows, each N blocks: shift both blocks
            nodes, inner = r[:N * self.nx].reshape(N, -1), r[N * self.nx:].reshape(N, -1) if per > self.nx else None
            out = [np.vstack([nodes[1:], nodes[-1:]]).ravel()]
            if inner is not None and inner.size:
                out.append(np.vstack([inner[1:], inner[-1:]]).ravel())
            return np.concatenate(out)
        return np.concatenate([np.vstack([box[1:], box[-1:]]).ravel(), active[N * n:N * n + 1], shift_rows(lo),
                               shift_rows(hi)])

    # ---- SQP ----------------------------------------------------------------------------
    def solve(self, x0, i: int, X0, U0, active=None, max_iter: int | None = None) -> Solution:
        o = self.options
        max_iter = o.max_iter if max_iter is None else max_iter
        t0, c0 = time.perf_counter(), time.process_time()
        X, U = np.array(X0, float), np.clip(np.array(U0, float), -self.u_max, self.u_max)
        x0 = np.asarray(x0, float)
        it, qp_iters, step, gap, slack = 0, [], np.inf, np.inf, 0.0
        status, per_iter = "iterate", 0.0
        ok = False
        while it < max_iter:
            used = time.process_time() - c0
            if it > 0 and used + per_iter > o.budget_s:
                break
            q = self.qp(x0, X, U, i)
            gap = float(np.abs(q["gap"]).max())
            du, t, flag, qi, act = self.solve_qp(q, active, max(o.budget_s - (time.process_time() - c0), 1e-4))
            qp_iters.append(qi)
            it += 1
            if act is None:          # DAQP failed: keep the last good iterate
                break
            D = du.reshape(self.N, self.n)
            Xn = X + (q["G"] @ du + q["c"]).reshape(self.N, self.nx)
            if not self._sane(Xn, x0):      # a linearisation far from any motion of the arm: keep the iterate
                break
            active = act
            ok = True
            step = float(np.max(np.abs(D) / self.tau_max))
            U = np.clip(U + D, -self.u_max, self.u_max)
            X = Xn
            slack = t
            per_iter = (time.process_time() - c0) / it
            if step <= o.tol and gap <= o.tol:
                status = "converged"
                break
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        if not ok or not np.all(np.isfinite(U)) or not np.all(np.isfinite(X)):
            status = "fallback"
        late = cpu > o.budget_s
        return Solution(X, U, active, status, it, qp_iters, cpu, wall, slack, gap, step, late)

    def _sane(self, X, x0) -> bool:
        """Nodes within 2 pi of the measured configuration and 10 speed limits beyond the
        measured speed: anything else is a linearisation run away (the step of a QP whose
        sensitivities exploded), not a plan."""
        n = self.n
        if not np.all(np.isfinite(X)):
            return False
        q, v = X[:, :n], X[:, n:]
        return bool(np.all(np.abs(q - x0[:n]) < 2 * np.pi) and np.all(np.abs(v) < 10 * self.xhi[n:] + np.abs(x0[n:])))

    def predict(self, x0, u) -> np.ndarray:
        """The model's state one interval after x0 under u + d."""
        return self.lib.step(x0, np.asarray(u, float) + self.d)
