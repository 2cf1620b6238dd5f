"""The LWR reach (examples/ocp_reach.py's id_rk4 formulation) solved by fatrop, a
structure-exploiting interior-point OCP solver (CasADi's `fatrop` plugin), with every function
it evaluates compiled to C.

Why: IPOPT with the compiled per-interval functions (examples/ocp_stages.py) spends most of
its time in MUMPS on the whole KKT system (about 4 ms an iteration); fatrop factorises the
same KKT system stage by stage (a Riccati recursion over N blocks). CasADi's fatrop plugin has
no option to pass the derivative functions (IPOPT's jac_g and hess_lag), it derives them from
the NLP by its own AD. So the NLP oracle here is a compiled library that already holds them:
CasADi's `external` looks up `nlp_jac_g`, `nlp_hess_l`, ... in the library of the oracle
(External::factory) before it differentiates. They are assembled in MX from the one-interval
SX functions of ocp_stages (constraints, Jacobian, Hessian of the interval's Lagrangian term)
mapped over the horizon, generated to C in one file and compiled once (gcc -O1, cached like
ocp_stages' libraries).

Stage layout (fatrop's structure, declared by hand: structure_detection manual): variables
z = (x_0, u_0, x_1, u_1, ..., x_N), constraints per stage k the gap x_{k+1} - F(x_k, u_k) first,
then the stage's path equalities (the inverse-dynamics residuals; at k = 0 also x_0 = p), the
terminal rows (flange position, rest) last; that is ocp_stages' order already.

Worked example::

    >>> from ocp_fatrop import FatropReach                               # doctest: +SKIP
    >>> r = FatropReach(N=20).solve(); r["status"], round(r["objective"], 3)   # doctest: +SKIP
    ('SOLVER_RET_SUCCESS', 759.931)
"""
from __future__ import annotations

import time

import casadi as ca
import numpy as np

import ocp_stages

# fatrop's own options, chosen by measurement (docs/optimal_control.md): from the default
# barrier 0.1 fatrop follows IPOPT's iterates for 16 iterations, then (without the
# second-order-correction steps IPOPT takes there) stalls, falls into restoration and stops
# infeasible; from 1e-4 to 3e-2 it converges in 60-70 iterations. tol 1e-6: at 1e-8 the
# dual infeasibility stays at ~6e-5 under heavy inertia regularisation (~10^1.5) after the
# primal point has converged (inf_pr 1e-14), until max_iter
FATROP_OPTIONS = {"tol": 1e-6, "mu_init": 1e-2, "max_iter": 500, "print_level": 0}


def oracle_functions(nlp_x, nlp_p, f, g, jac_g, hess_full):
    """The functions CasADi's fatrop plugin asks its oracle for, named and with the input and
    output names External::factory checks (':' written '_')."""
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", g.numel())
    grad_f = ca.gradient(f, nlp_x)
    grad_l = lam_f * grad_f + ca.mtimes(jac_g.T, lam_g)
    xp = [nlp_x, nlp_p]
    gamma = lam_f * f + ca.dot(lam_g, g)     # nlpsol's post-processing (multipliers) asks for nlp_grad
    return [ca.Function("nlp", xp, [f, g], ["x", "p"], ["f", "g"]),
            ca.Function("nlp_f", xp, [f], ["x", "p"], ["f"]),
            ca.Function("nlp_g", xp, [g], ["x", "p"], ["g"]),
            ca.Function("nlp_grad_f", xp, [grad_f], ["x", "p"], ["grad_f_x"]),
            ca.Function("nlp_jac_g", xp, [g, jac_g], ["x", "p"], ["g", "jac_g_x"]),
            ca.Function("nlp_hess_l", xp + [lam_f, lam_g], [grad_l, hess_full(lam_f, lam_g)],
                        ["x", "p", "lam_f", "lam_g"], ["grad_gamma_x", "hess_gamma_x_x"]),
            ca.Function("nlp_grad", xp + [lam_f, lam_g], [f, g, grad_l, ca.gradient(gamma, nlp_p)],
                        ["x", "p", "lam_f", "lam_g"], ["f", "g", "grad_gamma_x", "grad_gamma_p"])]


def full(triu):
    """Symmetric matrix from its upper triangle (fatrop reads the full Hessian blocks)."""
    return triu + triu.T - ca.diag(ca.diag(triu))


class FatropReach:
    """The reach NLP of ocp_stages.StageReach, solved by fatrop on a compiled oracle."""

    def __init__(self, N: int = 20, funcs: dict | None = None, options: dict | None = None):
        t0 = time.perf_counter()
        # StageReach builds (and compiles) IPOPT's externals too; only its SX stage functions,
        # bounds and helpers are used here
        self.s = s = ocp_stages.StageReach(N, funcs, compile_stages=False)
        self.N, self.n, self.nx, self.nu, self.st, self.nc = s.N, s.n, s.nx, s.nu, s.st, s.nc
        fs = {f.name(): f for f in s.stage_functions}
        Z, P = ca.MX.sym("x", s.nz), ca.MX.sym("p", s.nx + 3)
        g, J, hess = s.assemble(Z, P, fs)
        f = s.h * sum(ca.sumsqr(Z[k * s.st + s.nx:k * s.st + s.nx + s.n]) for k in range(N))
        funcs_c = oracle_functions(Z, P, f, g, J, lambda lf, lg: full(hess(lf, lg)))
        t1 = time.perf_counter()
        lib = ocp_stages.compile_library(funcs_c, f"reach_fatrop_{s.funcs['robot'].name}_N{N}")
        self.compile_s = time.perf_counter() - t1
        self.oracle_library = lib
        self.oracle = ca.external("nlp", lib)
        s.f_g = ca.external("nlp_g", lib)     # StageReach.result's constraint check, compiled
        opts = {"structure_detection": "manual", "N": N, "nx": [s.nx] * (N + 1), "nu": [s.nu] * N + [0],
                "ng": [s.nc] + [s.nc - s.nx] * (N - 1) + [3 + s.n],
                "print_time": False, "fatrop": dict(FATROP_OPTIONS, **(options or {}))}
        self.solver = ca.nlpsol("reach_fatrop", "fatrop", self.oracle, opts)
        self.build_s = time.perf_counter() - t0
        s.build_s, s.compile_s = self.build_s, self.compile_s

    def solve(self, x_init=None, goal=None, z0=None) -> dict:
        s = self.s
        p = s.p(x_init, goal)
        args = {"x0": s.guess() if z0 is None else z0, "lbx": s.lbx, "ubx": s.ubx, "lbg": s.lbg, "ubg": s.lbg,
                "p": p}
        t0, c0 = time.perf_counter(), time.process_time()
        sol = self.solver(**args)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        st = self.solver.stats()
        res = s.result(np.array(sol["x"]).ravel(), wall, cpu, int(st["iter_count"]), st["unified_return_status"],
                        bool(st["success"]), "fatrop (compiled stages)", np.array(sol["lam_g"]).ravel(), p)
        res["fatrop_return_flag"] = int(st["return_status"])
        res["fatrop_stats"] = {k: float(v) for k, v in st["fatrop"].items()}
        return res
