"""Time-optimal point-to-point motions (examples/ocp.py's problems): the mx_map formulation (one SX
RK4-step Function mapped over the intervals, IPOPT's exact derivatives through CasADi's virtual
machine) against the same NLP on kindyngen.control.time_optimal's native library (constraints,
Jacobian and exact Hessian in C over the generated fd and fd_derivatives; `examples/ocp.py
--solver native`), in one run.

    .venv/bin/python benchmarks/ocp_time_optimal.py            # Panda N = 40 and LWR N = 20
    .venv/bin/python benchmarks/ocp_time_optimal.py --problems panda --repeats 2

Per problem and formulation: IPOPT's status, iterations, CPU and wall time of the solve
(process time: the machine is shared), T, and Pinocchio's checks (examples/ocp.py's resimulate:
20 RK4 steps per interval of ABA; the tolerance of tests/integration/test_ocp.py: node error
below 10x the planner's RK4 error estimate + 1e-6 and below 2e-2, limits passed by no more
than that error). The native row's build time (the robot's derivation if not cached, the
library's compile) is recorded; --fresh-cache builds everything into an empty cache, so that
the whole build is measured. Writes benchmarks/results/ocp_time_optimal.json.
(The compiled per-interval stages of examples/ocp_time_stages.py this replaced are in the
runs' JSON before and in docs/optimal_control.md.)
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

from kindyngen.json_text import strict_json

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))
import ocp  # noqa: E402

DEFAULT_N = {"panda": 40, "lwr4": 20}
SUBSTEPS = 4                        # examples/ocp.py's default for the 7-joint arms


def machine() -> dict:
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    from kindyngen.control.native import compiler
    cc = compiler()
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    import pinocchio
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "casadi": ca.__version__,
            "numpy": np.__version__, "pinocchio": pinocchio.__version__, "native_compiler": version,
            "uptime": subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()}


def checks(setup: dict, res: dict, fd: ca.Function) -> dict:
    sim = ocp.resimulate(setup, res, 20)
    est = ocp.rk4_error_estimate(setup, res, fd)
    err = sim["resim_error"]
    lim = sim["limit_excess"]
    ok = (err < 10 * est + 1e-6 and err < 2e-2 and lim["tau"] == 0.0 and lim["q_nodes"] < 1e-6
          and lim["qd_nodes"] < 1e-6 and lim["q_resim"] <= err and lim["qd_resim"] <= err)
    return {"resim_error": err, "rk4_error_estimate": est, "limit_excess": lim, "within_tolerance": bool(ok)}


def run_one(problem: str, N: int, solver: str, funcs: dict, setup: dict, ipopt: dict | None = None) -> dict:
    c0 = time.process_time()
    t0 = time.perf_counter()
    if solver == "mx_map":
        res = ocp.solve(setup, funcs["fd"], N, "mx_map", SUBSTEPS, ipopt=ipopt)
    else:
        res = ocp.solve_native(setup, N, SUBSTEPS, ipopt=ipopt)
    total_wall, total_cpu = time.perf_counter() - t0, time.process_time() - c0
    chk = checks(setup, res, funcs["fd"])
    row = {"problem": problem, "N": N, "substeps": SUBSTEPS, "formulation": solver, "status": res["status"],
           "success": res["success"], "iterations": res["iterations"], "solve_cpu_s": res["solve_cpu_s"],
           "solve_wall_s": res["solve_s"], "cpu_per_iteration_s": res["solve_cpu_s"] / max(res["iterations"], 1),
           "build_wall_s": res["build_s"], "total_cpu_s": total_cpu, "total_wall_s": total_wall, "T": res["T"],
           "objective": res["objective"], "max_defect": res["max_defect"], "pinocchio": chk,
           "ipopt_options": dict(ipopt or {})}
    print(f"  {problem} N={N} {solver:7s}: {res['status']}, {res['iterations']} it, solve {res['solve_cpu_s']:.2f} s CPU "
          f"({res['solve_s']:.2f} s wall), build {res['build_s']:.1f} s, T = {res['T']:.9f}, Pinocchio ok: "
          f"{chk['within_tolerance']}", flush=True)
    return row


def _ipopt_option(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` as CasADi's ``ipopt.KEY`` with VALUE an int, a float or a string.

    >>> _ipopt_option("mu_linear_decrease_factor=0.1")
    ('ipopt.mu_linear_decrease_factor', 0.1)
    """
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise ValueError(f"{text!r}: expected KEY=VALUE")
    for kind in (int, float):
        try:
            return f"ipopt.{key}", kind(value)
        except ValueError:
            pass
    return f"ipopt.{key}", value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", nargs="+", choices=sorted(DEFAULT_N), default=["panda", "lwr4"])
    ap.add_argument("--repeats", type=int, default=1, help="interleaved repeats of each pair (default 1)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "ocp_time_optimal.json"))
    ap.add_argument("--fresh-cache", action="store_true",
                    help="derive the robots and build the native libraries into an empty cache (the whole build "
                         "measured; default: the user's cache, a cached library loads in milliseconds)")
    ap.add_argument("--ipopt", action="append", default=[], metavar="KEY=VALUE",
                    help="an IPOPT option for the native solve (repeatable), e.g. mu_linear_decrease_factor=0.1; "
                         "the baseline is then also solved with the same options (row mx_map_same_options), "
                         "the headline speed-up staying against the plain baseline")
    args = ap.parse_args(argv)
    try:
        ipopt = dict(_ipopt_option(text) for text in args.ipopt)
    except ValueError as exc:
        print(f"error: --ipopt {exc}", file=sys.stderr)
        return 2
    if args.repeats < 1:
        print(f"error: --repeats {args.repeats}: must be at least 1", file=sys.stderr)
        return 2
    if args.fresh_cache:
        os.environ["KINDYNGEN_CACHE"] = tempfile.mkdtemp(prefix="kindyngen_topt_bench_")
    doc = {"machine": machine(), "load_before": os.getloadavg(), "started_utc": time.strftime("%Y-%m-%d %H:%M:%S",
                                                                                                 time.gmtime()),
           "note": "CPU time (process_time) of the solve; the machine is shared, so wall times are not speeds. "
                   "speed-up = CPU time of mx_map's solve / CPU time of the native solve, within this run.",
           "fresh_cache": args.fresh_cache, "native_ipopt_options": ipopt, "rows": [], "summary": {}}
    for problem in args.problems:
        funcs = ocp.load_functions(problem)
        setup = ocp.problem_setup(problem, funcs)
        N = DEFAULT_N[problem]
        pairs = []
        for _ in range(args.repeats):
            pair = {"native": run_one(problem, N, "native", funcs, setup, ipopt),
                    "mx_map": run_one(problem, N, "mx_map", funcs, setup)}
            if ipopt:
                pair["mx_map_same_options"] = run_one(problem, N, "mx_map", funcs, setup, ipopt=ipopt)
                pair["mx_map_same_options"]["formulation"] = "mx_map_same_options"
            doc["rows"].extend(pair.values())
            pairs.append(pair)
        sp = [p["mx_map"]["solve_cpu_s"] / p["native"]["solve_cpu_s"] for p in pairs]
        spi = [p["mx_map"]["cpu_per_iteration_s"] / p["native"]["cpu_per_iteration_s"] for p in pairs]
        doc["summary"][problem] = {
            "N": N, "speedup_solve_cpu": sp, "speedup_cpu_per_iteration": spi,
            "T_difference": [abs(p["mx_map"]["T"] - p["native"]["T"]) for p in pairs],
            "iterations": [[p["mx_map"]["iterations"], p["native"]["iterations"]] for p in pairs]}
        if ipopt:
            doc["summary"][problem]["speedup_like_for_like"] = [
                p["mx_map_same_options"]["solve_cpu_s"] / p["native"]["solve_cpu_s"] for p in pairs]
            doc["summary"][problem]["iterations_same_options"] = [p["mx_map_same_options"]["iterations"] for p in pairs]
        print(f"  {problem}: speed-up (solve CPU) {', '.join(f'{v:.1f}x' for v in sp)}; per iteration "
              f"{', '.join(f'{v:.1f}x' for v in spi)}", flush=True)
    doc["load_after"] = os.getloadavg()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(strict_json(doc, indent=1) + "\n")
    print(f"wrote {args.out} (load {doc['load_before'][0]:.1f} -> {doc['load_after'][0]:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
