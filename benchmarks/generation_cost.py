"""What deriving and optimising each function costs against the robot's size: the measurements
behind the estimate and the limits of kindyngen/codegen/budget.py (``python -m
benchmarks.generation_cost [--quick] [--chains 7,10,...] [--trees 2,4,...] [--functions a,b]
[--timeout S] [--out DIR]``, writes ``results/generation_cost.json``).

Chains of n revolute joints written as YAML descriptions (:func:`chain_description`: joints by
origin and axis, the axes turning x, y, z, lengths and masses shrinking along the chain, full
inertia tensors) get every function of the catalog; trees with four limbs and a floating base
(:func:`benchmarks.tree_scaling.synthetic_tree`) the world-frame derivatives, which only they
get. Each function at each size runs in a fresh process (``--jobs`` functions at a time) under a CPU-time limit (``--cpu-s``,
RLIMIT_CPU) and an address-space limit (``--memory-gb``), and reports its CPU seconds
(derivation + CSE, this process only: the steadier measure on a shared machine), and the growth
of its peak resident memory over what it held before deriving (VmHWM, reset then through
/proc/self/clear_refs, less VmRSS; Linux). A function
stops growing at the first size it does not finish within those limits, which budget.py
records as a size it fails at. A wall-clock guard (an hour) only stops a process that hangs.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import yaml

from .common import RESULTS, machine

CHAINS = (7, 14, 20, 29, 40)
TREES = (2, 4, 6, 8)                 # joints per limb: nv 14, 22, 30, 38
TREE_FUNCTIONS = ("tau_derivatives", "fd_derivatives", "fd_derivatives_no_minv")
CPU_S = 90.0                         # 1.5 times budget.CPU_LIMIT_S: sizes past the limit are measured too
MEMORY_GB = 6.0
HANG_GUARD_S = 3600.0
_AXES = ((1, 0, 0), (0, 1, 0), (0, 0, 1))


def chain_description(n: int) -> dict:
    """A chain of ``n`` revolute joints as a YAML description (``dh: none``): the axes turn x,
    y, z in turn, link lengths from 0.3 m shrinking by 3 % a joint, every other origin 1 cm off
    the axis, masses from 4 kg shrinking by 5 %, full inertia tensors.

    >>> d = chain_description(3)
    >>> [j["axis"] for j in d["joints"]], d["links"][1]["mass"]
    ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], 3.8)
    """
    joints, links = [], []
    for i in range(n):
        length = round(0.3 * 0.97 ** i, 4)
        joints.append({"origin": {"xyz": [0.01 * (i % 2), 0, length if i else 0.1]}, "axis": list(_AXES[i % 3]),
                       "lower": -2.5, "upper": 2.5})
        mass = round(4.0 * 0.95 ** i, 4)
        links.append({"mass": mass, "com": [0.003, -0.002, round(0.45 * length, 4)],
                      "inertia": [round(mass * 0.01, 5), round(mass * 0.012, 5), round(mass * 0.005, 5),
                                  0.0001, -0.0001, 0.00005]})
    return {"name": f"chain{n}", "dh": "none", "gravity": [0, 0, -9.81], "joints": joints, "links": links}


def write_chain(n: int, folder: Path) -> Path:
    """:func:`chain_description` written as ``folder/chain<n>.yaml``."""
    path = Path(folder) / f"chain{n}.yaml"
    path.write_text(yaml.safe_dump(chain_description(n), sort_keys=False, default_flow_style=None))
    return path


def _model(kind: str, size: int, folder: Path):
    if kind == "chain":
        from kindyngen.readers.yaml_description import load_robot
        return load_robot(Path(folder) / f"chain{size}.yaml")
    from .tree_scaling import synthetic_tree
    return synthetic_tree(4, size, floating=True)


def measure_here(kind: str, size: int, name: str, folder: Path, cpu_s: float, memory_gb: float) -> dict:
    """One measurement in this process (a fresh one: ``--one``), under the CPU-time and
    address-space limits: its row."""
    from kindyngen.codegen.catalog import derive
    from kindyngen.codegen.optimize import optimize
    model = _model(kind, size, folder)
    resource.setrlimit(resource.RLIMIT_AS, (int(memory_gb * 2 ** 30), resource.RLIM_INFINITY))
    used = time.process_time()
    resource.setrlimit(resource.RLIMIT_CPU, (int(used + cpu_s), int(used + cpu_s) + 10))
    Path("/proc/self/clear_refs").write_text("5")       # the peak (VmHWM) from here on
    before = _status_kb("VmRSS")
    start = time.process_time()
    program = optimize(derive(model, name))
    cpu = time.process_time() - start
    peak = _status_kb("VmHWM")
    return {"nv": model.nv, "cpu_s": round(cpu, 3), "peak_mb": round(max(peak - before, 0) / 1024, 1),
            "ops": program.after.add + program.after.mul}


def _status_kb(field: str) -> int:
    """A memory field of /proc/self/status (kB): VmRSS now, VmHWM the peak since the last reset."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise OSError(f"/proc/self/status has no {field}")


