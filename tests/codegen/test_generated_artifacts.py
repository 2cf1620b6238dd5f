"""The committed generated/ tree (its reproducibility: tests/integration/test_reproducibility.py): C that
compiles cleanly, headers that say what they compute, operation counts under the kinematics paper's bars."""
import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from kindyngen.codegen import trig_kernel
from kindyngen.codegen.optimize import IN_PLACE_BOUND
from tests.harness import GENERATED, ROOT

ROBOTS = ("lwr4", "lwr4_hartl", "panda")
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_c_compiles_strictly(robot, compiler, tmp_path):
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} not installed")
    c_dir = GENERATED / robot / "c"
    done = subprocess.run([compiler, *STRICT, "-O2", "-c", str(c_dir / f"{robot}.c"), "-o", str(tmp_path / "x.o")],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_mex_gateway_compiles_strictly(robot, compiler):
    """The MEX gateway against Octave's mex.h (a system header: its own warnings are not the
    gateway's); the gateway itself as strict as the C."""
    mkoctfile = shutil.which("mkoctfile")
    if shutil.which(compiler) is None or mkoctfile is None:
        pytest.skip(f"{compiler} or mkoctfile (GNU Octave's headers) not installed")
    flags = subprocess.run([mkoctfile, "-p", "INCFLAGS"], capture_output=True, text=True, check=True).stdout.split()
    done = subprocess.run([compiler, *STRICT, "-fsyntax-only", *(f"-isystem{f[2:]}" for f in flags),
                           "-I", str(GENERATED / robot / "c"), str(GENERATED / robot / "matlab" / f"{robot}_mex.c")],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("robot", ROBOTS)
def test_c_builds_with_cmake(robot, tmp_path):
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed")
    build = tmp_path / "build"
    subprocess.run(["cmake", "-S", str(GENERATED / robot / "c"), "-B", str(build)], check=True, capture_output=True)
    subprocess.run(["cmake", "--build", str(build)], check=True, capture_output=True)


@pytest.mark.parametrize("robot", ROBOTS)
def test_c_has_no_globals_or_allocation(robot):
    source = (GENERATED / robot / "c" / f"{robot}.c").read_text()
    for forbidden in ("malloc", "calloc", "free("):
        assert forbidden not in source
    # the one static thing allowed is the sincos kernel's functions (kindyngen/codegen/trig_kernel.py)
    def statics_of(text):
        return [line for line in text.splitlines() if line.startswith("static ")]
    kernel = statics_of(trig_kernel.kernel_c())
    assert kernel[-1] == "static void kdg_sincos(long n, const double *restrict x, double *restrict s, double *restrict c)"
    # the loop over blocks, or the split kernel alone, as the calls need them (render._kernels); the
    # same of the half-angle variant where single calls read half angles in place (optimize.half_angles)
    plain = [statics_of(trig_kernel.kernel_c(blocks=blocks)) for blocks in (True, False)]
    half = [statics_of(trig_kernel.kernel_c("kdg_sincos_half", half=True, blocks=blocks)) for blocks in (True, False)]
    # the batch variants' one loop over a block's arguments (trig_kernel.batch_kernel_c)
    batch = statics_of(trig_kernel.batch_kernel_c())
    # and, inside functions, read-only tables (re-entrant): the derivatives' lane programs' seeds,
    # the batches' constant output entries and the entries they copy
    tables = re.compile(r"^ +static const (double|int) (kdg_seed|entry|value)\[")
    statics = [line for line in source.splitlines() if "static " in line and not tables.match(line)]
    assert statics in [a + b + c for a in plain + [[]] for b in half + [[]] for c in (batch, [])]
    # each printed where a call uses it
    calls = source[source.index("\nvoid "):]                 # the generated functions
    assert any(s in statics for s in half[1]) is ("kdg_sincos_half" in calls)
    assert any(s in statics for s in plain[1]) is bool(re.search(r"kdg_sincos(_split)?\(", calls))
    assert (batch[0] in statics) is ("kdg_sincos_batch(" in calls)
    # every statement lives inside a function body: nothing at file scope but includes, the
    # -ffast-math guard and functions (the int one: <robot>_rounds_to_nearest)
    depth, file_scope = 0, []
    for line in source.splitlines():
        if depth == 0 and line.strip() and not line.startswith(("#", "/*", " *", "void ", "int ", "static void ", "static int ",
                                                                 "{", "}")):
            file_scope.append(line)
        depth += line.count("{") - line.count("}")
    assert file_scope == []


@pytest.mark.parametrize("robot", ROBOTS)
def test_headers_state_conventions_units_and_costs(robot):
    header = (GENERATED / robot / "c" / f"{robot}.h").read_text()
    manifest = json.loads((GENERATED / robot / "functions.json").read_text())
    for f in manifest["functions"]:
        assert f"void {f['c_symbol']}(" in header
        if f.get("kind") == "iterative":  # costs per iteration instead (tests/ik/test_ik_dls.py)
            assert "per_iteration" in f["opcount"] and "Cost per iteration:" in header
            continue
        after = f["opcount"]["after"]
        assert f"Cost: {after['add']} add, {after['mul']} mul, {after['call']} call" in header
    counts = json.loads((GENERATED / robot / "opcounts.json").read_text())
    for name, entry in counts.items():
        if "per_iteration" not in entry:
            assert f"critical path {entry['critical_path']['cycles']} cycles" in header, name
    assert "row-major" in header and "rad" in header and "Gravity in the base frame" in header


def test_opcounts_json_schema_and_paper_bars():
    counts = json.loads((GENERATED / "lwr4" / "opcounts.json").read_text())
    for name, entry in counts.items():
        # a function derived by several routes (fd: L^T D L and articulated body) also records
        # each route's count and which one was kept: the one with the fewest add + mul
        # a function whose C single call is a lane program (the derivatives) records its counts
        assert set(entry) in ({"before", "after", "critical_path"},
                              {"before", "after", "critical_path", "route", "routes"},
                              {"before", "after", "critical_path", "c_lanes"}), name
        if "c_lanes" in entry:
            assert set(entry["c_lanes"]) == {"lanes", "used", "uniform", "per_lane", "executed", "critical_path"}
        if "routes" in entry:
            kept = entry["routes"][entry["route"]]
            assert (kept["add"], kept["mul"]) == (entry["after"]["add"], entry["after"]["mul"])
            # the fewest operations, or within optimize.IN_PLACE_BOUND of them (a route reading q in place)
            fewest = min(r["add"] + r["mul"] for r in entry["routes"].values())
            numerator, denominator = IN_PLACE_BOUND
            assert (kept["add"] + kept["mul"]) * denominator <= fewest * numerator
        for stage in (entry["before"], entry["after"]):
            assert set(stage) == {"add", "mul", "call"}
        assert set(entry["critical_path"]) == {"cycles", "operations"}
    # Kinematics paper, Table II, Maple-optimised: FK homogeneous 40/87/14, dual quaternion 38/88/14
    hom, dq = counts["fk_hom"]["after"], counts["fk_dq"]["after"]
    assert (hom["add"], hom["mul"], hom["call"]) <= (40, 87, 14) and hom["add"] <= 40 and hom["mul"] <= 87
    # fk_dq's cheapest route is under the paper's count in every kind; the route kept, whose
    # sin/cos arguments are halves of joint angles only (optimize.IN_PLACE_BOUND), may cost a few
    # more additions (the addition formulas), never more operations in all than the paper's
    sums = counts["fk_dq"]["routes"]["sum angles"]
    assert sums["add"] <= 38 and sums["mul"] <= 88 and sums["call"] <= 14
    assert counts["fk_dq"]["route"] == "half angles"
    assert dq["add"] + dq["mul"] <= 38 + 88 and dq["mul"] <= 88 and dq["call"] <= 14


def test_eval_command_round_trip():
    q = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7]
    outputs = {}
    for lang in ("c", "python", "casadi"):
        done = subprocess.run([sys.executable, "-m", "kindyngen", "eval", str(GENERATED / "lwr4"), "fk_hom",
                               "--lang", lang], input=json.dumps({"q": q}), capture_output=True, text=True,
                              cwd=ROOT, check=True)
        outputs[lang] = np.array(json.loads(done.stdout)["T"])
    assert outputs["c"].shape == (4, 4)
    np.testing.assert_allclose(outputs["c"], outputs["python"], atol=1e-14)
    np.testing.assert_allclose(outputs["casadi"], outputs["python"], atol=1e-14)
    batch = subprocess.run([sys.executable, "-m", "kindyngen", "eval", str(GENERATED / "lwr4"), "fk_hom"],
                           input=json.dumps({"q": [q, q, q]}), capture_output=True, text=True, cwd=ROOT, check=True)
    assert np.array(json.loads(batch.stdout)["T"]).shape == (3, 4, 4)


def test_eval_rejects_bad_requests_clearly():
    bad = [({"q": [0.1, 0.2]}, "has shape [2]; expected [7]"), ({}, "missing input 'q'"),
           ({"q": [0] * 7, "x": 1}, "unknown input")]
    for payload, message in bad:
        done = subprocess.run([sys.executable, "-m", "kindyngen", "eval", str(GENERATED / "lwr4"), "fk_hom"],
                              input=json.dumps(payload), capture_output=True, text=True, cwd=ROOT)
        assert done.returncode == 2 and message in done.stderr, done.stderr
    done = subprocess.run([sys.executable, "-m", "kindyngen", "eval", str(GENERATED / "lwr4"), "nope"],
                          input="{}", capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2 and "no function 'nope'" in done.stderr


@pytest.mark.parametrize("command", [[], ["generate"], ["count"], ["eval"], ["identify"], ["excite"], ["discover"], ["reproduce-identification"]])
def test_every_command_has_help(command):
    done = subprocess.run([sys.executable, "-m", "kindyngen", *command, "--help"], capture_output=True, text=True,
                          cwd=ROOT)
    assert done.returncode == 0 and "usage:" in done.stdout
