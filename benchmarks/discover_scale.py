"""`discover` on hour-long logs: peak memory and wall time against the length of the log.

The logs are those of :mod:`benchmarks.identify_scale` (the Panda at 1 kHz simulated with
Pinocchio: a periodic multisine, rigid-body torques plus viscous friction, Gaussian torque
noise of 0.05 N m drawn afresh for every sample), written as CSV.  Each run is ``kindyngen
discover`` with the defaults (every candidate, 5 folds, the last 30 % of the log held out,
5 Hz zero-phase low-pass, parallel filtering, decimation 25) in its own process, timed by
``/usr/bin/time -v`` (wall time, maximum resident set size, CPU time).  ``--candidates`` narrows
the library (the payload, base tilt and the effects on the measurement cost about 30 evaluations
of the nominal torques per sample; the joint laws are elementwise).  The load average before
and after each run is recorded: the machine is shared.  Results:
``benchmarks/results/discover_scale.json``.

    nice -n 10 python -m benchmarks.discover_scale [--minutes 10 60] [--candidates LIST]
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from kindyngen.json_text import strict_json

from benchmarks.identify_scale import ROBOT, _period, measure, write_csv

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def run(label: str, log: Path, out: Path, candidates: str | None) -> dict:
    command = ["-m", "kindyngen", "discover", "--robot", str(ROBOT), "--data", str(log), "--out", str(out)] + (
        ["--candidates", candidates] if candidates else [])
    return measure(label, command, ROOT, log, "discover:", 6)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, nargs="+", default=[10.0, 60.0], help="log lengths (default 10 60)")
    p.add_argument("--candidates", default=None, metavar="LIST",
                   help="discover's --candidates (default: all); the effects on the measurement and the payload "
                        "cost about 30 evaluations of the nominal torques per sample, the joint laws none")
    p.add_argument("--results", default="discover_scale", help="name of the results (.json) in benchmarks/results")
    args = p.parse_args(argv)
    cpu = next((line.split(":", 1)[1].strip() for line in subprocess.run(["lscpu"], capture_output=True,
                text=True).stdout.splitlines() if line.startswith("Model name")), platform.processor())
    period = _period()
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for minutes in args.minutes:
            log = work / f"panda_{minutes:g}min.csv"
            write_csv(log, 60.0 * minutes, period)
            runs.append(run(f"discover, {minutes:g} min CSV", log, work / f"out_{minutes:g}", args.candidates))
            log.unlink()
    doc = {"machine": {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
                       "note": "shared with other jobs: the load average (1, 5, 15 min) before and after is beside "
                               "each run, and its CPU time (user + system) beside its wall time"},
           "robot": "panda (robots/panda.yaml)", "rate_hz": 1000.0,
           "command": "kindyngen discover (5 folds, --holdout 0.3, 5 Hz zero-phase low-pass, parallel filtering, "
                      "decimation 25)",
           "candidates": args.candidates or "all",
           "runs": runs}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{args.results}.json").write_text(strict_json(doc, indent=1) + "\n")
    print(strict_json(doc, indent=1))
    return 0 if all(r["exit_code"] == 0 for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
