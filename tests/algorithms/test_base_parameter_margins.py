"""The structural decisions of the base-parameter analysis (rank, which columns are
independent) are taken only with a stated margin, so that no processor's last bit can change
the generated regressors; a decision inside the margin is refused, not guessed."""
from __future__ import annotations

import numpy as np
import pytest
import sympy

from tests.harness import robot
from kindyngen.algorithms import regressors
from kindyngen.algorithms.base_parameters import (ABOVE_MARGIN, DECISION_MARGIN, DEPENDENT_TOL, RANK_TOL, BaseParameterError,
                                       find_base_parameters, numeric_rank)


def _ratios(A):
    """(pivoted-QR ratios |R_kk|/|R_00|, unpivoted |R_kk|/column norm) of a stacked regressor."""
    import scipy.linalg
    _, diag = numeric_rank(A)
    R = scipy.linalg.qr(A, mode="r")[0]
    norms = np.linalg.norm(A, axis=0)
    keep = norms > DEPENDENT_TOL * norms.max()
    return diag / diag[0], (np.abs(np.diag(R))[: A.shape[1]] / np.where(norms > 0, norms, 1))[keep]


@pytest.mark.parametrize("name", ["lwr4", "lwr4_hartl", "panda"])
@pytest.mark.parametrize("kind", regressors.KINDS)
def test_shipped_robots_decide_far_from_the_thresholds(name, kind):
    model = robot(name)
    A = regressors.evaluate_full(model, kind, regressors.random_states(model, regressors.SAMPLES[kind],
                                                                       regressors.SEEDS[0]))
    rank_ratios, column_ratios = _ratios(A.reshape(-1, A.shape[-1]))
    for ratios, tol in ((rank_ratios, RANK_TOL), (column_ratios, DEPENDENT_TOL)):
        below, above = ratios[ratios < tol], ratios[ratios >= tol]
        assert below.size == 0 or below.max() < tol / DECISION_MARGIN
        assert above.min() > tol * ABOVE_MARGIN
    print(f"{name} {kind}: rank ratios {rank_ratios[rank_ratios >= RANK_TOL].min():.2g} (kept) / "
          f"{rank_ratios[rank_ratios < RANK_TOL].max():.2g} (dropped)")


def test_a_column_near_the_threshold_is_refused():
    """Column z = x + 1e-8 w (w independent of x and y) is neither clearly in the span of x and
    y nor clearly out of it."""
    def evaluate(seed):
        a = np.random.default_rng(seed).normal(size=(30, 3))
        return np.column_stack([a[:, 0], a[:, 1], a[:, 0] + 1e-8 * a[:, 2]])[:, None, :]

    with pytest.raises(BaseParameterError, match="would depend on rounding"):
        find_base_parameters(evaluate, ("x", "y", "z"), seeds=(0, 1))


def test_clear_dependence_gives_exact_rational_grouping():
    def evaluate(seed):
        a = np.random.default_rng(seed).normal(size=(30, 2))
        return np.column_stack([a[:, 0], a[:, 1], 2 * a[:, 0] - a[:, 1] / 4])[:, None, :]

    b = find_base_parameters(evaluate, ("x", "y", "z"), seeds=(0, 1))
    assert b.exact and b.T == ((sympy.Integer(2),), (sympy.Rational(-1, 4),))
    assert b.exact_values([sympy.Rational(1, 3), 1, 3]) == (sympy.Rational(19, 3), sympy.Rational(1, 4))


def test_irrational_grouping_is_rounded_to_twelve_digits():
    """z = sqrt(2) x: the coefficient is no rational; it is kept to 12 significant digits so that
    the last bits of a least-squares solve do not reach base_params.json."""
    def evaluate(seed):
        a = np.random.default_rng(seed).normal(size=(30, 2))
        return np.column_stack([a[:, 0], a[:, 1], np.sqrt(2) * a[:, 0]])[:, None, :]

    b = find_base_parameters(evaluate, ("x", "y", "z"), seeds=(0, 1))
    assert not b.exact
    assert b.T[0][0] == 1.41421356237 and b.T[1][0] == 0


def test_columns_of_very_different_sizes_group_exactly():
    """z = 100 x - y / 4 + 0 w with x, y, w of norms 1e2, 1 and 1e-2 (masses beside inertias
    of long links): the relations are solved on unit-norm columns and each coefficient's
    rounding judged at its column ratio (|z| / |w| = 1e6), so the zero stays an exact zero (judged
    against 1 the coefficient of the small column is rounding noise of about 1e-10, and the
    grouping was 'not exact')."""
    def evaluate(seed):
        a = np.random.default_rng(seed).normal(size=(40, 3)) * np.array([1e2, 1.0, 1e-2])
        return np.column_stack([a, 100 * a[:, 0] - a[:, 1] / 4])[:, None, :]

    b = find_base_parameters(evaluate, ("x", "y", "w", "z"), seeds=(0, 1))
    assert b.exact and b.T == ((sympy.Integer(100),), (sympy.Rational(-1, 4),), (sympy.Integer(0),))


def test_hundred_metre_links_group_exactly(tmp_path):
    """lwr4 with d3 = d5 = 100 m: every grouping coefficient is the exact rational the geometry
    gives (squares of the lengths), as for the shipped 0.4 m links."""
    from kindyngen.readers.yaml_description import load_robot
    from tests.harness import ROOT
    text = (ROOT / "robots" / "lwr4.yaml").read_text().replace("d: 0.40,", "d: 100,").replace("d: 0.39,", "d: 100,")
    (tmp_path / "long.yaml").write_text(text)
    document = regressors.base_params_document(load_robot(tmp_path / "long.yaml"))
    for kind, entry in document.items():
        assert entry["exact"], (kind, [e for e in entry["expressions"] if "e-" in e][:3])
    assert any("10000*m3" in e for e in document["Y_m"]["expressions"])
