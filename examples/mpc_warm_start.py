"""The MPC re-solve's warm start and iteration cap measured side by side, one run (issue 27):
examples/mpc.py --solver stages with

- the previous warm start (the shifted plan and constraint multipliers only, the row x_0 = p
  given the old x_0 row's multiplier),
- the current one (also the bound multipliers, and the row x_0 = p given the old first gap's
  multiplier: examples/ocp_stages.py shifted_lam, shifted_lam_x),
- the current one with IPOPT capped at 5 and at 3 iterations per re-solve (the capped iterate
  is applied), to show what a cap costs in tracking and limits.

    .venv/bin/python examples/mpc_warm_start.py --out benchmarks/results/mpc_lwr4_warm_start.json [--steps 20]

CPU time of each re-solve (time.process_time; set OPENBLAS_NUM_THREADS=1) is the figure to
compare on a shared machine; wall time is recorded too.
"""
from __future__ import annotations

import json
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

EXAMPLES = Path(__file__).resolve().parent
sys.path.insert(0, str(EXAMPLES))
import mpc  # noqa: E402
import ocp_stages  # noqa: E402


def previous_shifted_lam(self, lam):
    """The shift of the constraint multipliers before the bound multipliers were kept."""
    nc, nx, N = self.nc, self.nx, self.N
    stages = np.concatenate([lam[:nc], lam[nc + nx:nc + nx + (N - 1) * nc]]).reshape(N, nc)
    stages = np.vstack([stages[1:], stages[-1:]])
    return np.concatenate([stages[0], lam[nc:nc + nx], stages[1:].ravel(), lam[-(3 + self.n):]])


VARIANTS = [("previous warm start (plan, constraint multipliers)", {}, True),
            ("warm start with bound multipliers", {}, False),
            ("warm start with bound multipliers, max_iter 5", {"ipopt.max_iter": 5}, False),
            ("warm start with bound multipliers, max_iter 3", {"ipopt.max_iter": 3}, False)]


def main(argv=None) -> int:
    ap = mpc._Parser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--steps", type=int, default=20, help="control steps per variant (default 20)")
    args = ap.parse_args(argv)
    if args.steps < 2:
        ap.error(f"--steps {args.steps}: must be at least 2 (the first solve is cold)")
    current = (ocp_stages.StageReach.shifted_lam, ocp_stages.StageReach.shifted_lam_x)
    doc = {"problem": "lwr4", "N": 20, "steps": args.steps, "variants": {}}
    for name, options, previous in VARIANTS:
        if previous:
            ocp_stages.StageReach.shifted_lam = previous_shifted_lam
            ocp_stages.StageReach.shifted_lam_x = lambda self, lam_x: None
        else:
            ocp_stages.StageReach.shifted_lam, ocp_stages.StageReach.shifted_lam_x = current
        d = mpc.run(args.steps, 20, False, "stages", options)
        cpu, wall = np.array(d["solve_cpu_ms"][1:]), np.array(d["solve_ms"][1:])
        r = {"cpu_ms_median": float(np.median(cpu)), "cpu_ms_p95": float(np.percentile(cpu, 95)),
             "cpu_ms_worst": float(cpu.max()), "wall_ms_median": float(np.median(wall)),
             "wall_ms_p95": float(np.percentile(wall, 95)), "wall_ms_worst": float(wall.max()),
             "iterations": [int(min(d["iterations"][1:])), int(max(d["iterations"][1:]))],
             "cold_cpu_ms": d["solve_cpu_ms"][0], "tracking_rms": d["tracking_rms"],
             "goal_error_final_mm": 1e3 * d["goal_error_final_m"], "violations": d["violations"],
             "violations_by_kind": d["violations_by_kind"], "status": sorted(set(d["status"][1:])),
             "options": options}
        doc["variants"][name] = r
        print(f"{name}: CPU median {r['cpu_ms_median']:.1f} p95 {r['cpu_ms_p95']:.1f} worst {r['cpu_ms_worst']:.1f} ms, "
              f"iterations {r['iterations']}, tracking {r['tracking_rms']:.2e}, violations {r['violations']}", flush=True)
    ocp_stages.StageReach.shifted_lam, ocp_stages.StageReach.shifted_lam_x = current
    cpu_name = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")),
                    platform.processor()) if Path("/proc/cpuinfo").exists() else platform.processor()
    doc["machine"] = {"cpu": cpu_name, "uptime": subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"  wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
