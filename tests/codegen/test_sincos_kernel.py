"""The sincos kernel emitted into generated C (kindyngen/codegen/trig_kernel.py) against glibc's sin and cos:
dense grids, the half angles of the dual-quaternion functions, every multiple of pi/2 in the
kernel's range, random doubles of random exponent and the special values, compiled strictly and with vectorisation and FMA contraction."""
import platform
import shutil
import subprocess

import pytest

from kindyngen.codegen import trig_kernel

XORSHIFT = r"""
/* random bits for random doubles of uniform significand and exponent (xorshift64, seeded) */
static uint64_t state = 0x9E3779B97F4A7C15u;
static uint64_t next(void)
{
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return state;
}
"""

DRIVER = r"""
/* Compare the generated sincos kernel (included as KERNEL, a file holding kernel_c()) with libm:
 * prints one line per set of arguments, "<set> <max ulp sin> <max ulp cos> <points>", then one
 * line "special <failures>" for the values that must come out exactly. Used by
 * the tests below; argv[1] = points of the dense grid. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include KERNEL

#define CHUNK 4096

static double xs[CHUNK], ss[CHUNK], cs[CHUNK];
static long filled, points;
static double worst_sin, worst_cos;

/* doubles mapped to integers in the same order, so that ulp distance is a difference */
static int64_t ordered(double v)
{
    int64_t i;
    memcpy(&i, &v, sizeof i);
    return i < 0 ? INT64_MIN - i : i;
}

static double ulps(double a, double b)
{
    return fabs((double)(ordered(a) - ordered(b)));
}

static void flush(void)
{
    long i;
    kdg_sincos(filled, xs, ss, cs);
    for (i = 0; i < filled; ++i) {
        const double s = sin(xs[i]), c = cos(xs[i]);
        if (ulps(ss[i], s) > worst_sin) worst_sin = ulps(ss[i], s);
        if (ulps(cs[i], c) > worst_cos) worst_cos = ulps(cs[i], c);
    }
    points += filled;
    filled = 0;
}

static void add(double x)
{
    xs[filled++] = x;
    if (filled == CHUNK) flush();
}

static void report(const char *set)
{
    flush();
    printf("%s %.0f %.0f %ld\n", set, worst_sin, worst_cos, points);
    worst_sin = worst_cos = 0.0;
    points = 0;
}

""" + XORSHIFT + r"""
int main(int argc, char **argv)
{
    const long grid = argc > 1 ? atol(argv[1]) : 10000000;
    const double pi = 3.14159265358979323846;
    long i, failures = 0;
    int j;
    for (i = 0; i <= grid; ++i) add(-4.0*pi + 8.0*pi*(double)i/(double)grid);
    report("grid");
    /* the half angles of the dual-quaternion functions, computed as the generated C does:
     * 0.5*q and 0.5*(q_a +- q_b) for joint angles up to +-2 pi (arguments up to +-2 pi) */
    for (i = 0; i <= grid/2; ++i) add(0.5*(-2.0*pi + 4.0*pi*(double)i/(double)(grid/2)));
    for (i = 0; i < grid/4; ++i) {
        const double a = -2.0*pi + 4.0*pi*(double)(next() >> 11)/9007199254740992.0;
        const double b = -2.0*pi + 4.0*pi*(double)(next() >> 11)/9007199254740992.0;
        add(0.5*(a + b));
        add(0.5*(a - b));
    }
    report("half");
    /* logarithmic, from the smallest subnormal to 1e300 (beyond the kernel's bound: libm) */
    for (i = 0; i <= grid/10; ++i) {
        const double x = pow(10.0, -323.0 + 623.0*(double)i/(double)(grid/10));
        add(x);
        add(-x);
    }
    report("log");
    /* the hardest reductions: the doubles nearest to k pi/2 for every k in the kernel's range */
    for (i = 1; i <= 667544; ++i) {
        double x = (double)i*(pi/2.0);
        for (j = 0; j < 2; ++j) x = nextafter(x, 0.0);
        for (j = 0; j < 5; ++j, x = nextafter(x, INFINITY)) {
            add(x);
            add(-x);
        }
    }
    report("pi/2");
    for (i = 0; i < grid/10; ++i) {
        const uint64_t bits = next();
        const double significand = 1.0 + (double)(bits >> 12)/4503599627370496.0;
        add((bits & 1 ? -1.0 : 1.0)*ldexp(significand, (int)(next() % 100) - 80));
    }
    report("random");
    {
        /* exact: signed zeros, subnormals (sin x = x, cos x = 1), NaN for infinities and NaN */
        const double zero_and_tiny[] = {0.0, -0.0, 4.9406564584124654e-324, -2.2250738585072009e-308, 1e-20};
        double s, c;
        for (j = 0; j < 5; ++j) {
            const double x = zero_and_tiny[j];
            kdg_sincos(1, &x, &s, &c);
            if (s != x || signbit(s) != signbit(x) || c != 1.0) ++failures;
        }
        {
            const double x[3] = {INFINITY, -INFINITY, NAN};
            double sv[3], cv[3];
            kdg_sincos(3, x, sv, cv);
            for (j = 0; j < 3; ++j)
                if (!isnan(sv[j]) || !isnan(cv[j])) ++failures;
        }
    }
    printf("special %ld\n", failures);
    return 0;
}
"""

STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
BUILDS = [("gcc", ["-O2"]), ("gcc", ["-O3", "-march=native", "-ffp-contract=fast"]),
          ("clang", ["-O3", "-march=native"])]


def run_driver(tmp_path, compiler, flags, kernel_text, grid=10_000_000):
    (tmp_path / "kernel.h").write_text("#include <math.h>\n" + kernel_text)
    (tmp_path / "driver.c").write_text(DRIVER)
    exe = tmp_path / "driver"
    build = subprocess.run([compiler, *STRICT, *flags, '-DKERNEL="kernel.h"', "-I", str(tmp_path),
                            str(tmp_path / "driver.c"), "-o", str(exe), "-lm"], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    out = subprocess.run([str(exe), str(grid)], capture_output=True, text=True, check=True).stdout
    results = {}
    for line in out.splitlines():
        name, *values = line.split()
        results[name] = [float(v) for v in values]
    return results


@pytest.mark.parametrize("compiler,flags", BUILDS, ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_kernel_within_stated_ulp_of_libm(compiler, flags, tmp_path):
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} not installed")
    results = run_driver(tmp_path, compiler, flags, trig_kernel.kernel_c())
    assert results.pop("special") == [0]
    assert results["grid"][2] == 10_000_001 and results["pi/2"][2] > 6_000_000
    assert results["half"][2] == 5_000_001 + 5_000_000
    for name, (sin_ulp, cos_ulp, points) in results.items():
        assert sin_ulp <= trig_kernel.MAX_ULP and cos_ulp <= trig_kernel.MAX_ULP, (name, sin_ulp, cos_ulp)


def test_driver_detects_a_wrong_kernel(tmp_path):
    """The comparison can fail: the cubic coefficient of sin off by 1e-12 shows up."""
    coefficient = repr(trig_kernel.SIN_COEFFS[0])
    wrong = trig_kernel.kernel_c().replace(coefficient, repr(trig_kernel.SIN_COEFFS[0] * (1 + 1e-12)))
    assert wrong != trig_kernel.kernel_c()
    results = run_driver(tmp_path, "gcc", ["-O2"], wrong, grid=100_000)
    assert results["grid"][0] > 10 * trig_kernel.MAX_ULP


def test_constants_are_the_fit():
    """The coefficients and pi/2 parts written in codegen/trig_kernel.py are what its fit computes, and the
    fit is as good as the kernel's accuracy needs (2^-58 relative for sin, 2^-64 for cos)."""
    sin_coeffs, cos_coeffs, sin_error, cos_error = trig_kernel.fit_coefficients()
    assert (sin_coeffs, cos_coeffs) == (trig_kernel.SIN_COEFFS, trig_kernel.COS_COEFFS)
    assert sin_error < 2.0 ** -57.9 and cos_error < 2.0 ** -64
    assert trig_kernel.split_pio2() == (trig_kernel.PIO2_PARTS, trig_kernel.TWO_OVER_PI)
    for part in trig_kernel.PIO2_PARTS[:3]:   # 33 significant bits: k * part exact for |k| < 2^20
        mantissa, _ = part.as_integer_ratio()
        assert mantissa.bit_length() - (mantissa & -mantissa).bit_length() + 1 <= 33


HALF_DRIVER = r"""
/* kdg_sincos_half(n, x) against kdg_sincos(n, 0.5*x), which is what single calls ran before they
 * read half angles in place: prints the number of results whose bits differ, then the points */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include KERNEL

""" + XORSHIFT + r"""
int main(void)
{
    double x[9], h[9], s[9], c[9], sh[9], ch[9];
    const double special[6] = {INFINITY, -INFINITY, NAN, 0.0, -0.0, 4.9406564584124654e-324};
    long differ = 0, points = 0, r;
    int n, j;
    for (r = 0; r < 200000; ++r)
        for (n = 1; n <= 9; ++n) {
            for (j = 0; j < n; ++j) {
                const uint64_t bits = next();
                const double significand = 1.0 + (double)(bits >> 12)/4503599627370496.0;
                /* exponents 2^-30 .. 2^24: the kernel's range (+-2^20 after halving) and beyond it (libm) */
                x[j] = (bits & 1 ? -1.0 : 1.0)*ldexp(significand, (int)(next() % 55) - 30);
                if (r % 1000 == 0 && j < 6) x[j] = special[(j + n) % 6];
                h[j] = 0.5*x[j];
            }
            kdg_sincos(n, h, s, c);
            kdg_sincos_half(n, x, sh, ch);
            for (j = 0; j < n; ++j, ++points)
                if (memcmp(&s[j], &sh[j], sizeof s[j]) || memcmp(&c[j], &ch[j], sizeof c[j])) ++differ;
        }
    printf("%ld %ld\n", differ, points);
    return 0;
}
"""


@pytest.mark.parametrize("compiler,flags", BUILDS, ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_half_angle_kernel_is_the_kernel_on_halves_bit_for_bit(compiler, flags, tmp_path):
    """Single calls whose sin/cos arguments are all q[k]/2 run kdg_sincos_half over q in place
    (optimize.half_angles): its results must be those of the kernel on the halved copy it replaced."""
    differ, points = differing_bits(compiler, flags, tmp_path, HALF_DRIVER)
    assert points == 200000 * 45 and differ == 0


def differing_bits(compiler, flags, tmp_path, driver, extra=""):
    """(results whose bits differ, results compared) as ``driver`` prints them, built with the
    kernel, the half-angle kernel and ``extra`` C; skips where ``compiler`` is not installed."""
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} not installed")
    (tmp_path / "kernel.h").write_text("#include <math.h>\n" + trig_kernel.kernel_c()
                                       + trig_kernel.kernel_c("kdg_sincos_half", half=True) + extra)
    (tmp_path / "driver.c").write_text(driver)
    exe = tmp_path / "driver"
    build = subprocess.run([compiler, *STRICT, *flags, '-DKERNEL="kernel.h"', "-I", str(tmp_path),
                            str(tmp_path / "driver.c"), "-o", str(exe), "-lm"], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    return tuple(int(v) for v in subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split())


SPLIT_DRIVER = r"""
/* kdg_sincos_split(n, x) and kdg_sincos_half_split(n, x), with their libm fix-up behind the flag
 * they return, as single calls of four to seven angles run them, against the blocks of eight on the same arguments zero-padded (kdg_sincos(8, x)
 * and kdg_sincos_half(8, x)): prints the number of results whose bits differ, then the points */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include KERNEL

""" + XORSHIFT + r"""
static int slot(int k, int n) { return k < 4 ? k : k + 8 - n; }   /* trig_kernel.split_slot */

int main(void)
{
    double x[8], s8[8], c8[8], s[8], c[8];
    const double special[6] = {INFINITY, -INFINITY, NAN, 0.0, -0.0, 4.9406564584124654e-324};
    long differ = 0, points = 0, r;
    int n, j, half;
    for (r = 0; r < 200000; ++r)
        for (n = 4; n <= 7; ++n)
            for (half = 0; half < 2; ++half) {
                for (j = 0; j < 8; ++j) {
                    const uint64_t bits = next();
                    const double significand = 1.0 + (double)(bits >> 12)/4503599627370496.0;
                    /* exponents 2^-30 .. 2^24: the kernel's range and beyond it (libm) in either block */
                    x[j] = j < n ? (bits & 1 ? -1.0 : 1.0)*ldexp(significand, (int)(next() % 55) - 30) : 0.0;
                    if (r % 1000 == 0 && j < n) x[j] = special[(j + n) % 6];
                }
                if (half) {
                    kdg_sincos_half(8, x, s8, c8);
                    if (kdg_sincos_half_split(n, x, s, c))
                        kdg_sincos_half_split_libm(n, x, s, c);
                } else {
                    kdg_sincos(8, x, s8, c8);
                    if (kdg_sincos_split(n, x, s, c))
                        kdg_sincos_split_libm(n, x, s, c);
                }
                for (j = 0; j < n; ++j, ++points)
                    if (memcmp(&s8[j], &s[slot(j, n)], sizeof s[0]) || memcmp(&c8[j], &c[slot(j, n)], sizeof c[0]))
                        ++differ;
            }
    printf("%ld %ld\n", differ, points);
    return 0;
}
"""




def _runs_avx2() -> bool:
    """Whether this host runs AVX2 and FMA code (x86-64 with both flags in /proc/cpuinfo)."""
    try:
        flags = next(line for line in open("/proc/cpuinfo") if line.startswith("flags")).split()
    except (OSError, StopIteration):
        return False
    return platform.machine() in ("x86_64", "AMD64") and {"avx2", "fma"} <= set(flags)


# and an AVX2 machine's build (no AVX-512: each block of four one vector, eight lanes two)
SPLIT_BUILDS = BUILDS + ([("gcc", ["-O3", "-mavx2", "-mfma", "-ffp-contract=fast"])] if _runs_avx2() else [])


@pytest.mark.parametrize("compiler,flags", SPLIT_BUILDS, ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_split_kernel_is_the_blocks_of_eight_bit_for_bit(compiler, flags, tmp_path):
    """Single calls of four to seven angles (lwr4's and panda's seven) run the split kernel, two
    blocks of four in one loop body: lane for lane the arithmetic of the blocks of eight, so the
    same bits, left where trig_kernel.split_slot says (which the driver's slot() restates)."""
    assert [trig_kernel.split_slot(k, n) for n in trig_kernel.SPLIT for k in range(n)] == \
        [k if k < 4 else k + 8 - n for n in range(4, 8) for k in range(n)]
    differ, points = differing_bits(compiler, flags, tmp_path, SPLIT_DRIVER)
    assert points == 200000 * 2 * (4 + 5 + 6 + 7) and differ == 0


BATCH_DRIVER = r"""
/* kdg_sincos_batch(n, x), the batch variants' one loop over a block's arguments, against the
 * blocks of eight on the same arguments (kdg_sincos(n, x)), both with their libm fix-up: prints
 * the number of results whose bits differ, then the points */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include KERNEL

""" + XORSHIFT + r"""
int main(void)
{
    double x[70], s[70], c[70], sb[70], cb[70];
    const double special[6] = {INFINITY, -INFINITY, NAN, 0.0, -0.0, 4.9406564584124654e-324};
    long differ = 0, points = 0, r;
    int n, j;
    (void)kdg_sincos_half;                 /* included with the kernel, not compared here */
    for (r = 0; r < 4000; ++r)
        for (n = 1; n <= 70; ++n) {
            for (j = 0; j < n; ++j) {
                const uint64_t bits = next();
                const double significand = 1.0 + (double)(bits >> 12)/4503599627370496.0;
                /* exponents 2^-30 .. 2^24: the kernel's range (+-2^20) and beyond it (libm) */
                x[j] = (bits & 1 ? -1.0 : 1.0)*ldexp(significand, (int)(next() % 55) - 30);
                if (r % 100 == 0 && j < 6) x[j] = special[(j + n) % 6];
            }
            kdg_sincos(n, x, s, c);
            kdg_sincos_batch(n, x, sb, cb);
            for (j = 0; j < n; ++j, ++points)
                if (memcmp(&s[j], &sb[j], sizeof s[j]) || memcmp(&c[j], &cb[j], sizeof c[j])) ++differ;
        }
    printf("%ld %ld\n", differ, points);
    return 0;
}
"""


@pytest.mark.parametrize("compiler,flags", SPLIT_BUILDS, ids=lambda v: v if isinstance(v, str) else " ".join(v))
def test_batch_kernel_is_the_blocks_of_eight_bit_for_bit(compiler, flags, tmp_path):
    """The batch variants run the kernel as one loop over a block's 1-64 arguments
    (trig_kernel.batch_kernel_c), vectorised at the compiler's width: lane for lane the
    arithmetic of the blocks of eight, so the same bits, out-of-range lanes by libm alike."""
    differ, points = differing_bits(compiler, flags, tmp_path, BATCH_DRIVER, trig_kernel.batch_kernel_c())
    assert points == 4000 * 70 * 71 // 2 and differ == 0
