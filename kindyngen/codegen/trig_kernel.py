"""The sine/cosine kernel emitted into generated C (``kindyngen generate --trig kernel``).

Measured: the generated kinematics are bound by libm's ``sin``/``cos``, not by arithmetic
(seven sincos pairs took 76 ns of lwr4's fk_hom, all its arithmetic 11 ns). The sines and
cosines of the joint angles are therefore computed together, at the start of a function,
in blocks of four or eight lanes of plain C99 that compilers vectorise:

* range reduction x = k pi/2 + d + tail, k the integer nearest x 2/pi, by Cody-Waite: pi/2
  split into four parts, the first three with 33 significant bits so that k times each is
  exact for |k| < 2^20; the two roundings left are recovered (Fast2Sum), so d + tail carries
  x - k pi/2 to about 2^-140 absolute, enough even for the doubles closest to multiples of
  pi/2 (their |r| is above 2^-62 in the kernel's range);
* polynomials on |d| <= pi/4: sin d = d + d^3 S(d^2), cos d = 1 - d^2/2 + d^4 C(d^2), S and C
  of degree 5, minimax (Remez, :func:`fit_coefficients`) for the relative error of sin and
  the absolute error of cos; their own error is 2^-58 and 2^-64. Degree 4 would miss the
  1-ulp aim (its fit error is about 2^-50); what is cut is the latency, the kernel's chain of
  dependent operations being what a single call waits for (:func:`kernel_latency`): the
  polynomials start from d while the tail is summed, which enters to first order
  (sin(d + tail) = sin d + tail cos d), are evaluated by Estrin's scheme, and their terms are
  summed as balanced trees in the order they become ready. The chain went from 84 to 51 and
  then 47 cycles of :data:`kindyngen.codegen.opcount.LATENCY` (39 with Zen 5's 2-cycle
  addition);
* the quadrant q = k mod 4 in 0..3 picks (+-sin r, +-cos r) by selects, not branches, each
  from one compare (q odd, q >= 2, q in {1, 2}), so that gcc keeps the AVX-512 masks in mask
  registers instead of combining them in general ones; the tail is carried negated, which
  makes sin(-0) = -0 come out of the arithmetic (no select for tiny arguments);
* blocks (:data:`LANES`) of eight consecutive arguments (one AVX-512 vector) for n >= 8, instead
  of a loop over n, whose remainder for n = 7 took half the kernel's time with AVX-512; for
  4 <= n < 8 the split kernel: two blocks of four (one AVX2 vector each), x[0..3] and
  x[n-4..n-1], in one loop body (for seven angles one lane is computed twice), two independent
  chains the core overlaps, its results in arrays of eight (:func:`split_slot`);
* |x| > BOUND, infinities and NaN are computed by libm afterwards, in a loop entered only if a
  block's one range test saw one (for the split kernel, by the caller, so that the kernel is a
  leaf function without the calls' register saves).

Measured alone (the harness of ``python -m benchmarks.latency``, docs/latency.md): on AMD EPYC
Zen 5 (gcc 12.2 ``-O3 -march=native -ffp-contract=off``, load average 5.6-6.0) the blocks took
the latency of a call on seven angles in place (as lwr4's and panda's single calls make it)
from 134 to 92 cycles net and on eight from 62 to 60 cycles; on AMD EPYC Zen 4 the split kernel
took seven angles from 103 to 75 cycles net of the same eight-lane empty kernel, 64 net of an
empty kernel with its own loads and stores (1.37x the bound; eight angles 66, 1.41x;
docs/latency.md, "Seven angles by the split kernel"); the bound is 47 cycles (39 with Zen 5's
2-cycle addition).

Accuracy: at most MAX_ULP ulp from glibc's sin and cos (which are correctly rounded in
practice) for every double, as tests/codegen/test_sincos_kernel.py checks on dense grids, near every
multiple of pi/2 in range, at random and at the special values.

The coefficients below are written out (generation must not depend on a fit's numerics);
``fit_coefficients()`` and ``split_pio2()`` recompute them, and a test checks they agree.
"""
from __future__ import annotations

import re

TRIG_MODES = ("kernel", "libm")
"""kernel: sin/cos of joint angles and of arguments affine in them (half angles) by the emitted
kernel (default); libm: every sin/cos by libm."""

BOUND = 1048576.0
"""Largest |x| the kernel reduces itself (2^20 rad); beyond it, libm. Keeps |k| < 2^20."""

MAX_ULP = 1
"""Largest difference from glibc's sin/cos, in units in the last place of glibc's result."""

TWO_OVER_PI = 0.6366197723675814
PIO2_PARTS = (1.5707963267341256, 6.077100506303966e-11, 2.0222662487111665e-21, 8.4784276603689e-32)
SIN_COEFFS = (-0.16666666666666632, 0.008333333333322424, -0.0001984126982981672,
              2.7557313695144572e-06, -2.5050758640135855e-08, 1.5896827148989416e-10)
