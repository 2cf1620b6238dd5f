"""The reach on any arm through kindyngen.control: the LWR, the Panda and the UR5 (example-robot-
data's URDF) of benchmarks/control_robots.py, each solved by IPOPT on its native stage library
and by the plain Opti baseline, the plan checked by Pinocchio.

    .venv/bin/python examples/control_reach.py [--robots lwr4 panda ur5] [--no-baseline]

(The first run derives and compiles each robot once, about 15 s each; the cache is reused.)
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import control_robots as cr  # noqa: E402
from benchmarks.control_bench import plan_check  # noqa: E402
from kindyngen.control.reach import ReachNLP, solve_baseline  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="+", default=list(cr.ROBOTS), choices=list(cr.ROBOTS))
    ap.add_argument("--no-baseline", action="store_true")
    args = ap.parse_args(argv)
    for name in args.robots:
        if not cr.available(name):
            print(f"{name}: {cr.ROBOTS[name].description} not installed, skipped")
            continue
        model, robot, limits, task = cr.load(name)
        res = ReachNLP(robot, task, progress=print).solve()
        check = plan_check(name, model, task, res)
        print(f"{name}: {res.status}, {res.iterations} iterations, {1e3 * res.solve_cpu_s:.1f} ms CPU, objective "
              f"{res.objective:.4f}; Pinocchio: plan step error {check['plan_step_error']:.1e}, flange "
              f"{1e3 * check['goal_error_m']:.2e} mm from the goal")
        if not args.no_baseline:
            base = solve_baseline(robot, task)
            print(f"  baseline (Opti + IPOPT): {base.iterations} iterations, {base.solve_cpu_s:.2f} s CPU, objective "
                  f"{base.objective:.4f}: {base.solve_cpu_s / res.solve_cpu_s:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
