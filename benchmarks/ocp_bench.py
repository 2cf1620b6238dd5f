"""The LWR reach of the issue (kindyngen.control; benchmarks/control_robots.py's task: start at
rest at q0 = (0, .5, 0, -1, 0, 0, 0), flange to (0.35, 0.25, 0.55) m at rest at T = 1 s, N = 20,
one RK4 step per interval, the data sheet's speeds, torques 176/176/100/100/100/30/30 N m, minimum
h sum |tau|^2) by every route side by side in one run, each plan checked by Pinocchio; the same
NLP built from adam's and urdf2casadi's forward dynamics where they are installed; Crocoddyl in
its own environment (benchmarks/control_bench.py's peer).

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python -m benchmarks.ocp_bench [--out benchmarks/results/ocp.json]

Rows (kindyngen/control/reach.py): ``baseline`` (Opti + IPOPT, fd on MX symbols, IPOPT's
defaults: what a new user writes), ``baseline adaptive`` (the same with FAST, for a like-for-like
ratio), ``sx`` (IPOPT on the NLP as one SX graph), ``inverse-dynamics`` and ``inverse-dynamics x2``
(the stage accelerations as unknowns, one and two RK4 steps per interval, SX graph), ``fatrop``
and ``fatrop inverse-dynamics`` (fatrop on either SX graph, structure by hand; tol 1e-4 and
1e-6), ``native monotone`` and ``native`` (IPOPT on the native stage
library, with IPOPT's monotone barrier and with FAST, the package's default); ``native warm``:
the re-solve from the native solution and its multipliers shifted by one interval (the
receding-horizon step). The baseline and the native rows are solved --repeats times and the
median CPU time is used (ratios are of CPU times, to the plain baseline's).

Pinocchio's checks of every plan (benchmarks/control_bench.py plan_check, resimulation): from
each node the plan's RK4 step of pin.aba against the next node, the flange at the goal, the
limits' excess at the nodes; the torques re-simulated with 20 RK4 steps per interval (the
discretisation's own error) and the flange's distance from the goal after that.

(The rows of the example scripts this replaced, id_rk4 on compiled stages, fatrop on them and
the compiled fd_rk4 stages, are in benchmarks/results/ocp.json of the runs before;
docs/optimal_control.md keeps their tables.)
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
from dataclasses import replace
from importlib import metadata
from pathlib import Path

# CPU time is the measure: one BLAS thread unless the caller says otherwise (the 2026-12-02 run,
# without it, gave the two-substep id_rk4 row 7.3 s CPU for 3.7 s wall)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks import control_bench as cb, control_robots as cr  # noqa: E402
from kindyngen.control import reach  # noqa: E402
from kindyngen.control.integrators import Integrator  # noqa: E402
from kindyngen.json_text import strict_json  # noqa: E402
from kindyngen.output_folder import replace_file, replace_files  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

ROWS = {
    "baseline": lambda robot, task: reach.solve_baseline(robot, task),
    "baseline adaptive": lambda robot, task: reach.solve_baseline(robot, task, reach.FAST),
    "sx": lambda robot, task: reach.solve_sx(robot, task),
    "inverse-dynamics": lambda robot, task: reach.inverse_dynamics_reach(robot, task),
    "inverse-dynamics x2": lambda robot, task: reach.inverse_dynamics_reach(robot, task),
    "fatrop": lambda robot, task: reach.solve_fatrop(robot, task),
    "fatrop inverse-dynamics": lambda robot, task: reach.solve_fatrop(robot, task, formulation="inverse-dynamics"),
    "native monotone": None,          # built once, solved --repeats times
    "native": None,
}
REPEATED = ("baseline", "baseline adaptive", "native monotone", "native")
#: rows on another discretisation of the same reach
TASKS = {"inverse-dynamics x2": lambda task: replace(task, integrator=Integrator("rk4", 2), inner=False)}


def _version(dist):
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


class PeerRobot:
    """The prepared robot with another library's fd (for the baseline and SX rows)."""

    def __init__(self, robot, fd):
        self._robot, self.fd = robot, fd

    def __getattr__(self, name):
        return getattr(self._robot, name)


def peer_fds(model):
    """adam's and urdf2casadi's fd on the URDF of examples/dh_to_urdf.py, each checked against
    the generated fd (examples/ocp_peers.py's way)."""
    sys.path.insert(0, str(ROOT / "examples"))
    import casadi as ca
    import ocp_peers
    from dh_to_urdf import write_urdf
    urdf = write_urdf(model, ROOT / "examples" / "results" / "urdf" / f"{model.name}.urdf")
    generated = ca.Function.load(str(ROOT / "generated" / model.name / "casadi" / "fd.casadi"))
    out, failures = {}, []
    for name, build in (("adam", lambda: ocp_peers.adam_fd(urdf, model)),
                        ("urdf2casadi", lambda: ocp_peers.urdf2casadi_fd(urdf, model))):
        try:
            fd = build()
            err = ocp_peers.max_difference(fd, generated, model)
            if err > 1e-9:
                failures.append({"source": name, "error": f"max |fd - generated fd| = {err:.3e}"})
                continue
            out[name] = (fd, err)
        except Exception as exc:  # noqa: BLE001 - a peer that does not load is reported, not fatal
            failures.append({"source": name, "error": repr(exc)})
    return out, failures