COS_COEFFS = (0.0416666666666666, -0.0013888888888874138, 2.4801587289491644e-05,
              -2.755731435518579e-07, 2.0875723676428724e-09, -1.1359669434575456e-11)

R_MAX = "0.7854"
"""Fit interval |r| <= R_MAX, a little over pi/4: k from x*(2/pi) rounded may be one off
the nearest quadrant for x within a few ulp of an odd multiple of pi/4."""

SHIFTER = 6755399441055744.0
"""1.5 * 2^52: y + SHIFTER - SHIFTER rounds y (|y| < 2^51) to an integer in IEEE double."""



def split_pio2():
    """pi/2 as four doubles: three of 33 significant bits (k * part exact for |k| < 2^20), then
    the rounded rest."""
    import mpmath as mp
    with mp.workdps(60):
        rest, parts = mp.pi / 2, []
        for _ in range(3):
            scale = mp.mpf(2) ** (32 - mp.floor(mp.log(abs(rest), 2)))
            part = mp.floor(rest * scale) / scale
            parts.append(float(part))
            rest -= part
        parts.append(float(rest))
        return tuple(parts), float(2 / mp.pi)


def _remez(f, weight, degree, a, b, grid=1500, iterations=20):
    """Coefficients (low order first) of the polynomial minimising max |weight (f - p)| on
    [a, b]: Remez exchange on a grid of ``grid`` + 1 points."""
    import mpmath as mp
    n = degree + 2
    reference = [(a + b) / 2 - (b - a) / 2 * mp.cos(mp.pi * i / (n - 1)) for i in range(n)]
    xs = [a + (b - a) * i / grid for i in range(grid + 1)]
    fs, ws = [f(x) for x in xs], [weight(x) for x in xs]
    index = {x: i for i, x in enumerate(xs)}
    for _ in range(iterations):
        matrix, rhs = mp.matrix(n, n), mp.matrix(n, 1)
        for i, x in enumerate(reference):
            for j in range(degree + 1):
                matrix[i, j] = x ** j
            matrix[i, degree + 1] = (-1) ** i / weight(x)
            rhs[i] = fs[index[x]] if x in index else f(x)
        solution = mp.lu_solve(matrix, rhs)
        coeffs = [solution[j] for j in range(degree + 1)]
        level = abs(solution[degree + 1])
        errors = [w * (fx - mp.polyval(coeffs[::-1], x)) for x, fx, w in zip(xs, fs, ws)]
        extrema, i = [], 0
        while i < len(xs):       # the largest error of each run of one sign
            j, best = i, i
            while j < len(xs) and mp.sign(errors[j]) == mp.sign(errors[i]):
                best = j if abs(errors[j]) > abs(errors[best]) else best
                j += 1
            extrema.append(best)
            i = j
        while len(extrema) > n:  # keep n alternating extrema: drop the smaller end
            extrema.pop(0 if abs(errors[extrema[0]]) < abs(errors[extrema[-1]]) else -1)
        worst = max(abs(e) for e in errors)
        if len(extrema) < n or worst <= level * (1 + mp.mpf("1e-9")):
            break
        reference = [xs[k] for k in extrema]
    return coeffs, worst


def _minimax(degree: int):
    """(S, C, error of S, error of C) as mpmath numbers, polynomials of ``degree`` in z:
    S(z) ~ (sin sqrt z - sqrt z) / z^1.5 weighted by z (the relative error of sin), C(z) ~
    (cos sqrt z - 1 + z/2) / z^2 weighted by z^2 (the absolute error of cos), z in
    [z_max/1000, z_max] (below it the weight makes any error negligible)."""
    import mpmath as mp
    with mp.workdps(50):
        z_max = mp.mpf(R_MAX) ** 2

        def s(z):
            root = mp.sqrt(z)
            return (mp.sin(root) - root) / (z * root)

        def c(z):
            return (mp.cos(mp.sqrt(z)) - 1 + z / 2) / (z * z)

        sin_coeffs, sin_error = _remez(s, lambda z: z, degree, z_max / 1000, z_max)
        cos_coeffs, cos_error = _remez(c, lambda z: z * z, degree, z_max / 1000, z_max)
        return sin_coeffs, cos_coeffs, sin_error, cos_error


def fit_coefficients():
    """The double kernel's (S, C, error of S, error of C) as doubles: :func:`_minimax` of degree 5."""
    sin_coeffs, cos_coeffs, sin_error, cos_error = _minimax(5)
    return (tuple(float(v) for v in sin_coeffs), tuple(float(v) for v in cos_coeffs),
            float(sin_error), float(cos_error))