def measure(kind: str, size: int, name: str, folder: Path, cpu_s: float, memory_gb: float) -> dict:
    """One measurement in a fresh process: its row, or ``{"failed": why}``."""
    command = [sys.executable, "-m", "benchmarks.generation_cost", "--one", kind, str(size), name, str(folder),
               "--cpu-s", str(cpu_s), "--memory-gb", str(memory_gb)]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=HANG_GUARD_S)
    except subprocess.TimeoutExpired:
        return {"failed": f"hung: not finished in {HANG_GUARD_S:.0f} s"}
    if done.returncode == 0:
        return json.loads(done.stdout.strip().splitlines()[-1])
    if done.returncode in (-signal.SIGXCPU, -signal.SIGKILL):
        return {"failed": f"more than {cpu_s:g} s CPU"}
    if "MemoryError" in done.stderr:
        return {"failed": f"more than {memory_gb:g} GB"}
    return {"failed": f"exit {done.returncode}: {done.stderr.strip().splitlines()[-1:]}"[:300]}


def study(kind: str, sizes, names, folder: Path, cpu_s: float, memory_gb: float, jobs: int, log) -> dict:
    """{name: {"rows": [...], "failed": {"size": nv, "why": ...} or None}}: each function's
    sizes in turn, ``jobs`` functions at a time."""
    def one(name):
        entry = {"rows": [], "failed": None}
        for size in sizes:
            row = measure(kind, size, name, folder, cpu_s, memory_gb)
            if "failed" in row:
                entry["failed"] = {"size": _model(kind, size, folder).nv, "why": row["failed"]}
                log(f"generation_cost: {kind} {size} {name}: {row['failed']}")
                break
            entry["rows"].append(row)
            log(f"generation_cost: {kind} {size} {name}: {row['cpu_s']:.2f} s CPU, {row['peak_mb']:.0f} MB, "
                f"{row['ops']} add + mul")
        return entry

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return dict(zip(names, pool.map(one, names)))


def table(result: dict) -> str:
    """The measurements of ``result`` (results/generation_cost.json) as the ``COSTS`` literal of
    kindyngen/codegen/budget.py (a tree's derivatives under ``<name> (world frame)``)."""
    lines = ["COSTS: dict[str, Measured] = {"]
    for kind, suffix in (("chain", ""), ("tree", " (world frame)")):
        for name, entry in result[kind].items():
            rows, failed = entry["rows"], entry["failed"]
            fields = [f"sizes={tuple(r['nv'] for r in rows)!r}", f"cpu_s={tuple(r['cpu_s'] for r in rows)!r}",
                      f"peak_mb={tuple(r['peak_mb'] for r in rows)!r}"]
            if failed:
                fields += [f"failed={failed['size']}", f"why={failed['why']!r}"]
            lines.append(f"    {name + suffix!r}: Measured({', '.join(fields)}),")
    return "\n".join(lines + ["}"])


