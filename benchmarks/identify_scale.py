"""`identify` on hour-long logs: peak memory and wall time against the length of the log.

Logs of the Panda at 1 kHz are simulated here with Pinocchio (``pin.rnea`` on a model built
from the description's numbers by ``tests/reference.py``, nothing shared with the
identification): a periodic multisine excitation (period 100 s, harmonics of 0.01 Hz, within
the joint limits), its rigid-body torques plus viscous friction and Gaussian torque noise
(0.05 N m, drawn afresh for every sample, so no two periods are alike).  One period's
dynamics are computed once and tiled (an excitation trajectory is replayed periodically on a
real robot too); the noise makes every sample distinct.

Runs, each ``identify --split 0.8`` with the default preprocessing (5 Hz zero-phase low-pass,
parallel filtering of the regressor columns and the torque, decimation by 25) in its own process
timed by ``/usr/bin/time -v`` (wall time, maximum resident set size):

* the in-memory peer, :func:`kindyngen.measured.identify.identify` of this commit (the whole
  stacked regressor in memory, the same preprocessing and filter), on the 10-minute CSV
  (``--baseline-root``: another checkout's ``kindyngen identify`` CLI instead);
* the streaming ``kindyngen identify`` on the 10-minute CSV, the 1-hour CSV and the 10-hour
  Parquet file; on the 10-minute log the largest relative difference of its base parameters
  from the in-memory peer's is recorded.

The 10-hour file (4 GB) is written in row groups while simulating, and deleted after its run;
so are the others.  Results: ``benchmarks/results/identify_scale.json`` and ``.png``.

    nice -n 10 python -m benchmarks.identify_scale [--baseline-root CHECKOUT] [--hours 1 10]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from kindyngen.json_text import strict_json

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
ROBOT = ROOT / "robots" / "panda.yaml"
RATE = 1000.0
PERIOD_S = 100.0
NOISE = 0.05
VISCOUS = np.array([0.8, 0.7, 0.6, 0.5, 0.3, 0.2, 0.1])


def _period():
    """One period of the excitation: q, qd, qdd and noise-free torques (100 000 samples)."""
    sys.path.insert(0, str(ROOT / "tests"))
    import pinocchio as pin
    from reference import pinocchio_model
    from kindyngen.readers.yaml_description import load_robot
    model = load_robot(ROBOT)
    pm, pd, _ = pinocchio_model(model)
    rng = np.random.default_rng(7)
    lo = np.array([j.lower for j in model.joints])
    hi = np.array([j.upper for j in model.joints])
    harmonics = rng.integers(5, 60, size=(7, 4))           # multiples of 0.01 Hz: 0.05 .. 0.6 Hz
    amp = rng.uniform(0.2, 1.0, size=(7, 4))
    amp *= (0.55 * (hi - lo) / 2 / amp.sum(axis=1))[:, None]
    phase = rng.uniform(0, 2 * np.pi, size=(7, 4))
    t = np.arange(int(PERIOD_S * RATE)) / RATE
    w = 2 * np.pi * harmonics / PERIOD_S
    arg = w[None] * t[:, None, None] + phase[None]
    q = (lo + hi) / 2 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    tau = np.array([pin.rnea(pm, pd, a, b, c) for a, b, c in zip(q, qd, qdd)]) + VISCOUS * qd
    return q, tau


def _blocks(seconds: float, period, seed: int):
    """(t, q, tau) blocks of one period each, noise drawn per block."""
    q, tau = period
    m = len(q)
    total = int(round(seconds * RATE))
    rng = np.random.default_rng(seed)
    for start in range(0, total, m):
        k = min(m, total - start)
        t = (start + np.arange(k)) / RATE
        yield t, q[:k], tau[:k] + rng.normal(0.0, NOISE, size=(k, 7))


def _names():
    return ["t"] + [f"q{i + 1}" for i in range(7)] + [f"tau{i + 1}" for i in range(7)]


def write_csv(path: Path, seconds: float, period, seed: int = 1) -> None:
    with open(path, "w") as handle:
        handle.write(",".join(_names()) + "\n")
        for t, q, tau in _blocks(seconds, period, seed):
            np.savetxt(handle, np.column_stack([t, q, tau]), delimiter=",", fmt="%.17g")


def write_parquet(path: Path, seconds: float, period, seed: int = 1) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq
    writer = None
    for t, q, tau in _blocks(seconds, period, seed):
        table = pa.table(dict(zip(_names(), [t] + list(q.T) + list(tau.T))))
        writer = writer or pq.ParquetWriter(path, table.schema)
        writer.write_table(table)
    writer.close()


def in_memory(log: str, out: str) -> int:
    """The in-memory peer: ``identify()`` (everything stacked), the CLI's summary line."""
    from kindyngen.measured.identify import IdentificationRequest, identify, write_outputs
    result = identify(IdentificationRequest(ROBOT, (log,), split=0.8),
                      lambda text: print(f"identify: {text}", file=sys.stderr, flush=True))
    write_outputs(result, out)
    print(strict_json({"rms_train": [round(float(v), 4) for v in result.rms_train],
                      "rms_validation": [round(float(v), 4) for v in result.rms_validation],
                      "rms_validation_sum": round(float(np.sum(result.rms_validation)), 4),
                      "physically_consistent": result.physically_consistent}))
    return 0