def _pairs(coeffs, z: str):
    """The pairs (c0 + c1 z), (c2 + c3 z), (c4 + c5 z) of Estrin's scheme as C text: c0 + c1 z +
    ... + c5 z^5 = (c0 + c1 z) + z^2 (c2 + c3 z) + z^4 (c4 + c5 z), three dependent steps after
    z^4 where Horner's scheme has ten."""
    return [f"({coeffs[j]!r} + {coeffs[j + 1]!r}*{z})" for j in range(0, len(coeffs), 2)]


def _steps(suffix: str = "") -> tuple[tuple[str, str], ...]:
    """The kernel's arithmetic for one argument ``xi`` as (name, C expression) in evaluation
    order; every expression is also valid Python (names, literals, + - *, parentheses), which
    :func:`kernel_latency` reads. The quadrant selects follow in :func:`kernel_c`. ``suffix``
    is appended to every name (``xi`` included), for two arguments in one loop body.

    >>> _steps("_a")[0]
    ('k_a', '(xi_a*0.6366197723675814 + 6755399441055744.0) - 6755399441055744.0')
    """
    steps = _plain_steps()
    if not suffix:
        return steps
    names = re.compile(r"\b(" + "|".join(["xi"] + [n for n, _ in steps]) + r")\b")
    return tuple((n + suffix, names.sub(lambda m: m.group(1) + suffix, e)) for n, e in steps)


def _plain_steps() -> tuple[tuple[str, str], ...]:
    p1, p2, p3, p4 = (repr(p) for p in PIO2_PARTS)
    shifter = repr(SHIFTER)
    s0, s1, s2 = _pairs(SIN_COEFFS, "z")
    c0, c1, c2 = _pairs(COS_COEFFS, "z")
    return (
        # k = xi*2/pi rounded to an integer by the shifter 1.5*2^52
        ("k", f"(xi*{TWO_OVER_PI!r} + {shifter}) - {shifter}"),
        # the quadrant q = k mod 4 in 0..3, exact: floor(k/4) = round(k/4 - 3/8) for integer k
        ("q", f"k - 4.0*(((0.25*k - 0.375) + {shifter}) - {shifter})"),
        # d - ntail = xi - k*pi/2: k*part exact for the first three parts, the roundings of the
        # two subtractions recovered exactly (Fast2Sum); the tail is kept negated (ntail = +0
        # for xi = +-0, so that sin(-0) comes out -0 below without a select)
        ("a", f"xi - k*{p1}"),
        ("b", f"a - k*{p2}"),
        ("b_err", f"(a - b) - k*{p2}"),
        ("d", f"b - k*{p3}"),
        ("d_err", f"(b - d) - k*{p3}"),
        ("ntail", f"k*{p4} - (b_err + d_err)"),
        # the polynomials start from d while the tail is still being summed: it enters to
        # first order, sin(d + tail) = sin d + tail cos d, cos(d + tail) = cos d - tail sin d
        ("z", "d*d"),
        ("z2", "z*z"),
        ("z4", "z2*z2"),
        ("u", "d*z"),
        ("half_z", "0.5*z"),
        ("w", "1.0 - half_z"),
        # sin(d + tail) = d + d^3 S(z) + tail (1 - z/2) = d - nsin, S(z) in Estrin's pairs, the
        # terms summed as a balanced tree in the order they become ready (a zero xi gives
        # nsin = +0, so d - nsin = d keeps the sign of -0)
        ("nsin", f"(ntail*w - (u*z4)*{s2}) - (u*{s0} + (u*z2)*{s1})"),
        ("sin_r", "d - nsin"),
        # cos(d + tail) = (1 - z/2) + z^2 C(z) + d ntail, the rounding of 1 - z/2 added back
        ("cos_r", f"w + (((z2*{c0} + z4*{c1}) + (z2*z4)*{c2}) + (((1.0 - w) - half_z) + d*ntail))"),
    )


SELECTS = 2
"""Dependent selects after the polynomials: the quadrant's (sin, cos) swap, then its sign (the
negation itself is a sign flip, counted 0)."""


def kernel_latency(latency=None, half: bool = False) -> int:
    """Cycles from the argument to sin and cos along the kernel's longest chain, with
    :data:`kindyngen.codegen.opcount.LATENCY` (no contraction): the instruction-level latency bound
    of one call. Read from the very expressions :func:`kernel_c` prints; ``half``: of the
    half-angle kernel, whose chain starts with the halving.

    >>> kernel_latency(), kernel_latency(half=True)
    (47, 50)
    """
    import ast
    from .opcount import LATENCY
    lat = dict(LATENCY, **(latency or {}))
    ops = {ast.Add: lat["add"], ast.Sub: lat["add"], ast.Mult: lat["mul"]}
    ready = {"xi": lat["mul"] if half else 0}

    def visit(node):
        if isinstance(node, ast.BinOp):
            return max(visit(node.left), visit(node.right)) + ops[type(node.op)]
        if isinstance(node, ast.Name):
            return ready[node.id]
        if isinstance(node, ast.Constant) or (isinstance(node, ast.UnaryOp)
                                              and isinstance(node.operand, ast.Constant)):
            return 0            # a literal, negative ones included
        raise TypeError(f"kernel step not in + - * of names and literals: {ast.dump(node)}")

    for name, expr in _steps():
        ready[name] = visit(ast.parse(expr, mode="eval").body)
    quadrant = ready["q"] + 2 * lat["add"]      # fabs(q - 2.0) == 1.0: a subtraction, a compare
    return max(ready["sin_r"], ready["cos_r"], quadrant) + SELECTS * lat["select"]


