"""The LWR reach of examples/ocp_reach.py in the fd_rk4 formulation (one explicit RK4 step of the
generated forward dynamics per interval, torques the only controls: nu = 7) from compiled
per-interval functions with the exact Hessian, solved by IPOPT: examples/ocp.py --solver
fd_stages and benchmarks/ocp_bench.py's "fd_rk4 fd_stages" row.

Why: examples/ocp_stages.py compiles the id_rk4 interval (nu = 35: the torque and the four RK4
stage accelerations, 28 inverse-dynamics rows), whose KKT system IPOPT factorises at every
iteration (1858 variables): MUMPS is most of its solve time. fd_rk4's NLP is 5x smaller (434
variables, 304 equality rows), but the Hessian of the RK4 step of `fd` compiled directly is 19
MB of C (not built in 11 min). Here it is built from the inverse dynamics' Hessian instead
(examples/ocp_sqp.py's derivation, written in MX over generated functions so that it compiles
to a few hundred kB): at the four RK4 stages a_i = fd(q_i, qd_i, u) satisfies r_i =
tau(q_i, qd_i, a_i) - u = 0 and the stage states y_i = (q_i, qd_i, a_i) are linear in (x, u, a),
so the Hessian over w = (x, u) of mu' F(x, u) is

    sum_i (dy_i/dw)' Hess_y[lam_i' tau](y_i) (dy_i/dw),   R_a' lam = -F_a' mu,

with dy_i/dw chained forward from the analytic `fd_derivatives` (da/dq, da/dqd, M^-1) and lam by
back substitution through the block lower-triangular R_a (diagonal blocks the mass matrices,
inverted by fd_derivatives' M^-1; the off-diagonal blocks, the inverse dynamics' Jacobians
times RK4 coefficients, are -M da/dq and -M da/dqd, so fd_derivatives serves them too). The constraint Jacobian blocks (-A, -B, I) come from the same forward chain
(examples/mpc_sqp.rk4_step_with_jacobians).

The NLP, its variable and constraint order are examples/ocp_stages.py's, with the interval
(x_k, u_k, x_{k+1}) of 35 variables and 14 gap rows.

Two builds. native=True (default): examples/fd_stages_nlp.c, the NLP's constraints, Jacobian and
Hessian for the whole horizon in C over the robot's generated C (lwr4_fd, lwr4_fd_derivatives)
and CasADi's code of the lam' tau Hessian, the forward chain of every interval computed once per
point and kept for the Hessian (compile_native; 0.074 s CPU a solve against the baseline's 3.14
s, same run, load ~5.7: 43x). native=False: the MX functions above compiled by CasADi's code
generator (ocp_stages.compile_functions, gcc -O1) and assembled per interval in MX by
StageReach.assemble (0.163 s in that run: the Jacobian and the Hessian each redo the chain).

Worked example::

    >>> from ocp_fd_stages import FdStageReach                            # doctest: +SKIP
    >>> s = FdStageReach(N=20)                                             # doctest: +SKIP
    >>> r = s.solve_ipopt(); r["status"], round(r["objective"], 3)         # doctest: +SKIP
    ('Solve_Succeeded', 716.662)
"""
from __future__ import annotations

import time
from pathlib import Path

import casadi as ca
import numpy as np

import mpc_sqp
import ocp_reach
import ocp_stages


