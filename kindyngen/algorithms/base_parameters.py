"""Base parameters of a linear regressor ``y = Y(x) p``: which columns are independent, how the
others fold into them (the grouping of the identification paper, eq. 23), and what that means
for the parameters.

Method (numeric, then exact):

1. Evaluate the full regressor (10 n columns, every barycentric parameter) at random samples
   (fixed seed) and stack the rows; its numeric rank comes from a QR factorisation with column
   pivoting (``scipy.linalg.qr(pivoting=True)``), ``|R_kk| > RANK_TOL |R_00|``.
2. Choose the independent columns in the natural parameter order (link 1 first; per link
   ``m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz``): column k is dependent when it lies in the
   span of the columns before it (a QR factorisation without pivoting, ``|R_kk|`` against the
   column's norm, Gautier's method).  A later link's mass, first moment and inertia terms
   therefore fold into earlier links, which gives the classical grouped parameters
   (``Ixx2R = Ixx2 - Iyy2 + ...``).  The count is checked against the rank of step 1.
3. Every dependent column is ``D_j = sum_i t_ij D_i`` over the independent ones (least squares
   on the samples); each ``t_ij`` is made rational (:func:`rationalize`: over a known common
   denominator when the caller has one (for rigid-body regressors the squared lcm of the DH
   lengths' denominators: most ``t`` are polynomials of degree at most 2 in the lengths),
   else the simplest fraction with a small denominator (``t = 1/d`` occurs too), else it
   stays a float) and every
   relation is verified at fresh samples to ``VERIFY_TOL`` relative to the regressor's
   scale.  Then ``Y p = Y_B (p_B + T p_D)``: base parameter i is
   ``K_i^R = K_i + sum_j t_ij K_j`` (paper eq. 23), named ``K_i`` when nothing folds into it
   and ``K_iR`` otherwise.

Example:

>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> a = rng.normal(size=(20, 2))
>>> A = np.column_stack([a[:, 0], a[:, 1], 2 * a[:, 0] - a[:, 1] / 4])
>>> b = find_base_parameters(lambda s: A[10 * s:10 * s + 10, None, :], ("x", "y", "z"), seeds=(0, 1))
>>> b.names, b.expression_strings()
(('xR', 'yR'), ('x + 2*z', 'y - 1/4*z'))
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import Callable

import numpy as np
import scipy.linalg
import sympy

RANK_TOL = 1e-9          # numeric rank: |R_kk| > RANK_TOL * |R_00| (pivoted QR)
DEPENDENT_TOL = 1e-8     # a column is dependent when |R_kk| <= DEPENDENT_TOL * its norm
# The rank and the choice of columns are structural (they decide the generated regressors),
# so they are taken only when no ratio lies near its threshold.  What a last-bit difference
# between processors can move is a rounding residue: an exact zero shows up as a ratio of at
# most ~1e-14 (on the shipped robots below 7e-16), a genuine value is known to ~1e-14 of the
# scale.  So a ratio counts as zero only below threshold / DECISION_MARGIN (1e-11 for the
# column test: a thousand times above any residue) and as genuine only above threshold *
# ABOVE_MARGIN (1e-7: no residue comes near it, and a genuine value there is known to 1e-7
# relative). Real arms have genuine small ratios: the Kinova Jaco 2's joint 2 sits 1.6 mm off
# joint 1's axis, which gives link 2's mass a column of ratio 1.1e-6 in the inertia regressor.
DECISION_MARGIN = 1e3
ABOVE_MARGIN = 10
NUMERIC_DIGITS = 12      # significant digits kept of a grouping coefficient that is not rational
RATIONAL_TOL = 1e-12     # a rational replaces a float when it reproduces it to this (relative)
MAX_DENOMINATOR = 10 ** 4   # without a known denominator
VERIFY_TOL = 1e-12       # relations must hold at fresh samples to this, relative to max |Y|


class BaseParameterError(RuntimeError):
    """The numeric analysis is inconsistent (rank and column choice disagree, or a grouping
    relation does not hold at fresh samples)."""


def rationalize(value: float, denominator: int | None = None, tol: float = RATIONAL_TOL,
                max_denominator: int = MAX_DENOMINATOR, scale: float = 1.0):
    """A rational that reproduces ``value`` to ``tol`` (relative, absolute near zero, at
    least ``tol * scale``), as a sympy Rational, or ``None``.

    ``scale``: the size below which the value's last bits are noise. A grouping coefficient
    t relating a dependent column a to a base column b (a = t b + ...) is computed to about
    eps |a| / |b| (column norms): with 100 m links the mass columns are 1e4 times the inertia
    columns, and a coefficient that is exactly zero comes out near 1e-10 (the norm ratio,
    not 1, is its scale).

    With ``denominator`` (a known common denominator of the exact value, e.g. the squared
    lcm of the DH lengths' denominators) the candidate is ``round(value * D) / D``; without
    it, the simplest fraction with a denominator up to ``max_denominator`` (a small bound
    keeps a match meaningful: with denominators up to D and tolerance e, chance matches
    need D^2 e ~ 1).  This is sympy's ``nsimplify(value, rational=True, tolerance=tol)``,
    minus its preference for large denominators.

    >>> rationalize(0.15600000000000003), rationalize(-0.00680625, 4 * 10 ** 6), rationalize(np.pi)
    (39/250, -1089/160000, None)
    >>> rationalize(2.4e-10), rationalize(2.4e-10, scale=1e4)
    (None, 0)
    """
    value = float(value)
    bound = tol * max(1.0, abs(value), scale)
    if abs(value) <= bound:
        return sympy.Integer(0)
    if denominator is not None:
        f = Fraction(round(value * denominator), denominator)
        return sympy.Rational(f.numerator, f.denominator) if abs(float(f) - value) <= bound else None
    exact = Fraction(value)
    d = 1
    while d <= max_denominator:
        f = exact.limit_denominator(d)
        if abs(float(f) - value) <= bound:
            return sympy.Rational(f.numerator, f.denominator)
        d *= 10
    return None


@dataclass(frozen=True)
class BaseParameters:
    """Result of :func:`find_base_parameters`.

    ``full_names``: the parameters of the full regressor's columns; ``base``: indices of the
    independent columns, in order (the base regressor's columns); ``dependent``: the others;
    ``T[i][j]``: exact (sympy Rational) or float coefficient of dependent parameter j in base
    parameter i; ``rank``: numeric rank from the pivoted QR; ``condition_number``: 2-norm
    condition number of the stacked base regressor at the analysis samples;
    ``samples``: number of stacked rows analysed; ``zero_rows``: rows of the regressor that
    vanish at every sample (identically zero, e.g. g_1 on a level base);
    ``max_residual``: the worst relative residual of the relations at fresh samples."""

    full_names: tuple[str, ...]
    base: tuple[int, ...]
    dependent: tuple[int, ...]
    T: tuple[tuple, ...]
    rank: int
    condition_number: float
    samples: int
    zero_rows: tuple[int, ...]
    max_residual: float
    exact: bool

    @property
    def names(self) -> tuple[str, ...]:
        """``K`` for a parameter that stands alone, ``KR`` for one that others fold into."""
        return tuple(self.full_names[k] + ("R" if any(t != 0 for t in row) else "")
                     for k, row in zip(self.base, self.T))

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """Parameters whose columns are identically zero (they fold into nothing)."""
        return tuple(self.full_names[k] for j, k in enumerate(self.dependent)
                     if all(row[j] == 0 for row in self.T))

    def exact_values(self, full_values) -> tuple:
        """Base parameters of one full parameter vector computed without rounding: exact
        rationals when the grouping and the values are exact (sympy numbers)."""
        out = []
        for i, k in enumerate(self.base):
            value = sympy.sympify(full_values[k])
            for j, d in enumerate(self.dependent):
                t = self.T[i][j]
                if t != 0:
                    value += (t if isinstance(t, sympy.Rational) else sympy.Rational(t)) * sympy.sympify(full_values[d])
            out.append(value)
        return tuple(out)

    def map_matrix(self) -> np.ndarray:
        """P (rank x full) with ``base values = P @ full values``."""
        P = np.zeros((len(self.base), len(self.full_names)))
        for i, k in enumerate(self.base):
            P[i, k] = 1.0
            for j, d in enumerate(self.dependent):
                P[i, d] = float(self.T[i][j])
        return P

    def values(self, full_values) -> np.ndarray:
        """Base parameters of one full parameter vector (or a batch, last axis)."""
        return np.asarray(full_values, float) @ self.map_matrix().T

    def expressions(self, symbols=None) -> tuple[sympy.Expr, ...]:
        """Base parameters as sympy expressions in the full parameters' symbols (by default
        symbols named after ``full_names``)."""
        syms = symbols if symbols is not None else sympy.symbols(self.full_names)
        out = []
        for i, k in enumerate(self.base):
            terms = [syms[k]] + [self.T[i][j] * syms[d] for j, d in enumerate(self.dependent) if self.T[i][j] != 0]
            out.append(sympy.Add(*terms))
        return tuple(out)

    def expression_strings(self) -> tuple[str, ...]:
        """Base parameters as text, terms in column order: ``Ixx2 - Iyy2 + 4/25*m3``.
        Deterministic and readable by sympy/symengine ``sympify``."""
        out = []
        for i, k in enumerate(self.base):
            text = self.full_names[k]
            for j, d in enumerate(self.dependent):
                t = self.T[i][j]
                if t == 0:
                    continue
                text += (" - " if t < 0 else " + ") + _coefficient(abs(t)) + self.full_names[d]
            out.append(text)
        return tuple(out)

    def relations(self) -> tuple[str, ...]:
        """The grouping relations as text, one per dependent column with any effect:
        ``column(Iyy2) = -column(Ixx2) + 1*column(Ixx1) ...``."""
        out = []
        for j, d in enumerate(self.dependent):
            terms = [(self.T[i][j], self.full_names[k]) for i, k in enumerate(self.base) if self.T[i][j] != 0]
            if not terms:
                out.append(f"column({self.full_names[d]}) = 0")
                continue
            rhs = " ".join(("- " if t < 0 else "+ ") + _coefficient(abs(t)) + f"column({n})" for t, n in terms)
            out.append(f"column({self.full_names[d]}) = {rhs.lstrip('+ ')}")
        return tuple(out)


def _coefficient(t) -> str:
    """``'' `` for 1, else the number and a ``*``: ``4/25*``, ``0.123*``."""
    if t == 1:
        return ""
    if isinstance(t, (sympy.Rational, int)):
        return f"{t}*"
    return f"{float(t)!r}*"


def check_margin(ratios, threshold: float, what: str, margin: float = DECISION_MARGIN,
                 above: float = ABOVE_MARGIN) -> None:
    """Refuse a structural decision that a rounding difference could flip: every ratio must be
    below ``threshold / margin`` (a residue of an exact zero) or above ``threshold * above``
    (a genuine value).

    >>> check_margin([1e-15, 1e-6, 0.3], 1e-8, "rank")
    >>> check_margin([1e-9, 0.3], 1e-8, "rank")
    Traceback (most recent call last):
    ...
    kindyngen.algorithms.base_parameters.BaseParameterError: rank: ratio 1e-09 between 1e-11 and 1e-07 (the threshold 1e-08 divided by 1000, times 10); the decision would depend on rounding
    """
    for r in np.asarray(ratios, float).ravel():
        if threshold / margin <= r <= threshold * above:
            raise BaseParameterError(f"{what}: ratio {r:.3g} between {threshold / margin:g} and {threshold * above:g} "
                                     f"(the threshold {threshold:g} divided by {margin:g}, times {above:g}); "
                                     f"the decision would depend on rounding")


def numeric_rank(A: np.ndarray, tol: float = RANK_TOL) -> tuple[int, np.ndarray]:
    """Rank of ``A`` by QR with column pivoting, and the |diagonal of R| (descending)."""
    if A.size == 0:
        return 0, np.zeros(0)
    R = scipy.linalg.qr(A, mode="r", pivoting=True)[0]
    diag = np.abs(np.diag(R))
    if diag.size == 0 or diag[0] == 0:
        return 0, diag
    return int(np.sum(diag > tol * diag[0])), diag


def condition_number_2norm(A: np.ndarray) -> float:
    """2-norm condition number of ``A``: its largest over its smallest singular value; inf
    when the smallest is 0, 1 for an empty matrix (that of a 0 x 0 identity).

    >>> condition_number_2norm(np.diag([4.0, 0.5])), condition_number_2norm(np.zeros((3, 2)))
    (8.0, inf)
    """
    if A.size == 0:
        return 1.0
    s = np.linalg.svd(A, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def independent_columns(A: np.ndarray, tol: float = DEPENDENT_TOL, margin: float | None = None) -> tuple[int, ...]:
    """Columns of ``A`` not in the span of the columns before them (unpivoted QR).  With
    ``margin``, refuse (:func:`check_margin`) when a column's ratio is near ``tol``."""
    norms = np.linalg.norm(A, axis=0)
    scale = norms.max() if norms.size else 0.0
    if scale == 0:
        return ()
    R = scipy.linalg.qr(A, mode="r")[0]
    diag = np.zeros(A.shape[1])
    diag[:min(A.shape)] = np.abs(np.diag(R))
    if margin is not None:
        check_margin(norms / scale, tol, "zero columns", margin)
        nonzero = norms > tol * scale
        check_margin(diag[nonzero] / norms[nonzero], tol, "independent columns", margin)
    return tuple(k for k in range(A.shape[1]) if norms[k] > tol * scale and diag[k] > tol * norms[k])


def find_base_parameters(evaluate: Callable[[int], np.ndarray], full_names, seeds=(0, 1),
                         denominator: int | None = None) -> BaseParameters:
    """Base parameters of a regressor given ``evaluate(seed)``, the full regressor at random
    samples drawn with that seed (array samples x rows x len(full_names)): the first seed's
    samples serve the analysis, the second's the verification.  ``denominator``: a known
    common denominator of the exact relation coefficients (see :func:`rationalize`)."""
    full_names = tuple(full_names)
    A3 = np.asarray(evaluate(seeds[0]), float)
    A = A3.reshape(-1, A3.shape[-1])
    rank, diag = numeric_rank(A)
    if diag.size and diag[0] > 0:
        check_margin(diag / diag[0], RANK_TOL, "rank")
    base = independent_columns(A, margin=DECISION_MARGIN)
    if len(base) != rank:
        raise BaseParameterError(f"pivoted QR gives rank {rank} but {len(base)} columns are independent in order")
    dependent = tuple(k for k in range(len(full_names)) if k not in base)
    B = A[:, list(base)]
    # the relations solved on unit-norm columns (lengths of metres or hundreds of metres put
    # the mass columns orders of magnitude above the inertia columns); ratio[i, j] = |a_j| / |b_i|
    # is the scale of coefficient t_ij's rounding noise (rationalize's scale)
    base_norms = np.maximum(np.linalg.norm(B, axis=0), 1e-300)
    dependent_norms = np.maximum(np.linalg.norm(A[:, list(dependent)], axis=0), 1e-300)
    ratio = dependent_norms[None, :] / base_norms[:, None]
    if dependent:
        T_float = np.linalg.lstsq(B / base_norms, A[:, list(dependent)] / dependent_norms, rcond=None)[0] * ratio
    else:
        T_float = np.zeros((len(base), 0))
    T, T_check, exact = [], [], True
    for row, scales in zip(T_float, ratio):
        out = []
        for v, scale in zip(row, scales):
            r = rationalize(v, denominator, scale=scale) if denominator else None
            if r is None:
                r = rationalize(v, scale=scale)
            if r is None:
                # not rational: kept as a float rounded to NUMERIC_DIGITS, so that the
                # processor's last bits do not reach base_params.json (base_params.json
                # says "exact": false)
                exact = False
                out.append(float(f"{v:.{NUMERIC_DIGITS}g}"))
            else:
                out.append(r)
        T.append(tuple(out))
        # the relations are verified with the unrounded floats: rounding to NUMERIC_DIGITS
        # is a printing choice, the check is whether the grouping holds
        T_check.append([float(t) if isinstance(t, sympy.Rational) else v for t, v in zip(out, row)])
    T = tuple(T)
    # verification at fresh samples
    A2 = np.asarray(evaluate(seeds[1]), float)
    A2 = A2.reshape(-1, A2.shape[-1])
    scale = max(np.abs(A2).max(), 1e-300)
    Tn = np.array(T_check, float).reshape(len(base), len(dependent))
    residual = A2[:, list(dependent)] - A2[:, list(base)] @ Tn if dependent else np.zeros((A2.shape[0], 0))
    max_residual = float(np.abs(residual).max() / scale) if residual.size else 0.0
    if max_residual > VERIFY_TOL:
        raise BaseParameterError(f"grouping relations fail at fresh samples: relative residual {max_residual:.3g}")
    zero_rows = tuple(int(r) for r in np.flatnonzero(
        np.all(np.abs(A3) <= 1e-13 * max(np.abs(A3).max(), 1e-300), axis=(0, 2))))
    return BaseParameters(full_names=full_names, base=base, dependent=dependent, T=T, rank=rank,
                          condition_number=condition_number_2norm(B), samples=A.shape[0], zero_rows=zero_rows,
                          max_residual=max_residual, exact=exact)
