"""Paths, the generated functions' manifest, the machine description and the one summary
statistic every timing source reports (median, min, max of the per-call time over repeats)."""
from __future__ import annotations

import json
import os
import platform
import statistics
from pathlib import Path

from .build import compiler_version

ROOT = Path(__file__).resolve().parents[1]
GENERATED = ROOT / "generated"
ROBOTS = ROOT / "robots"
RESULTS = Path(__file__).resolve().parent / "results"


def manifest(robot_dir: Path) -> dict | None:
    """generated/<robot>/functions.json, or None when that robot is not generated (yet)."""
    path = robot_dir / "functions.json"
    if not path.exists():
        return None
    return json.loads(path.read_text())


def summary(per_call_ns) -> dict:
    values = sorted(float(v) for v in per_call_ns)
    return {"median_ns": statistics.median(values), "min_ns": values[0], "max_ns": values[-1]}


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def cpu_identity() -> dict:
    """The core's family and model numbers and its widest vector extension, from /proc/cpuinfo
    (the model name alone, "AMD EPYC", does not tell Zen 4 from Zen 5: family 25 from 26), or {}."""
    try:
        fields = {}
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if not line.strip():
                break                                # the first core's block
            key, _, value = line.partition(":")
            fields[key.strip()] = value.strip()
        flags = set(fields.get("flags", "").split())
        vector = next((v for v in ("avx512f", "avx2", "avx", "sse2") if v in flags), "none")
        return {"cpu_family": int(fields["cpu family"]), "cpu_model_number": int(fields["model"]), "vector": vector}
    except (OSError, KeyError, ValueError):
        return {}


def machine() -> dict:
    import casadi
    import numpy
    info = {"cpu": cpu_model(), **cpu_identity(), "cores": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), "numpy": numpy.__version__,
            "casadi": casadi.__version__, "gcc": compiler_version("gcc"), "g++": compiler_version("g++")}
    try:
        import pinocchio
        info["pinocchio"] = pinocchio.__version__
    except ImportError:
        info["pinocchio"] = "unavailable"
    return info