def rk4_lagrangian_hessian(fd, fd_derivatives, tau, n: int, h: float, w: ca.MX,
                           mu: ca.MX) -> ca.MX:
    """Hessian over w = (x, u) of mu' F(w), F the classic RK4 step of xdot = (qd, fd(q, qd, u))
    over h, from the inverse dynamics' Hessian (module docstring). MX over the generated
    Functions; the Hessian of one Newton-Euler pass is one SX Function called at the 4 stages."""
    q, v, u = w[:n], w[n:2 * n], w[2 * n:]
    nw = 3 * n
    Iw = ca.MX.eye(nw)
    Q, V = Iw[:n, :], Iw[n:2 * n, :]
    Eu = Iw[2 * n:, :]
    qs, vs, acc, dQ, dV, dA, minv, Dqs, Dvs = [], [], [], [], [], [], [], [], []
    coef = (0.0, h / 2, h / 2, h)
    for i in range(4):
        if i == 0:
            qi, vi, Qi, Vi = q, v, Q, V
        else:
            # q_i = q + c_i v_{i-1}, v_i = v + c_i a_{i-1}
            qi, vi = q + coef[i] * vs[i - 1], v + coef[i] * acc[i - 1]
            Qi, Vi = Q + coef[i] * dV[i - 1], V + coef[i] * dA[i - 1]
        ai = fd(qi, vi, u)
        Dq, Dv, Mi = fd_derivatives(qi, vi, u)
        qs.append(qi)
        vs.append(vi)
        acc.append(ai)
        dQ.append(Qi)
        dV.append(Vi)
        dA.append(Dq @ Qi + Dv @ Vi + Mi @ Eu)
        minv.append(Mi)
        Dqs.append(Dq)
        Dvs.append(Dv)
    # back substitution R_a' lam = b = -F_a' mu, R_a[i][j] = d r_i / d a_j: M_i on the diagonal,
    # below it (j < i) through q_i, v_i: v_i depends on a_{i-1} (c_i), q_3 on a_1 (h^2 / 4) and
    # q_4 on a_2 (h^2 / 2). With dtau/dq = -M da/dq, dtau/dqd = -M da/dqd at each stage and
    # rho_j = M_j lam_j, R_a[j][i]' lam_j = -(d q_j/d a_i) Dq_j' rho_j - (d v_j/d a_i) Dv_j' rho_j:
    # no inverse dynamics' Jacobian is needed
    mq, mv = mu[:n], mu[n:]
    b = [-(h ** 2 / 6 * mq + h / 6 * mv), -(h ** 2 / 6 * mq + h / 3 * mv), -(h ** 2 / 6 * mq + h / 3 * mv),
         -(h / 6 * mv)]
    dq_da = {(2, 0): h ** 2 / 4, (3, 1): h ** 2 / 2}                 # d q_j / d a_i
    dv_da = {(1, 0): coef[1], (2, 1): coef[2], (3, 2): coef[3]}     # d v_j / d a_i
    rho, lam = [None] * 4, [None] * 4
    for i in range(3, -1, -1):
        rhs = b[i]
        for j in range(i + 1, 4):
            if (j, i) in dq_da:
                rhs = rhs + dq_da[(j, i)] * (Dqs[j].T @ rho[j])
            if (j, i) in dv_da:
                rhs = rhs + dv_da[(j, i)] * (Dvs[j].T @ rho[j])
        rho[i] = rhs
        lam[i] = minv[i] @ rhs
    y, m = ca.SX.sym("y", nw), ca.SX.sym("m", n)
    hid = ca.Function("id_hessian", [y, m], [ca.hessian(ca.dot(m, tau(y[:n], y[n:2 * n], y[2 * n:])), y)[0]])
    H = ca.MX(nw, nw)
    for i in range(4):
        dY = ca.vertcat(dQ[i], dV[i], dA[i])
        H += dY.T @ hid(ca.vertcat(qs[i], vs[i], acc[i]), lam[i]) @ dY
    return H


NATIVE_C = Path(__file__).resolve().parent / "fd_stages_nlp.c"
# clang -O2: 14 s for the glue (mostly lwr4.c) against 23 s for gcc -O2, code as fast (kdg_idh 2.8
# vs 2.6 us a call, fd_derivatives 1.6 vs 1.5 us; the reach solve 0.070 vs 0.076 s CPU, same run).
# KINDYNGEN_FDNLP_CFLAGS adds flags, e.g. "-O3 -march=native" (not portable: the library is
# cached in $TMPDIR, per machine)
NATIVE_CC = ("clang", "-O2", "-std=c99", "-shared", "-fPIC")


