"""The time-optimal point-to-point NLP of examples/ocp.py (free T, multiple shooting, RK4 on the
generated `fd`), unchanged, with its constraint Jacobian and the Hessian of its Lagrangian
assembled from per-interval functions compiled to C once: the same iterates as
`examples/ocp.py`'s default (mx_map) formulation at a fraction of the cost per iteration.

Why: with mx_map, IPOPT spends its time in CasADi's virtual machine evaluating the exact
Hessian of the 40 mapped RK4 steps (~0.6 s an iteration on the Panda, N = 40). Compiling the
RK4 step's Hessian as one SX graph is hopeless (19 MB of C for the Panda; gcc -O1 had not
finished after 11 min, docs/optimal_control.md): with 4 substeps, 16 chained evaluations of
`fd` are inlined and differentiated together. Here the chain is split at the calls of `fd`.
For w = (x_k, u_k, h) of one interval and its Lagrangian term
L = lam' c(w) + sigma weight h |u / tau_max|^2 (c: the RK4 end state and the inner substep
states), the second-order chain rule gives

    d2L/dw2 = H_lin + sum_i J_i' Hf(y_i, mu_i) J_i

with y_i = (q_i, qd_i, tau) the input of the i-th call of fd, J_i = dy_i/dw, mu_i the adjoint
of that call's output and Hf(y, mu) = d2(mu' fd(y))/dy2 (21 x 21 for 7 joints). H_lin, J_i and
mu_i are the Hessian, the Jacobians and the adjoints of a *surrogate* step in which every call
of fd is replaced by its linearisation at the true stage point, fd(Y0_i) + A_i (y - Y0_i), with
A_i = d fd / dy there (the generated analytic `fd_derivatives`): the surrogate has the true
step's values and first derivatives, and its second derivatives are those of the RK4
arithmetic alone (the products of h with the stage slopes). So each piece is small: the RK4
forward pass, `fd_derivatives`, `Hf` and the surrogate step are SX Functions compiled once,
called from the per-interval MX Functions (mapped over the intervals by the NLP).

T enters every interval through h = T / N: the NLP's Hessian is block diagonal over the
intervals plus an arrowhead row/column for T, assembled by one constant sparse matrix from the
mapped interval Hessians (and the Jacobian likewise, with the -I of x_{k+1}).

Worked example::

    >>> import ocp, ocp_time_stages                                         # doctest: +SKIP
    >>> funcs = ocp.load_functions("panda"); setup = ocp.problem_setup("panda", funcs)   # doctest: +SKIP
    >>> nlp = ocp_time_stages.TimeOptimalStages(setup, funcs, N=40, substeps=4)         # doctest: +SKIP
    >>> round(nlp.solve()["T"], 6)                                        # doctest: +SKIP
    0.595957
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

import ocp
import ocp_stages


def fd_hessian(fd: ca.Function, n: int) -> ca.Function:
    """Hf(y, mu) = d2(mu' fd(q, qd, tau))/dy2 over y = (q, qd, tau): symmetric 3n x 3n, its
    structural pattern (the tau-tau block is zero: fd is affine in tau)."""
    y, mu = ca.SX.sym("y", 3 * n), ca.SX.sym("mu", n)
    H = ca.hessian(ca.dot(mu, fd(y[:n], y[n:2 * n], y[2 * n:])), y)[0]
    return ca.Function("topt_fd_hess", [y, mu], [H], ["y", "mu"], ["hess"])


def fd_jacobian(fd_derivatives: ca.Function, n: int) -> ca.Function:
    """A(y) = d fd / d(q, qd, tau), n x 3n, from the generated analytic derivatives."""
    y = ca.SX.sym("y", 3 * n)
    dq, dqd, minv = fd_derivatives(y[:n], y[n:2 * n], y[2 * n:])
    return ca.Function("topt_fd_jac", [y], [ca.horzcat(dq, dqd, minv)], ["y"], ["A"])


class _Recorder:
    """An RK4 right-hand side (x, u) -> (qd, slope) for examples/ocp.py's _rk4 that calls
    `slope(i, y)` for the i-th evaluation of the dynamics and records the stage inputs y."""

    def __init__(self, n, slope):
        self.n, self.slope, self.i, self.ys, self.outs = n, slope, 0, [], []

    def __call__(self, x, u):
        n = self.n
        y = ca.vertcat(x[:n], x[n:2 * n], u[:n])
        self.ys.append(y)
        out = self.slope(self.i, y)
        self.outs.append(out)
        self.i += 1
        return ca.vertcat(x[n:2 * n], out)


class TimeOptimalStages:
    """examples/ocp.py's p2p NLP (variables (T, vec X, vec U), the same constraints, bounds,
    objective and guess) with IPOPT's jac_g and hess_lag assembled from compiled per-interval
    functions. compile_stages=False keeps the SX/MX originals (no gcc: for tests)."""

    def __init__(self, setup: dict, funcs: dict, N: int, substeps: int = 4, compile_stages: bool = True,
                 cc: str = "gcc", cflags: tuple[str, ...] | None = None):
        if setup["kind"] != "p2p":
            raise ValueError(f"problem {setup['problem']}: the compiled route serves the p2p problems (lwr4, panda)")
        t0 = time.perf_counter()
        self.setup, self.N, self.substeps = setup, N, substeps
        n = self.n = setup["n"]
        nx, nu = self.nx, self.nu = 2 * n, n
        self.nw = nx + nu + 1                       # w = (x_k, u_k, h)
        self.S = 4 * substeps                       # calls of fd per interval
        self.nin = nx * (substeps - 1)              # inner substep states per interval
        self.nc = nx + self.nin
        fd = funcs["fd"]
        fdd = ca.Function.load(str(ocp.Path(funcs["folder"]) / "fd_derivatives.casadi"))
        self.pieces = self._interval_functions(fd, fdd)
        self.compile_s = 0.0
        if compile_stages:
            fs = list(self.pieces.values())
            t1 = time.perf_counter()
            so = ocp_stages.compile_library(fs, f"topt_{setup['problem']}_M{substeps}", cc, cflags)
            self.compile_s = time.perf_counter() - t1
            self.fns = {f.name(): ca.external(f.name(), so) for f in fs if not f.name().startswith("jac_")}
        else:
            self.fns = self.pieces
        self._build_nlp()
        self.build_s = time.perf_counter() - t0

    # ---- one interval ------------------------------------------------------------------
    def _interval_functions(self, fd, fdd) -> dict:
        n, nx, nu, S = self.n, self.nx, self.nu, self.S
        tau_max, weight = self.setup["tau_max"], self.setup["weight"]
        Hf, Af = fd_hessian(fd, n), fd_jacobian(fdd, n)
        # the true RK4 forward pass (SX, fd inlined), recording the stage inputs and slopes
        ws = ca.SX.sym("w", self.nw)
        rec = _Recorder(n, lambda i, y: fd(y[:n], y[n:2 * n], y[2 * n:]))
        c = self._step(rec, ws)
        forward = ca.Function("topt_forward", [ws], [c, ca.horzcat(*rec.ys), ca.horzcat(*rec.outs)], ["w"],
                              ["c", "Y", "F"])
        # the structural patterns of c's Jacobian and of the Lagrangian's Hessian (of this SX
        # step, as CasADi finds them for examples/ocp.py's NLP): the assembled matrices carry
        # exactly those nonzeros, so IPOPT and MUMPS see the KKT pattern of the mx_map NLP
        lam_s, sig_s = ca.SX.sym("lam", self.nc), ca.SX.sym("sigma")
        lag_s = ca.dot(lam_s, c) + sig_s * weight * ws[-1] * ca.sumsqr(ws[nx:nx + nu] / ca.DM(tau_max))
        jac_sp = ca.jacobian_sparsity(c, ws)
        hess_sp = ca.jacobian_sparsity(ca.gradient(lag_s, ws), ws)
        # the surrogate step, every call of fd linearised at its true stage point; MX, so that
        # its derivatives stay matrix products (as SX, the 16 chained 7 x 21 times 21 x 22
        # tangent products are 90k scalar instructions, ~4 MB of C)
        wm = ca.MX.sym("w", self.nw)
        Y0, F0, A = ca.MX.sym("Y0", 3 * n, S), ca.MX.sym("F0", n, S), ca.MX.sym("A", n, 3 * n * S)
        dlt = ca.MX.sym("delta", n, S)        # added to each linearised slope: its gradient is mu_i
        rec = _Recorder(n, lambda i, y: F0[:, i] + ca.mtimes(A[:, 3 * n * i:3 * n * (i + 1)], y - Y0[:, i])
                        + dlt[:, i])
        cs = self._step(rec, wm)
        lam, sigma = ca.MX.sym("lam", self.nc), ca.MX.sym("sigma")
        u, h = wm[nx:nx + nu], wm[-1]
        Lag = ca.dot(lam, cs) + sigma * weight * h * ca.sumsqr(u / ca.DM(tau_max))
        Jall = ca.jacobian(ca.vertcat(*rec.ys, cs), wm)
        nys = 3 * n * S
        sur_jac = ca.Function("topt_sur_jac", [wm, Y0, F0, A, dlt], [Jall[:nys, :], Jall[nys:, :]],
                              ["w", "Y0", "F0", "A", "delta"], ["Jy", "Jc"])
        sur_hess = ca.Function("topt_sur_hess", [wm, Y0, F0, A, lam, sigma, dlt],
                               [ca.hessian(Lag, wm)[0], ca.reshape(ca.gradient(Lag, ca.vec(dlt)), n, S)],
                               ["w", "Y0", "F0", "A", "lam", "sigma", "delta"], ["H_lin", "mu"])
        # the per-interval Functions the NLP maps
        w, lm, sg = ca.MX.sym("w", self.nw), ca.MX.sym("lam", self.nc), ca.MX.sym("sigma")
        cw, Yw, Fw = forward(w)
        Aw = Af.map(S)(Yw)
        dz = ca.DM.zeros(n, S)
        Jy, Jc = sur_jac(w, Yw, Fw, Aw, dz)
        Hlin, muw = sur_hess(w, Yw, Fw, Aw, lm, sg, dz)
        Hs = Hf.map(S)(Yw, muw)
        # sum_i J_i' Hs_i J_i as straight-line SX on the structural patterns (the tau rows of
        # J_i are [0 I 0], Hf's tau-tau block is zero): about 3x faster than MX matrix products
        Jis = [Jy[3 * n * i:3 * n * (i + 1), :] for i in range(S)]
        pattern = Jis[0].sparsity()
        for Ji in Jis[1:]:
            pattern = pattern.unite(Ji.sparsity())
        Ji, Hi = ca.SX.sym("J", pattern), ca.SX.sym("Hs", Hf.sparsity_out(0))
        one = ca.Function("topt_congruence", [Ji, Hi], [ca.mtimes([Ji.T, Hi, Ji])], ["J", "Hs"], ["JHJ"])
        parts = [one(ca.project(Ji, pattern), Hs[:, 3 * n * i:3 * n * (i + 1)]) for i, Ji in enumerate(Jis)]
        H = Hlin + sum(parts[1:], parts[0])
        out = ca.MX.sym("out", self.nc)
        return {"topt_c": ca.Function("topt_c", [w], [cw], ["w"], ["c"]),
                "jac_topt_c": ca.Function("jac_topt_c", [w, out], [Jc], ["w", "out_c"], ["jac_c_w"]),
                "topt_jc": ca.Function("topt_jc", [w], [cw, ca.project(Jc, jac_sp)], ["w"], ["c", "jac"]),
                "topt_hl": ca.Function("topt_hl", [w, lm, sg], [ca.triu(ca.project(H, hess_sp))],
                                       ["w", "lam", "sigma"], ["hess"])}

    def _step(self, rec, w):
        """c(w): the RK4 end state and the inner substep states of one interval, the slopes
        from `rec`."""
        nx, nu = self.nx, self.nu
        xe, xi = ocp._rk4(rec, w[:nx], w[nx:nx + nu], w[-1], self.substeps, inner=True)
        return ca.vertcat(xe, ca.vec(xi)) if self.substeps > 1 else xe

    # ---- the NLP -------------------------------------------------------------------------
    def _index(self):
        """Column of the NLP variable for interval k's local w index j (and its chain-rule
        factor: h = T / N)."""
        N, nx, nu = self.N, self.nx, self.nu

        def col(k, j):
            if j < nx:
                return 1 + nx * k + j, 1.0
            if j < nx + nu:
                return 1 + nx * (N + 1) + nu * k + (j - nx), 1.0
            return 0, 1.0 / N
        return col

    def _build_nlp(self):
        N, nx, nu, nin = self.N, self.nx, self.nu, self.nin
        nv = 1 + nx * (N + 1) + nu * N
        V = ca.MX.sym("V", nv)
        T = V[0]
        X = ca.reshape(V[1:1 + nx * (N + 1)], nx, N + 1)
        U = ca.reshape(V[1 + nx * (N + 1):], nu, N)
        W = ca.vertcat(X[:, :N], U, ca.repmat(T / N, 1, N))
        ng_eq = nx * N

        def gaps(C):
            return ca.vertcat(ca.vec(C[:nx, :] - X[:, 1:]), ca.vec(C[nx:, :]))
        # g of the NLP from topt_c (its Jacobian is in the library, for nlpsol's own derivative
        # functions); jac_g from topt_jc, the values and the Jacobian in one pass
        g = gaps(self.fns["topt_c"].map(N)(W))
        C, JC = self.fns["topt_jc"].map(N)(W)
        self.ng = g.numel()
        col = self._index()

        def crow(k, r):
            return nx * k + r if r < nx else ng_eq + nin * k + (r - nx)
        # Jacobian: nonzeros = Pj @ (the nonzeros of the N mapped blocks, 1); JC holds the
        # blocks side by side, its nonzeros block by block, each in jsp's order
        jsp = self.pieces["topt_jc"].sparsity_out(1)
        jr, jc = jsp.get_triplet()
        rows, cols, src, val = [], [], [], []
        for k in range(N):
            for t, (r, j) in enumerate(zip(jr, jc)):
                cj, fac = col(k, j)
                rows.append(crow(k, r)); cols.append(cj); src.append(jsp.nnz() * k + t); val.append(fac)
            for r in range(nx):      # -x_{k+1}
                rows.append(nx * k + r); cols.append(1 + nx * (k + 1) + r); src.append(jsp.nnz() * N); val.append(-1.0)
        Jnz, sp_j = self._scatter(rows, cols, src, val, ca.vertcat(JC.nz[:], 1), self.ng, nv)
        J = ca.MX(sp_j, Jnz)
        # Hessian: interval k's triu 22 x 22 block, local (a, b) -> global (min, max)
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", self.ng)
        Lc = ca.vertcat(ca.reshape(lam_g[:ng_eq], nx, N), ca.reshape(lam_g[ng_eq:], nin, N))
        HL = self.fns["topt_hl"].map(N)(W, Lc, ca.repmat(lam_f, 1, N))
        hsp = self.pieces["topt_hl"].sparsity_out(0)
        hr, hc = hsp.get_triplet()
        rows, cols, src, val = [], [], [], []
        for k in range(N):
            for t, (a, b) in enumerate(zip(hr, hc)):
                (ga, fa), (gb, fb) = col(k, a), col(k, b)
                rows.append(min(ga, gb)); cols.append(max(ga, gb)); src.append(hsp.nnz() * k + t); val.append(fa * fb)
        # HL: the N triu blocks side by side; its nonzeros run block by block, each in hsp's order
        Hnz, sp_h = self._scatter(rows, cols, src, val, HL.nz[:], nv, nv)
        Hfull = ca.MX(sp_h, Hnz)
        s = self.setup
        J_obj = T
        if s["weight"]:
            J_obj = J_obj + s["weight"] * (T / N) * ca.sumsqr(U / ca.repmat(ca.DM(s["tau_max"]), 1, N))
        self.nlp = {"x": V, "f": J_obj, "g": g}
        self.f_jac_g = ca.Function("nlp_jac_g", [V, ca.MX.sym("p", 0)], [gaps(C), J], ["x", "p"], ["g", "jac_g_x"])
        self.f_hess = ca.Function("nlp_hess_l", [V, ca.MX.sym("p", 0), lam_f, lam_g], [Hfull],
                                  ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])

    @staticmethod
    def _scatter(rows, cols, src, val, source: ca.MX, nr: int, nc: int):
        """Nonzeros (in CCS order of the pattern) of sum over entries of val * source[src] at
        (row, col), and the pattern: one constant sparse matrix times the source vector."""
        rows, cols = np.asarray(rows), np.asarray(cols)
        key = cols * nr + rows
        uniq, inv = np.unique(key, return_inverse=True)        # sorted by column, then row: CCS
        src, val = np.asarray(src), np.asarray(val, float)
        order = np.lexsort((inv, src))                          # P's own CCS order: by source, then row
        P = ca.DM(ca.Sparsity.triplet(len(uniq), source.numel(), inv.tolist(), src.tolist()), val[order])
        sp = ca.Sparsity.triplet(nr, nc, (uniq % nr).tolist(), (uniq // nr).tolist())
        return ca.mtimes(P, source), sp

    # ---- solve -------------------------------------------------------------------------------
    def solver(self, options: dict | None = None) -> ca.Function:
        """IPOPT with examples/ocp.py's options and the assembled derivatives."""
        opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": 3000, "ipopt.tol": 1e-8,
                "jac_g": self.f_jac_g, "hess_lag": self.f_hess}
        opts.update(options or {})
        return ca.nlpsol("ocp_stages", "ipopt", self.nlp, opts)

    def solve(self, options: dict | None = None) -> dict:
        """ocp.solve()'s result dict (plus solve_cpu_s, compile_s) for the same NLP."""
        t0 = time.perf_counter()
        solver = self.solver(options)
        build_s = self.build_s + time.perf_counter() - t0
        lbx, ubx, guess = ocp.bounds_and_guess(self.setup, self.N)
        lbg, ubg = self._gbounds()
        t1, c1 = time.perf_counter(), time.process_time()
        sol = solver(x0=guess, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        solve_s, solve_cpu = time.perf_counter() - t1, time.process_time() - c1
        st = solver.stats()
        v = np.array(sol["x"]).ravel()
        N, n, nx, nu = self.N, self.n, self.nx, self.nu
        X = v[1:1 + nx * (N + 1)].reshape((nx, N + 1), order="F")
        U = v[1 + nx * (N + 1):].reshape((nu, N), order="F")
        T = float(v[0])
        return {"status": st["return_status"], "success": bool(st["success"]), "iterations": int(st["iter_count"]),
                "solve_s": solve_s, "solve_cpu_s": solve_cpu, "build_s": build_s, "compile_s": self.compile_s,
                "T": T, "N": N, "mode": "stages", "substeps": self.substeps, "t": np.linspace(0, T, N + 1),
                "q": X[:n].T, "qd": X[n:].T, "tau": U.T, "s": X[2 * n:].T, "sdot": U[n:].T,
                "objective": float(sol["f"]), "max_defect": float(np.abs(np.array(sol["g"])[:N * nx]).max())}

    def _gbounds(self):
        """ocp.build_nlp's bounds on g: the gaps zero, the inner substep states within the
        position limits and the backed-off velocity limits."""
        s, N = self.setup, self.N
        lbg, ubg = np.zeros(self.ng), np.zeros(self.ng)
        if self.substeps > 1:
            qd_inner = (1.0 - ocp.VELOCITY_BACKOFF) * s["qd_max"]
            cnt = (self.substeps - 1) * N
            lbg[self.nx * N:] = np.tile(np.concatenate([s["q_lo"], -qd_inner]), cnt)
            ubg[self.nx * N:] = np.tile(np.concatenate([s["q_hi"], qd_inner]), cnt)
        return lbg, ubg
