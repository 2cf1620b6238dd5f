"""Fits of any set of ``discover``'s candidate columns from a pass's moments
(:mod:`kindyngen.measured.discovery_data`), inside the physical domain, with their
time-blocked cross-validation.

Columns are scaled to unit norm (the scaled unknowns ``theta``).  Coefficients with a physical
range (friction, armature and compliance >= 0, an encoder offset within +-0.05 rad, a torque
gain error within +-0.5, the load-dependent friction in [0, 0.9]) are fitted by bounded least
squares (BVLS); a fit with the rigid bodies' columns is a semidefinite program (a quadratic
objective under positive semidefinite cones, CLARABEL called directly) over the change of every
link's ten barycentric parameters, each link's pseudo-inertia
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
        """The semidefinite program (see the module text), a quadratic objective under conic
        constraints solved by CLARABEL directly: (theta on idx, link change or None)."""
        import clarabel
        from scipy import sparse
        key = tuple(idx)
        if key not in self._programs:
            self._programs[key] = self._build(idx)
        E, A, rhs, cones, nl = self._programs[key]
        # objective theta' G theta - 2 b' theta (+ the links' regularisation), theta = E z
        P = E.T @ G @ E
        if nl:
            P[-10 * nl:, -10 * nl:] += LINK_REGULARIZATION * self.m.sum_tau2 * np.eye(10 * nl)
        P = 0.5 * (P + P.T)
        top = max(float(np.max(np.abs(P))), 1e-300)
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.max_iter = 400
        solver = clarabel.DefaultSolver(sparse.triu(sparse.csc_matrix(2 * P / top)).tocsc(), -2 * (E.T @ b) / top,
                                        A, rhs, cones, settings)
        solution = solver.solve()
        z = np.asarray(solution.x, float)
        if not np.all(np.isfinite(z)) or str(solution.status) not in ("Solved", "AlmostSolved", "MaxIterations",
                                                                      "InsufficientProgress"):
            raise RuntimeError(f"the physical fit failed ({solution.status})")
        return E @ z, (z[-10 * nl:] if nl else None)

    def _build(self, idx):
        """(E: theta = E z, constraint matrix, right-hand side, cones, links) of the program on
        ``idx``: z holds the scaled unknowns of the non-rigid columns and the links' change."""
        from scipy import sparse
        import clarabel
        k = len(idx)
        T = _pseudo_inertia_matrices()
        upper = [(r, c) for c in range(4) for r in range(c + 1)]          # CLARABEL's svec order

        def svec_rows(M):                                                  # (10, 4, 4) -> (10, 10)
            return np.array([[M[i][r, c] * (1.0 if r == c else math.sqrt(2.0)) for (r, c) in upper]
                             for i in range(len(M))]).T

        svec_T = svec_rows(T)                                              # svec(J(p)) = svec_T @ p
        svec_eps = np.array([PSEUDO_INERTIA_EPSILON if r == c else 0.0 for (r, c) in upper])
        rigid = np.isin(idx, self.rigid) if self.rigid is not None else np.zeros(k, bool)
        others = np.flatnonzero(~rigid)
        nl = 0
        blocks_A, blocks_b, cones = [], [], []
        if rigid.any():
            base_map, point_links = self.links
            nl = len(point_links) // 10
        nz = len(others) + 10 * nl
        E = np.zeros((k, nz))
        E[others, np.arange(len(others))] = 1.0
        if nl:
            where = np.flatnonzero(rigid)
            cols = idx[where] - self.rigid[0]
            inv_scale = np.where(self.scale[idx[where]] > 0, 1.0 / np.where(self.scale[idx[where]] > 0,
                                                                            self.scale[idx[where]], 1.0), 0.0)
            E[where, len(others):] = inv_scale[:, None] * base_map[cols]
            for l in range(nl):
                A = np.zeros((10, nz))
                A[:, len(others) + 10 * l:len(others) + 10 * l + 10] = -svec_T
                blocks_A.append(A)
                blocks_b.append(svec_T @ point_links[10 * l:10 * l + 10] - svec_eps)
                cones.append(clarabel.PSDTriangleConeT(4))
        if self.payload_columns is not None and np.all(np.isin(self.payload_columns, idx)):
            where = np.array([np.flatnonzero(idx == c)[0] for c in self.payload_columns])
            A = np.zeros((10, nz))
            A[:, where] = -svec_T * self.scale[self.payload_columns][None, :]
            blocks_A.append(A)
            blocks_b.append(svec_T @ self.payload - svec_eps)
            cones.append(clarabel.PSDTriangleConeT(4))
        lower, upper_b = self.lower[idx], self.upper[idx]
        rows, rhs = [], []
        for i in others:
            if np.isfinite(lower[i]):
                row = np.zeros(nz)
                row[np.flatnonzero(others == i)[0]] = -1.0
                rows.append(row)
                rhs.append(-lower[i])
            if np.isfinite(upper_b[i]):
                row = np.zeros(nz)
                row[np.flatnonzero(others == i)[0]] = 1.0
                rows.append(row)
                rhs.append(upper_b[i])
        if rows:
            blocks_A.insert(0, np.array(rows))
            blocks_b.insert(0, np.array(rhs))
            cones.insert(0, clarabel.NonnegativeConeT(len(rows)))
        A = sparse.csc_matrix(np.vstack(blocks_A)) if blocks_A else sparse.csc_matrix((0, nz))
        rhs = np.concatenate(blocks_b) if blocks_b else np.zeros(0)
        return E, A, rhs, cones, nl

    def fit(self, idx, fixed=None, damping: float = 0.0) -> dict:
        """Full-data fit and out-of-fold residual sums of the columns ``idx``; ``fixed``:
        ``(columns, theta)`` held at those scaled values (not fitted, in every fold);
        ``damping``: Levenberg-Marquardt's ``lambda``, added to the normal matrix's diagonal of
        the scaled columns (whose own diagonal is 1), so that a step at a point of a nonlinear
        reading stays where the linearisation holds."""
        idx = np.asarray(idx, int)
        if fixed is not None:
            fcols, fth = np.asarray(fixed[0], int), np.asarray(fixed[1], float)
            idx = idx[~np.isin(idx, fcols)]
        else:
            fcols, fth = np.zeros(0, int), np.zeros(0)

        def shifted(G, b):
            return b[idx] - G[np.ix_(idx, fcols)] @ fth if len(fcols) else b[idx]

        def whole(theta):
            out = self.raw(idx, theta)
            out[fcols] = fth * self.scale[fcols]
            return out
        G, b = self.G[np.ix_(idx, idx)], shifted(self.G, self.b)
        damp = damping * np.eye(len(idx))
        theta, inv, rank, links = self._solve(G + damp, b, idx)
        joint_rss = self.joint_rss(whole(theta))
        oof = np.zeros((self.m.folds, self.n))
        for k in range(self.m.folds):
            Gk, bk = (self.G - self.Gf[k]), (self.b - self.bf[k])
            th = self._solve(Gk[np.ix_(idx, idx)] + damp, shifted(Gk, bk), idx)[0]
            oof[k] = self.joint_rss(whole(th), folds=(k,))
        if len(fcols):           # the fit's columns and values include the fixed ones
            order = np.argsort(np.concatenate([idx, fcols]))
            idx, theta = np.concatenate([idx, fcols])[order], np.concatenate([theta, fth])[order]
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
