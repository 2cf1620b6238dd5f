"""The identification paper's own linear parametrisation (Sect. V-VI): the gravity vector and
the inertia stack expanded as sums of products of sines and cosines of the joint angles,
each product times a coefficient in the paper's parameters (m_i, c_i, I_i about the CoM, the
DH lengths kept as symbols), and "all the single products of trigonometric functions"
collected, "taking then their coefficients when different" (eq. 17, 18, 28).

This is the one place in KinDynGen where expressions are expanded on purpose: it is what the
paper did.  It stays cheap because everything is a polynomial from the start: ``cos q_i``,
``sin q_i`` are the plain symbols ``C{i}``, ``S{i}``, and each step of the moving-frames
recursion is expanded at once (symengine), so no large unexpanded tree is ever expanded.

Collection rule (what counts as one column):

* each entry (g_j, or M_jk of the lower triangle) is expanded and grouped by trigonometric
  monomial ``prod C_i^a_i S_i^b_i``; the coefficient of a monomial is a polynomial in the
  paper's parameters and DH lengths;
* coefficients equal up to a numeric factor (sign, 2, g0, ...) are one parameter: it is
  normalised (rational content removed, first term positive in a fixed order), and the numeric
  factor goes into the regressor entry;
* optionally ``S_i^2`` is first replaced by ``1 - C_i^2`` (``reduce_squares``): without it,
  ``I_xx C^2 + I_yy S^2`` gives two coefficients, with it ``I_yy + (I_xx - I_yy) C^2``; the
  paper does not say which form its Maple expressions had, and the column count depends on it.

:func:`collect_gravity` and :func:`collect_inertia` return a :class:`Collection`; its
``numeric_rank`` drops dependent columns as the paper did (pivoted QR on random samples).

Example:

>>> from kindyngen.readers.yaml_description import load_robot
>>> c = collect_gravity(load_robot("robots/lwr4.yaml"))      # doctest: +SKIP
>>> len(c.coefficients)                                      # doctest: +SKIP
12
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import symengine as se
import sympy

from kindyngen.algorithms.base_parameters import numeric_rank
from kindyngen.model.robot_model import RobotModel

ZERO = se.Integer(0)


# ----------------------------------------------------------------------------- symbols

def trig_symbols(n: int):
    """``C1..Cn`` (cos q_i) and ``S1..Sn`` (sin q_i), 1-based like the paper."""
    return tuple(se.Symbol(f"C{i + 1}") for i in range(n)), tuple(se.Symbol(f"S{i + 1}") for i in range(n))


def link_symbols(i: int):
    """Paper parameters of link i (1-based): m, (cx, cy, cz), inertia about the CoM as a
    symmetric 3x3 of ``I{i}xx, I{i}xy, ...``."""
    m = se.Symbol(f"m{i}")
    c = [se.Symbol(f"c{i}{a}") for a in "xyz"]
    I = {k: se.Symbol(f"I{i}{k}") for k in ("xx", "yy", "zz", "xy", "xz", "yz")}
    Imat = [[I["xx"], I["xy"], I["xz"]], [I["xy"], I["yy"], I["yz"]], [I["xz"], I["yz"], I["zz"]]]
    return m, c, Imat


def length_symbols(model: RobotModel) -> dict:
    """Each non-zero DH length as a symbol ``a{i}`` / ``d{i}`` (1-based row of the table),
    mapped to its value.  (The paper's d1, d2 of the LWR are rows 3 and 5: ``d3``, ``d5``.)"""
    out = {}
    for i, joint in enumerate(model.joints, start=1):
        for name, value in (("a", joint.a), ("d", joint.d)):
            if sympy.sympify(value) != 0:
                out[se.Symbol(f"{name}{i}")] = sympy.sympify(value)
    return out


def _exact(v):
    return se.sympify(sympy.nsimplify(v) if isinstance(v, float) else sympy.sympify(v))


def _cos_sin(angle):
    angle = sympy.sympify(angle)
    return _exact(sympy.cos(angle)), _exact(sympy.sin(angle))


def _expand3(v):
    return [se.expand(x) for x in v]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _mat_t_vec(R, v):
    return [se.Add(*(R[k][r] * v[k] for k in range(3))) for r in range(3)]


def _mat_vec(R, v):
    return [se.Add(*(R[r][k] * v[k] for k in range(3))) for r in range(3)]


def _matmul(A, B):
    return [[se.expand(se.Add(*(A[r][k] * B[k][c] for k in range(3)))) for c in range(3)] for r in range(3)]


def dh_frames(model: RobotModel):
    """Per joint i: (R_{i-1,i}, p_{i-1,i}) with trig symbols and length symbols, and the
    flag whether joint i turns about z_{i-1} (standard DH) or z_i (modified DH)."""
    C, S = trig_symbols(model.n)
    lengths = {str(k): k for k in length_symbols(model)}
    out = []
    for i, joint in enumerate(model.joints):
        ca, sa = _cos_sin(joint.alpha)
        co, so = _cos_sin(joint.offset)
        c = se.expand(C[i] * co - S[i] * so)       # cos(q + offset)
        s = se.expand(S[i] * co + C[i] * so)
        a = lengths.get(f"a{i + 1}", ZERO)
        d = lengths.get(f"d{i + 1}", ZERO)
        if model.convention == "standard":     # Rz(theta) Tz(d) Tx(a) Rx(alpha)
            R = [[c, -s * ca, s * sa], [s, c * ca, -c * sa], [ZERO, sa, ca]]
            p = [a * c, a * s, d]
        else:                                  # Rx(alpha) Tx(a) Rz(theta) Tz(d)
            R = [[c, -s, ZERO], [ca * s, ca * c, -sa], [sa * s, sa * c, ca]]
            p = [a, -sa * d, ca * d]
        out.append(([[se.expand(x) for x in row] for row in R], _expand3(p)))
    return out


# ----------------------------------------------------------------------------- the paper's model

@lru_cache(maxsize=None)
def paper_dynamics(model: RobotModel):
    """Gravity vector g (list) and inertia matrix M (nested lists) of the paper's method,
    expanded polynomials in C_i, S_i, the paper's parameters and the DH length symbols:
    positions by the product of DH matrices (eq. 12), velocities by moving frames (steps
    a-d), ``T`` by Koenig (eq. 13), ``M = Hessian of T`` taken as ``sum_i m_i Jv_i^T Jv_i +
    Jw_i^T I_i Jw_i`` with the frame-i velocity Jacobians, ``g = grad U`` (eq. 14) with
    ``d/dq_i = -S_i d/dC_i + C_i d/dS_i``."""
    n = model.n
    C, S = trig_symbols(n)
    frames = dh_frames(model)
    gamma = [_exact(v) for v in model.gravity]
    # velocities: columns (one per qd_k) of omega_i and v_i (origin), in frame i axes
    w = [[ZERO] * n for _ in range(3)]
    v = [[ZERO] * n for _ in range(3)]
    R0 = [[se.Integer(int(r == c)) for c in range(3)] for r in range(3)]
    o0 = [ZERO, ZERO, ZERO]
    U_terms = []
    M = [[ZERO] * n for _ in range(n)]
    for i, (R, p) in enumerate(frames):
        m, c, Imat = link_symbols(i + 1)
        z = [ZERO, ZERO, se.Integer(1)]
        if model.convention == "standard":
            # a) w_{i-1} + qd_i z_{i-1}; b) v_i = R^T (v_{i-1} + w x p); c) w_i = R^T w
            cols_w = [[w[r][k] + (z[r] if k == i else ZERO) for r in range(3)] for k in range(n)]
            cols_v = [[v[r][k] for r in range(3)] for k in range(n)]
            new_v = [_expand3(_mat_t_vec(R, [a + b for a, b in zip(cv, _cross(cw, p))])) for cv, cw in zip(cols_v, cols_w)]
            new_w = [_expand3(_mat_t_vec(R, cw)) for cw in cols_w]
        else:
            cols_w = [[w[r][k] for r in range(3)] for k in range(n)]
            cols_v = [[v[r][k] for r in range(3)] for k in range(n)]
            new_v = [_expand3(_mat_t_vec(R, [a + b for a, b in zip(cv, _cross(cw, p))])) for cv, cw in zip(cols_v, cols_w)]
            new_w = [_expand3(_mat_t_vec(R, cw)) for cw in cols_w]
            new_w[i] = [x + zz for x, zz in zip(new_w[i], z)]
        w = [[new_w[k][r] for k in range(n)] for r in range(3)]
        v = [[new_v[k][r] for k in range(n)] for r in range(3)]
        # d) CoM velocity columns
        vc = [_expand3([a + b for a, b in zip(new_v[k], _cross(new_w[k], c))]) for k in range(i + 1)]
        wc = new_w[:i + 1]
        for j in range(i + 1):
            for k in range(j + 1):
                Iw = _mat_vec(Imat, wc[k])
                M[j][k] = M[j][k] + m * se.Add(*(vc[j][r] * vc[k][r] for r in range(3))) \
                    + se.Add(*(wc[j][r] * Iw[r] for r in range(3)))
        # potential energy: -m gamma . (o_i + R_0i c)
        o0 = _expand3([a + b for a, b in zip(o0, _mat_vec(R0, p))])
        R0 = _matmul(R0, R)
        rc = _expand3([a + b for a, b in zip(o0, _mat_vec(R0, c))])
        U_terms.append(-m * se.Add(*(gg * x for gg, x in zip(gamma, rc))))
    U = se.expand(se.Add(*U_terms))
    g = [se.expand(-S[i] * se.diff(U, C[i]) + C[i] * se.diff(U, S[i])) for i in range(n)]
    M = [[se.expand(M[j][k]) for k in range(j + 1)] for j in range(n)]
    return g, M


# ----------------------------------------------------------------------------- collection

@dataclass(frozen=True)
class Collection:
    """The paper's coefficients of one quantity.

    ``rows``: names of the rows (``g1..gn`` or ``M11, M21, M22, ...``, 1-based as in the
    paper); ``coefficients``: the distinct normalised coefficients (sympy, in the paper's
    parameters and the DH length symbols), sorted by their text; ``entries``: per row a dict
    column index -> regressor entry (sympy polynomial in C_i, S_i; numeric factors included);
    ``terms``: number of (row, trigonometric monomial) pairs collected."""

    quantity: str
    rows: tuple[str, ...]
    coefficients: tuple[sympy.Expr, ...]
    entries: tuple[dict, ...]
    terms: int
    n: int
    lengths: dict

    def regressor(self) -> sympy.Matrix:
        Y = sympy.zeros(len(self.rows), len(self.coefficients))
        for r, row in enumerate(self.entries):
            for c, e in row.items():
                Y[r, c] = e
        return Y

    def numeric(self, q: np.ndarray) -> np.ndarray:
        """The regressor at joint angles ``q`` (samples x n): samples x rows x columns."""
        q = np.atleast_2d(np.asarray(q, float))
        C, S = trig_symbols(self.n)
        args = [sympy.Symbol(str(x)) for x in C + S]
        cells = [(r, col, e) for r, row in enumerate(self.entries) for col, e in row.items()]
        fn = sympy.lambdify(args, [e for _, _, e in cells], "numpy")
        values = fn(*np.concatenate([np.cos(q), np.sin(q)], axis=1).T)
        out = np.zeros((q.shape[0], len(self.rows), len(self.coefficients)))
        for (r, col, _), v in zip(cells, values):
            out[:, r, col] = v
        return out

    def numeric_rank(self, samples: int = 200, seed: int = 0, lower=None, upper=None) -> int:
        """Rank of the stacked regressor at random configurations (the paper's column drop)."""
        rng = np.random.default_rng(seed)
        lo = -np.pi if lower is None else lower
        hi = np.pi if upper is None else upper
        A = self.numeric(rng.uniform(lo, hi, size=(samples, self.n)))
        return numeric_rank(A.reshape(-1, A.shape[-1]))[0]

    def value(self, substitutions: dict) -> np.ndarray:
        """Coefficients evaluated at numbers for the paper's parameters (and lengths)."""
        subs = {sympy.Symbol(str(k)): v for k, v in {**self.lengths, **substitutions}.items()}
        return np.array([float(k.xreplace(subs)) for k in self.coefficients])


def _split(term):
    """term -> (trig monomial, rest) for one expanded product."""
    trig, rest = [], []
    factors = term.args if isinstance(term, se.Mul) else (term,)
    for f in factors:
        base = f.args[0] if isinstance(f, se.Pow) else f
        if base.is_Symbol and str(base)[0] in "CS" and str(base)[1:].isdigit():
            trig.append(f)
        else:
            rest.append(f)
    return se.Mul(*trig), se.Mul(*rest)


MERGES = ("factor", "sign", "exact")


def _normalise(coefficient: sympy.Expr, merge: str = "factor"):
    """(normalised coefficient, numeric factor).  ``merge``: "factor" (rational content
    removed, first term by text positive: ``2 I_xy`` and ``-I_xy`` are one coefficient),
    "sign" (only the sign normalised), "exact" (coefficients must be identical, as a Maple
    set of ``coeffs`` would have them)."""
    coefficient = sympy.expand(coefficient)
    if merge == "exact":
        return coefficient, sympy.Integer(1)
    if merge == "factor":
        content, primitive = coefficient.as_content_primitive()
    else:
        content, primitive = sympy.Integer(1), coefficient
    terms = sorted(sympy.Add.make_args(primitive), key=sympy.default_sort_key)
    lead = terms[0].as_coeff_Mul()[0]
    sign = -1 if lead < 0 else 1
    return sympy.expand(sign * primitive), content * sign


def collect(quantity: str, rows: tuple[str, ...], exprs, n: int, lengths: dict,
            reduce_squares: bool = False, substitutions: dict | None = None, merge: str = "factor") -> Collection:
    """Group every expanded entry by trigonometric monomial and merge equal coefficients
    (``merge``: see :func:`_normalise`)."""
    if merge not in MERGES:
        raise ValueError(f"merge must be one of {MERGES}, got {merge!r}")
    C, S = trig_symbols(n)
    square = {s ** 2: 1 - c ** 2 for c, s in zip(C, S)}
    subs = {se.Symbol(str(k)): se.sympify(v) for k, v in (substitutions or {}).items()}
    per_row = []
    terms = 0
    for e in exprs:
        if subs:
            e = se.expand(e.xreplace(subs))
        if reduce_squares:
            e = se.expand(e.subs(square))
        groups: dict = {}
        for term in se.Add.make_args(e) if isinstance(e, se.Add) else ((e,) if e != 0 else ()):
            mono, rest = _split(term)
            groups[mono] = groups.get(mono, ZERO) + rest
        row = []
        for mono, coeff in groups.items():
            coeff = se.expand(coeff)
            if coeff == 0:
                continue
            terms += 1
            row.append((sympy.sympify(mono), sympy.sympify(coeff)))
        per_row.append(row)
    normalised = {}
    for row in per_row:
        for mono, coeff in row:
            key, factor = _normalise(coeff, merge)
            normalised.setdefault(key, None)
    coefficients = tuple(sorted(normalised, key=lambda k: (len(str(k)), str(k))))
    index = {k: i for i, k in enumerate(coefficients)}
    entries = []
    for row in per_row:
        out: dict = {}
        for mono, coeff in row:
            key, factor = _normalise(coeff, merge)
            col = index[key]
            out[col] = out.get(col, 0) + factor * mono
        entries.append(out)
    return Collection(quantity, tuple(rows), coefficients, tuple(entries), terms, n,
                      {k: v for k, v in lengths.items()})


def collect_gravity(model: RobotModel, drop_zero_rows: bool = True, reduce_squares: bool = False,
                    merge: str = "factor") -> Collection:
    """The paper's pi_g: coefficients of the trigonometric products in g (eq. 17, 28); a row
    that vanishes identically (g_1 on a level base) is dropped as in the paper."""
    g, _ = paper_dynamics(model)
    rows = [(f"g{i + 1}", e) for i, e in enumerate(g) if not (drop_zero_rows and e == 0)]
    return collect("g", tuple(r for r, _ in rows), [e for _, e in rows], model.n, length_symbols(model),
                   reduce_squares, merge=merge)


def eq27(n: int) -> dict:
    """The paper's eq. 27 for the last link: ``I_nxz = m_n c_nx c_nz``, ``I_nyz = m_n c_ny c_nz``
    (what ``M_{n,n-1} = 0`` forces)."""
    m = sympy.Symbol(f"m{n}")
    cx, cy, cz = (sympy.Symbol(f"c{n}{a}") for a in "xyz")
    return {sympy.Symbol(f"I{n}xz"): m * cx * cz, sympy.Symbol(f"I{n}yz"): m * cy * cz}


def collect_inertia(model: RobotModel, reduce_squares: bool = False, use_eq27: bool = False,
                    merge: str = "factor", numeric_lengths: bool = False) -> Collection:
    """The paper's pi_m: coefficients of the trigonometric products in the inertia stack
    (lower triangle row by row, eq. 18), optionally after eq. 27."""
    _, M = paper_dynamics(model)
    n = model.n
    rows = tuple(f"M{j + 1}{k + 1}" for j in range(n) for k in range(j + 1))
    exprs = [M[j][k] for j in range(n) for k in range(j + 1)]
    lengths = length_symbols(model)
    if numeric_lengths:
        values = {k: se.sympify(v) for k, v in lengths.items()}
        exprs = [se.expand(e.xreplace(values)) for e in exprs]
        lengths = {}
    return collect("m", rows, exprs, n, lengths, reduce_squares, eq27(n) if use_eq27 else None, merge)


def inertia_column_counts(model: RobotModel, samples: int = 60, merges: tuple[str, ...] = MERGES) -> list[dict]:
    """Columns and numeric rank of the paper's Y_m under every collection choice (merge rule of
    ``merges``, ``S^2 -> 1 - C^2`` or not, DH lengths symbolic or numeric, eq. 27 or not): the
    paper's 108 -> 74 depends on which form its expressions had."""
    out = []
    for numeric_lengths in (False, True):
        for merge in merges:
            for reduce_squares in (False, True):
                for use_eq27 in (False, True):
                    c = collect_inertia(model, reduce_squares, use_eq27, merge, numeric_lengths)
                    out.append({"lengths": "numeric" if numeric_lengths else "symbolic", "merge": merge,
                                "reduce_squares": reduce_squares, "eq27": use_eq27,
                                "columns": len(c.coefficients), "rank": c.numeric_rank(samples)})
    return out
