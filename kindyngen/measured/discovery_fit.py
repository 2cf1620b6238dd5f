"""Fits of any set of ``discover``'s candidate columns from a pass's moments
(:mod:`kindyngen.measured.discovery_data`), inside the physical domain, with their
time-blocked cross-validation.

Columns are scaled to unit norm (the scaled unknowns ``theta``).  Coefficients with a physical
range (friction, armature and compliance >= 0, an encoder offset within +-0.05 rad, a torque
gain error within +-0.5, the load-dependent friction in [0, 0.9]) are fitted by bounded least
squares (BVLS); a fit with the rigid bodies' columns is a semidefinite program (CLARABEL through
cvxpy) over the change of every link's ten barycentric parameters, each link's pseudo-inertia
held >= 1e-6 (the columns are the base regressor's: the change of the base parameters is the
base map times the change of the links'), as is a fit whose flange payload would otherwise not
be a body.  Bounds are on the *total* coefficient: a pass at a point that already holds values
(a Gauss-Newton step) fits the change, within the range less the point's value.

Cross-validation: fit on all folds but k, residual sums on fold k (exact, from the per-joint
factors), for every k; the held-out RMS per joint is the root of the out-of-fold sum over all
rows.

Example:

>>> problem = Problem(result, bounds, point_values)          # doctest: +SKIP
>>> fit = problem.fit(problem.columns(["coulomb_friction"]))   # doctest: +SKIP
>>> fit["heldout"]                                             # doctest: +SKIP
"""
from __future__ import annotations

import math

import numpy as np

from .discovery_data import PassResult

#: eigenvalues of the column-scaled normal matrix below this times the largest are dropped
#: (minimum-norm solution: some candidates' columns are rank-deficient among themselves)
RCOND = 1e-11
#: smallest eigenvalue (kg m^2) a body's pseudo-inertia is held to
PSEUDO_INERTIA_EPSILON = 1e-6
#: weight of the change of the link parameters (SI units) in a rigid-body fit, relative to the
#: sum of squared torques: picks, among link parameters that fit equally well, the nearest to the
#: point's (the weight :mod:`kindyngen.measured.consistent` measured as the compromise)
LINK_REGULARIZATION = 1e-7


def _pseudo_inertia_matrices() -> np.ndarray:
    """(10, 4, 4): the pseudo-inertia is linear in the ten barycentric numbers."""
    from .consistent import pseudo_inertia
    return np.stack([pseudo_inertia(np.eye(10)[k]) for k in range(10)])


def _bounded_solve(G, b, lower, upper):
    """Minimise ``th' G th - 2 b' th`` with ``lower <= th <= upper``: bounded least squares
    on the square root of ``G`` (eigen-decomposition, so a singular ``G`` is fine)."""
    from scipy.optimize import lsq_linear
    w, V = np.linalg.eigh(G)
    keep = w > RCOND * max(w.max(), 1e-300)
    root = np.sqrt(w[keep])[:, None] * V[:, keep].T
    target = (V[:, keep].T @ b) / np.sqrt(w[keep])
    return lsq_linear(root, target, bounds=(lower, upper), method="bvls").x


