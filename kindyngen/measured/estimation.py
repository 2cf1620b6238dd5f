"""Least squares on stacked regressor rows: base parameters (and effect coefficients) from
measured data, refusing what cannot be identified.

Identification of one quantity (the identification paper's eqs. 21-25):
``identify(Y, y, names)`` solves ``Y pi = y`` in the least-squares sense and returns an
:class:`Estimate`.  It raises, with a message that says what to change:

* :class:`IdentificationDataError` for NaN or infinite data, mismatched shapes, or fewer
  stacked rows than parameters ("too few samples");
* :class:`RankDeficientError` when the stacked regressor does not have full column rank (too
  few distinct samples, all samples at one configuration, an excitation that never moves a
  joint, an effect column equal to a rigid-body one ...): the error lists the unidentifiable
  directions, each a combination of the parameter names (adding any multiple of it to the
  parameters leaves every prediction unchanged), instead of returning one arbitrary solution
  silently.

``check_identifiable`` runs these checks alone (least squares below reuses them).
``identify_samples(model, kind, inputs, measured)`` stacks the base regressor of ``kind``
("Y_g", "Y_m", "Y", see :mod:`kindyngen.algorithms.regressors`) at the given samples first.

Torques with uncertainties: ``least_squares(Y, tau, names, weighted=False)`` -> :class:`Fit`
(values, standard deviations, condition numbers, per-joint residual RMS), ordinary or
weighted per joint (Gautier); ``predict`` and ``rms_per_joint`` evaluate a fit on other data.

Example:

>>> import numpy as np
>>> Y = np.array([[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]])
>>> try:
...     identify(Y, Y @ [1.0, 1.0], ("a", "b"))
... except RankDeficientError as e:
...     print(e.directions)
('a - 0.5*b',)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..algorithms.base_parameters import RANK_TOL, condition_number_2norm, numeric_rank
from . import MeasuredDataError


class IdentificationDataError(MeasuredDataError):
    """Data that cannot be used for identification (NaN, shapes, too few samples)."""


class RankDeficientError(IdentificationDataError):
    """The excitation does not determine every base parameter.

    ``rank``: numeric rank of the stacked regressor; ``parameters``: how many there are;
    ``directions``: the unidentifiable directions as text (``"Ixx2R - 0.16*m3"``);
    ``null_space``: the same as rows of numbers (one per direction, over ``names``)."""

    def __init__(self, rank: int, names, null_space: np.ndarray, hint: str = ""):
        self.rank, self.parameters, self.names = rank, len(names), tuple(names)
        self.null_space = null_space
        self.directions = tuple(format_direction(v, names) for v in null_space)
        shown = "; ".join(self.directions[:10]) + (f"; ... ({len(self.directions) - 10} more)"
                                                    if len(self.directions) > 10 else "")
        super().__init__(
            f"rank-deficient excitation: the stacked regressor has rank {rank} < {len(names)} base parameters, "
            f"so {len(names) - rank} direction(s) cannot be identified{hint}: {shown}. "
            f"Add samples at other configurations (and, for the torque regressor, other velocities "
            f"and accelerations).")


@dataclass(frozen=True)
class Estimate:
    """Least-squares estimate: ``values`` in ``names`` order, the RMS of the residual
    ``y - Y values``, the stacked regressor's rank and 2-norm condition number."""

    names: tuple[str, ...]
    values: np.ndarray
    residual_rms: float
    condition_number: float
    rows: int

    def as_dict(self) -> dict:
        return dict(zip(self.names, map(float, self.values)))


def format_direction(v: np.ndarray, names, digits: int = 6) -> str:
    """``[1, 0, -0.16]`` over ``(a, b, c)`` -> ``"a - 0.16*c"`` (entries below 1e-9 of the
    largest dropped)."""
    v = np.asarray(v, float)
    scale = np.abs(v).max()
    parts = []
    for value, name in zip(v, names):
        if abs(value) <= 1e-9 * scale:
            continue
        mag = abs(value)
        text = name if abs(mag - 1) < 1e-12 else f"{mag:.{digits}g}*{name}"
        parts.append(("- " if value < 0 else "+ ") + text)
    out = " ".join(parts)
    return out[2:] if out.startswith("+ ") else "-" + out[2:]