def compile_native(funcs: dict, n: int, N: int, h: float) -> dict:
    """examples/fd_stages_nlp.c for the robot's generated C (generated/<robot>/c) and CasADi's
    code of its small helpers, compiled into one library (cached by the hash of the sources and
    flags, like ocp_stages.compile_library); {name: external Function} for fdnlp_g,
    fdnlp_jac_g, fdnlp_hess."""
    import os
    name = funcs["robot"].name
    cdir = Path(ocp_reach.ROOT) / "generated" / name / "c"
    y, m = ca.SX.sym("y", 3 * n), ca.SX.sym("m", n)
    tau = funcs["tau"]
    Hid = ca.hessian(ca.dot(m, tau(y[:n], y[n:2 * n], y[2 * n:])), y)[0]
    # the C reads only the blocks qq, qv, qa, vv: tau is linear in qdd, without qd-qdd terms
    assert Hid[2 * n:, n:].nnz() == 0
    xN, goal, lamT = ca.SX.sym("xN", 2 * n), ca.SX.sym("goal", 3), ca.SX.sym("lamT", 3 + n)
    term = ca.vertcat(funcs["fk_hom"](xN[:n])[:3, 3] - goal, xN[n:])
    helpers = [ca.Function("kdg_idh", [y, m], [ca.densify(Hid)]),
               ca.Function("kdg_term", [xN, goal], [ca.densify(term)]),
               ca.Function("kdg_jterm", [xN, goal], [ca.densify(ca.jacobian(term, xN))]),
               ca.Function("kdg_hterm", [xN, lamT], [ca.densify(ca.hessian(ca.dot(lamT, term), xN)[0])])]
    cg = ca.CodeGenerator("kdg_helpers.c", {"with_header": False})
    for f in helpers:
        cg.add(f)
    szw = max(f.sz_w() for f in helpers)
    sziw = max(f.sz_iw() for f in helpers)
    glue = "\n".join([
        f'#include "{cdir / (name + ".c")}"',
        cg.dump(),
        f"#define NDOF {n}", f"#define NINT {N}", f"#define HSTEP {float(h)!r}",
        f"#define KDG_FD {name}_fd", f"#define KDG_FDD {name}_fd_derivatives",
        f"#define KDG_SZW {szw + 1}", f"#define KDG_SZIW {sziw + 1}",
        f'#include "{NATIVE_C}"', ""])
    src = glue + (cdir / f"{name}.c").read_text() + NATIVE_C.read_text()
    import shutil
    cc = [*(NATIVE_CC if shutil.which(NATIVE_CC[0]) else ("gcc",) + NATIVE_CC[1:]),
          *os.environ.get("KINDYNGEN_FDNLP_CFLAGS", "").split()]
    so = ocp_stages.cached_library(f"fdnlp_{name}_N{N}", glue, src + " ".join(cc), [*cc, f"-I{cdir}"])
    return {f: ca.external(f, str(so)) for f in ("fdnlp_g", "fdnlp_jac_g", "fdnlp_hess")}


