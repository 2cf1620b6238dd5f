"""Least squares in bounded memory: the triangular factor of the stacked regressor, built chunk
by chunk and combined across logs, instead of the stacked regressor itself.

For the torque equations ``tau_j = A_j p`` of joint j (``A_j``: that joint's regressor rows, N x
k) everything ordinary and weighted least squares, their standard deviations, the condition
numbers and the semidefinite program of :mod:`kindyngen.measured.consistent` need is, per
joint, the triangular factor of ``[A_j tau_j]``::

    ||A_j p - tau_j||^2 = ||R_j p - c_j||^2 + rss_j     for every p,

with ``R_j`` (k x k, upper triangular), ``c_j = (Q^T tau)_j`` (k) and ``rss_j`` (the part of
``||tau_j||^2`` no parameter explains).  :class:`LSFactor` holds these for the n joints and the
sample count: O(n k^2) numbers whatever the log length (7 x 43 x 44 floats, 106 KB, for the
LWR's base regressor).  ``fold`` adds a chunk of samples by a QR factorisation of the old
factor stacked on the chunk's rows (an update: the chunk is never stacked with earlier ones);
``combine`` adds two factors the same way, so the factors of separate logs combine exactly (up
to rounding) in any order.  Keeping one factor per joint, not one for all equations, is what
makes weighted least squares exact in one pass: joint j's residual for any ``p`` is
``||R_j p - c_j||^2 + rss_j``, and the weighted factor is the QR of the stacked ``w_j [R_j c_j]``.

Example (two chunks fold to the factor of the whole):

>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> Y, tau = rng.normal(size=(100, 2, 3)), rng.normal(size=(100, 2))
>>> f = LSFactor.empty(2, 3).fold(Y[:40], tau[:40]).fold(Y[40:], tau[40:])
>>> p = rng.normal(size=3)
>>> bool(np.allclose(f.residual_sums(p), ((Y @ p - tau) ** 2).sum(axis=0)))
True
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import reduce

from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy.linalg.lapack import dgeqrf as _geqrf

from ..algorithms.base_parameters import condition_number_2norm
from .estimation import (Fit, IdentificationDataError, RankDeficientError, check_identifiable, effect_hint,
                         solve_triangle)


def _triangle(stacked: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(R, c, r^2) of the QR factorisation of ``stacked = [A b]`` (rows x k + 1, overwritten;
    Fortran order avoids a copy); rows below k + 1 are padded with zeros so a short stack still
    gives a k x k R."""
    if stacked.shape[0] < k + 1:
        stacked = np.vstack([stacked, np.zeros((k + 1 - stacked.shape[0], k + 1))])
    qr, _, _, info = _geqrf(stacked, overwrite_a=1)
    if info != 0:
        raise IdentificationDataError(f"QR factorisation failed (LAPACK geqrf info {info})")
    F = np.triu(qr[:k + 1])
    return F[:k, :k], F[:k, k], float(F[k, k] ** 2)


def _update(R: np.ndarray, c: np.ndarray, A: np.ndarray, b: np.ndarray):
    """The triangle of ``[[R c], [A b]]``, stacked once in Fortran order."""
    k = R.shape[0]
    stacked = np.empty((k + len(A), k + 1), order="F")
    stacked[:k, :k], stacked[:k, k] = R, c
    stacked[k:, :k], stacked[k:, k] = A, b
    return _triangle(stacked, k)