def null_space_directions(Y: np.ndarray, rank: int) -> np.ndarray:
    """A readable basis of the null space of ``Y``: reduced row echelon form of the right
    singular vectors of the smallest singular values (each direction has one leading
    parameter with coefficient 1 that no other direction contains)."""
    _, _, Vt = np.linalg.svd(Y, full_matrices=True)
    N = Vt[rank:].copy()                  # k x p, rows span the null space
    k, p = N.shape
    row, pivots = 0, []
    for col in range(p):
        if row == k:
            break
        r = row + int(np.argmax(np.abs(N[row:, col])))
        if abs(N[r, col]) < 1e-9:
            continue
        N[[row, r]] = N[[r, row]]
        N[row] /= N[row, col]
        for other in range(k):
            if other != row:
                N[other] -= N[other, col] * N[row]
        pivots.append(col)
        row += 1
    N[np.abs(N) < 1e-12] = 0.0
    return N


def check_rows(Y, y):
    """Validate a stacked regressor and its measured data; returns ``(Y2, y2, samples,
    per_sample)`` with ``Y2`` (rows x p) and ``y2`` (rows) flattened (``samples`` and
    ``per_sample`` are None for data given flat).  ``Y``: rows x p, or samples x rows x p;
    ``y``: rows, or samples x rows.  Raises :class:`IdentificationDataError` for mismatched
    shapes and NaN or infinite entries (naming the samples or rows)."""
    Y = np.asarray(Y, float)
    y = np.asarray(y, float)
    if Y.ndim == 3:
        if y.shape != Y.shape[:2]:
            raise IdentificationDataError(f"measured data of shape {y.shape} do not match the regressor's "
                                          f"{Y.shape[:2]} (samples x rows)")
        Y2, y2, samples, per_sample = Y.reshape(-1, Y.shape[-1]), y.reshape(-1), Y.shape[0], Y.shape[1]
    elif Y.ndim != 2 or y.ndim != 1 or y.shape[0] != Y.shape[0]:
        raise IdentificationDataError(f"expected a stacked regressor (rows x parameters) and a vector of as many "
                                      f"rows, got shapes {Y.shape} and {y.shape}")
    else:
        Y2, y2, samples, per_sample = Y, y, None, None
    bad_y = ~np.isfinite(y2)
    bad_Y = ~np.isfinite(Y2).all(axis=1)
    if bad_y.any() or bad_Y.any():
        rows = np.flatnonzero(bad_y | bad_Y)
        where = (f"samples {sorted(set((rows // per_sample).tolist()))[:10]}" if per_sample
                 else f"rows {rows[:10].tolist()}")
        what = "measured values" if bad_y.any() else "regressor"
        raise IdentificationDataError(f"the {what} contain NaN or infinite entries ({len(rows)} rows; {where}): "
                                      f"remove or repair those samples first")
    return Y2, y2, samples, per_sample


