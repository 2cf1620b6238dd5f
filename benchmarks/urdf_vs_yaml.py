"""The Panda from its URDF and from ``robots/panda.yaml``: operation counts and generation
time side by side (``python -m benchmarks.urdf_vs_yaml [--repeats 3] [--out DIR]``, writes
``results/urdf_vs_yaml.json``).

The pair describes the same arm in the same frames: example-robot-data's ``panda.urdf``
without the hand (joints and links named ``*hand*``, ``*finger*`` removed), chain from
``panda_link0`` to ``panda_link8``; and the modified-DH table of ``robots/panda.yaml`` with
the URDF's 0.107 m flange offset as its ``tool``. The Franka URDF's link frames are the DH
frames and both use the same identified inertial parameters (Gaz et al. 2019), so the two
models must give the same kinematics and dynamics (``tests/test_urdf_panda.py``)."""
from __future__ import annotations

import argparse
import importlib.metadata
import json
import statistics
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

from .common import RESULTS, machine

ROOT = Path(__file__).resolve().parents[1]
TOOL = {"xyz": [0, 0, 0.107]}      # panda_joint8: link7 -> link8 (the flange)


def example_robot_data() -> Path:
    """The robots folder of the installed example-robot-data wheel (a test extra)."""
    dist = importlib.metadata.distribution("example-robot-data")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def panda_arm_urdf(folder: Path) -> Path:
    """example-robot-data's panda.urdf without the hand, written to ``folder``."""
    tree = ET.parse(example_robot_data() / "panda_description" / "urdf" / "panda.urdf")
    robot = tree.getroot()
    for element in list(robot):
        if element.tag in ("link", "joint") and any(k in element.get("name", "") for k in ("hand", "finger")):
            robot.remove(element)
    path = folder / "panda_arm.urdf"
    tree.write(path)
    return path


def panda_pair(folder: Path):
    """(model from the URDF, model from the YAML with the flange tool)."""
    from kindyngen.robot import load_robot, parse_robot
    urdf = load_robot(panda_arm_urdf(folder), tip="panda_link8")
    data = yaml.safe_load((ROOT / "robots" / "panda.yaml").read_text())
    data["tool"] = TOOL
    return urdf, parse_robot(data, "robots/panda.yaml + tool")


def _timed_counts(loads: dict, repeats: int):
    """{name: (op counts after CSE, seconds of each timed run)} for each description loader; one
    untimed warm-up run first (imports, caches), then the descriptions alternate, so that
    neither pays for going first."""
    from kindyngen.pipeline import build_programs
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
    from kindyngen.robot import load_robot, parse_robot
    with tempfile.TemporaryDirectory() as tmp:
        urdf_path = panda_arm_urdf(Path(tmp))
        data = yaml.safe_load((ROOT / "robots" / "panda.yaml").read_text())
        data["tool"] = TOOL
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
    (args.out / "urdf_vs_yaml.json").write_text(json.dumps(result, indent=1) + "\n")
    print(f"generation (all functions, median of {args.repeats}): URDF {urdf_time:.2f} s, YAML {yaml_time:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