def margins(result: dict) -> list[tuple]:
    """How far budget.power_law's estimate is from a measurement it was not given: for each
    function and each measured size past the second, the estimate from the smaller sizes alone
    (an extrapolation, as for a robot larger than any measured) against the measurement:
    (kind, name, nv, measured / estimated CPU, measured / estimated peak memory), for sizes
    measured at 1 s CPU or more and 20 MB or more respectively (None below: noise)."""
    from kindyngen.codegen.budget import power_law
    out = []
    for kind in ("chain", "tree"):
        for name, entry in result[kind].items():
            rows = entry["rows"]
            for k in range(2, len(rows)):
                sizes = tuple(r["nv"] for r in rows[:k])
                cpu = power_law(sizes, tuple(r["cpu_s"] for r in rows[:k]), rows[k]["nv"])
                mb = power_law(sizes, tuple(r["peak_mb"] for r in rows[:k]), rows[k]["nv"])
                out.append((kind, name, rows[k]["nv"],
                            rows[k]["cpu_s"] / cpu if rows[k]["cpu_s"] >= 1 else None,
                            rows[k]["peak_mb"] / mb if rows[k]["peak_mb"] >= 20 else None))
    return out


def report(result: dict) -> str:
    """:func:`table` and a summary of :func:`margins` (the worst under- and over-estimates)."""
    rows = margins(result)
    text = [table(result), ""]
    for column, what in ((3, "CPU"), (4, "peak memory")):
        ratios = sorted((r[column], r[:3]) for r in rows if r[column] is not None)
        if ratios:
            text.append(f"# {what}: measured / extrapolated from the smaller sizes, over {len(ratios)} cases: "
                        f"{ratios[0][0]:.2f} ({' '.join(map(str, ratios[0][1]))}) to {ratios[-1][0]:.2f} "
                        f"({' '.join(map(str, ratios[-1][1]))}); median {ratios[len(ratios) // 2][0]:.2f}")
    return "\n".join(text)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--chains", default=",".join(map(str, CHAINS)), help="chain sizes (joints)")
    parser.add_argument("--trees", default=",".join(map(str, TREES)), help="joints per limb of the 4-limb trees")
    parser.add_argument("--functions", default=None, help="only these functions (default: every one)")
    parser.add_argument("--cpu-s", type=float, default=CPU_S, help="CPU seconds one measurement may take")
    parser.add_argument("--memory-gb", type=float, default=MEMORY_GB, help="address space of one measurement")
    parser.add_argument("--quick", action="store_true", help="chains of 3 and 5 joints, trees of 1 per limb")
    parser.add_argument("--jobs", type=int, default=1, help="functions measured at the same time (processes)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--table", action="store_true",
                        help="measure nothing: print results/generation_cost.json as budget.py's COSTS, with "
                             "how far an extrapolation from the smaller sizes was from each measurement")
    parser.add_argument("--one", nargs=4, metavar=("KIND", "SIZE", "NAME", "FOLDER"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.table:
        print(report(json.loads((args.out / "generation_cost.json").read_text())))
        return 0
    if args.one:                              # one measurement, in this fresh process
        kind, size, name, folder = args.one
        print(json.dumps(measure_here(kind, int(size), name, Path(folder), args.cpu_s, args.memory_gb)))
        return 0
    from kindyngen.codegen.catalog import BUILDERS
    from tempfile import TemporaryDirectory
    chains = (3, 5) if args.quick else tuple(int(s) for s in args.chains.split(","))
    trees = (1,) if args.quick else tuple(int(s) for s in args.trees.split(","))
    # every function a chain can get but the closed-form IK (fixed at 7 joints: nothing to grow);
    # the loop functions are a closed mechanism's, not a chain's
    names = [n for n, _ in BUILDERS if n not in ("ik_hom", "ik_dq")]
    if args.functions:
        names = [n for n in names if n in args.functions.split(",")]
    log = lambda text: print(text, file=sys.stderr, flush=True)
    with TemporaryDirectory() as folder:
        for n in chains:
            write_chain(n, Path(folder))
        result = {"machine": machine(), "load_average": os.getloadavg(), "chains": list(chains),
                  "trees_per_limb": list(trees), "cpu_s": args.cpu_s, "memory_gb": args.memory_gb, "jobs": args.jobs,
                  "chain": study("chain", chains, names, Path(folder), args.cpu_s, args.memory_gb, args.jobs, log),
                  "tree": study("tree", trees, [n for n in TREE_FUNCTIONS if n in names], Path(folder),
                                args.cpu_s, args.memory_gb, args.jobs, log)}
    result["load_average_after"] = os.getloadavg()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "generation_cost.json").write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