LANES = (8, 4)
"""Lanes of the kernel's blocks: eight doubles are one AVX-512 vector, four one AVX2 vector. A
block is a loop of fixed count over consecutive arguments, which compilers vectorise whole,
without the scalar remainder a loop over n = 7 has (measured: with AVX-512 the remainder took
half the kernel's time, docs/latency.md). Four to seven arguments are two blocks of four in
one loop body, x[0..3] and x[n-4..n-1] (for seven angles x[3] is computed twice, to the same
value): two independent chains the core overlaps, where two blocks one after the other took
1.6x as long on Zen 4 (86 against 55 cycles; docs/latency.md, "Two blocks of four in one loop")."""


def _quadrant(s: str, c: str, suffix: str = "") -> str:
    """The quadrant selects of lane j (the steps' names with ``suffix``), storing to ``s`` and ``c``."""
    q, sin_r, cos_r, sin_q, cos_q = (name + suffix for name in ("q", "sin_r", "cos_r", "sin_q", "cos_q"))
    return f"""\
        const double {sin_q} = fabs({q} - 2.0) == 1.0 ? {cos_r} : {sin_r};
        const double {cos_q} = fabs({q} - 2.0) == 1.0 ? {sin_r} : {cos_r};
        {s} = {q} >= 2.0 ? -{sin_q} : {sin_q};
        {c} = fabs({q} - 1.5) == 0.5 ? -{cos_q} : {cos_q};"""


QUADRANT_COMMENT = """\
        /* x = r + k pi/2: quadrants q = 0, 1, 2, 3 give sin x = s, c, -s, -c and
           cos x = c, -s, -c, s; one compare each, so the masks stay in vector registers */"""


def _body(suffix: str, argument: str) -> str:
    """The steps of one argument as C declarations in a block's loop body."""
    xi = "xi" + suffix
    return "\n".join([f"        const double {xi} = {argument};"]
                     + [f"        const double {n} = {e};" for n, e in _steps(suffix)])


def _in_range(*xs: str) -> str:
    """C: 0.0 if every argument is within the kernel's range, else 1.0 (a lane libm must redo)."""
    return " && ".join(f"fabs({x}) <= {BOUND!r}" for x in xs) + " ? 0.0 : 1.0"


def _block8(name: str, argument: str) -> str:
    """The C of ``name``8: the kernel's steps on eight consecutive arguments (each ``argument``
    of lane j), returning nonzero if a lane needs libm (its range flags summed as a balanced tree)."""
    return f"""static int {name}8(const double *restrict x, double *restrict s, double *restrict c)
{{
    double out[8];
    int j;
    for (j = 0; j < 8; ++j) {{
{_body("", argument.format(j="j"))}
{QUADRANT_COMMENT}
{_quadrant("s[j]", "c[j]")}
        out[j] = {_in_range("xi")};
    }}
    return ((out[0] + out[1]) + (out[2] + out[3])) + ((out[4] + out[5]) + (out[6] + out[7])) != 0.0;
}}
"""


