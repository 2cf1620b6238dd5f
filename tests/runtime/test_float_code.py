"""--scalar float C (and the function set / batch options) against independent references:
the numpy double module of the same robot, the correctly rounded sin/cos, exact rationals;
then the same code on emulated Cortex-M4F and Cortex-M7 boards (QEMU) against the host."""
import json
import random
import subprocess
from fractions import Fraction

import numpy as np
import pytest

from kindyngen.codegen import trig_kernel
from kindyngen.runtime import embedded
from kindyngen.runtime.evaluate import load_generated
from kindyngen.codegen.float32 import c_float, nearest_float32
from kindyngen.readers.yaml_description import load_robot
from kindyngen.codegen.pipeline import generate

FUNCTIONS = {"fk_hom", "fk_dq", "jacobian", "M", "tau", "fd", "ik_hom", "Y_m"}
ROBOTS = ("lwr4", "panda")


@pytest.fixture(scope="session")
def generated(tmp_path_factory):
    """lwr4 and panda, FUNCTIONS only, without batch variants: float C (+ its Python module,
    the double reference) and double C."""
    root = tmp_path_factory.mktemp("float_code")
    out = {}
    for robot in ROBOTS:
        model = load_robot(f"robots/{robot}.yaml")
        out[robot, "float"] = generate(model, root / "float", ("c", "python"), progress=False, only=FUNCTIONS,
                                       scalar="float", batch=False)
        out[robot, "double"] = generate(model, root / "double", ("c",), progress=False, only=FUNCTIONS, batch=False)
        out[robot, "model"] = model
    return out


def test_nearest_float32_is_the_nearest():
    """Exact rationals rounded once: no float is nearer (checked against both neighbours with
    exact arithmetic), ties to even."""
    rng = random.Random(3)
    for _ in range(3000):
        x = Fraction(rng.randrange(1, 10 ** 30), rng.randrange(1, 10 ** 30)) * Fraction(2) ** rng.randrange(-60, 60)
        f = nearest_float32(x)
        for g in (np.nextafter(f, np.float32(0)), np.nextafter(f, np.float32(np.inf))):
            assert abs(Fraction(float(f)) - x) <= abs(Fraction(float(g)) - x)
        assert np.float32(c_float(x)[:-1]) == f
    assert float(nearest_float32(Fraction(2 ** 24 + 3))) == 2 ** 24 + 4       # tie to even


def test_float_kernel_constants_recomputed():
    """The written-out float constants are what the fit and the split of pi/2 give."""
    parts, two_over_pi = trig_kernel.split_pio2_float()
    assert parts == trig_kernel.FLOAT_PIO2_PARTS and two_over_pi == trig_kernel.FLOAT_TWO_OVER_PI
    assert trig_kernel.fit_coefficients_float() == (trig_kernel.FLOAT_SIN_COEFFS, trig_kernel.FLOAT_COS_COEFFS)


DRIVER = r"""
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include KERNEL
static int32_t ord(float v) { int32_t i; memcpy(&i, &v, 4); return i < 0 ? INT32_MIN - i : i; }
#define N 4096
static float xs[N], ss[N], cs[N];
static long fill, worst;
static void flush(void)
{
    long i;
    kdg_sincosf(fill, xs, ss, cs);
    for (i = 0; i < fill; ++i) {
        /* the double sin rounded to float: correctly rounded (double's 29 extra bits) */
        long a = labs((long)ord(ss[i]) - ord((float)sin((double)xs[i])));
        long b = labs((long)ord(cs[i]) - ord((float)cos((double)xs[i])));
        worst = a > worst ? a : worst;
        worst = b > worst ? b : worst;
    }
    fill = 0;
}
static void add(float x) { xs[fill++] = x; if (fill == N) flush(); }
int main(void)
{
    long j, k;
    float x;
    uint32_t state = 12345u;
    for (j = 0; j < 4000000; ++j) {            /* a grid over [-7, 7] */
        add(-7.0f + 14.0f * (float)j / 4000000.0f);
    }
    for (k = -652; k <= 652; ++k) {            /* 400 floats each side of every k pi/2 in range */
        x = (float)((double)k * 1.5707963267948966);
        for (j = 0; j < 400; ++j) x = nextafterf(x, -2000.0f);
        for (j = 0; j < 800; ++j) { add(x); x = nextafterf(x, 2000.0f); }
    }
    for (j = 0; j < 2000000; ++j) {            /* random in +-1024 (xorshift) */
        state ^= state << 13; state ^= state >> 17; state ^= state << 5;
        add(((float)(state >> 8) / 16777216.0f) * 2048.0f - 1024.0f);
    }
    add(0.0f); add(-0.0f); add(1e-30f); add(-1e-30f); add(2000.0f); add(-1e6f);
    flush();
    printf("%ld\n", worst);
    return 0;
}
"""


