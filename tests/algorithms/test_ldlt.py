"""The unrolled factorisations of :mod:`kindyngen.algorithms.ldlt` on numbers, against numpy:
the dense ``L D L^T`` (``ldlt_factor`` rebuilds M, ``ldlt_solve`` and ``ldlt_substitute``
solve it) and the tree-sparse ``L^T D L`` (``tree_ldlt_factor`` finds the sparse factor a
matrix was built from, without fill-in; ``tree_ldlt_solve`` and ``tree_ldlt_substitute``
solve it) on random positive definite matrices of branched trees."""
from __future__ import annotations

import numpy as np
import pytest
import symengine as se

from kindyngen.algorithms.ldlt import (ldlt_factor, ldlt_solve, ldlt_substitute, tree_ldlt_factor, tree_ldlt_solve,
                                       tree_ldlt_substitute)
from kindyngen.algorithms.symbolic import naming

TOL = 1e-12
TREES = [(-1,), (-1, 0, 1, 2), (-1, 0, 0, 1, 1, 2), (-1, 0, 1, -1, 3, 0, 5)]


def _se(M):
    return [[se.RealDouble(float(v)) for v in row] for row in M]


def _floats(v):
    return np.array([float(x) for x in v])


def _spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


@pytest.mark.parametrize("n", [1, 2, 5, 7])
def test_dense_factor_rebuilds_the_matrix_and_solves(n):
    rng = np.random.default_rng(n)
    M, b = _spd(rng, n), rng.normal(size=n)
    L, inv_d = ldlt_factor(_se(M))
    Ln = np.eye(n)
    for i in range(n):
        for j in range(i):
            Ln[i, j] = float(L[i][j])
    D = np.diag(1 / _floats(inv_d))
    assert np.allclose(Ln @ D @ Ln.T, M, rtol=0, atol=TOL * np.abs(M).max())
    x = np.linalg.solve(M, b)
    assert np.allclose(_floats(ldlt_solve(_se(M), [se.RealDouble(v) for v in b])), x, rtol=0, atol=TOL)
    assert np.allclose(_floats(ldlt_substitute(L, inv_d, [se.RealDouble(v) for v in b])), x, rtol=0, atol=TOL)


def test_dense_solve_of_exact_numbers_is_exact():
    x = ldlt_solve([[se.Integer(4), se.Integer(2)], [se.Integer(2), se.Integer(3)]], [se.Integer(1), se.Integer(0)])
    assert x == [se.Rational(3, 8), se.Rational(-1, 4)]        # [[4, 2], [2, 3]]^-1 e_1 by hand


def _ancestors(parents, k):
    out, i = [], parents[k]
    while i >= 0:
        out.append(i)
        i = parents[i]
    return out


def _tree_matrix(rng, parents):
    """M = L^T D L with L unit lower triangular, L[k, i] nonzero only for i an ancestor of k:
    M is as sparse as the tree (M[i, j] != 0 only between a coordinate and its ancestors)."""
    n = len(parents)
    L = np.eye(n)
    for k in range(n):
        for i in _ancestors(parents, k):
            L[k, i] = rng.normal()
    D = np.diag(rng.uniform(0.5, 3.0, size=n))
    return L.T @ D @ L, L, D


@pytest.mark.parametrize("parents", TREES)
def test_tree_factor_is_the_sparse_factor_and_solves(parents):
    rng = np.random.default_rng(len(parents))
    n = len(parents)
    M, L, D = _tree_matrix(rng, parents)
    for i in range(n):
        for j in range(n):
            if i != j and i not in _ancestors(parents, j) and j not in _ancestors(parents, i):
                assert M[i, j] == 0                     # the tree's sparsity
    H, inv_d, ancestors = tree_ldlt_factor(_se(M), parents)
    assert ancestors == [_ancestors(parents, k) for k in range(n)]
    assert np.allclose(1 / _floats(inv_d), np.diag(D), rtol=1e-12, atol=0)
    for k in range(n):
        for i in ancestors[k]:
            assert abs(float(H[k][i]) - L[k, i]) <= TOL * max(1, abs(L[k, i]))
    b = rng.normal(size=n)
    x = np.linalg.solve(M, b)
    assert np.allclose(_floats(tree_ldlt_solve(_se(M), parents, [se.RealDouble(v) for v in b])), x,
                       rtol=0, atol=TOL * np.abs(x).max())
    assert np.allclose(_floats(tree_ldlt_substitute((H, inv_d, ancestors), [se.RealDouble(v) for v in b],
                                                    naming(None))), x, rtol=0, atol=TOL * np.abs(x).max())


def test_tree_solve_on_a_chain_equals_the_dense_solve():
    rng = np.random.default_rng(3)
    M, b = _spd(rng, 5), rng.normal(size=5)
    chain = (-1, 0, 1, 2, 3)
    assert np.allclose(_floats(tree_ldlt_solve(_se(M), chain, [se.RealDouble(v) for v in b])),
                       _floats(ldlt_solve(_se(M), [se.RealDouble(v) for v in b])), rtol=0, atol=TOL)