def row(variant, source, runs, model, task, base_s=None) -> dict:
    res = runs[-1]
    cpu = [r.solve_cpu_s for r in runs]
    out = {"variant": variant, "dynamics": source, "solver": res.solver, "status": res.status, "success": res.success,
           "iterations": res.iterations, "solve_cpu_s": float(np.median(cpu)), "solve_cpu_s_runs": cpu,
           "objective": res.objective, **cb.plan_check("lwr4", model, task, res),
           **cb.resimulation("lwr4", model, task, res)}
    if base_s:
        out["speedup_vs_baseline"] = base_s / out["solve_cpu_s"]
    print(f"{variant:24s} {res.status:24s} it={res.iterations:4d} cpu={out['solve_cpu_s']:8.4f}s f={res.objective:.4f} "
          f"step_err={out['plan_step_error']:.1e} resim={out['resim_error']:.1e} "
          f"goal={1e3 * out['resim_goal_error_m']:.2f}mm" + (f" x{out['speedup_vs_baseline']:.1f}" if base_s else ""),
          flush=True)
    return out


def warm_resolve(robot, task, repeats: int) -> dict:
    nlp = reach.ReachNLP(robot, task)
    res = nlp.solve()
    warm_solver = nlp.build(dict(nlp.options, **{"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                                               "ipopt.warm_start_bound_push": 1e-6,
                                               "ipopt.warm_start_mult_bound_push": 1e-6}))
    lam_g, lam_x = nlp.shifted_multipliers(res.lam_g, res.lam_x)
    x1 = np.concatenate([res.q[1], res.qd[1]])
    runs = [nlp.solve(x1, z0=nlp.shifted(res.z), lam_g0=lam_g, lam_x0=lam_x, solver=warm_solver) for _ in range(repeats)]
    cpu = [r.solve_cpu_s for r in runs]
    return {"what": "native IPOPT from the solution and its multipliers shifted by one interval, start at node 1",
            "status": runs[-1].status, "iterations": runs[-1].iterations, "solve_cpu_s": cpu,
            "median_ms": 1e3 * float(np.median(cpu))}


def plot(doc, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = doc["rows"]
    fig, ax = plt.subplots(figsize=(9, 4))
    names = [r["variant"] for r in rows]
    ax.barh(names, [r["solve_cpu_s"] for r in rows],
            color=["C3" if r["variant"].endswith("baseline") else "C0" for r in rows])
    ax.set_xscale("log")
    ax.set_xlabel("solve CPU time [s] (cold start, log scale)")
    ax.set_title(f"LWR reach, N = 20, one run on {doc['machine']['cpu']}", fontsize=9)
    ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "ocp.json"))
    ap.add_argument("--no-peers", action="store_true", help="skip adam, urdf2casadi and Crocoddyl")
    ap.add_argument("--repeats", type=int, default=5,
                    help="solves of the baseline and native rows, median CPU time used (default 5)")
    ap.add_argument("--rows", nargs="+", choices=list(ROWS), help="only these rows (the plain baseline always)")
    ap.add_argument("--crocoddyl-venv", default=str(ROOT / ".venv-crocoddyl"),
                    help="environment with crocoddyl, mim-solvers (benchmarks/crocoddyl_reach.py says how to make it)")
    args = ap.parse_args(argv)
    model, robot, limits, task = cr.load("lwr4")
    names = ["baseline"] + [r for r in (args.rows or ROWS) if r != "baseline"]
    doc = {"machine": cb.machine(), "uptime_start": cb.uptime(), "python": platform.python_version(),
           "versions": {d: _version(d) for d in ("casadi", "pin", "adam-robotics", "liecasadi", "urdf2casadi")},
           "problem": f"LWR reach, N = {task.N}, T = {task.T} s, q0 {list(task.q0)}, goal {list(task.goal)} "
                      "(benchmarks/control_robots.py)",
           "rows": [], "peer_failures": []}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    base_s = None
    for name in names:
        repeats = args.repeats if name in REPEATED else 1
        t = TASKS.get(name, lambda x: x)(task)
        if name.startswith("native"):
            nlp = reach.ReachNLP(robot, t, adaptive=name == "native")
            runs = [nlp.solve() for _ in range(repeats)]
        else:
            runs = [ROWS[name](robot, t) for _ in range(repeats)]
        doc["rows"].append(row(name, "generated", runs, model, t, base_s))
        if name == "baseline":
            base_s = doc["rows"][-1]["solve_cpu_s"]
        replace_file(out, strict_json(doc, indent=1) + "\n")
    if not args.no_peers:
        peers, failures = peer_fds(model)
        doc["peer_failures"] = failures
        for source, (fd, err) in peers.items():
            pr = PeerRobot(robot, fd)
            for name, solve in (("baseline", reach.solve_baseline), ("sx", reach.solve_sx)):
                r = row(f"{source} {name}", source, [solve(pr, task)], model, task, base_s)
                r["fd_max_abs_diff"] = err
                doc["rows"].append(r)
                replace_file(out, strict_json(doc, indent=1) + "\n")
        doc["crocoddyl"] = cb.crocoddyl_rows("lwr4", model, task, Path(args.crocoddyl_venv), False)
        for c in doc["crocoddyl"].get("rows", []):
            print(f"crocoddyl {c['solver']:20s} {c['status'][:24]:24s} it={c['iterations']:4d} cpu={c['solve_cpu_s']:8.4f}s "
                  f"f={c['objective']:.4f} step_err={c['plan_step_error']:.1e}"
                  + (f" x{base_s / c['solve_cpu_s']:.1f}" if base_s else ""), flush=True)
    if not args.rows:
        doc["warm_resolve"] = warm_resolve(robot, task, args.repeats)
        print(f"native warm re-solve: {doc['warm_resolve']['iterations']} iterations, median "
              f"{doc['warm_resolve']['median_ms']:.1f} ms CPU")
    doc["uptime_end"] = cb.uptime()

    def both(folder):          # the finished JSON and its figure, both or neither
        (folder / out.name).write_text(strict_json(doc, indent=1) + "\n")
        plot(doc, folder / out.with_suffix(".png").name)
    replace_files(out.parent, both)
    print(f"wrote {out} and {out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
