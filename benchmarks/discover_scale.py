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
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.identify_scale import ROBOT, _period, write_csv

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def run(label: str, log: Path, out: Path, candidates: str | None) -> dict:
    argv = ["/usr/bin/time", "-v", sys.executable, "-m", "kindyngen", "discover", "--robot", str(ROBOT),
            "--data", str(log), "--out", str(out)] + (["--candidates", candidates] if candidates else [])
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    print(f"[{label}] {' '.join(argv[2:])}", flush=True)
    load_before = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    proc = subprocess.run(argv, env=env, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - started
    peak_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr).group(1))
    cpu_s = sum(float(re.search(rf"{kind} time \(seconds\): ([\d.]+)", proc.stderr).group(1))
                for kind in ("User", "System"))
    progress = [line for line in proc.stderr.splitlines() if line.startswith("discover:")]
    record = {"label": label, "log": log.name, "log_bytes": log.stat().st_size, "exit_code": proc.returncode,
              "wall_s": round(wall, 1), "cpu_s": round(cpu_s, 1), "peak_rss_gb": round(peak_kb / 1024 ** 2, 3),
              "load_average_before": load_before, "load_average_after": [round(x, 2) for x in os.getloadavg()],
              "stdout": proc.stdout.strip()[-400:], "progress_tail": progress[-6:]}
    if proc.returncode != 0:
        record["stderr_tail"] = proc.stderr.strip().splitlines()[-3:]
    print(f"[{label}] exit {proc.returncode}, {wall:.1f} s, peak {peak_kb / 1024 ** 2:.2f} GB", flush=True)
    return record


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
    (RESULTS / f"{args.results}.json").write_text(json.dumps(doc, indent=1) + "\n")
    print(json.dumps(doc, indent=1))
    return 0 if all(r["exit_code"] == 0 for r in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