def _split(name: str, argument: str, libm_argument: str, what: str) -> str:
    """The C of ``name``_split, four to seven arguments as two blocks of four in one loop body,
    and of ``name``_split_libm, which redoes the lanes out of the kernel's range by libm. The
    caller runs the second only where the first returns nonzero: kept apart, the kernel is a
    leaf function without the libm calls' register saves and stack frame, which measured
    1.08-1.10x on lwr4's and panda's fk_hom and jacobian (docs/latency.md)."""
    bound = repr(BOUND)
    lo, hi = libm_argument.format(i="i"), libm_argument.format(i="n - 4 + i")
    x_lo, x_hi = what.format(i="i"), what.format(i="n - 4 + i")
    return f"""/* s[i] = sin({x_lo}), c[i] = cos({x_lo}) and s[4 + i] = sin({x_hi}), c[4 + i] = cos({x_hi})
 * for i < 4, 4 <= n <= 8 (s and c hold eight): x[0..3] and x[n-4..n-1] as two blocks of four in
 * one loop body, two independent chains instead of one after the other. Returns nonzero if some
 * |{what.format(i="k")}| exceeds {BOUND:g} or is not a number: its lanes are garbage (no undefined
 * behaviour: all in double) until {name}_split_libm replaces them. */
static int {name}_split(long n, const double *restrict x, double *restrict s, double *restrict c)
{{
    double out[4];
    int j;
    for (j = 0; j < 4; ++j) {{
{_body("_a", argument.format(j="j"))}
{_body("_b", argument.format(j="n - 4 + j"))}
{QUADRANT_COMMENT}
{_quadrant("s[j]", "c[j]", "_a")}
{_quadrant("s[4 + j]", "c[4 + j]", "_b")}
        out[j] = {_in_range("xi_a", "xi_b")};
    }}
    return (out[0] + out[1]) + (out[2] + out[3]) != 0.0;
}}

/* The lanes of {name}_split(n, x, s, c) whose argument is beyond +-{BOUND:g}, infinite or NaN, by libm. */
static void {name}_split_libm(long n, const double *restrict x, double *restrict s, double *restrict c)
{{
    long i;
    for (i = 0; i < 4; ++i) {{
        if (!(fabs({lo}) <= {bound})) {{
            s[i] = sin({lo});
            c[i] = cos({lo});
        }}
        if (!(fabs({hi}) <= {bound})) {{
            s[4 + i] = sin({hi});
            c[4 + i] = cos({hi});
        }}
    }}
}}
"""


def split_slot(k: int, n: int) -> int:
    """Where ``name``_split(n, ...) leaves sin/cos of argument k < n: x[0..3] in lanes 0..3,
    x[n-4..n-1] in lanes 4..7 (for k = 3 of seven, lane 3).

    >>> [split_slot(k, 7) for k in range(7)]
    [0, 1, 2, 3, 5, 6, 7]
    """
    return k if k < 4 else k + 8 - n


SPLIT = range(4, 8)
"""Argument counts that single calls pass to the split kernel (``name``_split) in place of the
loop over blocks; the arrays then hold eight (:func:`split_slot`)."""


def kernel_c(name: str = "kdg_sincos", half: bool = False, blocks: bool = True) -> str:
    """The kernel as static C99 functions: ``name(n, x, s, c)``: s[i] = sin x[i], c[i] = cos x[i]
    for i < n, and ``name``_split(n, x, s, c) for 4 <= n <= 8, which leaves argument k in lane
    :func:`split_slot` of arrays of eight (single calls of 4-7 angles read them there). The
    arrays must not overlap. The work is done in blocks of consecutive arguments: ``name``8 on
    eight (n >= 8; the last block overlaps the one before), the split kernel's two blocks of four
    in one loop body for 4 <= n < 8, through a zero-padded copy for n < 4.

    ``half``: the same kernel of sin and cos of x[i]/2 instead, for the half angles of the
    dual-quaternion functions read in place from q; the halving is its first step, exact
    (a multiplication by 0.5 loses no bit above the subnormals), so each result is the plain
    kernel's on the double 0.5*x[i], bit for bit. ``blocks=False``: the split kernel alone (a
    static function no call uses is a compiler warning)."""
    bound = repr(BOUND)
    argument = "0.5*x[{j}]" if half else "x[{j}]"
    libm_argument = "0.5*x[{i}]" if half else "x[{i}]"
    what = "x[{i}]/2" if half else "x[{i}]"
    whole = what.format(i="i")
    if not blocks:
        return _split(name, argument, libm_argument, what)
    return f"""\
/* The blocks of {name} (below): s[i] = sin({whole}), c[i] = cos({whole}) for eight lanes; they return
 * nonzero if some |{whole}| exceeds {BOUND:g} or is not a number: those lanes are garbage here (no
 * undefined behaviour: all in double) and {name} replaces them by libm. codegen/trig_kernel.py's
 * _steps explains each step. */
{_block8(name, argument)}
{_split(name, argument, libm_argument, what)}
/* s[i] = sin({whole}), c[i] = cos({whole}) for i < n, within {MAX_ULP} ulp of glibc (kindyngen/codegen/trig_kernel.py
 * explains the method and where its constants come from): blocks of eight lanes (n >= 8) or
 * the split kernel's two blocks of four without a branch or a call, which compilers vectorise;
 * arguments beyond +-{BOUND:g}, infinities and NaN take libm afterwards, in a loop entered only
 * if a block saw one. Needs IEEE double arithmetic as C99 specifies it: no -ffast-math. */
static void {name}(long n, const double *restrict x, double *restrict s, double *restrict c)
{{
    long i;
    int out = 0;
    if (n >= 8) {{
        for (i = 0; i + 8 <= n; i += 8)
            out |= {name}8(x + i, s + i, c + i);
        if (i < n)
            out |= {name}8(x + n - 8, s + n - 8, c + n - 8);
        if (out)
            for (i = 0; i < n; ++i)
                if (!(fabs({libm_argument.format(i="i")}) <= {bound})) {{
                    s[i] = sin({libm_argument.format(i="i")});
                    c[i] = cos({libm_argument.format(i="i")});
                }}
    }} else if (n >= 4) {{
        double sb[8], cb[8];
        if ({name}_split(n, x, sb, cb))
            {name}_split_libm(n, x, sb, cb);
        for (i = 0; i < n; ++i) {{
            s[i] = sb[i < 4 ? i : i + 8 - n];
            c[i] = cb[i < 4 ? i : i + 8 - n];
        }}
    }} else if (n > 0) {{
        double xb[4] = {{0.0, 0.0, 0.0, 0.0}}, sb[8], cb[8];
        for (i = 0; i < n; ++i)
            xb[i] = x[i];
        if ({name}_split(4, xb, sb, cb))
            {name}_split_libm(4, xb, sb, cb);
        for (i = 0; i < n; ++i) {{
            s[i] = sb[i];
            c[i] = cb[i];
        }}
    }}
}}
"""


