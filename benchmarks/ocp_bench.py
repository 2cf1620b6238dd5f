"""The LWR reach of examples/ocp_reach.py, every formulation and solver side by side in one
run, each solution checked by Pinocchio; the same formulation built from adam's and
urdf2casadi's forward dynamics when they are installed.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.ocp_bench [--out benchmarks/results/ocp.json]

(one BLAS thread: on a shared machine OpenBLAS's spinning threads inflate the CPU time of
MUMPS.) The "stages" rows are examples/ocp_stages.py: the per-interval functions compiled to C
(the first run compiles them), IPOPT given the assembled Jacobian and Hessian.

Rows: solve wall and CPU time (the ratio to the baseline is on CPU time, which other jobs on a
shared machine disturb far less than the wall time) (cold, from rest with gravity-compensating torques), iterations,
objective, ratio to the baseline (Opti + IPOPT, fd on MX, the issue's reference), and the
Pinocchio checks: plan_step_error (the plan's own RK4 steps of pin.aba from each node vs the
next node), resim_error (20 RK4 steps per interval, state error at the nodes) and the flange's
distance from the goal after re-simulation. Also the warm re-solve of id_rk4 + IPOPT from the
solution shifted by one interval (what examples/mpc.py does at each step).
Writes the JSON and a bar chart (ocp.png) beside it. Wall times on a shared machine: compare
rows of one run only.

The Crocoddyl rows (benchmarks/crocoddyl_reach.py: the same reach with mim-solvers' CSQP, and a
softer BoxFDDP problem) need their own environment, by default .venv-crocoddyl here:

    python3 -m venv .venv-crocoddyl
    .venv-crocoddyl/bin/pip install crocoddyl==3.0.1.1 pin==3.7.0 mim-solvers==0.1.1 "cmeel-urdfdom<5" "cmeel-tinyxml2<11"

(elsewhere: --crocoddyl-venv DIR); without it the run goes on and says so in the JSON. Every
peer's version is recorded under "versions" (the Crocoddyl environment's under "crocoddyl_venv").
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path

# CPU time is the measure: one BLAS thread unless the caller says otherwise (the 2026-12-02 run,
# without it, gave the two-substep id_rk4 row 7.3 s CPU for 3.7 s wall)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

from kindyngen.json_text import strict_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))
import ocp_fd_options  # noqa: E402
import ocp_reach  # noqa: E402
from kindyngen.output_folder import replace_file, replace_files  # noqa: E402

VARIANTS = [("baseline", "ipopt", 1), ("fd_rk4", "ipopt", 1), ("id_rk4", "ipopt", 1), ("id_rk4", "fatrop", 1),
            ("id_rk4", "ipopt", 2), ("id_rk4", "stages", 1), ("id_rk4", "stages mu_init=1e-2", 1),
            ("id_rk4", "stages mu_strategy=adaptive", 1), ("id_rk4", "fatrop_stages", 1), ("fd_rk4", "fd_stages", 1),
            ("fd_rk4", "fd_stages adaptive", 1), ("baseline", "ipopt adaptive", 1)]
# "stages": examples/ocp_stages.py, the per-interval functions compiled to C and IPOPT given the
# assembled Jacobian and Hessian; "mu_init=1e-2" starts IPOPT's barrier lower (the default 0.1);
# "mu_strategy=adaptive": IPOPT's adaptive barrier (it ends at the baseline's KKT point, 716.66;
# benchmarks/reach_sqp.py);
# "fatrop_stages": examples/ocp_fatrop.py, fatrop on the same compiled functions; "fd_stages":
# examples/ocp_fd_stages.py, the fd_rk4 interval (nu = 7) and its exact Hessian compiled, IPOPT;
# "fd_stages adaptive": the same with examples/ocp_fd_options.FAST (IPOPT's adaptive barrier, affine
# corrector; same tol and termination options), and "baseline ipopt adaptive" the Opti baseline with
# the same options, for a like-for-like ratio (the speedups stay relative to the plain baseline)
STAGE_OPTIONS = {"stages": {}, "stages mu_init=1e-2": {"ipopt.mu_init": 1e-2},
                 "stages mu_strategy=adaptive": {"ipopt.mu_strategy": "adaptive"}}


def _version(dist):
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def _machine():
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        return next(line.split(":", 1)[1].strip() for line in out.splitlines() if line.startswith("Model name"))
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def _row(name, source, res, setup, funcs, base_s=None):
    sim = ocp_reach.check(setup, res, funcs)
    row = {"variant": name, "dynamics": source, "formulation": res["formulation"], "solver": res["solver"],
           "substeps": res.get("substeps", 1), "status": res["status"], "success": res["success"],
           "iterations": res["iterations"], "build_s": res["build_s"], "solve_s": res["solve_s"],
           "solve_cpu_s": res["solve_cpu_s"],
           "ms_per_iteration": 1e3 * res["solve_s"] / max(res["iterations"], 1), "objective": res["objective"],
           "plan_step_error": sim["plan_step_error"], "resim_error": sim["resim_error"],
           "resim_goal_error_m": sim["resim_goal_error_m"], "limit_excess": sim["limit_excess"]}
    if base_s:   # on CPU time: the wall time of a shared machine swings by 5x between rows
        row["speedup_vs_baseline"] = base_s / res["solve_cpu_s"]
    print(f"{name:28s} {row['status']:24s} it={row['iterations']:4d} build={row['build_s']:6.2f}s "
          f"solve={row['solve_s']:7.3f}s cpu={row['solve_cpu_s']:7.3f}s f={row['objective']:.4f} step_err={row['plan_step_error']:.1e} "
          f"resim={row['resim_error']:.1e} goal={1e3 * row['resim_goal_error_m']:.2f}mm"
          + (f" x{row['speedup_vs_baseline']:.1f}" if base_s else ""), flush=True)
    return row


def peer_fds(funcs):
    """adam's and urdf2casadi's fd on the URDF of examples/dh_to_urdf.py (ocp_peers.py's way)."""
    import ocp_peers
    from dh_to_urdf import write_urdf
    robot = funcs["robot"]
    urdf = write_urdf(robot, ROOT / "examples" / "results" / "urdf" / f"{robot.name}.urdf")
    out, failures = {}, []
    for name, build in (("adam", lambda: ocp_peers.adam_fd(urdf, robot)),
                        ("urdf2casadi", lambda: ocp_peers.urdf2casadi_fd(urdf, robot))):
        try:
            fd = build()
            err = ocp_peers.max_difference(fd, funcs["fd"], robot)
            if err > 1e-9:
                failures.append({"source": name, "error": f"max |fd - generated fd| = {err:.3e}"})
                continue
            out[name] = (fd, err)
        except Exception as exc:  # noqa: BLE001 - a peer that does not load is reported, not fatal
            failures.append({"source": name, "error": repr(exc)})
    return out, failures


def warm_resolve_stages(funcs, repeats=5):
    """warm_resolve() with examples/ocp_stages.py's compiled per-interval functions."""
    import ocp_stages
    from mpc import WARM
    s = ocp_stages.StageReach(20, funcs)
    solver = s.ipopt(WARM)
    cold = s.solve_ipopt(solver)
    times, its = [], []
    for _ in range(repeats):
        x1 = np.concatenate([cold["q"][1], cold["qd"][1]])
        r = s.solve_ipopt(solver, x_init=x1, z0=s.shifted(cold["z"]), lam_g0=s.shifted_lam(cold["lam_g"]))
        times.append(r["solve_cpu_s"])
        its.append(r["iterations"])
    return {"what": "compiled stages + IPOPT warm start (shifted solution, mu_init 1e-4), CPU time",
            "solve_cpu_s": times, "iterations": its, "median_ms": 1e3 * float(np.median(times))}


def warm_resolve(funcs, repeats=5):
    """id_rk4 + IPOPT re-solved from its own solution shifted by one interval, the initial
    state moved to the solution's node 1: the receding-horizon step of examples/mpc.py."""
    nlp = ocp_reach.reach_problem("id_rk4", "ipopt", funcs=funcs,
                                  options={"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                                           "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
    cold = nlp.solve()
    times, its = [], []
    for _ in range(repeats):
        x1 = np.concatenate([cold["q"][1], cold["qd"][1]])
        r = nlp.solve(x_init=x1, z0=nlp.shifted(cold["z"]), lam_g0=cold["lam_g"])
        times.append(r["solve_cpu_s"])
        its.append(r["iterations"])
    return {"what": "id_rk4 + IPOPT warm start (shifted solution, mu_init 1e-4), CPU time", "solve_cpu_s": times, "iterations": its,
            "median_ms": 1e3 * float(np.median(times))}


CROCODDYL_FORMULATION = {"csqp": "crocoddyl hard (ours)", "csqp tol=1e-2": "crocoddyl hard (ours)",
                         "boxfddp": "crocoddyl penalty (softer)"}


def crocoddyl_peer(venv: Path, funcs: dict, setup: dict, base_s=None):
    """benchmarks/crocoddyl_reach.py in its own virtual environment (see its docstring), given
    this problem's numbers; each returned plan checked by Pinocchio here like every other row.
    Returns (summary for doc["crocoddyl"]: versions and the rows without the trajectories,
    rows for doc["rows"])."""
    from dh_to_urdf import write_urdf
    urdf = write_urdf(funcs["robot"], ROOT / "examples" / "results" / "urdf" / f"{funcs['robot'].name}.urdf")
    py = venv / "bin" / "python"
    if not py.exists():
        return {"error": f"no Crocoddyl environment at {venv}"}, []
    problem = {k: setup[k].tolist() for k in ("q0", "goal", "tau_max", "qd_max", "q_lo", "q_hi")}
    problem.update(N=setup["N"], T=setup["T"], frame="flange")
    # -X faulthandler: a crash (the segfault of newer version sets) says where in the last line
    r = subprocess.run([str(py), "-X", "faulthandler", str(ROOT / "benchmarks" / "crocoddyl_reach.py"),
                        "--urdf", str(urdf), "--problem", json.dumps(problem)], capture_output=True, text=True)
    if r.returncode != 0:
        lines = [line for line in r.stderr.strip().splitlines() if line.strip()]
        return {"error": " | ".join(lines[-3:]) if lines else f"exit {r.returncode}"}, []
    out = json.loads(r.stdout.strip().splitlines()[-1])
    rows = []
    for c in out["rows"]:
        res = {k: c[k] for k in ("status", "success", "iterations", "solve_s", "solve_cpu_s", "objective")}
        res.update(formulation=CROCODDYL_FORMULATION[c["solver"]], solver=f"{c['solver']} (mim-solvers {out['versions']['mim-solvers']})"
                   if c["solver"].startswith("csqp") else c["solver"], substeps=1, build_s=0.0, N=setup["N"], T=setup["T"],
                   q=np.array(c["q"]), qd=np.array(c["qd"]), tau=np.array(c["tau"]))
        row = _row(f"crocoddyl {c['solver']}", "crocoddyl", res, setup, funcs, base_s)
        row.update({k: c[k] for k in ("solve_cpu_s_runs", "kkt", "crocoddyl_cost", "goal_error_m", "final_speed",
                                      "warm_resolve_cpu_s", "warm_iterations")})
        row["limit_excess_own_plan"] = c["limit_excess"]
        rows.append(row)
    # the earlier interface's top-level fields, now of the hard-constrained CSQP row; every
    # row in doc["rows"] under the names in "row_variants"
    summary = {k: v for k, v in out.items() if k != "rows"}
    summary.update({k: rows[0][k] for k in ("formulation", "solver", "status", "iterations", "solve_s", "solve_cpu_s",
                                            "objective", "goal_error_m", "final_speed", "kkt")},
                   row_variants=[row["variant"] for row in rows])
    return summary, rows


def plot(doc, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = doc["rows"]
    fig, ax = plt.subplots(figsize=(9, 4))
    names = [r["variant"] for r in rows]
    ax.barh(names, [r["solve_cpu_s"] for r in rows], color=["C3" if r["formulation"] == "baseline" else "C0" for r in rows])
    ax.set_xscale("log")
    ax.set_xlabel("solve CPU time [s] (cold start, log scale)")
    ax.set_title(f"LWR reach, N = 20, one run on {doc['machine']}")
    ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "ocp.json"))
    ap.add_argument("--no-peers", action="store_true", help="skip adam, urdf2casadi and Crocoddyl")
    ap.add_argument("--repeats", type=int, default=5,
                    help="solves of the baseline and of the compiled rows, median CPU time used (default 5)")
    ap.add_argument("--crocoddyl-venv", default=str(ROOT / ".venv-crocoddyl"),
                    help="virtual environment with crocoddyl==3.0.1.1 pin==3.7.0 mim-solvers==0.1.1 "
                         "(benchmarks/crocoddyl_reach.py says how to make it; default .venv-crocoddyl)")
    ap.add_argument("--only-crocoddyl", action="store_true",
                    help="run only the Crocoddyl rows and put them into --out (an existing file: its other rows kept)")
    ap.add_argument("--rows", nargs="+", metavar="ROW",
                    help='only these rows of VARIANTS, named "formulation solver" (e.g. "baseline ipopt" '
                         '"fd_rk4 fd_stages adaptive"), without the warm re-solves; the plain baseline is run '
                         'first whether named or not (the ratios are to it)')
    args = ap.parse_args(argv)
    variants = VARIANTS
    if args.rows:
        known = {f"{f} {s}": (f, s, m) for f, s, m in VARIANTS}
        unknown = [r for r in args.rows if r not in known]
        if unknown:
            ap.error(f"unknown rows {unknown}; known: {list(known)}")
        variants = [VARIANTS[0]] + [known[r] for r in args.rows if known[r] != VARIANTS[0]]
    if args.only_crocoddyl:
        out = Path(args.out)
        doc = json.loads(out.read_text()) if out.exists() else {
            "machine": _machine(), "cores": len(os.sched_getaffinity(0)), "rows": [], "versions": {}}
        funcs = ocp_reach.load()
        # no ratio to the baseline: that was solved in another run, under another load
        summary, rows = crocoddyl_peer(Path(args.crocoddyl_venv), funcs, ocp_reach.setup_dict(funcs))
        doc["crocoddyl"] = dict(summary, loadavg=list(os.getloadavg()))
        doc.setdefault("versions", {})["crocoddyl_venv"] = summary.get("versions", {"error": summary.get("error")})
        doc["rows"] = [r for r in doc["rows"] if r.get("dynamics") != "crocoddyl"] + rows
        replace_file(out, strict_json(doc, indent=1) + "\n")
        print(f"crocoddyl: {summary.get('versions', summary)}")
        return
    funcs = ocp_reach.load()
    doc = {"machine": _machine(), "cores": len(os.sched_getaffinity(0)), "casadi": ca.__version__,
           "python": platform.python_version(),
           # the peers' versions: adam's and urdf2casadi's here, Crocoddyl's environment's below
           "versions": {d: _version(d) for d in ("casadi", "pin", "adam-robotics", "liecasadi", "urdf2casadi")},
           "problem": "lwr4_reach N = 20, T = 1 s, data-sheet qd limits (examples/ocp_reach.py)",
           "note": "wall times on a shared 2-core machine; compare rows of this run only",
           "rows": [], "peer_failures": [], "loadavg_start": list(os.getloadavg())}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    # read before the rows overwrite the file: without a Crocoddyl environment here the earlier
    # run's Crocoddyl row is kept, marked as such
    old_crocoddyl = json.loads(out.read_text()).get("crocoddyl", {}) if out.exists() else {}
    base_s = None
    setup = ocp_reach.setup_dict(funcs)
    for form, solver, M in variants:
        name = f"{form} {solver} M={M}"
        # the baseline and the sub-second compiled rows are solved --repeats times (same built
        # solver, same start) and their median CPU time is used: a single sub-second solve on
        # the shared machine swings by up to 1.7x with the other jobs' load
        if form == "baseline":
            extra = ocp_fd_options.FAST if solver == "ipopt adaptive" else None
            solve = lambda: ocp_reach.solve_baseline(funcs=funcs, substeps=M, ipopt_options=extra)   # noqa: E731
        elif solver == "fatrop_stages":
            import ocp_fatrop
            solve = ocp_fatrop.FatropReach(20, funcs).solve
        elif solver in ("fd_stages", "fd_stages adaptive"):
            import ocp_fd_stages
            fd_stages = ocp_fd_stages.FdStageReach(20, funcs)
            fd_built = fd_stages.ipopt(ocp_fd_options.FAST if solver == "fd_stages adaptive" else None)
            label = "ipopt (compiled fd_rk4 stages" + (", adaptive barrier)" if solver == "fd_stages adaptive" else ")")
            solve = lambda: dict(fd_stages.solve_ipopt(fd_built), solver=label)   # noqa: E731
        elif solver in STAGE_OPTIONS:
            import ocp_stages
            stages = ocp_stages.StageReach(20, funcs)
            built = stages.ipopt(STAGE_OPTIONS[solver])
            solve = lambda: stages.solve_ipopt(built)   # noqa: E731
        else:
            solve = ocp_reach.reach_problem(form, solver, funcs=funcs, substeps=M).solve
        repeats = args.repeats if (form == "baseline" or "stages" in solver) else 1
        runs = [solve() for _ in range(repeats)]
        res = runs[-1]
        res["solve_cpu_s_runs"] = [r["solve_cpu_s"] for r in runs]
        res["solve_cpu_s"] = float(np.median(res["solve_cpu_s_runs"]))
        res["solve_s"] = float(np.median([r["solve_s"] for r in runs]))
        doc["rows"].append(_row(name, "generated", res, setup, funcs, base_s))
        doc["rows"][-1]["solve_cpu_s_runs"] = res["solve_cpu_s_runs"]
        if form == "baseline" and solver == "ipopt":
            base_s = res["solve_cpu_s"]
        replace_file(out, strict_json(doc, indent=1) + "\n")
    if not args.no_peers:
        peers, failures = peer_fds(funcs)
        doc["peer_failures"] = failures
        for source, (fd, err) in peers.items():
            pf = dict(funcs, fd=fd)
            for form, solver in (("baseline", "ipopt"), ("fd_rk4", "ipopt")):
                res = (ocp_reach.solve_baseline(funcs=pf) if form == "baseline"
                       else ocp_reach.reach_problem(form, solver, funcs=pf).solve())
                row = _row(f"{source} {form} {solver} M=1", source, res, setup, funcs, base_s)
                row["fd_max_abs_diff"] = err
                doc["rows"].append(row)
                replace_file(out, strict_json(doc, indent=1) + "\n")
        summary, rows = crocoddyl_peer(Path(args.crocoddyl_venv), funcs, setup, base_s)
        doc["crocoddyl"], doc["rows"] = summary, doc["rows"] + rows
        if "error" in summary and old_crocoddyl and "error" not in old_crocoddyl:
            doc["crocoddyl"] = dict(old_crocoddyl, carried_over_from_earlier_run=True, this_run_error=summary["error"])
        doc["versions"]["crocoddyl_venv"] = doc["crocoddyl"].get("versions", {"error": summary.get("error")})
        print(f"crocoddyl: {doc['versions']['crocoddyl_venv']}", flush=True)
    if not args.rows:
        doc["warm_resolve"] = warm_resolve(funcs)
        print(f"warm re-solve: median {doc['warm_resolve']['median_ms']:.1f} ms, iterations {doc['warm_resolve']['iterations']}")
        doc["warm_resolve_stages"] = warm_resolve_stages(funcs)
        print(f"warm re-solve, compiled stages: median {doc['warm_resolve_stages']['median_ms']:.1f} ms, "
              f"iterations {doc['warm_resolve_stages']['iterations']}")
    doc["loadavg_end"] = list(os.getloadavg())

    def both(folder):          # the finished JSON and its figure, both or neither
        (folder / out.name).write_text(strict_json(doc, indent=1) + "\n")
        plot(doc, folder / out.with_suffix(".png").name)
    replace_files(out.parent, both)
    print(f"wrote {out} and {out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
