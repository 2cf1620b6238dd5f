"""The unrolled solves of forward dynamics ``qdd = M(q)^-1 (tau - c(q, qd) - g(q))``
(:func:`kindyngen.algorithms.dynamics.forward_dynamics_tree` builds M and the bias): a fixed-size
``L D L^T`` factorisation and the two triangular solves, dense or as sparse as the tree,
all written as symengine expressions on the same DAG.  No square roots; one division per
joint (``1 / D_j``, D_j > 0 because M is positive definite), so the generated C is
allocation-free straight-line code.

Example:

>>> [float(v) for v in ldlt_solve([[4, 2], [2, 3]], [2, 1])]
[0.5, 0.0]
"""
from __future__ import annotations

import symengine as se

from .symbolic import naming


def ldlt_solve(M, b):
    """Solve ``M x = b`` for a symmetric positive definite M (nested lists) by an unrolled
    ``M = L D L^T`` (unit lower L, diagonal D); returns x as a list of expressions."""
    return ldlt_substitute(*ldlt_factor(M), b)


def ldlt_factor(M):
    """The unrolled ``M = L D L^T`` of a symmetric positive definite M (nested lists):
    ``(L, inv_d)``, L's entries below the diagonal and the reciprocals ``1 / D_j``.

    ``E_ij = L_ij D_j = M_ij - sum_{k<j} E_ik L_jk``, ``D_j = M_jj - sum_{k<j} E_jk L_jk``,
    ``L_ij = E_ij / D_j`` (one reciprocal per column)."""
    n = len(M)
    L = [[None] * n for _ in range(n)]
    E = [[None] * n for _ in range(n)]
    inv_d = [None] * n
    for j in range(n):
        d = se.Add(M[j][j], *(-E[j][k] * L[j][k] for k in range(j)))
        inv_d[j] = se.Pow(d, -1)
        for i in range(j + 1, n):
            E[i][j] = se.Add(M[i][j], *(-E[i][k] * L[j][k] for k in range(j)))
            L[i][j] = E[i][j] * inv_d[j]
    return L, inv_d


def ldlt_substitute(L, inv_d, b):
    """``x = M^-1 b`` from the factors of :func:`ldlt_factor`: ``L y = b``, ``z = y / D``,
    ``L^T x = z``."""
    n = len(b)
    y = [None] * n
    for i in range(n):
        y[i] = se.Add(b[i], *(-L[i][k] * y[k] for k in range(i)))
    x = [None] * n
    for i in range(n - 1, -1, -1):
        x[i] = se.Add(y[i] * inv_d[i], *(-L[k][i] * x[k] for k in range(i + 1, n)))
    return x


def tree_ldlt_solve(M, parents, b, stages=None):
    """Solve ``M x = b`` for a symmetric positive definite M whose nonzeros lie between a
    coordinate and its ancestors in a tree (``parents[k] < k``, -1 at a root), by ``M = L^T
    D L`` with L unit lower triangular and as sparse as M (Featherstone, *Rigid Body Dynamics
    Algorithms*, sec. 6.5: no fill-in), unrolled: O(n d^2) for depth d instead of O(n^3).

    >>> [float(v) for v in tree_ldlt_solve([[4, 1, 1], [1, 2, 0], [1, 0, 2]], (-1, 0, 0), [6, 3, 3])]
    [1.0, 1.0, 1.0]

    With ``stages`` (:class:`kindyngen.algorithms.symbolic.Stages`) every updated entry and every
    intermediate of the solves is a named intermediate.
    """
    return tree_ldlt_substitute(tree_ldlt_factor(M, parents, stages), b, naming(stages))


def tree_ldlt_factor(M, parents, stages=None):
    """The factor of :func:`tree_ldlt_solve`, kept for many right-hand sides: ``(H, inv_d,
    ancestors)``, ``H[k][i]`` the entries of L for i above k, ``inv_d`` the ``1 / D_k``."""
    name = naming(stages)
    n = len(M)
    H = [list(row) for row in M]
    ancestors = []
    for k in range(n):
        up, i = [], parents[k]
        while i >= 0:
            up.append(i)
            i = parents[i]
        ancestors.append(up)
    inv_d = [None] * n
    for k in range(n - 1, -1, -1):
        inv_d[k] = name(se.Pow(H[k][k], -1))
        for pos, i in enumerate(ancestors[k]):
            a = name(H[k][i] * inv_d[k])
            for j in [i] + ancestors[k][pos + 1:]:
                H[i][j] = name(H[i][j] - a * H[k][j])
            H[k][i] = a
    return H, inv_d, ancestors


def tree_ldlt_substitute(factor, b, name):
    """``x = M^-1 b`` from :func:`tree_ldlt_factor` (``name``: :func:`naming` of the stages;
    exact zeros of b fold away)."""
    H, inv_d, ancestors = factor
    n = len(b)
    x = [name(e) for e in b]           # L^T y = b, leaves first
    for k in range(n - 1, -1, -1):
        for i in ancestors[k]:
            x[i] = name(x[i] - H[k][i] * x[k])
    x = [name(x[k] * inv_d[k]) for k in range(n)]
    for k in range(n):                 # L x = y / D, root first
        x[k] = name(se.Add(x[k], *(-H[k][i] * x[i] for i in ancestors[k])))
    return x