# -- single precision (``generate --scalar float``) -------------------------------------------
# The same method in float arithmetic: the float kernel is the double one with its constants
# rounded once to float from their exact values (pi/2 split for float, minimax polynomials of
# degree 3 fitted for float's precision) for |x| <= FLOAT_BOUND, and beyond it a Payne-Hanek
# reduction in integer arithmetic (the bits of 2/pi as a table), so that every finite float
# stays in the kernel: no libm sinf/cosf is called or linked, and an angle's cost is bounded.

FLOAT_BOUND = 1024.0
"""Largest |x| the float kernel reduces by Cody-Waite (2^10 rad): |k| < 2^10, so k times each of
the first three parts of pi/2 (14 significant bits) is exact in float. Beyond it (and for
infinities and NaN) the Payne-Hanek reduction of :func:`kernel_c_float`."""

FLOAT_MAX_ULP = 1
"""Largest difference of the float kernel from the correctly rounded sin and cos, in ulp of the
float result, for every finite float, in round-to-nearest (tests/runtime/test_float_code.py and
tests/runtime/test_firmware.py check it)."""

FLOAT_TWO_OVER_PI = "0.63661975f"
FLOAT_PIO2_PARTS = ("1.5706787f", "0.000117614865f", "9.920313e-10f", "6.223372e-14f")
FLOAT_SIN_COEFFS = ("-0.16666667f", "0.008333329f", "-0.00019839335f", "2.7183114e-06f")
FLOAT_COS_COEFFS = ("0.041666668f", "-0.0013888883f", "2.479952e-05f", "-2.7210237e-07f")

FLOAT_TINY = "0.00024414062f"
"""2^-12: below it sinf x = x and cosf x = 1 after rounding."""

TWO_OVER_PI_WORDS = ("0xA2F9836Eu", "0x4E441529u", "0xFC2757D1u", "0xF534DDC0u", "0xDB629599u", "0x3C439041u",
                     "0xFE5163ABu")
"""The first 224 bits of 2/pi's binary fraction, 32 per word (:func:`two_over_pi_words`): the
Payne-Hanek reduction of a float of exponent e (x = m 2^(e-23), m < 2^24, e <= 127) reads
its bits e - 24 to e + 71; the bits before weigh multiples of 4 quarter turns."""

PIO2_Q31 = "0xC90FDAA2u"
"""pi/2 in units of 2^-31, rounded down (3373259426.13...): the reduced fraction of a quarter turn
times this is the reduced argument, in integer arithmetic."""


def two_over_pi_words() -> tuple[str, ...]:
    """2/pi's binary fraction as seven 32-bit words (C literals), recomputed from mpmath.

    >>> two_over_pi_words()[0]
    '0xA2F9836Eu'
    """
    import mpmath as mp
    with mp.workprec(400):
        value, words = 2 / mp.pi, []
        for _ in range(len(TWO_OVER_PI_WORDS)):
            value *= 2 ** 32
            word = int(mp.floor(value))
            words.append(f"0x{word:08X}u")
            value -= word
        return tuple(words)


def pio2_q31() -> str:
    """floor(pi/2 2^31) as a C literal, recomputed from mpmath.

    >>> pio2_q31()
    '0xC90FDAA2u'
    """
    import mpmath as mp
    with mp.workprec(100):
        return f"0x{int(mp.floor(mp.pi / 2 * 2 ** 31)):08X}u"


def split_pio2_float():
    """pi/2 as four floats, three of 14 significant bits, then the rest rounded; and 2/pi
    rounded; as C literals."""
    import mpmath as mp
    from .float32 import c_float
    with mp.workdps(60):
        rest, parts = mp.pi / 2, []
        for _ in range(3):
            scale = mp.mpf(2) ** (13 - mp.floor(mp.log(abs(rest), 2)))
            part = mp.floor(rest * scale) / scale
            parts.append(c_float(_fraction(part)))
            rest -= part
        parts.append(c_float(_fraction(rest)))
        return tuple(parts), c_float(_fraction(2 / mp.pi))