def fold_rows(R: np.ndarray, c: np.ndarray, A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """One joint's factor with rows added: ``(R', c', extra)`` with ``||A' p - b'||^2 = ||R' p -
    c'||^2 + rss + extra`` for the rows of ``[R c]`` stacked on ``[A b]``."""
    return _update(R, c, A, b)


def _map_joints(function, n: int):
    """``[function(j) for j in range(n)]`` on two threads: LAPACK releases the GIL, and each
    joint's factorisation is the same arithmetic whichever thread runs it."""
    with ThreadPoolExecutor(max_workers=2) as pool:
        return list(pool.map(function, range(n)))


@dataclass(frozen=True, eq=False)
class LSFactor:
    """Per joint j, ``R[j]`` (k x k upper triangular), ``c[j]`` (k) and ``rss[j]`` with
    ``||A_j p - tau_j||^2 = ||R[j] p - c[j]||^2 + rss[j]``; ``samples``: how many samples (rows of
    every joint) were folded in; ``sum_tau2``: per joint ``||tau_j||^2`` (for the semidefinite
    program's weights).  Immutable: ``fold`` and ``combine`` return new factors."""

    R: np.ndarray
    c: np.ndarray
    rss: np.ndarray
    samples: int
    sum_tau2: np.ndarray

    @staticmethod
    def empty(n: int, k: int) -> "LSFactor":
        """The factor of no samples (the neutral element of :meth:`combine`)."""
        return LSFactor(np.zeros((n, k, k)), np.zeros((n, k)), np.zeros(n), 0, np.zeros(n))

    @property
    def n(self) -> int:
        return self.R.shape[0]

    @property
    def k(self) -> int:
        return self.R.shape[2]

    def fold(self, Y, tau) -> "LSFactor":
        """This factor with the samples ``Y`` (m, n, k) and ``tau`` (m, n) added."""
        Y = np.asarray(Y, float)
        tau = np.asarray(tau, float)
        if Y.ndim != 3 or Y.shape[1:] != (self.n, self.k) or tau.shape != Y.shape[:2]:
            raise IdentificationDataError(f"chunk of shapes {Y.shape} and {tau.shape}; expected (m, {self.n}, "
                                          f"{self.k}) and (m, {self.n})")
        if not (np.isfinite(Y).all() and np.isfinite(tau).all()):
            bad = np.flatnonzero(~(np.isfinite(Y).all(axis=(1, 2)) & np.isfinite(tau).all(axis=1)))
            raise IdentificationDataError(f"the regressor or torques contain NaN or infinite entries (samples "
                                          f"{bad[:10].tolist()} of a chunk): remove or repair those samples first")
        if len(Y) == 0:
            return self
        parts = _map_joints(lambda j: _update(self.R[j], self.c[j], Y[:, j, :], tau[:, j]), self.n)
        R = np.array([p[0] for p in parts])
        c = np.array([p[1] for p in parts])
        rss = self.rss + np.array([p[2] for p in parts])
        return LSFactor(R, c, rss, self.samples + len(Y), self.sum_tau2 + np.sum(tau ** 2, axis=0))

    def residual_sums(self, p) -> np.ndarray:
        """Per joint, ``||A_j p - tau_j||^2`` (exact up to rounding, from the factor alone)."""
        p = np.asarray(p, float)
        return np.sum((self.R @ p - self.c) ** 2, axis=1) + self.rss

    def rms(self, p) -> np.ndarray:
        """Per joint, the RMS of ``tau_j - A_j p`` over the samples (N m)."""
        return np.sqrt(np.maximum(self.residual_sums(p), 0.0) / max(self.samples, 1))

    def stacked(self, weights=None) -> tuple[np.ndarray, np.ndarray, float]:
        """(R, c, rss) of all joints' equations together, joint j's multiplied by ``weights[j]``
        (default 1): the factor of the whole stacked (weighted) regressor."""
        w = np.ones(self.n) if weights is None else np.asarray(weights, float)
        rows = np.asfortranarray(np.vstack([w[j] * np.column_stack([self.R[j], self.c[j]]) for j in range(self.n)]))
        R, c, extra = _triangle(rows, self.k)
        return R, c, extra + float(np.sum(w ** 2 * self.rss))


def combine(a: LSFactor, b: LSFactor) -> LSFactor:
    """The factor of the samples of ``a`` and ``b`` together (any order gives the same values
    up to rounding; R's rows may differ in sign, which no result depends on)."""
    if (a.n, a.k) != (b.n, b.k):
        raise IdentificationDataError(f"cannot combine factors of {a.n} joints x {a.k} columns and "
                                      f"{b.n} joints x {b.k} columns")
    if b.samples == 0:
        return a
    if a.samples == 0:
        return b
    R, c, rss = np.empty_like(a.R), np.empty_like(a.c), a.rss + b.rss
    for j in range(a.n):
        R[j], c[j], extra = _update(a.R[j], a.c[j], b.R[j], b.c[j])
        rss[j] += extra
    return LSFactor(R, c, rss, a.samples + b.samples, a.sum_tau2 + b.sum_tau2)


def combine_in_order(factors) -> LSFactor:
    """``combine`` from left to right: the fixed reduction order that makes a fleet's result the
    same bit for bit however many workers computed the factors."""
    return reduce(combine, factors)


def condition_number(factor: LSFactor) -> float:
    """2-norm condition number of the stacked regressor (that of its triangular factor)."""
    return condition_number_2norm(factor.stacked()[0])


def least_squares_factor(factor: LSFactor, names=None, weighted: bool = False) -> Fit:
    """:func:`kindyngen.measured.estimation.least_squares` from the factor alone: the same
    :class:`~kindyngen.measured.estimation.Fit` (values, standard deviations, condition numbers,
    per-joint RMS, weights) and the same refusals (too few samples, rank deficiency naming the
    unidentifiable directions), without the stacked regressor."""
    N, n, k = factor.samples, factor.n, factor.k
    R, c, _ = factor.stacked()
    names = tuple(names) if names is not None else tuple(f"pi{i + 1}" for i in range(k))
    if N * n < k:
        raise IdentificationDataError(f"too few samples: {N} samples x {n} rows = {N * n} equations for {k} base "
                                      f"parameters; at least {-(-k // n)} samples are needed (many more for noisy "
                                      f"data)")
    try:
        check_identifiable(R, c, names)     # R has the stacked regressor's rank and null space
    except RankDeficientError as error:
        hint = effect_hint(error)
        if not hint:
            raise
        raise RankDeficientError(error.rank, error.names, error.null_space, hint) from None
    dof = N * n - k
    if dof <= 0:
        raise IdentificationDataError(f"too few samples for standard deviations: {N} samples x {n} joints = "
                                      f"{N * n} equations for {k} parameters leave no degree of freedom")
    values, inverse_diagonal, cond, cond_scaled = solve_triangle(R, c)
    if not weighted:
        sigma2 = float(np.sum(factor.residual_sums(values))) / dof
        std = np.sqrt(sigma2 * inverse_diagonal)
        sigma, weights, method = np.full(n, np.sqrt(sigma2)), None, "ols"
    else:
        joint_dof = N - k / n
        if joint_dof <= 0:
            raise IdentificationDataError(f"too few samples for weighted least squares: {N} samples per joint for "
                                          f"{k / n:g} parameters per joint")
        sigma = np.sqrt(np.maximum(factor.residual_sums(values), 0.0) / joint_dof)
        largest = sigma.max()
        sigma = np.maximum(sigma, 1e-6 * largest) if largest > 0 else np.ones(n)
        weights = 1.0 / sigma
        Rw, cw, _ = factor.stacked(weights)
        values, inverse_diagonal, cond, cond_scaled = solve_triangle(Rw, cw)
        sigma_w2 = float(np.sum(weights ** 2 * factor.residual_sums(values))) / dof
        std = np.sqrt(sigma_w2 * inverse_diagonal)
        method = "wls"
    with np.errstate(divide="ignore", invalid="ignore"):
        std_percent = np.where(values != 0, 100.0 * std / np.abs(values), np.inf)
    return Fit(names=names, values=values, std=std, std_percent=std_percent, condition_number=cond,
               condition_number_scaled=cond_scaled, rms=factor.rms(values), sigma=sigma,
               weights=weights, method=method, rows=N * n, dof=dof)
