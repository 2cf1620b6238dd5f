"""End-to-end smoke test of the benchmark pipeline in its --quick setting: it runs, writes
timings.json in the documented schema, and the report renders. No assertion on any time:
benchmarks are measurements, not tests; the subprocesses' timeout is a hang guard only
(HANG_GUARD_S: on a loaded 2-core machine --quick took over the 45 s it once had)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.harness import HANG_GUARD_S

ROOT = Path(__file__).resolve().parents[2]
STATS = {"median_ns", "min_ns", "max_ns"}


def _run(*args: str) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=HANG_GUARD_S)
    assert done.returncode == 0, f"{' '.join(args)} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


@pytest.mark.skipif(not (ROOT / "generated" / "lwr4" / "functions.json").exists(),
                    reason="generated/lwr4 missing: run `make generate`")
def test_bench_quick_and_report(tmp_path):
    run = _run("benchmarks.run", "--quick", "--out", str(tmp_path))
    assert "Pinocchio C++ skipped" in run.stdout  # quick mode says so

    timings = json.loads((tmp_path / "timings.json").read_text())
    assert {"machine", "date", "functions", "ratios"} <= timings.keys()
    assert {"cpu", "cores", "gcc"} <= timings["machine"].keys()
    manifest = json.loads((ROOT / "generated" / "lwr4" / "functions.json").read_text())
    assert {f["name"] for f in manifest["functions"]} == set(timings["functions"])
    for name, per_impl in timings["functions"].items():
        assert {"c", "python", "python_batch", "casadi", "casadi_codegen"} <= per_impl.keys(), name
        for impl, stats in per_impl.items():
            assert STATS <= stats.keys(), (name, impl)
            assert 0 < stats["min_ns"] <= stats["median_ns"] <= stats["max_ns"], (name, impl)
    for name, ratios in timings["ratios"].items():
        assert all(key.startswith("pinocchio_cpp/") for key in ratios), name
    # Each implementation was checked against the generated numpy code on one input.
    for impl, per_function in timings["checks"].items():
        assert all(error is not None and error <= 1e-6 for error in per_function.values()), (impl, per_function)

    _run("benchmarks.report", "--results", str(tmp_path), "--out", str(tmp_path))
    for name in ("report.md", "report.json", "fig1_times.png", "peers.png", "scaling.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    report = (tmp_path / "report.md").read_text()
    assert "Table II" in report and "40 / 87 / 14" in report


def test_machine_code_reads_each_function(tmp_path):
    """benchmarks.latency.machine_code against a C file whose functions' memory traffic is
    known: one load-free register function, one with two loads and a store; batch variants are
    left out."""
    import platform
    import shutil
    from benchmarks.latency import machine_code
    if platform.machine() not in ("x86_64", "AMD64") or not (shutil.which("gcc") and shutil.which("objdump")):
        pytest.skip("machine_code reads x86-64 objects with gcc and objdump")
    source = tmp_path / "r.c"
    source.write_text("double r_sq(double x) { return x * x; }\n"
                      "void r_mul(const double *x, double *y) { y[0] = x[0] * x[1]; }\n"
                      "void r_mul_batch(const double *x, double *y) { y[0] = x[0] + x[1]; }\n")
    shape = machine_code(source, "r", ["-O2"], tmp_path / "obj")
    assert set(shape) == {"sq", "mul"}
    assert shape["sq"]["memory_operands"] == 0 and shape["sq"]["instructions"] >= 2     # mulsd, ret
    assert shape["mul"]["memory_operands"] == 3 and shape["mul"]["instructions"] >= 4   # 2 loads, 1 store
    assert all(0 < s["bytes"] for s in shape.values())