def test_float_kernel_within_max_ulp(tmp_path):
    """kdg_sincosf against the correctly rounded sin/cos (the host's double sin rounded to
    float) on a grid, near every multiple of pi/2 up to FLOAT_BOUND, at random and beyond."""
    (tmp_path / "kernel.h").write_text(trig_kernel.kernel_c_float())
    (tmp_path / "driver.c").write_text(DRIVER)
    exe = tmp_path / "driver"
    subprocess.run(["cc", "-std=c99", "-O2", "-Wall", "-Wdouble-promotion", "-Werror", '-DKERNEL="kernel.h"',
                    "-o", str(exe), str(tmp_path / "driver.c"), "-lm"], check=True, cwd=tmp_path)
    worst = int(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout)
    assert worst <= trig_kernel.FLOAT_MAX_ULP


@pytest.mark.parametrize("robot", ROBOTS)
def test_float_c_is_strict_c99_without_double(generated, robot):
    """Strict C99, -Wdouble-promotion clean, and no 'double' in any declaration."""
    c_dir = generated[robot, "float"] / "c"
    subprocess.run(["cc", "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Wdouble-promotion", "-Werror",
                    "-O1", "-c", str(c_dir / f"{robot}.c"), "-o", "/dev/null"], check=True)
    code = [line for line in (c_dir / f"{robot}.c").read_text().splitlines() if not line.lstrip().startswith(("/*", "*"))]
    assert not [line for line in code if "double" in line]
    assert "_batch" not in (c_dir / f"{robot}.h").read_text()
    manifest = json.loads((generated[robot, "float"] / "functions.json").read_text())
    assert manifest["c_scalar"] == "float" and manifest["c_batch"] is False
    assert {f["name"] for f in manifest["functions"]} <= FUNCTIONS | {"ik_dls"}


@pytest.mark.parametrize("robot", ROBOTS)
def test_float_c_equals_numpy_double_within_reported_error(generated, robot):
    """kindyngen eval runs the float C; at 300 fresh random states (not the report's) it is
    within the reported float error (max, relative to the reported scale) of the numpy double
    module, an implementation that shares no compiled code with it."""
    folder = generated[robot, "float"]
    model = generated[robot, "model"]
    report = json.loads((folder / "opcounts.json").read_text())
    c_lib, py_lib = load_generated(folder, "c"), load_generated(folder, "python")
    rng = np.random.default_rng(12345)
    for name, counts in report.items():
        error = counts["float_error"]
        assert error["acceptable"], (name, error)
        n = 300
        q = rng.uniform(model.lower, model.upper, (n, model.n))
        inputs = {"q": q, "qd": rng.uniform(-2, 2, (n, model.n)), "qdd": rng.uniform(-5, 5, (n, model.n))}
        if name == "fd":
            inputs["tau"] = rng.uniform(-20, 20, (n, model.n))
        if name == "ik_hom":
            inputs = {"T": py_lib.call("fk_hom", {"q": q})["T"], "theta3": rng.uniform(model.lower[2], model.upper[2], (n, 1))}
        spec = c_lib.functions[name]
        inputs = {p["name"]: inputs[p["name"]] for p in spec["inputs"]}
        single = c_lib.call(name, inputs)
        reference = py_lib.call(name, {k: np.asarray(v, np.float32).astype(float) for k, v in inputs.items()})
        for port in spec["outputs"]:
            if port["dtype"] == "int":
                continue
            d, f = reference[port["name"]], single[port["name"]]
            bound = 4 * error["max"] * error["scale"][port["name"]]   # 4: a fresh sample's tail
            assert np.max(np.abs(f - d)) <= bound, (name, port["name"], np.max(np.abs(f - d)), bound)


def test_generate_options_leave_double_default_unchanged(generated):
    """Asking for a function set without batch variants changes nothing in the double code of
    those functions: each body is the one in the committed generated/ library."""
    import re
    committed = open("generated/lwr4/c/lwr4.c").read()
    subset = (generated["lwr4", "double"] / "c" / "lwr4.c").read_text()
    bodies = re.findall(r"\nvoid lwr4_(\w+)\((.*?\n})\n", subset, re.S)
    assert {name for name, _ in bodies} == FUNCTIONS        # ik_dls only when asked for (--functions)
    for name, body in bodies:
        assert f"\nvoid lwr4_{name}({body}\n" in committed, name


SKIP = embedded.missing_tools()