class FdStageReach(ocp_stages.StageReach):
    """The reach NLP of examples/ocp_reach.py, fd_rk4 (one RK4 step per interval, u = tau), from
    compiled per-interval functions; ocp_stages.StageReach's assembly, bounds order, warm-start
    shifts and IPOPT interface. Parameters p = (initial state, goal position)."""

    def __init__(self, N: int = 20, funcs: dict | None = None, native: bool = True):
        t0 = time.perf_counter()
        self.native = native
        self.funcs = funcs or ocp_reach.load()
        folder = Path(ocp_reach.ROOT) / "generated" / self.funcs["robot"].name / "casadi"
        if "fd_derivatives" not in self.funcs:
            self.funcs["fd_derivatives"] = ca.Function.load(str(folder / "fd_derivatives.casadi"))
        self.setup = ocp_reach.setup_dict(self.funcs, N)
        n = self.n = self.setup["n"]
        self.N, self.h = N, self.setup["T"] / N
        nx, nu = 2 * n, n
        self.nx, self.nu, self.st = nx, nu, nx + nu
        self.nc = nx
        f = self.funcs
        step = mpc_sqp.rk4_step_with_jacobians(f["fd"], f["fd_derivatives"], n, self.h)
        v = ca.MX.sym("v", self.st + nx)           # (x_k, u_k, x_{k+1})
        xn, A, B = step(v[:nx], v[nx:self.st])[:3]   # the inner-substep speed outputs are the MPC's
        c = v[self.st:] - xn
        jc = ca.horzcat(-A, -B, ca.MX.eye(nx))
        w, lam, sigma = ca.MX.sym("w", self.st), ca.MX.sym("lam", nx), ca.MX.sym("sigma")
        # lam multiplies x_{k+1} - F: the Hessian of -lam' F, i.e. mu = -lam in the derivation
        H = rk4_lagrangian_hessian(f["fd"], f["fd_derivatives"], f["tau"], n, self.h, w, -lam)
        H = H + ca.diagcat(ca.MX(nx, nx), 2 * self.h * sigma * ca.MX.eye(n))
        xN, goal, lamT = ca.SX.sym("xN", nx), ca.SX.sym("goal", 3), ca.SX.sym("lamT", 3 + n)
        term = ca.vertcat(f["fk_hom"](xN[:n])[:3, 3] - goal, xN[n:])
        fs = [ca.Function("reach_c", [v], [c]),
              ca.Function("reach_jc", [v], [jc]),
              ca.Function("reach_hl", [w, lam, sigma], [ca.triu(H)]),
              ca.Function("reach_t", [xN, goal], [term]),
              ca.Function("reach_jt", [xN, goal], [ca.jacobian(term, xN)]),
              ca.Function("reach_ht", [xN, lamT], [ca.triu(ca.hessian(ca.dot(lamT, term), xN)[0])])]
        self.stage_functions = fs
        self.nz = N * self.st + nx
        self._bounds()
        # jac_reach_c and jac_reach_t: looked up by name for nlpsol's multiplier post-processing
        fs = fs + [fs[0].jacobian(), fs[3].jacobian()]
        t1 = time.perf_counter()
        if native:
            self.ext = {f.name(): f for f in self.stage_functions}      # SX/MX originals (tests)
            self.native_ext = compile_native(self.funcs, n, N, self.h)
            self.compile_s = time.perf_counter() - t1
            self._build_native_nlp_functions()
        else:
            self.ext = ocp_stages.compile_functions(fs, f"reach_fd_{self.funcs['robot'].name}_N{N}")
            self.compile_s = time.perf_counter() - t1
            self._build_nlp_functions()
        self.build_s = time.perf_counter() - t0

    def _build_native_nlp_functions(self):
        """The NLP's g, Jacobian and Hessian from examples/fd_stages_nlp.c (compile_native)."""
        N, nx, st, n = self.N, self.nx, self.st, self.n
        Z, P = ca.MX.sym("z", self.nz), ca.MX.sym("p", nx + 3)
        e = self.native_ext
        g = e["fdnlp_g"](Z, P)
        gj, J = e["fdnlp_jac_g"](Z, P)
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", self.ng)
        f = self.h * sum(ca.sumsqr(Z[k * st + nx:k * st + nx + n]) for k in range(N))
        self.nlp = {"x": Z, "p": P, "f": f, "g": g}
        self.f_jac_g = ca.Function("nlp_jac_g", [Z, P], [gj, J], ["x", "p"], ["g", "jac_g_x"])
        self.f_hess = ca.Function("nlp_hess_l", [Z, P, lam_f, lam_g], [e["fdnlp_hess"](Z, P, lam_f, lam_g)],
                                  ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        self.f_g = ca.Function("g", [Z, P], [g])

    def _bounds(self):
        s, n, N = self.setup, self.n, self.N
        xlo = np.concatenate([s["q_lo"], -s["qd_max"]])
        xhi = np.concatenate([s["q_hi"], s["qd_max"]])
        free = np.full(self.nx, np.inf)   # node 0 is fixed by x0 = p (see ocp_reach)
        self.lbx = np.concatenate([-free, -s["tau_max"]] + [np.concatenate([xlo, -s["tau_max"]])] * (N - 1) + [xlo])
        self.ubx = np.concatenate([free, s["tau_max"]] + [np.concatenate([xhi, s["tau_max"]])] * (N - 1) + [xhi])
        self.ng = N * self.nc + self.nx + 3 + n
        self.lbg = np.zeros(self.ng)

    def guess(self):
        xr = np.concatenate([self.setup["q0"], np.zeros(self.n)])
        return np.concatenate([np.concatenate([xr, self.setup["gravity_torque"]])] * self.N + [xr])

    def shifted(self, z):
        """Every stage one interval earlier; the appended interval holds the last node (at
        rest at the goal) with its gravity torque, which satisfies its gap exactly."""
        st, N, n = self.st, self.N, self.n
        xN = z[N * st:]
        g = np.array(self.funcs["tau"](xN[:n], np.zeros(n), np.zeros(n))).ravel()
        return np.concatenate([z[st:N * st], xN, g, xN])

    def result(self, *args, **kwargs):
        res = super().result(*args, **kwargs)
        res["formulation"] = "fd_rk4"
        return res
