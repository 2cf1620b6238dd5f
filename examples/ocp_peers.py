"""The OCPs of examples/ocp.py with the forward dynamics of URDF-based CasADi libraries.

    .venv/bin/python examples/ocp_peers.py [--problems lwr4 panda two_link] [--out examples/results/ocp_peers.json]

Peers (optional, not project dependencies; `pip install "adam-robotics[casadi]" urdf2casadi`):
  adam        adam-robotics' casadi KinDynComputations on the URDF of examples/dh_to_urdf.py,
              fixed base (base transform = identity, base velocity = 0): fd = M_jj^-1 (tau - h_j)
              with M_jj the joint block of its mass matrix and h_j the joint part of its bias force
              (casadi.solve on SX). adam's `aba` is the floating-base ABA (base acceleration free),
              not the fixed-base forward dynamics; it is checked and reported but not used.
  urdf2casadi urdf2casadi's URDFparser.get_forward_dynamics_aba (fixed-base ABA), root base_link,
              tip link{n}.
Both are evaluated on SX symbols and wrapped as SX Functions fd(q, qd, tau) -> qdd; each must
match the generated fd to 1e-9 at random states before its OCP is solved. The OCP (N, RK4
substeps, IPOPT settings, VELOCITY_BACKOFF = 0 as in examples/ocp_speed.py) is the one of
ocp.solve; modes sx and mx_map. Also the generated fd in the same modes, for reference rows on
the same machine and run. Reported as in ocp_speed.py.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import traceback
from importlib import metadata
from pathlib import Path

import casadi as ca
import numpy as np

EXAMPLES = Path(__file__).resolve().parent
sys.path.insert(0, str(EXAMPLES))
import ocp  # noqa: E402
from dh_to_urdf import check_against_reference, write_urdf  # noqa: E402

CASES = {"lwr4": (10, 4), "panda": (10, 4), "two_link": (100, 1)}   # (N, RK4 substeps)
MODES = ("mx_map", "sx")


def _sx_function(q, qd, tau, qdd):
    return ca.Function("fd", [q, qd, tau], [qdd], ["q", "qd", "tau"], ["qdd"])


def adam_fd(urdf: Path, robot, use_aba: bool = False) -> ca.Function:
    from adam.casadi import KinDynComputations
    n = robot.n
    joints = [f"joint{i + 1}" for i in range(n)]
    g = np.concatenate([np.array(robot.gravity, float), np.zeros(3)])
    kd = KinDynComputations(str(urdf), joints, gravity=g)
    q, qd, tau = (ca.SX.sym(s, n) for s in ("q", "qd", "tau"))
    H = ca.SX.eye(4)
    vb = ca.SX.zeros(6)
    if use_aba:
        out = kd.aba(H, q, vb, qd, tau)
        return _sx_function(q, qd, tau, out[6:])
    M = kd.mass_matrix(H, q)[6:, 6:]
    h = kd.bias_force(H, q, vb, qd)[6:]
    return _sx_function(q, qd, tau, ca.solve(M, tau - h))


def urdf2casadi_fd(urdf: Path, robot) -> ca.Function:
    from urdf2casadi import urdfparser as u2c
    p = u2c.URDFparser()
    p.from_file(str(urdf))
    f = p.get_forward_dynamics_aba("base_link", f"link{robot.n}", gravity=list(map(float, robot.gravity)))
    q, qd, tau = (ca.SX.sym(s, robot.n) for s in ("q", "qd", "tau"))
    return _sx_function(q, qd, tau, f(q, qd, tau))


def max_difference(fd, ref, robot, count=50, seed=3):
    rng = np.random.default_rng(seed)
    err = 0.0
    for _ in range(count):
        q = rng.uniform(robot.lower, robot.upper)
        qd, tau = rng.uniform(-2, 2, robot.n), rng.uniform(-20, 20, robot.n)
        err = max(err, float(np.abs(np.array(fd(q, qd, tau)) - np.array(ref(q, qd, tau))).max()))
    return err


def _version(dist):
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def main(argv=None):
    ocp.VELOCITY_BACKOFF = 0.0   # as examples/ocp_speed.py
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(EXAMPLES / "results" / "ocp_peers.json"))
    ap.add_argument("--problems", nargs="*", default=list(CASES))
    ap.add_argument("--sources", nargs="*", default=["generated", "adam", "urdf2casadi"])
    ap.add_argument("--modes", nargs="*", default=list(MODES))
    args = ap.parse_args(argv)
    doc = {"casadi": ca.__version__, "machine": platform.machine(), "python": platform.python_version(),
           "versions": {d: _version(d) for d in ("adam-robotics", "urdf2casadi", "urdf-parser-py", "urdfdom-py",
                                                  "liecasadi", "pin")},
           "velocity_backoff": 0.0,
           "note": "wall times on a shared 2-core machine; compare rows of one problem",
           "checks": [], "failures": [], "rows": []}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)

    def dump():
        out.write_text(json.dumps(doc, indent=1) + "\n")

    for prob in args.problems:
        N, M = CASES[prob]
        funcs = ocp.load_functions(prob)
        robot = funcs["robot"]
        setup = ocp.problem_setup(prob, funcs)
        urdf = write_urdf(robot, EXAMPLES / "results" / "urdf" / f"{robot.name}.urdf")
        urdf_err = check_against_reference(robot, urdf)
        doc["checks"].append({"problem": prob, "what": "pinocchio(URDF) vs tests/reference.py", **urdf_err})
        builders = {"generated": lambda: funcs["fd"], "adam": lambda: adam_fd(urdf, robot),
                    "urdf2casadi": lambda: urdf2casadi_fd(urdf, robot)}
        if "adam" in args.sources:   # the floating-base ABA, for the record
            try:
                e = max_difference(adam_fd(urdf, robot, use_aba=True), funcs["fd"], robot)
                doc["checks"].append({"problem": prob, "what": "adam aba (floating base) joint part vs generated fd",
                                      "max_abs_diff": e})
                print(f"{prob}: adam floating-base aba vs generated fd: {e:.2e}", flush=True)
            except Exception as exc:  # noqa: BLE001
                doc["failures"].append({"problem": prob, "source": "adam aba", "error": repr(exc)})
        for source in args.sources:
            try:
                t0 = time.perf_counter()
                fd = builders[source]()
                fd_build_s = time.perf_counter() - t0
                err = max_difference(fd, funcs["fd"], robot)
            except Exception as exc:  # noqa: BLE001
                traceback.print_exc()
                doc["failures"].append({"problem": prob, "source": source, "stage": "build fd", "error": repr(exc)})
                dump()
                continue
            doc["checks"].append({"problem": prob, "what": f"{source} fd vs generated fd", "max_abs_diff": err})
            print(f"{prob}: {source} fd vs generated: {err:.2e} (fd built in {fd_build_s:.2f} s)", flush=True)
            if not err <= 1e-9:
                doc["failures"].append({"problem": prob, "source": source, "stage": "check",
                                        "error": f"max |fd - generated fd| = {err:.3e} > 1e-9"})
                dump()
                continue
            n_fd, n_jac = fd.n_instructions(), fd.jacobian().n_instructions()
            for mode in args.modes:
                try:
                    r = ocp.solve(setup, fd, N, mode, M, fk_hom=funcs["fk_hom"])
                except Exception as exc:  # noqa: BLE001
                    traceback.print_exc()
                    doc["failures"].append({"problem": prob, "source": source, "mode": mode, "stage": "solve",
                                            "error": repr(exc)})
                    dump()
                    continue
                row = {"problem": prob, "N": N, "substeps": M, "dynamics": source, "mode": mode,
                       "status": r["status"], "iterations": r["iterations"], "T": r["T"],
                       "fd_build_s": fd_build_s, "build_s": r["build_s"], "solve_s": r["solve_s"],
                       "ms_per_iteration": 1e3 * r["solve_s"] / max(r["iterations"], 1),
                       "fd_instructions": n_fd, "fd_jacobian_instructions": n_jac, "fd_max_abs_diff": err}
                doc["rows"].append(row)
                dump()
                print(f"{prob:8s} {source:11s} {mode:7s} {row['status']:16s} T={row['T']:.6f} it={row['iterations']:4d} "
                      f"build={row['build_s']:6.2f}s solve={row['solve_s']:7.2f}s {row['ms_per_iteration']:7.1f} ms/it "
                      f"fd={n_fd} dfd={n_jac}", flush=True)
    dump()
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