@pytest.fixture(scope="session")
def boards(generated, tmp_path_factory):
    """Each robot's float C on the M4F board and double C on the M7 board (one cross build and
    one QEMU run each)."""
    if SKIP:
        pytest.skip(SKIP)
    work = tmp_path_factory.mktemp("boards")
    out = {}
    for robot in ROBOTS:
        model = generated[robot, "model"]
        for target, scalar in (("m4f", "float"), ("m7", "double")):
            out[robot, target] = embedded.figures(generated[robot, scalar], target, work / f"{robot}_{target}",
                                                  model.lower, model.upper)
    return out


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("target", ("m4f", "m7"))
def test_on_emulated_board(boards, generated, robot, target):
    """On the board: bit-exact with the host wherever the same IEEE operations run (functions
    calling no libm function but sqrt); otherwise within the float error reported at generate
    time (float) or 1e-12 of the output scale (double). The M4F object calls no double-precision
    soft-float helper; no single call needs over 4 KB of stack."""
    r = boards[robot, target]
    assert set(r["outputs"]) == set(r["host"])
    report = json.loads((generated[robot, "float"] / "opcounts.json").read_text())
    for fn, ports in r["outputs"].items():
        for port, board in ports.items():
            host = np.ravel(r["host"][fn][port])
            if not r["libm"][fn] or board.dtype == np.int32:
                assert np.array_equal(board.astype(float), host.astype(board.dtype).astype(float)), (fn, port)
            elif target == "m4f":
                e = report[fn]["float_error"]
                assert np.max(np.abs(board - host)) <= 4 * e["max"] * e["scale"][port], (fn, port)
            else:
                assert np.max(np.abs(board - host)) <= 1e-12 * max(np.max(np.abs(host)), 1.0), (fn, port)
        assert r["stack"][fn] <= 4096, (fn, r["stack"][fn])
        assert r["flash"][fn] and r["instructions"][fn] > 0
    if target == "m4f":
        assert not [s for s in r["undefined"] if s.startswith("__aeabi_d")], r["undefined"]
        # the board's float results against the host's double code, within the reported error
        double = load_generated(generated[robot, "double"], "c")
        for fn, ports in r["outputs"].items():
            reference = double.call(fn, {k: v.astype(float) for k, v in r["inputs"][fn].items()})
            e = report[fn]["float_error"]
            for port, board in ports.items():
                if board.dtype == np.int32:
                    assert np.array_equal(board, np.ravel(reference[port])), (fn, port)
                else:
                    diff = np.max(np.abs(board - np.ravel(reference[port])))
                    assert diff <= 4 * e["max"] * e["scale"][port], (fn, port, diff)


def test_bad_generate_options_are_refused(tmp_path):
    """Unknown --functions names and python_c with --scalar float: one error line, exit 2."""
    import sys
    base = [sys.executable, "-m", "kindyngen", "generate", "robots/lwr4.yaml", "--out", str(tmp_path), "--quiet"]
    for extra, needle in ((["--functions", "fk_hom,nope"], "nope"),
                          (["--scalar", "float", "--lang", "c,python_c"], "python_c")):
        done = subprocess.run(base + extra, capture_output=True, text=True)
        assert done.returncode == 2 and needle in done.stderr and "Traceback" not in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1


def test_float_generation_is_deterministic(generated, tmp_path):
    """Generating the float code again gives the same bytes (code, header with its measured
    float error, opcounts)."""
    model = generated["lwr4", "model"]
    again = generate(model, tmp_path, ("c", "python"), progress=False, only=FUNCTIONS, scalar="float", batch=False)
    first = generated["lwr4", "float"]
    names = sorted(p.relative_to(first) for p in first.rglob("*") if p.is_file())
    assert names == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for name in names:
        assert (first / name).read_bytes() == (again / name).read_bytes(), name


def test_cmake_toolchain_cross_builds_the_library(generated, tmp_path):
    """The CMake toolchain example builds the generated CMakeLists.txt for Cortex-M4F with
    the measured flags (no -fPIC, no contraction) into a library free of double soft-float."""
    import shutil
    if SKIP or shutil.which("cmake") is None:
        pytest.skip(SKIP or "cmake not found")
    toolchain = embedded.HERE / "arm-none-eabi.cmake"
    source, build = generated["lwr4", "float"] / "c", tmp_path / "build"
    subprocess.run(["cmake", "-S", str(source), "-B", str(build), f"-DCMAKE_TOOLCHAIN_FILE={toolchain}"],
                   check=True, capture_output=True)
    flags = next(build.rglob("flags.make")).read_text()
    assert "-mfpu=fpv4-sp-d16" in flags and "-ffp-contract=off" in flags and "-fPIC" not in flags
    subprocess.run(["cmake", "--build", str(build)], check=True, capture_output=True)
    undefined = subprocess.run(["arm-none-eabi-nm", "-u", str(build / "libkindyngen_lwr4.a")],
                               capture_output=True, text=True, check=True).stdout
    assert "sinf" in undefined or "sqrtf" in undefined
    assert "__aeabi_d" not in undefined
