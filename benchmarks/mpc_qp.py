"""The tracking MPC's QP (kindyngen/control/mpc.py) solved two ways on the same linearisations,
one run: the condensed dense QP in the N n torque steps by DAQP (what TrackingMPC uses), cold
and warm-started from its own working set, against the sparse structured multiple-shooting QP
(stage variables (dx_k, du_k), the linearised dynamics as equality rows, state and torque limits
as simple bounds) by CasADi's `hpipm` conic (Riccati-based interior point) in its speed, balance
and robust modes.

    .venv/bin/python -m benchmarks.mpc_qp --out benchmarks/results/mpc_qp.json [--points 3]

Both with hard state limits at the nodes (the MPC's exact-penalty slack and inner rows are left
out), so that they solve the same QP; the solutions are compared (largest |du| difference). CPU
time (time.process_time) of the solver call only, mean of 20 calls; one call of the
linearisation and condensing (TrackingMPC.qp) is timed apart. The LWR reach reference of the
control benchmark (two RK4 steps per interval, margins), N = 20; the linearisation points are
the reference with the measured state's speeds perturbed (seeded).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from kindyngen.json_text import strict_json  # noqa: E402


def _cpu_ms(f, rep=20):
    f()
    c = time.process_time()
    for _ in range(rep):
        out = f()
    return 1e3 * (time.process_time() - c) / rep, out


def sparse_qp(mpc, x0, X, U, i):
    """The multiple-shooting QP in w = (dx_0, du_0, ..., dx_N) (dx_0 fixed at 0) for hpipm."""
    N, n, nx = mpc.N, mpc.n, mpc.nx
    st, nw = nx + n, N * (nx + n) + nx
    Xr, Ur = mpc.reference_window(i)
    F, Am, Bm, _, _ = mpc.lib.linearise(x0, X, U, mpc.d)
    H, g = np.zeros((nw, nw)), np.zeros(nw)
    A, b = np.zeros((N * nx, nw)), np.zeros(N * nx)
    lbx, ubx = np.zeros(nw), np.zeros(nw)
    for k in range(N):
        iu, ix = k * st + nx, (k + 1) * st
        wu, wx = mpc.wu[k * n:(k + 1) * n], mpc.wx[k * nx:(k + 1) * nx]
        H[iu:iu + n, iu:iu + n] = np.diag(wu)
        g[iu:iu + n] = wu * (U[k] - Ur[k] + mpc.d)
        H[ix:ix + nx, ix:ix + nx] = np.diag(wx)
        g[ix:ix + nx] = wx * (X[k] - Xr[k])
        r = slice(k * nx, (k + 1) * nx)
        A[r, k * st:k * st + nx] = -Am[k]
        A[r, k * st + nx:k * st + st] = -Bm[k]
        A[r, ix:ix + nx] = np.eye(nx)
        b[r] = F[k] - X[k]
        lbx[iu:iu + n], ubx[iu:iu + n] = -mpc.u_max - U[k], mpc.u_max - U[k]
        lbx[ix:ix + nx], ubx[ix:ix + nx] = mpc.xlo - X[k], mpc.xhi - X[k]
    return H, g, A, b, lbx, ubx


def main(argv=None) -> int:
    import casadi as ca
    import daqp
    from benchmarks import control_bench as cb, control_robots as cr
    from kindyngen.control.integrators import Integrator
    from kindyngen.control.mpc import MPCOptions, TrackingMPC
    from kindyngen.control.reach import ReachNLP
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--points", type=int, default=3, help="linearisation points (default 3)")
    args = ap.parse_args(argv)
    if args.points < 1:
        ap.error(f"--points {args.points}: must be at least 1")
    model, robot, limits, task = cr.load("lwr4")
    rt = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3, margin_position=0.05,
                 margin_torque=0.1)
    ref = ReachNLP(robot, rt).solve()
    mpc = TrackingMPC(robot, limits, np.hstack([ref.q, ref.qd]), ref.tau, MPCOptions())
    N, n, nx = mpc.N, mpc.n, mpc.nx
    st = nx + n
    rows = []
    for seed in range(args.points):
        rng = np.random.default_rng(seed)
        X, U = mpc.initial_guess(0)
        x0 = mpc.Xref[0] + np.concatenate([np.zeros(n), 0.05 * rng.standard_normal(n)])
        c0 = time.process_time()
        q = mpc.qp(x0, X, U, 0)
        condense_ms = 1e3 * (time.process_time() - c0)
        rows_n = N * nx                   # the node rows (the inner ones left out)
        bu = np.concatenate([q["box_hi"], q["row_hi"][:rows_n]])
        bl = np.concatenate([q["box_lo"], q["row_lo"][:rows_n]])
        Gc = np.ascontiguousarray(q["G"])
        cold_ms, (du_d, _, flag, info) = _cpu_ms(lambda: daqp.solve(q["H"], q["g"], Gc, bu, bl))
        du_d = np.asarray(du_d)
        act = np.sign(np.asarray(info["lam"])).astype(np.int32)
        sense = (act != 0).astype(np.int32) | (2 * (act < 0)).astype(np.int32)
        warm_ms, (du_w, _, flag_w, info_w) = _cpu_ms(lambda: daqp.solve(q["H"], q["g"], Gc, bu, bl, sense))
        row = {"seed": seed, "linearise_and_condense_cpu_ms": condense_ms,
               "daqp_condensed_cold": {"cpu_ms": cold_ms, "exitflag": int(flag), "iterations": int(info["iterations"]),
                                       "active": int(np.count_nonzero(act))},
               "daqp_condensed_warm": {"cpu_ms": warm_ms, "exitflag": int(flag_w),
                                       "iterations": int(info_w["iterations"]),
                                       "max_du_difference_to_cold": float(np.abs(np.asarray(du_w) - du_d).max())}}
        H, g, A, b, lbx, ubx = sparse_qp(mpc, x0, X, U, 0)
        Hs, As = ca.sparsify(ca.DM(H)), ca.sparsify(ca.DM(A))
        for mode in ("speed", "balance", "robust"):
            S = ca.conic("S", "hpipm", {"h": Hs.sparsity(), "a": As.sparsity()},
                         {"N": N, "nx": [nx] * (N + 1), "nu": [n] * N + [0], "ng": [0] * (N + 1), "error_on_fail": False,
                          "hpipm": {"mode": mode, "res_g_max": 1e-8, "res_b_max": 1e-8, "res_d_max": 1e-8,
                                    "res_m_max": 1e-8, "iter_max": 200}})
            ms, sol = _cpu_ms(lambda: S(h=Hs, g=g, a=As, lba=b, uba=b, lbx=lbx, ubx=ubx))
            w = np.array(sol["x"]).ravel()
            du = np.concatenate([w[k * st + nx:k * st + st] for k in range(N)])
            stats = S.stats()
            row[f"hpipm_sparse_{mode}"] = {"cpu_ms": ms, "return_status": int(stats.get("return_status", -1)),
                                           "iterations": int(stats.get("iter_count", -1)),
                                           "max_du_difference_to_daqp": float(np.abs(du - du_d).max())}
        rows.append(row)
        print(strict_json(row), flush=True)
    doc = {"problem": "the tracking MPC's QP, LWR reach reference, N = 20, hard state limits", "points": rows,
           "versions": {"daqp": getattr(daqp, "__version__", "0.11.0 (pip)"), "casadi": ca.__version__},
           "machine": cb.machine(), "uptime": cb.uptime(), "max_du_scale": "torque steps up to a few N m"}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(strict_json(doc, indent=1) + "\n")
    print(f"  wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