def check_identifiable(Y, y, names=None, rank_tol: float = RANK_TOL, hint: str = ""):
    """Every refusal of :func:`identify` without solving: returns ``(Y2, y2, names)`` (rows x
    p, rows, p names) or raises :class:`IdentificationDataError` (shapes, NaN, too few
    samples) or :class:`RankDeficientError` (naming the unidentifiable directions)."""
    Y, y, samples, per_sample = check_rows(Y, y)
    p = Y.shape[1]
    names = tuple(names) if names is not None else tuple(f"pi{k + 1}" for k in range(p))
    if len(names) != p:
        raise IdentificationDataError(f"{len(names)} names for {p} regressor columns")
    if Y.shape[0] < p:
        need = -(-p // per_sample) if per_sample else p
        got = f"{samples} samples x {per_sample} rows = {Y.shape[0]} equations" if per_sample else f"{Y.shape[0]} rows"
        raise IdentificationDataError(f"too few samples: {got} for {p} base parameters; at least {need} "
                                      f"{'samples' if per_sample else 'rows'} are needed (many more for noisy data)")
    rank, _ = numeric_rank(Y, rank_tol)
    if rank < p:
        raise RankDeficientError(rank, names, null_space_directions(Y, rank), hint)
    return Y, y, names


def identify(Y, y, names=None, rank_tol: float = RANK_TOL, hint: str = "") -> Estimate:
    """Least-squares base parameters from the stacked regressor ``Y`` (rows x p, or samples
    x rows x p) and the measured quantity ``y`` (rows, or samples x rows)."""
    Y, y, names = check_identifiable(Y, y, names, rank_tol, hint)
    values, *_ = np.linalg.lstsq(Y, y, rcond=None)
    residual = y - Y @ values
    return Estimate(names=names, values=values, residual_rms=float(np.sqrt(np.mean(residual ** 2))),
                    condition_number=condition_number_2norm(Y), rows=Y.shape[0])


def stacked_regressor(model, kind: str, inputs: dict) -> np.ndarray:
    """The base regressor ``kind`` of ``model`` at samples (samples x rows x base params);
    ``inputs``: ``q`` (and for "Y" ``qd``, ``qdd``), each samples x n."""
    from ..algorithms.regressors import base_parameters, evaluate_full, full_regressor
    full = full_regressor(model, kind)
    missing = [port.name for port in full.inputs if port.name not in inputs]
    if missing:
        raise IdentificationDataError(f"{kind} needs inputs {[p.name for p in full.inputs]}; missing {missing}")
    arrays = {}
    count = None
    for port in full.inputs:
        a = np.asarray(inputs[port.name], float).reshape(-1, port.size)
        if count is not None and a.shape[0] != count:
            raise IdentificationDataError(f"inputs have different numbers of samples ({count} and {a.shape[0]})")
        count = a.shape[0]
        if not np.isfinite(a).all():
            bad = np.flatnonzero(~np.isfinite(a).all(axis=1))
            raise IdentificationDataError(f"input {port.name} contains NaN or infinite entries (samples {bad[:10].tolist()})")
        arrays[port.name] = a
    A = evaluate_full(model, kind, arrays)
    return A[:, :, list(base_parameters(model, kind).base)]


def identify_samples(model, kind: str, inputs: dict, measured, rank_tol: float = RANK_TOL) -> Estimate:
    """Identify the base parameters of regressor ``kind`` ("Y_g": measured g; "Y_m": the
    inertia stack, lower triangle of M row by row; "Y": tau) from samples."""
    from ..algorithms.regressors import base_parameters
    names = base_parameters(model, kind).names
    Y = stacked_regressor(model, kind, inputs)
    measured = np.asarray(measured, float)
    if measured.ndim == 1 and Y.shape[0] == 1:
        measured = measured[None]
    if measured.shape != Y.shape[:2]:
        raise IdentificationDataError(f"measured data of shape {measured.shape}; expected {Y.shape[:2]} "
                                      f"(samples x rows of {kind})")
    q = np.asarray(inputs["q"], float).reshape(Y.shape[0], -1)
    hint = ""
    if Y.shape[0] > 1 and np.all(q == q[0]):
        hint = f" (all {Y.shape[0]} samples are at one configuration)"
    elif len(np.unique(q, axis=0)) < Y.shape[0]:
        hint = f" ({len(np.unique(q, axis=0))} distinct configurations among {Y.shape[0]} samples)"
    return identify(Y, measured, names, rank_tol, hint)


# ---------------------------------------------------------------------------------------------
# torques: ordinary and weighted least squares with standard deviations

@dataclass(frozen=True)
class Fit:
    """A least-squares fit of torque rows ``tau = Y @ values``.

    ``names``, ``values``: the parameters (base parameters and effect coefficients, in the
    regressor's column order); ``std``: their standard deviations (absolute, same units);
    ``std_percent``: ``100 * std / |value|`` (inf where the value is 0);
    ``condition_number``: 2-norm condition number of the stacked regressor the solution was
    computed from (the weighted one for "wls"), plain, as usually compared;
    ``condition_number_scaled``: the same after scaling every column to unit 2-norm (what is
    left once the units and magnitudes of the parameters are taken out);
    ``rms``: per joint, the RMS of the training residual ``tau - Y @ values`` (N m);
    ``sigma``: per joint, the noise standard deviation the standard deviations assume ("ols":
    one common value; "wls": the per-joint values of the first, ordinary, pass);
    ``weights``: per joint, the factor ``1 / sigma_j`` its rows were multiplied by ("wls"),
    or None ("ols"); ``method``: "ols" or "wls"; ``rows``: stacked equations ``N n``;
    ``dof``: degrees of freedom of the residual, ``N n - k``."""

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    std_percent: np.ndarray
    condition_number: float
    condition_number_scaled: float
    rms: np.ndarray
    sigma: np.ndarray
    weights: np.ndarray | None
    method: str
    rows: int
    dof: int

    def as_dict(self) -> dict:
        return dict(zip(self.names, map(float, self.values)))


def predict(Y, values) -> np.ndarray:
    """Torques ``Y @ values``: ``Y`` (N, n, k) -> (N, n)."""
    Y = np.asarray(Y, float)
    values = np.asarray(values, float)
    if Y.ndim != 3 or values.shape != (Y.shape[-1],):
        raise IdentificationDataError(f"expected a regressor of shape (samples, joints, k) and k values, "
                                      f"got shapes {Y.shape} and {values.shape}")
    return Y @ values


def rms_per_joint(tau, predicted) -> np.ndarray:
    """Per joint (column), the RMS of ``tau - predicted`` over the samples: (N, n) -> (n,)."""
    tau, predicted = np.asarray(tau, float), np.asarray(predicted, float)
    if tau.shape != predicted.shape or tau.ndim != 2:
        raise IdentificationDataError(f"expected two arrays samples x joints of one shape, got {tau.shape} "
                                      f"and {predicted.shape}")
    return np.sqrt(np.mean((tau - predicted) ** 2, axis=0))


def effect_hint(error: RankDeficientError) -> str:
    """A hint when effect coefficients are among the unidentifiable directions."""
    from .effect_columns import effect_of
    involved = []
    for vector in error.null_space:
        for value, name in zip(vector, error.names):
            if value != 0 and name not in involved:
                try:
                    effect_of(name)
                except ValueError:
                    continue
                involved.append(name)
    if not involved:
        return ""
    armature = [name for name in involved if effect_of(name) == "armature"]
    text = f" (the effect parameter(s) {', '.join(involved)} share their columns with others"
    if armature:
        text += (f"; the armature of a joint whose axis is fixed in the base has the column of the link "
                 f"inertia about that axis, so only their sum is seen: drop {', '.join(armature)} from the "
                 f"columns and read the inertia parameter as the sum")
    offsets = [name for name in involved if effect_of(name) == "encoder_offset"]
    gains = [name for name in involved if effect_of(name) == "torque_sensor_gain"]
    if offsets:
        text += (f"; an encoder offset turns the links after its joint, which for the last joint (and for one "
                 f"whose axis is parallel to gravity and fixed in the base) is the same as turned inertial "
                 f"parameters: drop those of {', '.join(offsets)}, fit with --consistent (the description "
                 f"as prior), or find offsets against the nominal model with 'kindyngen discover'")
    if gains:
        text += ("; a gain error common to every torque sensor is the same as every mass and inertia scaled: "
                 "torque gains are seen only against known masses (fit with --consistent, the description as "
                 "prior, or find them against the nominal model with 'kindyngen discover')")
    return text + ")"


def _solve(A: np.ndarray, b: np.ndarray):
    """Least squares by a QR factorisation of ``[A b]`` (A has full column rank): what
    :func:`solve_triangle` gives for its factor."""
    k = A.shape[1]
    F = scipy.linalg.qr(np.column_stack([A, b]), mode="r")[0]
    return solve_triangle(F[:k, :k], F[:k, k])


def solve_triangle(R: np.ndarray, c: np.ndarray):
    """Least squares from the triangular factor ``R`` of a full-column-rank ``A`` and
    ``c = Q^T b``: values ``R^-1 c``, diag((A^T A)^-1) (``(A^T A)^-1 = R^-1 R^-T``), plain
    and column-scaled 2-norm condition numbers (those of R, whose columns have A's norms)."""
    values = scipy.linalg.solve_triangular(R, c)
    R_inv = scipy.linalg.solve_triangular(R, np.eye(R.shape[0]))
    return (values, np.sum(R_inv ** 2, axis=1), condition_number_2norm(R),
            condition_number_2norm(R / np.linalg.norm(R, axis=0)))


def least_squares(Y, tau, names=None, weighted: bool = False) -> Fit:
    """Fit ``tau ~ Y @ values`` by ordinary (``weighted=False``) or weighted least squares.

    ``Y``: stacked regressor rows (N, n, k) (base columns, and effect columns appended);
    ``tau``: measured torques (N, n); ``names``: the k column names.

    Ordinary ("ols"): ``values = argmin ||Y values - tau||^2`` over all N n equations;
    ``sigma^2 = ||r||^2 / (N n - k)`` (r the residual), covariance ``sigma^2 (Y^T Y)^-1``.

    Weighted ("wls", Gautier & Poignet 2001): an ordinary pass first; per joint j the noise
    variance ``sigma_j^2 = ||r_j||^2 / (N - k / n)`` (r_j: joint j's N residuals; the k degrees
    of freedom the fit uses are shared equally among the n joints, so the per-joint degrees of
    freedom add up to the total ``N n - k`` and equal noise gives the ordinary estimate back;
    Gautier's ``N - k`` differs by O(k / N)); joint j's rows (regressor and torque) are
    multiplied by ``w_j = 1 / sigma_j`` and solved again; covariance
    ``sigma_w^2 ((W Y)^T (W Y))^-1`` with ``sigma_w^2 = ||W r_w||^2 / (N n - k)`` from the
    weighted residual (about 1 when the per-joint noise model holds).  A joint whose residual
    is below 1e-6 of the largest (noise-free data) gets sigma = 1e-6 times the largest.

    ``std = sqrt(diag(covariance))``; this assumes zero-mean noise independent between samples
    (filtered data are correlated in time: the values stay right, the std are optimistic).

    Refuses like :func:`identify` (it runs the same :func:`check_identifiable`): NaN or
    infinite data, too few rows, and a rank-deficient regressor (:class:`RankDeficientError` naming the unidentifiable directions, with a hint
    when an effect column coincides with rigid-body ones, e.g. the armature of joint 1)."""
    Y = np.asarray(Y, float)
    tau = np.asarray(tau, float)
    if Y.ndim != 3:
        raise IdentificationDataError(f"expected regressor rows of shape (samples, joints, parameters), got {Y.shape}")
    try:
        _, _, names = check_identifiable(Y, tau, names)
    except RankDeficientError as error:
        hint = effect_hint(error)
        if not hint:
            raise
        raise RankDeficientError(error.rank, error.names, error.null_space, hint) from None
    N, n, k = Y.shape
    dof = N * n - k
    if dof <= 0:
        raise IdentificationDataError(f"too few samples for standard deviations: {N} samples x {n} joints = "
                                      f"{N * n} equations for {k} parameters leave no degree of freedom")
    A, b = Y.reshape(N * n, k), tau.reshape(N * n)
    values, inverse_diagonal, cond, cond_scaled = _solve(A, b)
    residual = tau - Y @ values
    if not weighted:
        sigma2 = float(np.sum(residual ** 2)) / dof
        std = np.sqrt(sigma2 * inverse_diagonal)
        sigma, weights, method = np.full(n, np.sqrt(sigma2)), None, "ols"
    else:
        joint_dof = N - k / n
        if joint_dof <= 0:
            raise IdentificationDataError(f"too few samples for weighted least squares: {N} samples per joint for "
                                          f"{k / n:g} parameters per joint")
        sigma = np.sqrt(np.sum(residual ** 2, axis=0) / joint_dof)
        largest = sigma.max()
        sigma = np.maximum(sigma, 1e-6 * largest) if largest > 0 else np.ones(n)
        weights = 1.0 / sigma
        Aw = (Y * weights[None, :, None]).reshape(N * n, k)
        bw = (tau * weights[None, :]).reshape(N * n)
        values, inverse_diagonal, cond, cond_scaled = _solve(Aw, bw)
        residual = tau - Y @ values
        sigma_w2 = float(np.sum((residual * weights) ** 2)) / dof
        std = np.sqrt(sigma_w2 * inverse_diagonal)
        method = "wls"
    with np.errstate(divide="ignore", invalid="ignore"):
        std_percent = np.where(values != 0, 100.0 * std / np.abs(values), np.inf)
    return Fit(names=names, values=values, std=std, std_percent=std_percent, condition_number=cond,
               condition_number_scaled=cond_scaled, rms=rms_per_joint(tau, Y @ values), sigma=sigma,
               weights=weights, method=method, rows=N * n, dof=dof)
