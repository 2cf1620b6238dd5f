"""Least-squares identification of base parameters from stacked regressor rows (the
identification paper's eqs. 21-25), refusing what cannot be identified.

``identify(Y, y, names)`` solves ``Y pi = y`` in the least-squares sense and returns an
:class:`Estimate`.  It raises, with a message that says what to change:

* :class:`IdentificationDataError` for NaN or infinite data, mismatched shapes, or fewer
  stacked rows than parameters ("too few samples");
* :class:`RankDeficientError` when the stacked regressor does not have full column rank (too
  few distinct samples, all samples at one configuration, an excitation that never moves a
  joint ...): the error lists the unidentifiable directions, each a combination of the
  base-parameter names (adding any multiple of it to the parameters leaves every prediction
  unchanged), instead of returning one arbitrary solution silently.

``identify_samples(model, kind, inputs, measured)`` stacks the base regressor of ``kind``
("Y_g", "Y_m", "Y", see :mod:`kindyngen.regressors`) at the given samples first.

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

from .base_parameters import RANK_TOL, numeric_rank


class IdentificationDataError(ValueError):
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


def _as_rows(Y, y):
    Y = np.asarray(Y, float)
    y = np.asarray(y, float)
    if Y.ndim == 3:
        if y.shape != Y.shape[:2]:
            raise IdentificationDataError(f"measured data of shape {y.shape} do not match the regressor's "
                                          f"{Y.shape[:2]} (samples x rows)")
        return Y.reshape(-1, Y.shape[-1]), y.reshape(-1), Y.shape[0], Y.shape[1]
    if Y.ndim != 2 or y.ndim != 1 or y.shape[0] != Y.shape[0]:
        raise IdentificationDataError(f"expected a stacked regressor (rows x parameters) and a vector of as many "
                                      f"rows, got shapes {Y.shape} and {y.shape}")
    return Y, y, None, None


def identify(Y, y, names=None, rank_tol: float = RANK_TOL, hint: str = "") -> Estimate:
    """Least-squares base parameters from the stacked regressor ``Y`` (rows x p, or samples
    x rows x p) and the measured quantity ``y`` (rows, or samples x rows)."""
    Y, y, samples, per_sample = _as_rows(Y, y)
    p = Y.shape[1]
    names = tuple(names) if names is not None else tuple(f"pi{k + 1}" for k in range(p))
    if len(names) != p:
        raise IdentificationDataError(f"{len(names)} names for {p} regressor columns")
    bad_y = ~np.isfinite(y)
    bad_Y = ~np.isfinite(Y).all(axis=1)
    if bad_y.any() or bad_Y.any():
        rows = np.flatnonzero(bad_y | bad_Y)
        where = (f"samples {sorted(set((rows // per_sample).tolist()))[:10]}" if per_sample
                 else f"rows {rows[:10].tolist()}")
        what = "measured values" if bad_y.any() else "regressor"
        raise IdentificationDataError(f"the {what} contain NaN or infinite entries ({len(rows)} rows; {where}): "
                                      f"remove or repair those samples first")
    if Y.shape[0] < p:
        need = -(-p // per_sample) if per_sample else p
        got = f"{samples} samples x {per_sample} rows = {Y.shape[0]} equations" if per_sample else f"{Y.shape[0]} rows"
        raise IdentificationDataError(f"too few samples: {got} for {p} base parameters; at least {need} "
                                      f"{'samples' if per_sample else 'rows'} are needed (many more for noisy data)")
    rank, _ = numeric_rank(Y, rank_tol)
    if rank < p:
        raise RankDeficientError(rank, names, null_space_directions(Y, rank), hint)
    values, *_ = np.linalg.lstsq(Y, y, rcond=None)
    residual = y - Y @ values
    sv = np.linalg.svd(Y, compute_uv=False)
    return Estimate(names=names, values=values, residual_rms=float(np.sqrt(np.mean(residual ** 2))),
                    condition_number=float(sv[0] / sv[-1]), rows=Y.shape[0])


def stacked_regressor(model, kind: str, inputs: dict) -> np.ndarray:
    """The base regressor ``kind`` of ``model`` at samples (samples x rows x base params);
    ``inputs``: ``q`` (and for "Y" ``qd``, ``qdd``), each samples x n."""
    from .regressors import base_parameters, evaluate_full, full_regressor
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
    from .regressors import base_parameters
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
