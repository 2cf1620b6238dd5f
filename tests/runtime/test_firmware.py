"""The generated C as firmware builds it (issue 45): each finding of a Cortex-M4F trial, against
references that share no code with the generator (mpmath, the compilers themselves, fesetround,
the linked image's symbol table, the host's strict build)."""
import json
import shutil
import subprocess
import sys
from fractions import Fraction

import mpmath
import numpy as np
import pytest

from kindyngen.codegen import trig_kernel
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot
from kindyngen.runtime import embedded
from tests.harness import HANG_GUARD_S, ROOT

STEP = {"fk_hom", "jacobian", "M", "g", "tau"}
FLT_MAX = float(np.finfo(np.float32).max)
# the float beyond 1024 rad nearest a multiple of pi/2 relative to its size (x = 0x1.f37c8ap+95,
# |x - k pi/2| = 1.7e-9: found by reducing every float, confirmed by mpmath below)
NEAREST = float.fromhex("0x1.f37c8ap+95")
SKIP_BOARD = embedded.missing_tools()


@pytest.fixture(scope="module")
def builds(tmp_path_factory):
    """lwr4's controller-step functions as a firmware generates them (--no-batch), float and double C."""
    root = tmp_path_factory.mktemp("firmware")
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    return {scalar: generate(model, root / scalar, ("c",), progress=False, only=STEP, scalar=scalar, batch=False)
            for scalar in ("float", "double")}


