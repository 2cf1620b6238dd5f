"""The tracking MPC of kindyngen.control on a Pinocchio plant (benchmarks/control_plant.py, 1 kHz)
under one disturbance: the reach re-planned with margins, tracked for 2.5 s.

    .venv/bin/python examples/control_mpc.py --robot ur5 --disturbance push
    .venv/bin/python examples/control_mpc.py --robot lwr4 --disturbance payload

Disturbances: none, noise (1e-4 rad, 1e-3 rad/s), payload (5 kg at the flange from 0.5 s), push
(60 N at the flange, 0.4-0.7 s), mass (links 10 % heavier), torque (80 % of joint 2's limit,
0.4-0.7 s). Prints the plant's samples past a limit, the re-solve times and the final distance
from the goal (benchmarks/control_bench.py runs every case on every arm).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import control_bench, control_robots as cr  # noqa: E402
from benchmarks.control_plant import Disturbance  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default="ur5", choices=list(cr.ROBOTS))
    ap.add_argument("--disturbance", default="push", choices=("none", "noise", "payload", "push", "mass", "torque"))
    args = ap.parse_args(argv)
    model, robot, limits, task = cr.load(args.robot)
    dist = {"none": Disturbance(), "noise": Disturbance("noise", noise=(1e-4, 1e-3)),
            "payload": Disturbance("payload", start=0.5, mass_kg=5.0),
            "push": Disturbance("push", start=0.4, duration=0.3, force=(0.0, 60.0, 0.0)),
            "mass": Disturbance("mass_error", mass_scale=1.1),
            "torque": Disturbance("torque", start=0.4, duration=0.3, joint=1, torque=0.8 * limits.tau_max[1])}
    from dataclasses import replace
    import numpy as np
    from kindyngen.control.integrators import Integrator
    from kindyngen.control.reach import ReachNLP
    rt = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3, margin_position=0.05,
                 margin_torque=0.1)
    res = ReachNLP(robot, rt).solve()
    ref = {"X": np.hstack([res.q, res.qd]), "U": res.tau, "goal": task.goal}
    control_bench.mpc_case(args.robot, model, robot, limits, ref, args.disturbance, dist[args.disturbance], False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