def run(label: str, code_root: Path, log: Path, out: Path, extra=(), peer: bool = False) -> dict:
    command = (["-m", "benchmarks.identify_scale", "--in-memory", str(log), str(out)] if peer else
               ["-m", "kindyngen", "identify", "--robot", str(ROBOT), "--data", str(log), "--split", "0.8",
                "--out", str(out), *extra])
    return measure(label, command, code_root, log, "identify:", 4)


def measure(label: str, command: list, code_root: Path, log: Path, progress_prefix: str, tail: int) -> dict:
    """Run ``python *command`` under ``/usr/bin/time -v`` from ``code_root``: wall and CPU time,
    peak resident memory, the load average around it, the last ``tail`` progress lines (those
    starting with ``progress_prefix``) and the output's end."""
    argv = ["/usr/bin/time", "-v", sys.executable, *command]
    env = dict(os.environ, PYTHONPATH=str(code_root))
    print(f"[{label}] {' '.join(argv[2:])}", flush=True)
    load_before = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    # cwd = the code's root: ``python -m`` puts the working folder before PYTHONPATH
    proc = subprocess.run(argv, env=env, capture_output=True, text=True, cwd=code_root)
    wall = time.perf_counter() - started
    peak_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr).group(1))
    cpu_s = sum(float(re.search(rf"{kind} time \(seconds\): ([\d.]+)", proc.stderr).group(1))
                for kind in ("User", "System"))
    progress = [line for line in proc.stderr.splitlines() if line.startswith(progress_prefix)]
    record = {"label": label, "log": log.name, "log_bytes": log.stat().st_size, "exit_code": proc.returncode,
              "wall_s": round(wall, 1), "cpu_s": round(cpu_s, 1), "peak_rss_gb": round(peak_kb / 1024 ** 2, 3),
              "load_average_before": load_before, "load_average_after": [round(x, 2) for x in os.getloadavg()],
              "stdout": proc.stdout.strip()[-400:], "progress_tail": progress[-tail:]}
    if proc.returncode != 0:
        # the command's own last lines, before /usr/bin/time's report
        record["stderr_tail"] = proc.stderr.split("\tCommand being timed")[0].strip().splitlines()[-3:]
    print(f"[{label}] exit {proc.returncode}, {wall:.1f} s, peak {peak_kb / 1024 ** 2:.2f} GB", flush=True)
    return record


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--baseline-root", type=Path, default=None,
                   help="a checkout of today's code (default: none, the baseline run is skipped)")
    p.add_argument("--hours", type=float, nargs="*", default=[1.0, 10.0])
    p.add_argument("--minutes-baseline", type=float, default=10.0,
                   help="length of the log the in-memory peer and the streaming code both run (0: skip both)")
    p.add_argument("--results", default="identify_scale", help="name of the results (.json, .png) in benchmarks/results")
    p.add_argument("--work", type=Path, default=None, help="folder for the logs (default: a temporary one)")
    p.add_argument("--in-memory", nargs=2, metavar=("LOG", "OUT"), help="run the in-memory peer alone (internal)")
    args = p.parse_args(argv)
    if args.in_memory:
        return in_memory(*args.in_memory)
    work = Path(tempfile.mkdtemp(prefix="identify_scale.", dir=args.work))
    cpu = next((line.split(":", 1)[1].strip() for line in subprocess.run(["lscpu"], capture_output=True,
                text=True).stdout.splitlines() if line.startswith("Model name")), platform.processor())
    records = []
    try:
        print("simulating one 100 s period with Pinocchio", flush=True)
        period = _period()
        short = work / "panda_10min.csv"
        if args.minutes_baseline > 0:
            write_csv(short, args.minutes_baseline * 60, period)
            if args.baseline_root is not None:
                records.append(run("other checkout, 10 min CSV", args.baseline_root, short, work / "out_base"))
            else:
                records.append(run("in-memory identify(), 10 min CSV", ROOT, short, work / "out_base", peer=True))
            records.append(run("streaming, 10 min CSV", ROOT, short, work / "out_10min"))
            peer, streamed = (json.loads((work / d / "identification.json").read_text())["base_params"]["values"]
                              for d in ("out_base", "out_10min"))
            records[-1]["base_params_max_relative_difference_from_peer"] = float(
                np.max(np.abs(np.subtract(streamed, peer))) / np.max(np.abs(peer)))
            short.unlink()
        for hours in args.hours:
            if hours <= 1:
                log = work / f"panda_{hours:g}h.csv"
                write_csv(log, hours * 3600, period)
            else:
                log = work / f"panda_{hours:g}h.parquet"
                write_parquet(log, hours * 3600, period)
            records.append(run(f"streaming, {hours:g} h {log.suffix[1:]}", ROOT, log, work / f"out_{hours:g}h"))
            log.unlink()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    doc = {"machine": {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
                       "memory_gb": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1024 ** 3, 1),
                       "note": "shared with other jobs: the load average (1, 5, 15 min) before and after is beside each "
                               "run, and its CPU time (user + system) beside its wall time"},
           "robot": "panda (robots/panda.yaml), 43 base columns", "rate_hz": RATE,
           "command": "kindyngen identify --split 0.8 (defaults: 5 Hz zero-phase low-pass, parallel filtering of "
                      "the regressor columns with the torque, decimation 25, OLS)",
           "runs": records}
    from kindyngen.output_folder import replace_files

    def both(folder):          # the JSON and its figure, both or neither
        (folder / f"{args.results}.json").write_text(strict_json(doc, indent=1) + "\n")
        _plot(doc, folder / f"{args.results}.png")
    replace_files(RESULTS, both)
    return 0


def _plot(doc, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs = doc["runs"]
    labels = [r["label"] for r in runs]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    colors = ["tab:blue" if r["label"].startswith("streaming") else "tab:red" for r in runs]
    axes[0].barh(labels, [r["peak_rss_gb"] for r in runs], color=colors)
    axes[0].set_xlabel("peak resident memory (GB)")
    axes[1].barh(labels, [r["wall_s"] for r in runs], color=colors)
    axes[1].set_xlabel("wall time (s)")
    for ax in axes:
        ax.invert_yaxis()
    axes[1].set_yticklabels([])
    fig.suptitle(f"identify, Panda at 1 kHz, --split 0.8 ({doc['machine']['cpu']}, {doc['machine']['cores']} cores)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