class Problem:
    """Fits of column sets of a pass (see the module text).

    ``bounds``: per global column (lower, upper) of the *change* (raw units; +-inf: none);
    ``links``: for a pass with the rigid bodies' columns, ``(base_map, point link values)``
    (the full barycentric parameters at the point); ``payload``: for a pass with the payload's,
    the flange body's barycentric values at the point; ``sum_tau2``: the regularisation scale."""

    def __init__(self, result: PassResult, bounds, links=None, payload=None):
        m, L = result.moments, result.layout
        self.result, self.m, self.layout = result, m, L
        self.n, self.N, self.p = m.n, m.samples, L.p
        folds = m.folds
        Gf = np.zeros((folds, L.p, L.p))
        bf = np.zeros((folds, L.p))
        for k in range(folds):
            for j in range(self.n):
                S = L.support[j]
                R, c = m.R[k, j], m.c[k, j]
                Gf[k][np.ix_(S, S)] += R.T @ R
                bf[k][S] += R.T @ c
        G, b = Gf.sum(axis=0), bf.sum(axis=0)
        norm = np.sqrt(np.maximum(np.diag(G), 0.0))
        self.scale = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 0.0)
        D = self.scale
        self.Gf = D[None, :, None] * Gf * D[None, None, :]
        self.bf = D[None, :] * bf
        self.G, self.b = D[:, None] * G * D[None, :], D * b
        lower, upper = (np.asarray(x, float) for x in bounds)
        live = np.where(self.scale > 0, self.scale, 1.0)
        self.lower = np.where(self.scale > 0, lower / live, -np.inf)
        self.upper = np.where(self.scale > 0, upper / live, np.inf)
        self.links, self.payload = links, payload
        self.rigid = L.slices.get("rigid_bodies") if links is not None else None
        self.payload_columns = next((L.slices[b.key] for b in L.blocks if b.candidate == "payload"), None)
        self._programs = {}

    # -- columns
    def columns(self, keys) -> np.ndarray:
        return np.concatenate([self.layout.slices[k] for k in keys]) if keys else np.zeros(0, int)

    def live(self, idx) -> bool:
        """Whether any of the columns is non-zero on this motion."""
        return bool(np.any(self.scale[idx] > 0))

    def raw(self, idx, theta) -> np.ndarray:
        """Coefficients of all global columns (raw units) for ``theta`` on ``idx``."""
        out = np.zeros(self.p)
        out[idx] = theta * self.scale[idx]
        return out

    def joint_rss(self, coef, folds=None) -> np.ndarray:
        """Per joint, the residual sum of squares for raw coefficients ``coef`` over ``folds``
        (default all), exactly from the factors."""
        out = np.zeros(self.n)
        for k in range(self.m.folds) if folds is None else folds:
            for j in range(self.n):
                out[j] += np.sum((self.m.R[k, j] @ coef[self.layout.support[j]] - self.m.c[k, j]) ** 2) + \
                    self.m.rss[k, j]
        return out

    # -- solving
    def _solve(self, G, b, idx):
        """Solution in the physical domain, the pseudo-inverse of the normal matrix and its rank
        (and the link parameters' change of a rigid-body fit)."""
        if len(idx) == 0:
            return np.zeros(0), np.zeros((0, 0)), 0, None
        w, V = np.linalg.eigh(G)
        keep = w > RCOND * max(w.max(), 1e-300)
        inv = (V[:, keep] / w[keep]) @ V[:, keep].T
        rank = int(keep.sum())
        if self.rigid is not None and np.any(np.isin(idx, self.rigid)):
            theta, links = self._program(G, b, idx)
            return theta, inv, rank, links
        theta = inv @ b
        lower, upper = self.lower[idx], self.upper[idx]
        if np.any(theta < lower) or np.any(theta > upper):
            theta = _bounded_solve(G, b, lower, upper)
        if self.payload_columns is not None and np.all(np.isin(self.payload_columns, idx)) and \
                not self._payload_physical(theta, idx):
            theta, _ = self._program(G, b, idx)
        return theta, inv, rank, None

    def _payload_physical(self, theta, idx) -> bool:
        where = np.searchsorted(idx, self.payload_columns) if np.all(np.diff(idx) > 0) else \
            np.array([np.flatnonzero(idx == c)[0] for c in self.payload_columns])
        values = self.payload + theta[where] * self.scale[self.payload_columns]
        J = np.tensordot(values, _pseudo_inertia_matrices(), axes=1)
        return bool(np.linalg.eigvalsh(J)[0] >= PSEUDO_INERTIA_EPSILON)

    def _program(self, G, b, idx):
        """The semidefinite program (see the module text); (theta on idx, link change or None)."""
        import cvxpy as cp
        key = tuple(idx)
        if key not in self._programs:
            self._programs[key] = self._build(idx)
        problem, root, target, theta_of, links = self._programs[key]
        w, V = np.linalg.eigh(G)
        top = max(w.max(), 1e-300)
        keep = w > RCOND * top
        sq = np.where(keep, np.sqrt(np.maximum(w, 0)), 0.0)
        root.value = sq[:, None] * V.T
        target.value = np.where(keep, (V.T @ b) / np.where(keep, sq, 1.0), 0.0)
        import warnings
        with warnings.catch_warnings():
            # "optimal_inaccurate" (CLARABEL stopped at its iteration limit near the optimum) is
            # taken: the fit is judged by its held-out error like every other
            warnings.simplefilter("ignore", UserWarning)
            try:
                problem.solve(solver="CLARABEL")
            except cp.error.SolverError:
                problem.solve(solver="CLARABEL", max_iter=500, tol_gap_abs=1e-7, tol_gap_rel=1e-7)
        value = theta_of.value
        if value is None:
            raise RuntimeError(f"the physical fit failed ({problem.status})")
        return np.asarray(value, float), (None if links is None else np.asarray(links.value, float))

    def _build(self, idx):
        import cvxpy as cp
        k = len(idx)
        root, target = cp.Parameter((k, k)), cp.Parameter(k)
        T = _pseudo_inertia_matrices()
        x = cp.Variable(k)
        constraints, extra = [], 0
        links = None
        rigid = np.isin(idx, self.rigid) if self.rigid is not None else np.zeros(k, bool)
        if rigid.any():
            base_map, point_links = self.links
            nl = len(point_links) // 10
            links = cp.Variable(10 * nl)
            # the rigid columns' scaled unknowns are the base map times the links' change
            where = np.flatnonzero(rigid)
            cols = idx[where] - self.rigid[0]
            inv_scale = np.where(self.scale[idx[where]] > 0, 1.0 / np.where(self.scale[idx[where]] > 0,
                                                                            self.scale[idx[where]], 1.0), 0.0)
            constraints.append(x[where] == cp.multiply(inv_scale, base_map[cols] @ links))
            for l in range(nl):
                body = point_links[10 * l:10 * l + 10] + links[10 * l:10 * l + 10]
                J = sum(body[i] * T[i] for i in range(10))
                constraints.append(0.5 * (J + J.T) >> PSEUDO_INERTIA_EPSILON * np.eye(4))
            extra = LINK_REGULARIZATION * self.m.sum_tau2 * cp.sum_squares(links)
        if self.payload_columns is not None and np.all(np.isin(self.payload_columns, idx)):
            where = np.array([np.flatnonzero(idx == c)[0] for c in self.payload_columns])
            body = self.payload + cp.multiply(self.scale[self.payload_columns], x[where])
            J = sum(body[i] * T[i] for i in range(10))
            constraints.append(0.5 * (J + J.T) >> PSEUDO_INERTIA_EPSILON * np.eye(4))
        lower, upper = self.lower[idx], self.upper[idx]
        for bound, sign in ((lower, 1), (upper, -1)):
            finite = np.flatnonzero(np.isfinite(bound) & ~rigid)
            if finite.size:
                constraints.append(sign * (x[finite] - bound[finite]) >= 0)
        problem = cp.Problem(cp.Minimize(cp.sum_squares(root @ x - target) + extra), constraints)
        return problem, root, target, x, links

    def fit(self, idx) -> dict:
        """Full-data fit and out-of-fold residual sums of the columns ``idx``."""
        idx = np.asarray(idx, int)
        G, b = self.G[np.ix_(idx, idx)], self.b[idx]
        theta, inv, rank, links = self._solve(G, b, idx)
        joint_rss = self.joint_rss(self.raw(idx, theta))
        oof = np.zeros((self.m.folds, self.n))
        for k in range(self.m.folds):
            Gk, bk = (self.G - self.Gf[k])[np.ix_(idx, idx)], (self.b - self.bf[k])[idx]
            th = self._solve(Gk, bk, idx)[0]
            oof[k] = self.joint_rss(self.raw(idx, th), folds=(k,))
        fold_mse = np.sum(oof, axis=1) / np.maximum(self.m.rows, 1)
        heldout = np.sqrt(np.maximum(np.sum(oof, axis=0), 0) / max(self.N, 1))
        return dict(idx=idx, theta=theta, inv=inv, rank=rank, links=links, joint_rss=joint_rss,
                    rss=float(np.sum(joint_rss)), fold_mse=fold_mse, heldout=heldout,
                    mse=float(np.sum(heldout ** 2)))

    def residual_rms(self, fit) -> np.ndarray:
        return np.sqrt(np.maximum(fit["joint_rss"], 0) / max(self.N, 1))

    def fold_fit(self, fit, k, column) -> tuple[float, float]:
        """Coefficient ``column`` (raw) refitted on fold k alone with the fit's other
        coefficients held, and its standard error there (time-block drift)."""
        coef = self.raw(fit["idx"], fit["theta"])
        L = self.layout
        num = den = 0.0
        rss = 0.0
        for j in range(self.n):
            S = L.support[j]
            where = np.flatnonzero(S == column)
            if not where.size:
                continue
            R, c = self.m.R[k, j], self.m.c[k, j]
            a = R[:, where[0]]
            others = coef[S].copy()
            others[where[0]] = 0.0
            r = c - R @ others
            num += float(a @ r)
            den += float(a @ a)
        if den <= 0:
            return math.nan, math.inf
        value = num / den
        coef_k = coef.copy()
        coef_k[column] = value
        rss = float(np.sum(self.joint_rss(coef_k, folds=(k,))))
        dof = max(self.m.rows[k] * self.n - len(fit["idx"]), 1)
        return value, math.sqrt(rss / dof / den)

    # -- statistics of the final fit (a pass with lags and signals)
    def effective_samples(self, fit) -> tuple[np.ndarray, bool]:
        """Per joint ``N / (1 + 2 sum rho_k)`` of the fit's residual from the lagged products,
        and whether the first non-positive lag lies within the lags folded."""
        N, L = self.N, self.m.lags
        coef = self.raw(fit["idx"], fit["theta"])
        out = np.empty(self.n)
        exact = True
        for j in range(self.n):
            S = self.layout.support[j]
            wv = np.concatenate([-coef[S], [1.0]])
            Sg = self.m.signals[j]
            wdt = self.m.w
            total = Sg[wdt, wdt + 6] - coef[S] @ Sg[:wdt, wdt + 6]
            mean = total / N
            acf0 = fit["joint_rss"][j] - N * mean ** 2
            if acf0 <= 0:
                out[j] = N
                continue
            head = np.cumsum(self.m.head[j] @ wv)
            tail = np.cumsum((self.m.tail[j] @ wv)[::-1])
            s = 0.0
            lags = min(L, N - 1)
            for k in range(1, lags + 1):
                acf = wv @ self.m.lagged[j][k - 1] @ wv - mean * ((total - tail[k - 1]) + (total - head[k - 1])) \
                    + (N - k) * mean ** 2
                rho = acf / acf0
                if rho <= 0:
                    break
                s += rho
            else:
                exact = exact and lags >= N - 1
            out[j] = min(N, max(1.0, N / (1.0 + 2.0 * s)))
        return out, exact

    def correlations(self, fit, j, labels) -> list[tuple[float, str]]:
        """(|correlation|, label) of joint j's residual with each filtered signal."""
        Sg, wdt, N = self.m.signals[j], self.m.w, self.N
        coef = self.raw(fit["idx"], fit["theta"])[self.layout.support[j]]
        wv = np.concatenate([-coef, [1.0]])
        total = Sg[wdt, wdt + 6] - coef @ Sg[:wdt, wdt + 6]
        r_norm2 = fit["joint_rss"][j] - total ** 2 / N
        out = []
        for k, label in enumerate(labels):
            x = wdt + 1 + k
            cross = wv @ Sg[:wdt + 1, x] - total * Sg[x, wdt + 6] / N
            x_norm2 = Sg[x, x] - Sg[x, wdt + 6] ** 2 / N
            den = math.sqrt(max(r_norm2, 0) * max(x_norm2, 0))
            out.append((abs(float(cross)) / den if den > 0 else 0.0, label))
        return out

    def contribution_rms(self, fit, column) -> np.ndarray:
        """Per joint, the RMS of one column's torque in ``fit`` (N m)."""
        return abs(self.raw(fit["idx"], fit["theta"])[column]) * self.column_rms(column)

    def column_rms(self, column) -> np.ndarray:
        """Per joint, the RMS of one (raw) column over the rows."""
        coef = np.zeros(self.p)
        coef[column] = 1.0
        out = np.zeros(self.n)
        for k in range(self.m.folds):
            for j in range(self.n):
                S = self.layout.support[j]
                out[j] += np.sum((self.m.R[k, j] @ coef[S]) ** 2)
        return np.sqrt(out / max(self.N, 1))
