"""examples/ocp_time_stages.py: the time-optimal NLP of examples/ocp.py with its constraint
Jacobian and Lagrangian Hessian assembled from per-interval pieces (the RK4 step's Hessian
split at the calls of fd: a linearised surrogate step plus sum_i J_i' Hf(y_i, mu_i) J_i, the
interval blocks scattered into the arrowhead pattern of T). Checked against CasADi's own
Jacobian and Hessian of examples/ocp.py's mx_map NLP at a random point with random
multipliers (the uncompiled pieces: the compiled ones are their C code generation).

Tolerance: the two sides evaluate the same derivatives in a different order; the entries are
up to ~1e4 (Panda wrist), so 1e-9 relative to the largest entry is rounding, while a wrong
chain-rule term, a missing 1/N or a misplaced block is off by O(1) relative.
"""
from __future__ import annotations

import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples"))
import ocp  # noqa: E402
import ocp_time_stages  # noqa: E402


@pytest.mark.parametrize("problem, N, M", [("panda", 3, 4), ("lwr4", 2, 2), ("panda", 2, 1)])
def test_assembled_derivatives_equal_casadi(problem, N, M):
    funcs = ocp.load_functions(problem)
    setup = ocp.problem_setup(problem, funcs)
    staged = ocp_time_stages.TimeOptimalStages(setup, funcs, N, M, compile_stages=False)
    nlp, _, (lbg, ubg) = ocp.build_nlp(setup, funcs["fd"], N, "mx_map", M)
    V, g = nlp["x"], nlp["g"]
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", g.numel())
    ref_g = ca.Function("g", [V], [g])
    ref_j = ca.Function("j", [V], [ca.jacobian(g, V)])
    ref_h = ca.Function("h", [V, lam_f, lam_g], [ca.triu(ca.hessian(lam_f * nlp["f"] + ca.dot(lam_g, g), V)[0])])
    rng = np.random.default_rng(7)
    _, _, guess = ocp.bounds_and_guess(setup, N)
    v = guess + 0.3 * rng.standard_normal(guess.size)
    v[0] = 0.8                                   # T
    lg = rng.standard_normal(g.numel())
    gs, J = staged.f_jac_g(v, [])
    H = staged.f_hess(v, [], 0.7, lg)
    np.testing.assert_array_equal(np.array(gs), np.array(ref_g(v)))
    Jr, Hr = np.array(ref_j(v)), np.array(ref_h(v, 0.7, lg))
    assert np.abs(np.array(J) - Jr).max() <= 1e-9 * np.abs(Jr).max()
    assert np.abs(np.array(H) - Hr).max() <= 1e-9 * np.abs(Hr).max()
    assert np.abs(Hr[0, 1:]).max() > 0           # T couples every interval: the arrowhead is there
    for mine, theirs in zip(staged._gbounds(), (lbg, ubg)):
        np.testing.assert_array_equal(mine, theirs)


def test_path_problem_refused():
    funcs = {"fd": None, "folder": "."}
    with pytest.raises(ValueError, match="p2p"):
        ocp_time_stages.TimeOptimalStages({"kind": "path", "problem": "two_link"}, funcs, 10)
