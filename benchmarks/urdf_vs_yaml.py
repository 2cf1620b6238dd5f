"""The Panda from its URDF and from ``robots/panda.yaml``: operation counts and generation
time side by side (``python -m benchmarks.urdf_vs_yaml [--repeats 3] [--out DIR]``, writes
``results/urdf_vs_yaml.json``).

The pair (``tests/robot_files.py``, which says why it is one arm) describes the same arm in
the same frames: example-robot-data's ``panda.urdf`` without the hand, and ``robots/panda.yaml``
with the URDF's flange offset as its ``tool``; ``tests/readers/test_urdf_panda.py`` checks they agree."""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from kindyngen.json_text import strict_json

from .common import RESULTS, machine

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from robot_files import example_robot_data, panda_arm_urdf, panda_yaml_with_tool  # noqa: E402,F401
# (the pair is the tests'; example_robot_data is also what benchmarks/trees.py and tree_scaling.py import from here)


def _timed_counts(loads: dict, repeats: int):
    """{name: (op counts after CSE, seconds of each timed run)} for each description loader; one
    untimed warm-up run first (imports, caches), then the descriptions alternate, so that
    neither pays for going first."""
    from kindyngen.codegen.pipeline import build_programs
    for load in loads.values():
        build_programs(load(), progress=False)
    seconds = {name: [] for name in loads}
    counts = {}
    for _ in range(repeats):
        for name, load in loads.items():
            start = time.perf_counter()
            programs = build_programs(load(), progress=False)
            seconds[name].append(time.perf_counter() - start)
            counts[name] = {p.function.name: p.after.to_json() for p in programs}
    return {name: (counts[name], seconds[name]) for name in loads}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.urdf_vs_yaml", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed generation runs per description (median)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="results folder")
    args = parser.parse_args(argv)
    from kindyngen.readers.yaml_description import load_robot, parse_robot
    with tempfile.TemporaryDirectory() as tmp:
        urdf_path = panda_arm_urdf(Path(tmp))
        data = panda_yaml_with_tool()
        # loading is part of generation: each run reads its description again
        timed = _timed_counts({"urdf": lambda: load_robot(urdf_path, tip="panda_link8"),
                               "yaml": lambda: parse_robot(data, "panda.yaml")}, args.repeats)
        (urdf_counts, urdf_runs), (yaml_counts, yaml_runs) = timed["urdf"], timed["yaml"]
    urdf_time, yaml_time = statistics.median(urdf_runs), statistics.median(yaml_runs)
    result = {"machine": machine(), "repeats": args.repeats,
              "generation_seconds": {"urdf": round(urdf_time, 2), "yaml": round(yaml_time, 2)},
              "generation_seconds_runs": {"urdf": [round(t, 2) for t in urdf_runs],
                                          "yaml": [round(t, 2) for t in yaml_runs]},
              "opcounts_after_cse": {name: {"urdf": urdf_counts[name], "yaml": yaml_counts[name]}
                                     for name in yaml_counts}}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "urdf_vs_yaml.json").write_text(strict_json(result, indent=1) + "\n")
    print(f"generation (all functions, median of {args.repeats}): URDF {urdf_time:.2f} s, YAML {yaml_time:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
