"""Play a trajectory on a simulated arm and write the log a real robot would give.

    .venv/bin/python examples/simulate_log.py --robot robots/lwr4.yaml --trajectory runs/excite/excitation.csv \
        --viscous 0.8 --coulomb 1.5 --noise 0.05 --out runs/log.csv

The handbook's tutorials use it where a reader has no robot at hand: it reads a trajectory CSV
(t, q1..qn, qd1..qdn, qdd1..qddn: what ``kindyngen excite`` writes), computes the joint torques
of the description's rigid bodies with Pinocchio's RNEA (an implementation that shares no code
with KinDynGen), adds the joint friction you give (``fv qd + fc sign(qd)``, the same on every
joint) and Gaussian torque noise, and writes t, q1..qn, tau1..taun (s, rad, N m): the log
format ``kindyngen identify`` and ``kindyngen discover`` read. Needs Pinocchio (pip install pin).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robot", required=True, help="a DH robot description (YAML)")
    p.add_argument("--trajectory", required=True, help="CSV with t, q1..qn, qd1..qdn, qdd1..qddn")
    p.add_argument("--viscous", type=float, default=0.0, help="viscous friction fv, N m s/rad (default 0)")
    p.add_argument("--coulomb", type=float, default=0.0, help="Coulomb friction fc, N m (default 0)")
    p.add_argument("--noise", type=float, default=0.0, help="torque noise standard deviation, N m (default 0)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, help="the log to write (CSV)")
    args = p.parse_args(argv)

    import pinocchio as pin
    from kindyngen.readers.yaml_description import load_robot
    from reference import pinocchio_model

    robot = load_robot(args.robot)
    model, data, _ = pinocchio_model(robot)
    table = np.genfromtxt(args.trajectory, delimiter=",", names=True)
    n = robot.n
    q, qd, qdd = (np.column_stack([table[f"{k}{i + 1}"] for i in range(n)]) for k in ("q", "qd", "qdd"))
    tau = np.array([pin.rnea(model, data, *state) for state in zip(q, qd, qdd)])
    tau += args.viscous * qd + args.coulomb * np.sign(qd)
    tau += np.random.default_rng(args.seed).normal(scale=args.noise, size=tau.shape) if args.noise else 0.0
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    header = ",".join(["t"] + [f"q{i + 1}" for i in range(n)] + [f"tau{i + 1}" for i in range(n)])
    np.savetxt(out, np.column_stack([table["t"], q, tau]), delimiter=",", header=header, comments="", fmt="%.17g")
    print(f"wrote {out}: {len(q)} samples of {n} joints", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
