"""How long the discrepancy workflow takes on a 40 s log at 200 Hz (the issue's yardstick):
``python -m benchmarks.discovery_timing [--repeats 3] [--out DIR]`` simulates the log (KUKA
LWR, Pinocchio's rnea plus hidden viscous friction and 0.02 N m torque noise), then times the
whole ``kindyngen discover`` command in-process (reading, preprocessing, selection, model.yaml,
report and figures) and ``discover()`` alone; writes ``results/discovery_timing.json``."""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from kindyngen.json_text import strict_json

from .common import RESULTS, machine

ROOT = Path(__file__).resolve().parents[1]


def simulate(path: Path, seconds: float = 40.0, rate: float = 200.0) -> Path:
    import pinocchio as pin
    sys.path.insert(0, str(ROOT / "tests"))
    from reference import pinocchio_model
    from kindyngen.readers.yaml_description import load_robot
    rng = np.random.default_rng(1)
    t = np.arange(0, seconds, 1 / rate)
    amp, w = rng.uniform(0.2, 0.6, size=(7, 3)), 2 * np.pi * rng.uniform(0.1, 0.5, size=(7, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(7, 3))
    arg = w[None] * t[:, None, None] + phase[None]
    q, qd = np.sum(amp * np.sin(arg), axis=2), np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    model, data, _ = pinocchio_model(load_robot(ROOT / "robots" / "lwr4.yaml"))
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)]) + 0.5 * qd
    tau += rng.normal(scale=0.02, size=tau.shape)
    header = ["t"] + [f"{k}{i}" for k in ("q", "qd", "qdd", "tau") for i in range(1, 8)]
    np.savetxt(path, np.column_stack([t, q, qd, qdd, tau]), delimiter=",", header=",".join(header), comments="")
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    from kindyngen.cli.main import main as cli
    from kindyngen.measured.discovery import discover
    from kindyngen.measured.log_preparing import Preprocessing, load_segments
    from kindyngen.readers.yaml_description import load_robot
    with tempfile.TemporaryDirectory() as tmp:
        log = simulate(Path(tmp) / "log.csv")
        robot = load_robot(ROOT / "robots" / "lwr4.yaml")
        segments = load_segments(log, 7, Preprocessing())
        discover(robot, segments)                        # warm: the symbolic regressors, once per process
        command, core = [], []
        for k in range(args.repeats):
            start = time.perf_counter()
            assert cli(["discover", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(log),
                        "--out", str(Path(tmp) / f"out{k}"), "--quiet"]) == 0
            command.append(time.perf_counter() - start)
            start = time.perf_counter()
            found = discover(robot, segments)
            core.append(time.perf_counter() - start)
        named = list(found.effects)
    result = {"machine": machine(), "log": "40 s at 200 Hz (8000 samples), 7 joints, hidden viscous friction",
              "named": named, "command_s": command, "discover_s": core,
              "command_median_s": float(np.median(command)), "discover_median_s": float(np.median(core)),
              "note": "after one warm-up call that builds the symbolic regressors (about 1-2 s, once per process)"}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "discovery_timing.json").write_text(strict_json(result, indent=1) + "\n")
    print(strict_json({k: result[k] for k in ("named", "command_median_s", "discover_median_s")}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