@pytest.mark.parametrize("compiler", ["gcc", "clang"])
@pytest.mark.parametrize("flag", ["-ffast-math", "-Ofast"])
@pytest.mark.parametrize("scalar", ["float", "double"])
def test_fast_math_is_refused_at_compile_time(builds, compiler, flag, scalar):
    """-ffast-math (or -Ofast) lets the compiler fold the kernel's exact steps away: the source
    refuses to compile, saying why; without it, it compiles."""
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} not installed")
    source = builds[scalar] / "c" / "lwr4.c"
    done = subprocess.run([compiler, "-std=c99", flag, "-c", str(source), "-o", "/dev/null"],
                          capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert done.returncode != 0 and "-ffast-math" in done.stderr and "IEEE" in done.stderr, done.stderr
    subprocess.run([compiler, "-std=c99", "-O2", "-c", str(source), "-o", "/dev/null"], check=True, timeout=HANG_GUARD_S)


ROUNDING = r"""
#include <fenv.h>
#include <math.h>
#include <stdio.h>
#include "lwr4.h"
static void step(const REAL *q, REAL *out)
{
    static const REAL qd[7] = {0.1, 0.2, -0.3, 0.4, -0.5, 0.6, -0.7}, qdd[7] = {1, -1, 2, -2, 3, -3, 0.5};
    lwr4_fk_hom(q, out);
    lwr4_jacobian(q, out + 16);
    lwr4_M(q, out + 58);
    lwr4_g(q, out + 107);
    lwr4_tau(q, qd, qdd, out + 114);
}
int main(void)
{
    /* angles in both reductions' ranges: within +-1024 rad and beyond */
    static const REAL qs[3][7] = {{0.3, -1.1, 2.0, 1.2, -0.4, 0.9, 2.5}, {-2.9, 0.7, -0.2, -1.9, 2.6, -1.4, 0.05},
                                  {1e4, -3e5, 7.5, 123456.0, -1e3, 2e6, 0.5}};
    static const int modes[4] = {FE_TONEAREST, FE_UPWARD, FE_DOWNWARD, FE_TOWARDZERO};
    REAL out[121];
    int s, m, i;
    for (s = 0; s < 3; ++s) {
        for (m = 0; m < 4; ++m) {
            int nearest;
            if (fesetround(modes[m]) != 0) return 1;
            step(qs[s], out);
            nearest = lwr4_rounds_to_nearest();
            fesetround(FE_TONEAREST);
            printf("%d %d %d", s, m, nearest);
            for (i = 0; i < 121; ++i) printf(" %.9e", (double)out[i]);
            printf("\n");
        }
    }
    return 0;
}
"""


def test_rounding_modes(builds, tmp_path):
    """With fesetround to each directed mode, the float code's results stay within 1e-5 of the
    output scale of its round-to-nearest results (measured: 4.5e-7; a wrong quadrant in the
    kernel gave errors of the output's size), and the check lwr4_rounds_to_nearest() fires in
    every directed mode and only there, in float and double builds alike; the double kernel
    needs rounding to nearest (its results in the directed modes are what the check warns of)."""
    ports = {"T": (0, 16), "J": (16, 58), "M": (58, 107), "g": (107, 114), "tau": (114, 121)}
    for scalar, real in (("float", "float"), ("double", "double")):
        c_dir = builds[scalar] / "c"
        (tmp_path / "driver.c").write_text(ROUNDING)
        exe = tmp_path / f"rounding_{scalar}"
        # -frounding-math for the driver only: the library is built as a firmware builds it
        subprocess.run(["cc", "-std=c99", "-O2", "-c", str(c_dir / "lwr4.c"), "-o", str(tmp_path / f"{scalar}.o")],
                       check=True, timeout=HANG_GUARD_S)
        subprocess.run(["cc", "-std=c99", "-O2", "-frounding-math", f"-DREAL={real}", "-I", str(c_dir),
                        str(tmp_path / "driver.c"), str(tmp_path / f"{scalar}.o"), "-o", str(exe), "-lm"],
                       check=True, timeout=HANG_GUARD_S)
        rows = [line.split() for line in subprocess.run([str(exe)], capture_output=True, text=True, check=True,
                                                         timeout=HANG_GUARD_S).stdout.splitlines()]
        values = {(int(r[0]), int(r[1])): np.array(r[3:], float) for r in rows}
        nearest = {(int(r[0]), int(r[1])): int(r[2]) for r in rows}
        for (state, mode), got in values.items():
            assert nearest[state, mode] == (mode == 0), (scalar, state, mode)
            if scalar == "double":
                continue
            reference = values[state, 0]
            for port, (lo, hi) in ports.items():
                scale = np.max(np.abs(reference[lo:hi]))
                assert np.max(np.abs(got[lo:hi] - reference[lo:hi])) <= 1e-5 * scale, (state, mode, port)


KERNEL_DRIVER = r"""
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include "kernel.h"
int main(int argc, char **argv)
{
    int i;
    for (i = 1; i < argc; ++i) {
        float x = strtof(argv[i], 0), s, c;
        kdg_sincosf(1, &x, &s, &c);
        printf("%a %a\n", (double)s, (double)c);
    }
    return 0;
}
"""


def _correctly_rounded(x: float, function) -> np.float32:
    """sin or cos of the float ``x`` rounded to float, from mpmath with enough bits for any float
    (x up to 2^128 needs 128 bits before the binary point, then float's 24 and a margin)."""
    with mpmath.workprec(400):
        value = function(mpmath.mpf(Fraction(x).numerator) / Fraction(x).denominator)
        below = np.float32(float(value))
        candidates = [np.nextafter(below, np.float32(-2)), below, np.nextafter(below, np.float32(2))]
        return min(candidates, key=lambda f: abs(mpmath.mpf(float(f)) - value))


def _ulps(a: np.float32, b: np.float32) -> int:
    def order(v):
        i = int(np.array(v, np.float32).view(np.int32))
        return i if i >= 0 else -(i & 0x7FFFFFFF)
    return abs(order(a) - order(b))


def large_angles():
    """Floats beyond the Cody-Waite range, 1e4 rad and FLT_MAX among them, the float nearest a
    multiple of pi/2, and a random float of every exponent from 10 to 127 (both signs)."""
    rng = np.random.default_rng(45)
    xs = [1e4, -1e4, FLT_MAX, -FLT_MAX, NEAREST, -NEAREST, 1024.0001, 2.0 ** 127, 3e38]
    for e in range(10, 128):
        m = rng.integers(2 ** 23, 2 ** 24)
        xs.append(float(np.float32(m * 2.0 ** (e - 23) * (1 if e % 2 else -1))))
    return [float(np.float32(x)) for x in xs]


def test_float_kernel_over_the_whole_range_against_mpmath(tmp_path):
    """1e4 rad, FLT_MAX, the float nearest a multiple of pi/2 and a float of every exponent:
    the kernel (host) within FLOAT_MAX_ULP of the correctly rounded sin and cos (mpmath);
    infinities and NaN give NaN. The nearest float's reduced argument is confirmed by mpmath."""
    with mpmath.workprec(400):
        reduced = mpmath.mpf(Fraction(NEAREST).numerator) - mpmath.nint(NEAREST / (mpmath.pi / 2)) * mpmath.pi / 2
        assert 1e-9 < abs(reduced) < 2e-9
    (tmp_path / "kernel.h").write_text(trig_kernel.kernel_c_float())
    (tmp_path / "driver.c").write_text(KERNEL_DRIVER)
    subprocess.run(["cc", "-std=c99", "-O2", "-Wall", "-Werror", "-o", str(tmp_path / "driver"), str(tmp_path / "driver.c"),
                    "-lm"], check=True, cwd=tmp_path, timeout=HANG_GUARD_S)
    xs = large_angles()
    out = subprocess.run([str(tmp_path / "driver")] + [x.hex() for x in xs] + ["inf", "-inf", "nan"],
                         capture_output=True, text=True, check=True, timeout=HANG_GUARD_S).stdout.split()
    values = np.array([float.fromhex(v) if "nan" not in v and "inf" not in v else float(v) for v in out],
                      dtype=np.float32).reshape(-1, 2)
    for x, (s, c) in zip(xs, values):
        assert _ulps(s, _correctly_rounded(x, mpmath.sin)) <= trig_kernel.FLOAT_MAX_ULP, (x, "sin")
        assert _ulps(c, _correctly_rounded(x, mpmath.cos)) <= trig_kernel.FLOAT_MAX_ULP, (x, "cos")
    assert np.all(np.isnan(values[len(xs):]))


@pytest.fixture(scope="module")
def board_kernel(tmp_path_factory):
    if SKIP_BOARD:
        pytest.skip(SKIP_BOARD)
    arguments = {"in_range": [0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7], "1e4": [1e4] * 7, "FLT_MAX": [FLT_MAX] * 7,
                 "nearest": [NEAREST] * 7, "mixed": [1e5, -3e7, 1e12, -2e20, 7e30, -1e38, NEAREST]}
    return arguments, embedded.kernel_figures(arguments, tmp_path_factory.mktemp("kernel_m4f"))


def test_large_angles_stay_in_the_kernel_on_the_m4f(board_kernel):
    """On the Cortex-M4F (QEMU): sin/cos of 1e4 rad, FLT_MAX and the other large angles within
    FLOAT_MAX_ULP of the correctly rounded values (mpmath); newlib's sinf/cosf are not linked
    into the image; seven large angles cost at most 2.5x the instructions of seven in range
    (measured 2.3x; newlib's fallback cost 33x at 1e4 rad), the same for every large angle to
    within 2 %."""
    arguments, r = board_kernel
    for name, xs in arguments.items():
        for k, x in enumerate(xs):
            x = float(np.float32(x))
            assert _ulps(r["sin"][name][k], _correctly_rounded(x, mpmath.sin)) <= trig_kernel.FLOAT_MAX_ULP, (name, x)
            assert _ulps(r["cos"][name][k], _correctly_rounded(x, mpmath.cos)) <= trig_kernel.FLOAT_MAX_ULP, (name, x)
    assert not {"sinf", "cosf", "sin", "cos"} & set(r["symbols"]), [s for s in r["symbols"] if "sin" in s or "cos" in s]
    n = r["instructions"]
    large = [n[name] for name in ("1e4", "FLT_MAX", "nearest", "mixed")]
    assert max(large) <= 2.5 * n["in_range"], n
    assert max(large) <= 1.02 * min(large), n


@pytest.fixture(scope="module")
def board_step(builds, tmp_path_factory):
    """The float controller-step functions on the M4F with joint angles of 1e4 rad and FLT_MAX."""
    if SKIP_BOARD:
        pytest.skip(SKIP_BOARD)
    q = np.array([1e4, -FLT_MAX, 0.3, FLT_MAX, -1e4, NEAREST, 2.0], np.float32)
    inputs = {name: {"q": q} for name in ("fk_hom", "jacobian", "M", "g")}
    inputs["tau"] = {"q": q, "qd": np.full(7, 0.5, np.float32), "qdd": np.full(7, -1.0, np.float32)}
    folder = builds["float"]
    r = embedded.build_and_run(folder, embedded.TARGETS["m4f"], tmp_path_factory.mktemp("step_m4f"), inputs)
    r["host"] = embedded.host_outputs(folder, inputs)
    return r


def test_generated_functions_link_no_libm_sin_on_the_m4f(board_step):
    """A firmware image of the controller-step functions links no sinf/cosf (their sin/cos of q
    come from the kernel for every angle), and with angles of 1e4 rad and FLT_MAX the board's
    outputs are the host's bit for bit and finite."""
    assert not {"sinf", "cosf", "sin", "cos"} & set(board_step["linked"])
    assert not {"sinf", "cosf"} & set(board_step["undefined"]), board_step["undefined"]
    for fn, ports in board_step["outputs"].items():
        for port, board in ports.items():
            host = np.ravel(board_step["host"][fn][port]).astype(np.float32)
            assert np.all(np.isfinite(board)) and np.array_equal(board, host), (fn, port)


def test_functions_json_gives_the_c_scalar_of_every_port(builds):
    """A float build's functions.json says "float" for every port that is not an int (it said
    "double"), a double build "double"."""
    for scalar, folder in builds.items():
        manifest = json.loads((folder / "functions.json").read_text())
        for f in manifest["functions"]:
            for port in f["inputs"] + f["outputs"]:
                assert port["dtype"] == ("int" if port["name"] == "status" else scalar), (scalar, f["name"], port)


def _generate(tmp_path, *options):
    done = subprocess.run([sys.executable, "-m", "kindyngen", "generate", str(ROOT / "robots" / "lwr4.yaml"), "--out",
                           str(tmp_path), "--lang", "c,python", "--no-batch", "--quiet", *options],
                          capture_output=True, text=True, cwd=ROOT, timeout=HANG_GUARD_S)
    assert done.returncode == 0, done.stderr
    return tmp_path / "lwr4", done.stderr


def test_functions_selects_ik_dls_like_every_function(tmp_path):
    """--functions fk_hom,jacobian writes no ik_dls (it did, though --functions refused the name);
    --functions ik_dls writes it, with the fk_hom and jacobian it iterates (noted), and it solves."""
    folder, _ = _generate(tmp_path / "without", "--functions", "fk_hom,jacobian")
    names = [f["name"] for f in json.loads((folder / "functions.json").read_text())["functions"]]
    assert names == ["fk_hom", "jacobian"]
    for path in (folder / "c" / "lwr4.c", folder / "c" / "lwr4.h", folder / "python" / "lwr4.py"):
        assert "ik_dls" not in path.read_text(), path
    folder, notes = _generate(tmp_path / "with", "--functions", "ik_dls")
    names = [f["name"] for f in json.loads((folder / "functions.json").read_text())["functions"]]
    assert names == ["fk_hom", "jacobian", "ik_dls"]
    assert "fk_hom generated too" in notes and "jacobian generated too" in notes
    from kindyngen.runtime.evaluate import load_generated
    lib = load_generated(folder, "c")
    q = np.array([0.3, -0.5, 0.2, 1.1, -0.4, 0.6, 0.1])
    target = lib.call("fk_hom", {"q": q})["T"]
    solved = lib.call("ik_dls", {"T": target, "q0": q + 0.2})
    assert int(np.ravel(solved["status"])[0]) == 0
    np.testing.assert_allclose(lib.call("fk_hom", {"q": solved["q"]})["T"], target, atol=1e-6)


CMAKE_DRIVER = r"""
#include <stdio.h>
#include <string.h>
#include "lwr4.h"
int main(void)
{
    static const double q[7] = {0.3, -1.1, 2.0, 1.2, -0.4, 0.9, 2.5}, qd[7] = {0.1, 0.2, -0.3, 0.4, -0.5, 0.6, -0.7},
                        qdd[7] = {1, -1, 2, -2, 3, -3, 0.5};
    double out[121];
    unsigned long long bits;
    int i;
    lwr4_fk_hom(q, out);
    lwr4_jacobian(q, out + 16);
    lwr4_M(q, out + 58);
    lwr4_g(q, out + 107);
    lwr4_tau(q, qd, qdd, out + 114);
    for (i = 0; i < 121; ++i) {
        memcpy(&bits, out + i, sizeof bits);
        printf("%016llx\n", bits);
    }
    return 0;
}
"""


def test_cmake_build_is_bit_exact_with_the_strict_build(builds, tmp_path):
    """The generated CMakeLists.txt built with a firmware's or a host's usual flags (-O3 with
    FMA instructions available: it used to say gnu99, which contracts products into fused
    multiply-adds) gives the bits of the host's strict build (cc -std=c99 -O2)."""
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed")
    machine = subprocess.run(["cc", "-dumpmachine"], capture_output=True, text=True, check=True).stdout
    fma = "-mfma" if machine.startswith("x86_64") else ""    # aarch64 and the M4F have FMA anyway
    c_dir = builds["double"] / "c"
    (tmp_path / "driver.c").write_text(CMAKE_DRIVER)
    build = tmp_path / "build"
    subprocess.run(["cmake", "-S", str(c_dir), "-B", str(build), f"-DCMAKE_C_FLAGS=-O3 {fma}"], check=True,
                   capture_output=True, timeout=HANG_GUARD_S)
    subprocess.run(["cmake", "--build", str(build)], check=True, capture_output=True, timeout=HANG_GUARD_S)
    outputs = {}
    for name, command in (
            ("cmake", ["cc", "-O3", "-I", str(c_dir), str(tmp_path / "driver.c"), str(build / "libkindyngen_lwr4.a")]),
            ("strict", ["cc", "-std=c99", "-O2", "-I", str(c_dir), str(tmp_path / "driver.c"), str(c_dir / "lwr4.c")])):
        subprocess.run(command + ["-o", str(tmp_path / name), "-lm"], check=True, timeout=HANG_GUARD_S)
        outputs[name] = subprocess.run([str(tmp_path / name)], capture_output=True, text=True, check=True,
                                       timeout=HANG_GUARD_S).stdout.split()
    assert len(outputs["strict"]) == 121
    assert outputs["cmake"] == outputs["strict"]


def test_float_library_without_sin_of_q_compiles_strictly(tmp_path):
    """A float library whose functions take no joint angles (ik_hom alone) has no sincos kernel
    to leave unused: strict C99 with -Wall -Werror compiles it (the kernel was printed anyway,
    an unused static function)."""
    folder, _ = _generate(tmp_path, "--scalar", "float", "--functions", "ik_hom")
    subprocess.run(["cc", "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Wdouble-promotion", "-Werror", "-c",
                    str(folder / "c" / "lwr4.c"), "-o", "/dev/null"], check=True, timeout=HANG_GUARD_S)
    assert "kdg_sincosf" not in (folder / "c" / "lwr4.c").read_text()


def test_a_tree_closed_by_loops_runs_on_the_m4f(tmp_path):
    """The delta robot (3 drives, 12 joints, no closed form) as float firmware: the board's inputs
    are sized by its coordinates ("nq"), not its joints, its loop_solve closes the loops there as
    on the host (the loop residual of the board's q_all evaluated in double by the host's
    loop_residual); fk_hom and loop_residual equal the host's float C bit for bit, loop_solve's
    q_all within float rounding (its Newton steps take sinf/cosf of the dependent joints from the
    C library: newlib's and glibc's differ in the last bit)."""
    if SKIP_BOARD:
        pytest.skip(SKIP_BOARD)
    from kindyngen.runtime.evaluate import load_generated
    model = load_robot(ROOT / "examples" / "loops" / "delta.urdf", tree=True)
    folder = generate(model, tmp_path / "gen", ("c",), progress=False, only={"loop_solve", "loop_residual", "fk_hom"},
                      scalar="float", batch=False)
    manifest = json.loads((folder / "functions.json").read_text())
    assert manifest["nq"] == 3 and manifest["n"] == 12
    r = embedded.figures(folder, "m4f", tmp_path / "work")
    assert r["inputs"]["loop_solve"]["q"].shape == (3,)
    agreement = embedded.agreement(r)
    assert agreement["fk_hom"] == agreement["loop_residual"] == "bit-exact", agreement
    assert r["libm"]["loop_solve"] == ["cosf", "sinf"]
    q_all = r["outputs"]["loop_solve"]["q_all"].astype(float)
    assert np.max(np.abs(q_all - np.ravel(r["host"]["loop_solve"]["q_all"]))) < 1e-6
    double = load_generated(folder, "c")        # the float build: residual of the float solution
    residual = double.call("loop_residual", {"q": q_all[None]})
    assert np.max(np.abs(next(iter(residual.values())))) < 1e-5
