"""Numeric helpers of the closed-form IK that only the tests use (moved out of
kindyngen.ik.lwr_common, which does not need them)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from kindyngen.ik.lwr_common import ADMISSIBLE, N_BRANCHES, Solver


def admissible(status, accept: Sequence[int] = ADMISSIBLE) -> np.ndarray:
    """Boolean mask of the rows whose status is in ``accept``."""
    return np.isin(np.asarray(status), np.asarray(accept))


def closest_solution(q, status, q_ref, weights=None, accept: Sequence[int] = ADMISSIBLE):
    """The admissible branch closest to ``q_ref`` (weighted Euclidean distance in joint
    space; no wrap-around, joints cannot pass through their limits).

    ``q``: (..., 8, n), ``status``: (..., 8), ``q_ref``: (..., n). Returns
    ``(index, q_best, found)``: index (...) of the row (-1 if none admissible), the row
    (q_ref where none) and a boolean mask.

    >>> q = np.zeros((8, 7)); q[3] = 1.0
    >>> closest_solution(q, np.array([1, 0, 0, 0, 1, 1, 1, 1]), np.full(7, 0.9))[0]
    array(3)
    """
    q = np.asarray(q, float)
    status = np.asarray(status)
    q_ref = np.asarray(q_ref, float)
    w = np.ones(q.shape[-1]) if weights is None else np.asarray(weights, float)
    dist = np.sqrt(np.sum(w * (q - q_ref[..., None, :]) ** 2, axis=-1))
    ok = admissible(status, accept)
    dist = np.where(ok, dist, np.inf)
    index = np.argmin(dist, axis=-1)
    found = np.take_along_axis(ok, index[..., None], axis=-1)[..., 0]
    best = np.take_along_axis(q, index[..., None, None], axis=-2)[..., 0, :]
    best = np.where(found[..., None], best, q_ref)
    return np.where(found, index, -1), best, found


def theta3_intervals(solve: Solver, target, lower: float, upper: float, samples: int = 721,
                     tol: float = 1e-10, accept: Sequence[int] = ADMISSIBLE):
    """Admissible intervals of theta3 in [lower, upper] for one target, per branch.

    ``solve(targets, theta3)`` evaluates the IK on a batch: ``targets`` (m, ...) repeated
    target, ``theta3`` (m,) -> ``(q (m, 8, 7), status (m, 8))`` (e.g. generated code or
    :func:`tests.harness.evaluate_symbolic`). theta3 is sampled on ``samples`` points, every
    change of admissibility between neighbours is refined by bisection to ``tol``.

    Returns ``(per_branch, union)``: per_branch[k] is a list of (start, end) intervals where
    row k is admissible, ``union`` those where some row is. Intervals narrower than the
    sampling step can be missed (raise ``samples``).
    """
    target = np.asarray(target, float)
    grid = np.linspace(lower, upper, samples)

    def admissible_at(theta):
        theta = np.atleast_1d(np.asarray(theta, float))
        targets = np.broadcast_to(target, (theta.size,) + target.shape)
        _, status = solve(targets, theta)
        return admissible(np.asarray(status).reshape(theta.size, N_BRANCHES), accept)

    ok = admissible_at(grid)                                     # (samples, 8)
    ok = np.concatenate([ok, ok.any(axis=1, keepdims=True)], axis=1)  # column 8: union

    # every sign change between neighbours: bisect all of them at once
    ks, cols = np.nonzero(ok[1:] != ok[:-1])
    lo, hi = grid[ks].copy(), grid[ks + 1].copy()
    left_ok = ok[ks, cols]
    while lo.size and np.max(hi - lo) > tol:
        mid = 0.5 * (lo + hi)
        at = admissible_at(mid)
        at = np.concatenate([at, at.any(axis=1, keepdims=True)], axis=1)
        same = at[np.arange(mid.size), cols] == left_ok
        lo = np.where(same, mid, lo)
        hi = np.where(same, hi, mid)
    # a boundary: the admissible side's last point
    edge = np.where(left_ok, lo, hi)

    result = []
    for col in range(N_BRANCHES + 1):
        intervals, start = [], (grid[0] if ok[0, col] else None)
        for k, e, lok in zip(ks[cols == col], edge[cols == col], left_ok[cols == col]):
            if lok:      # admissible -> not: an interval ends
                intervals.append((float(start), float(e)))
                start = None
            else:        # not -> admissible: one starts
                start = e
        if start is not None:
            intervals.append((float(start), float(grid[-1])))
        result.append(intervals)
    return result[:N_BRANCHES], result[N_BRANCHES]