def _fraction(value):
    """An mpmath number as an exact Fraction."""
    from fractions import Fraction
    sign, man, exp, _ = value._mpf_
    return (-1) ** sign * Fraction(int(man)) * Fraction(2) ** int(exp)


def fit_coefficients_float():
    """(S, C) for float: :func:`_minimax` of degree 3, each coefficient rounded once to float
    from its exact value, as C literals."""
    import mpmath as mp
    from .float32 import c_float
    sin_coeffs, cos_coeffs, _, _ = _minimax(3)
    with mp.workdps(50):
        return (tuple(c_float(_fraction(mp.mpf(v))) for v in sin_coeffs),
                tuple(c_float(_fraction(mp.mpf(v))) for v in cos_coeffs))


def _horner_text(coeffs, z: str) -> str:
    text = coeffs[-1]
    for c in reversed(coeffs[:-1]):
        text = f"{c} + {z}*({text})"
    return text


def _reduce_large_float(name: str) -> str:
    """The C of ``name``_reduce, the Payne-Hanek reduction of one float beyond FLOAT_BOUND."""
    words = ", ".join(TWO_OVER_PI_WORDS)
    return f"""\
/* x = (k + f) pi/2 for |x| > {FLOAT_BOUND:g}, an infinity or NaN (Payne-Hanek, integer arithmetic):
 * returns k mod 4 and *r + *rlo = f pi/2 (|f| <= 1/2) to about 2^-29 of its size; for an infinity or
 * NaN, 0 and NaN. x = m 2^(e-23) with m < 2^24, 10 <= e <= 127; x 2/pi mod 4 needs only 2/pi's bits
 * e - 24 to e + 71 (earlier ones weigh multiples of 4, later ones under 2^-71), which the table
 * holds after 32 zero bits. Its cost does not depend on x beyond the exponent's table position. */
static unsigned {name}_reduce(float x, float *r, float *rlo)
{{
    static const uint32_t bits[8] = {{0x00000000u, {words}}};
    union {{ float f; uint32_t u; }} v, scale;
    uint32_t m, w2, w1, w0, top, hi, lo;
    uint64_t p, a, prod;
    unsigned k, e, word, shift, sh;
    v.f = x;
    e = (v.u >> 23) & 0xFFu;
    if (e == 0xFFu) {{
        *r = x - x;          /* an infinity or NaN: sin and cos are NaN */
        *rlo = 0.0f;
        return 0u;
    }}
    m = (v.u & 0x7FFFFFu) | 0x800000u;
    /* bit e - 24 of 2/pi (e the unbiased exponent, e = biased - 127) is bit e + 7 of the table */
    word = (e - 127u + 7u) >> 5;
    shift = (e - 127u + 7u) & 31u;
    w2 = (uint32_t)(((uint64_t)bits[word] << 32 | bits[word + 1]) >> (32u - shift));
    w1 = (uint32_t)(((uint64_t)bits[word + 1] << 32 | bits[word + 2]) >> (32u - shift));
    w0 = (uint32_t)(((uint64_t)bits[word + 2] << 32 | bits[word + 3]) >> (32u - shift));
    /* p = x 2/pi mod 4 in units of 2^-62: the product's bits 32..95 (mod 2^96) */
    p = ((uint64_t)(m * w2) << 32) + (uint64_t)m * w1 + (((uint64_t)m * w0) >> 32);
    k = (unsigned)((p + ((uint64_t)1 << 61)) >> 62);     /* the nearest quarter turn, 0..4 */
    p -= (uint64_t)k << 62;                              /* f 2^62, two's complement */
    a = (p >> 63) ? (uint64_t)0 - p : p;                 /* |f| 2^62 <= 2^61 */
    /* normalised to [2^60, 2^61) by sh bits: six steps whatever a is */
    sh = a < ((uint64_t)1 << 29) ? 32u : 0u;
    a <<= sh;
    sh += a < ((uint64_t)1 << 45) ? 16u : 0u;
    a <<= sh & 16u;
    sh += a < ((uint64_t)1 << 53) ? 8u : 0u;
    a <<= sh & 8u;
    sh += a < ((uint64_t)1 << 57) ? 4u : 0u;
    a <<= sh & 4u;
    sh += a < ((uint64_t)1 << 59) ? 2u : 0u;
    a <<= sh & 2u;
    sh += a < ((uint64_t)1 << 60) ? 1u : 0u;
    a <<= sh & 1u;
    /* |f| pi/2 = top 2^-(31 + sh) * pi/2 2^31 2^-31: the product's 48 leading bits as two floats */
    top = (uint32_t)(a >> 29);
    prod = (uint64_t)top * {PIO2_Q31};
    sh += (prod >> 63) ? 0u : 1u;
    prod <<= (prod >> 63) ? 0u : 1u;
    hi = (uint32_t)(prod >> 40);
    lo = (uint32_t)(prod >> 16) & 0xFFFFFFu;
    scale.u = (127u - 24u - sh) << 23;                   /* 2^(-24 - sh), a normal float */
    *r = (float)hi * scale.f;
    *rlo = (float)lo * scale.f * 5.9604645e-08f;          /* times 2^-24 */
    if ((p >> 63) != (v.u >> 31)) {{                      /* f < 0 xor x < 0 */
        *r = -*r;
        *rlo = -*rlo;
    }}
    return (v.u >> 31) ? (0u - k) & 3u : k & 3u;          /* sin(-x) = -sin x, cos(-x) = cos x */
}}
"""


