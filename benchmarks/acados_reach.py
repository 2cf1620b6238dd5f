"""The reach of benchmarks/control_bench.py in acados: the peer run by control_bench in its own
virtual environment (acados is not on PyPI as acados_template; the registry's one wheel that
carries it is openpilot's ``comma-deps-acados``, with libacados, HPIPM, BLASFEO, the tera
renderer and its own slimmed CasADi 3.6, which cannot share an environment with CasADi 3.8):

    python3 -m venv .venv-acados
    .venv-acados/bin/pip install comma-deps-acados==0.2.2.post92

The model is the robot's generated CasADi module (kindyngen.control's cache: ``<robot>_casadi.py``,
plain Python building SX graphs, so CasADi 3.6 reads it): x = (q, qd), u = tau, xdot = (qd,
fd(q, qd, tau)), one RK4 step per interval (acados' ERK, 4 stages, 1 step), N intervals over T.
Cost h sum |u|^2 (acados' EXTERNAL cost, exact Hessian); torques as bounds, q and qd at the
nodes 1..N-1 as bounds, at N the flange position = goal (nonlinear terminal constraint) and
qd = 0; SQP with the exact Hessian (regularised by PROJECT) and HPIPM on the partially
condensed QP. Prints one JSON line: per solve the status, iterations, CPU time, the plan.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import tempfile
import time

import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--module", required=True, help="the robot's generated <robot>_casadi.py")
    ap.add_argument("--problem", required=True, help="JSON: q0, goal, tau_max, qd_max, q_lo, q_hi, N, T")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--maxiter", type=int, default=200)
    ap.add_argument("--build", help="folder for the generated solvers (default: a temporary one)")
    ap.add_argument("--hessian", choices=("exact", "gauss-newton"), default="gauss-newton",
                    help="SQP Hessian: gauss-newton (acados' usual setup; the cost's, builds in a minute) or exact "
                         "(the RK4 step's exact Hessian in C: 15 min to compile for a 7-joint arm on the loaded "
                         "2-core machine)")
    args = ap.parse_args()
    import acados
    # the wheel's layout: libraries and headers under acados/install, the Python interface and
    # its templates beside it, the tera renderer in install/bin
    os.environ.setdefault("ACADOS_SOURCE_DIR", acados.DIR)
    os.environ.setdefault("ACADOS_PYTHON_INTERFACE_PATH", acados.TEMPLATE_DIR)
    os.environ.setdefault("TERA_PATH", acados.TERA_PATH)
    # the generated solver's library finds libacados' own dependencies only on the loader's path
    # (fixed at start): load them first, globally
    import ctypes
    for lib in ("libblasfeo.so", "libhpipm.so", "libqpOASES_e.so.3.1", "libacados.so"):
        ctypes.CDLL(os.path.join(acados.LIB_DIR, lib), mode=ctypes.RTLD_GLOBAL)
    import casadi as ca
    from acados.acados_template import AcadosModel, AcadosOcp, AcadosOcpSolver
    p = {k: np.asarray(v, float) if isinstance(v, list) else v for k, v in json.loads(args.problem).items()}
    spec = importlib.util.spec_from_file_location("robot_casadi", args.module)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    fd, fk = mod.fd(), mod.fk_hom()
    n, N, T = len(p["q0"]), int(p["N"]), float(p["T"])
    h = T / N
    x, u = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n)
    model = AcadosModel()
    model.name = "kdg_reach"
    model.x, model.u = x, u
    model.f_expl_expr = ca.vertcat(x[n:], fd(x[:n], x[n:], u))
    if args.hessian == "exact":
        model.cost_expr_ext_cost = ca.sumsqr(u)        # acados integrates: h sum |u|^2
        model.cost_expr_ext_cost_e = ca.SX(0)
    model.con_h_expr_e = fk(x[:n])[:3, 3]
    ocp = AcadosOcp()
    ocp.model = model
    ocp.dims.N = N
    ocp.solver_options.tf = T
    if args.hessian == "exact":
        ocp.cost.cost_type = "EXTERNAL"
        ocp.cost.cost_type_e = "EXTERNAL"
    else:        # the same cost as linear least squares: 0.5 |sqrt(2) u|^2 integrated = h sum |u|^2
        ocp.cost.cost_type = "LINEAR_LS"
        ocp.cost.cost_type_e = "LINEAR_LS"
        ocp.cost.Vx = np.zeros((n, 2 * n))
        ocp.cost.Vu = np.eye(n)
        ocp.cost.W = 2.0 * np.eye(n)
        ocp.cost.yref = np.zeros(n)
        ocp.cost.Vx_e = np.zeros((0, 2 * n))
        ocp.cost.W_e = np.zeros((0, 0))
        ocp.cost.yref_e = np.zeros(0)
    ocp.constraints.x0 = np.concatenate([p["q0"], np.zeros(n)])
    ocp.constraints.lbu, ocp.constraints.ubu = -p["tau_max"], p["tau_max"]
    ocp.constraints.idxbu = np.arange(n)
    ocp.constraints.lbx = np.concatenate([p["q_lo"], -p["qd_max"]])
    ocp.constraints.ubx = np.concatenate([p["q_hi"], p["qd_max"]])
    ocp.constraints.idxbx = np.arange(2 * n)
    ocp.constraints.lbx_e = np.concatenate([p["q_lo"], np.zeros(n)])
    ocp.constraints.ubx_e = np.concatenate([p["q_hi"], np.zeros(n)])
    ocp.constraints.idxbx_e = np.arange(2 * n)
    ocp.constraints.lh_e = ocp.constraints.uh_e = p["goal"]
    so = ocp.solver_options
    so.integrator_type = "ERK"
    so.sim_method_num_stages = 4
    so.sim_method_num_steps = 1
    so.nlp_solver_type = "SQP"
    so.hessian_approx = "EXACT" if args.hessian == "exact" else "GAUSS_NEWTON"
    if args.hessian == "exact":
        so.regularize_method = "PROJECT"
    so.qp_solver_iter_max = 200
    so.qp_solver = "PARTIAL_CONDENSING_HPIPM"
    so.nlp_solver_max_iter = args.maxiter
    so.tol = 1e-6
    so.globalization = "MERIT_BACKTRACKING"
    # generated and compiled once per problem (minutes: the exact Hessian of the RK4 step in C),
    # kept under --build keyed by the problem, the module and this script
    import hashlib
    key = hashlib.sha256((args.problem + args.hessian + open(args.module).read() + open(__file__).read()).encode()).hexdigest()[:16]
    build = os.path.join(args.build or tempfile.mkdtemp(prefix="acados_reach_"), key)
    ready = os.path.isfile(os.path.join(build, "built"))
    os.makedirs(build, exist_ok=True)
    ocp.code_export_directory = os.path.join(build, "c_generated_code")
    t0 = time.perf_counter()
    solver = AcadosOcpSolver(ocp, json_file=os.path.join(build, "ocp.json"), verbose=False, build=not ready,
                             generate=not ready)
    open(os.path.join(build, "built"), "w").close()
    build_s = time.perf_counter() - t0
    g = np.array(mod.tau()(p["q0"], np.zeros(n), np.zeros(n))).ravel()
    x0 = np.concatenate([p["q0"], np.zeros(n)])
    cpu, rows = [], None
    for _ in range(args.repeats):
        for k in range(N + 1):
            solver.set(k, "x", x0)
        for k in range(N):
            solver.set(k, "u", g)
        c0 = time.process_time()
        status = solver.solve()
        cpu.append(time.process_time() - c0)
        X = np.array([solver.get(k, "x") for k in range(N + 1)])
        U = np.array([solver.get(k, "u") for k in range(N)])
        rows = {"status": int(status), "success": status == 0, "iterations": int(np.ravel(solver.get_stats("sqp_iter"))[0]),
                "q": X[:, :n].tolist(), "qd": X[:, n:].tolist(), "tau": U.tolist(), "objective": float(h * np.sum(U ** 2))}
    rows.update(solve_cpu_s=float(np.median(cpu)), solve_cpu_s_runs=cpu, build_s=build_s, built_now=not ready)
    print(json.dumps({"versions": {"comma-deps-acados": __import__("importlib.metadata").metadata.version("comma-deps-acados"),
                                   "casadi (vendored)": ca.__version__},
                      "options": {"nlp_solver": f"SQP, {args.hessian} Hessian, merit backtracking",
                                  "qp_solver": "PARTIAL_CONDENSING_HPIPM", "tol": 1e-6, "max_iter": args.maxiter},
                      "row": rows}))


if __name__ == "__main__":
    main()
