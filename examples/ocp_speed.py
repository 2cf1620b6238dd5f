"""Speed of the OCPs of examples/ocp.py by the way the dynamics enter the NLP.

    .venv/bin/python examples/ocp_speed.py [--out examples/results/ocp_speed.json]

Same problem, discretisation and IPOPT settings for every row; what changes is `fd`:
the generated Function (loaded from the .casadi files; two_link generated on the fly) used
  sx         called on SX symbols: the whole NLP is one SX graph (fd inlined)
  mx         called on MX symbols: a call node per RK4 stage, derivatives through the call
  mx_expand  the same MX NLP, expanded to SX by nlpsol(..., {"expand": True})
  mx_map     one SX RK4-step Function (fd inlined) mapped over the N intervals in an MX NLP
and, as the peer, a hand-written ABA in SX from the DH table (examples/handwritten_dynamics.py)
used the same ways (sx, mx_map). adam-robotics and urdf2casadi are not installed: not compared.
Reported: build (graph + nlpsol construction) and solve wall time, iterations, time per
iteration, T, and the instruction counts of fd and of its Jacobian (Function.n_instructions()).
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import casadi as ca

sys.path.insert(0, str(Path(__file__).resolve().parent))
import ocp  # noqa: E402
from handwritten_dynamics import handwritten_fd  # noqa: E402

CASES = {"two_link": (100, 1), "lwr4": (10, 4), "panda": (10, 4)}   # (N, RK4 substeps)
VARIANTS = [("generated", m) for m in ("sx", "mx", "mx_expand", "mx_map")] + \
           [("handwritten", m) for m in ("sx", "mx_map")]


def main(argv=None):
    # The comparison is of the dynamics' cost per iteration on one NLP. With ocp.py's 5 %
    # velocity back-off, the N = 10 LWR problem becomes fragile (IPOPT's restoration fails in
    # some modes, others take different iteration counts), so the table is measured with the
    # velocity limits at their full value, as results/ocp_speed.json records.
    ocp.VELOCITY_BACKOFF = 0.0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "ocp_speed.json"))
    ap.add_argument("--problems", nargs="*", default=list(CASES))
    args = ap.parse_args(argv)
    rows = []
    for prob in args.problems:
        N, M = CASES[prob]
        funcs = ocp.load_functions(prob)
        setup = ocp.problem_setup(prob, funcs)
        fds = {"generated": funcs["fd"], "handwritten": handwritten_fd(funcs["robot"])}
        for source, mode in VARIANTS:
            fd = fds[source]
            r = ocp.solve(setup, fd, N, mode, M, fk_hom=funcs["fk_hom"])
            row = {"problem": prob, "N": N, "substeps": M, "dynamics": source, "mode": mode,
                   "status": r["status"], "iterations": r["iterations"], "T": r["T"],
                   "build_s": r["build_s"], "solve_s": r["solve_s"],
                   "ms_per_iteration": 1e3 * r["solve_s"] / max(r["iterations"], 1),
                   "fd_instructions": fd.n_instructions(),
                   "fd_jacobian_instructions": fd.jacobian().n_instructions()}
            rows.append(row)
            print(f"{prob:8s} {source:11s} {mode:9s} {row['status']:16s} T={row['T']:.6f} it={row['iterations']:4d} "
                  f"build={row['build_s']:6.2f}s solve={row['solve_s']:7.2f}s {row['ms_per_iteration']:7.1f} ms/it "
                  f"fd={row['fd_instructions']} dfd={row['fd_jacobian_instructions']}", flush=True)
    doc = {"casadi": ca.__version__, "machine": platform.machine(), "python": platform.python_version(),
           "note": "wall times on a shared 2-core machine; compare rows of one problem",
           "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
