"""examples/ocp_fd_stages.py (IPOPT on the fd_rk4 reach with the interval's exact Hessian built
from the inverse dynamics' Hessian, compiled to C), checked by independent computations:

- the compiled interval Hessian equals CasADi's AD Hessian of the same Lagrangian term on the
  SX graph of the explicit RK4 step of `fd` (1e-8 relative), and the compiled Jacobian blocks
  equal AD's, at random points;
- the solve converges to the optimum of IPOPT on fd_rk4's SX graph (1e-6 relative), and its
  plan satisfies its RK4 steps of Pinocchio's ABA (tests/reference.py's model) to 1e-8, the
  flange (Pinocchio's forward kinematics) at the goal within 1e-6 m, at rest;
- examples/ocp_fd_options.FAST (the adaptive barrier) ends at the default options' optimum in
  fewer iterations.
(The first run compiles the library, about a minute of gcc; later runs load the cache.)
"""
from __future__ import annotations

import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

pytest.importorskip("pinocchio")
ROOT = Path(__file__).resolve().parents[2]
for _p in (str(ROOT / "examples"), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)
import ocp_fd_stages  # noqa: E402
import ocp_reach  # noqa: E402

N = 20


@pytest.fixture(scope="module")
def stages():
    return ocp_fd_stages.FdStageReach(N, ocp_reach.load())


def test_interval_hessian_and_jacobian_against_ad(stages):
    s, n, nx = stages, stages.n, stages.nx
    v = ca.SX.sym("v", s.st + nx)
    lam, sigma = ca.SX.sym("lam", nx), ca.SX.sym("sigma")
    x, u = v[:nx], v[nx:s.st]
    xn = ocp_reach._rk4_fd(s.funcs["fd"], n, s.h)(x, u)
    c = v[s.st:] - xn
    lag = sigma * s.h * ca.sumsqr(u) + ca.dot(lam, c)
    ad = ca.Function("ad", [v, lam, sigma], [ca.hessian(lag, v[:s.st])[0], ca.jacobian(c, v)])
    rng = np.random.default_rng(0)
    for _ in range(3):
        vv = np.concatenate([np.concatenate([s.setup["q0"], np.zeros(n)]) + 0.3 * rng.standard_normal(nx),
                             20 * rng.standard_normal(n), rng.standard_normal(nx)])
        ll, sg = 100 * rng.standard_normal(nx), 1.0
        H_ad, J_ad = (np.array(m) for m in ad(vv, ll, sg))
        H = np.array(s.ext["reach_hl"](vv[:s.st], ll, sg))
        assert np.abs(np.triu(H_ad) - H).max() < 1e-8 * np.abs(H_ad).max()
        J = np.array(s.ext["reach_jc"](vv))
        assert np.abs(J_ad - J).max() < 1e-9 * np.abs(J_ad).max()


def test_reach_optimum_and_pinocchio(stages):
    import pinocchio as pin
    from tests.reference import pinocchio_model
    funcs = stages.funcs
    res = stages.solve_ipopt()
    assert res["success"], res["status"]
    ref = ocp_reach.reach_problem("fd_rk4", "ipopt", N, funcs).solve()
    assert abs(res["objective"] - ref["objective"]) < 1e-6 * ref["objective"]
    setup = stages.setup
    sim = ocp_reach.check(setup, res, funcs)
    assert sim["plan_step_error"] < 1e-8
    model, data, flange = pinocchio_model(setup["robot"])
    pin.framesForwardKinematics(model, data, res["q"][-1])
    assert np.linalg.norm(data.oMf[flange].translation - setup["goal"]) < 1e-6
    assert np.abs(res["qd"][-1]).max() < 1e-6
    assert np.all(np.abs(res["tau"]) <= setup["tau_max"] + 1e-9)


def test_adaptive_barrier_options_same_optimum_fewer_iterations(stages):
    """examples/ocp_fd_options.FAST (IPOPT's adaptive barrier, same tol): the same KKT point as
    the default options (objective 1e-8 relative, variables 1e-3 absolute, torques up to ~100 N m)
    in fewer iterations, its plan on Pinocchio's RK4 steps to 1e-8, at the goal, inside the limits."""
    import ocp_fd_options
    ref = stages.solve_ipopt()
    res = stages.solve_ipopt(stages.ipopt(ocp_fd_options.FAST))
    assert res["success"], res["status"]
    assert abs(res["objective"] - ref["objective"]) < 1e-8 * ref["objective"]
    assert np.abs(res["z"] - ref["z"]).max() < 1e-3
    assert res["iterations"] < ref["iterations"]
    sim = ocp_reach.check(stages.setup, res, stages.funcs)
    assert sim["plan_step_error"] < 1e-8
    assert res["max_constraint_violation"] < 1e-8
    assert np.all(np.abs(res["tau"]) <= stages.setup["tau_max"] + 1e-9)