def kernel_c_float(name: str = "kdg_sincosf") -> str:
    """The float kernel as static C99 functions: ``name(n, x, s, c)``: s[i] = sinf x[i],
    c[i] = cosf x[i] for i < n; the double kernel's steps in float (see kernel_c) for
    |x| <= FLOAT_BOUND, ``name``_reduce beyond, so every finite float stays in the kernel.

    Independent of the rounding mode where that is cheap: the quadrant k is x 2/pi rounded to
    the nearest integer by a conversion (which truncates in every mode) and an exact
    correction, so that in a directed rounding mode the reduced argument stays within the
    polynomials' interval and the quadrant's selects see an exact integer; only the roundings
    of the arithmetic (and Fast2Sum's recovery of them) change, by a few ulp. The double
    kernel's float shifter (k = (y + 1.5 2^23) - 1.5 2^23) picked a wrong quadrant there."""
    p1, p2, p3, p4 = FLOAT_PIO2_PARTS
    return f"""\
{_reduce_large_float(name)}
/* s[i] = sin(x[i]), c[i] = cos(x[i]) for i < n in float, within {FLOAT_MAX_ULP} ulp of the correctly
 * rounded values for every float (kindyngen/codegen/trig_kernel.py: the double kernel's method, its
 * constants rounded to float, for |x| <= {FLOAT_BOUND:g}; Payne-Hanek beyond); no libm call. Needs IEEE
 * float arithmetic: no -ffast-math (the .c refuses it); rounding to nearest for the stated ulp bound,
 * a few ulp more in the other rounding modes. */
static void {name}(long n, const float *restrict x, float *restrict s, float *restrict c)
{{
    long i;
    for (i = 0; i < n; ++i) {{
        const float xi = x[i];
        float r, rlo, sin_r, cos_r, sin_q, cos_q;
        unsigned q;
        if (fabsf(xi) <= {FLOAT_BOUND!r}f) {{
            /* k = xi*2/pi rounded to the nearest integer (ties away from 0): the conversion truncates
               in any rounding mode, the fraction y - trunc(y) is exact */
            const float y = xi*{FLOAT_TWO_OVER_PI};
            const int kt = (int)y;
            const float frac = y - (float)kt;
            const int ki = kt + (frac >= 0.5f) - (frac <= -0.5f);
            const float k = (float)ki;
            /* r + rlo = xi - k*pi/2 (Cody-Waite, the roundings recovered by Fast2Sum) */
            const float a = xi - k*{p1};
            const float b = a - k*{p2};
            const float b_err = (a - b) - k*{p2};
            const float d = b - k*{p3};
            const float d_err = (b - d) - k*{p3};
            const float tail = (b_err + d_err) - k*{p4};
            r = d + tail;
            rlo = (d - r) + tail;
            q = (unsigned)ki & 3u;
        }} else {{
            q = {name}_reduce(xi, &r, &rlo);
        }}
        {{
            const float z = r*r;
            const float half_z = 0.5f*z;
            const float w = 1.0f - half_z;
            sin_r = r + (r*z*({_horner_text(FLOAT_SIN_COEFFS, "z")}) + rlo*(1.0f - 0.5f*z));
            cos_r = w + (((1.0f - w) - half_z) + (z*z*({_horner_text(FLOAT_COS_COEFFS, "z")}) - r*rlo));
        }}
        /* x = r + k pi/2: quadrants q = 0, 1, 2, 3 give sin x = s, c, -s, -c and cos x = c, -s, -c, s */
        sin_q = (q & 1u) ? cos_r : sin_r;
        cos_q = (q & 1u) ? sin_r : cos_r;
        s[i] = fabsf(xi) < {FLOAT_TINY} ? xi : ((q & 2u) ? -sin_q : sin_q);
        c[i] = fabsf(xi) < {FLOAT_TINY} ? 1.0f : (((q + 1u) & 2u) ? -cos_q : cos_q);
    }}
}}
"""
