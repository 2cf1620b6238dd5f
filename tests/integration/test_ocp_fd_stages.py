"""examples/ocp_fd_stages.py (IPOPT on the fd_rk4 reach with the interval's exact Hessian built
from the inverse dynamics' Hessian, compiled to C), checked by independent computations:

- the native library's (examples/fd_stages_nlp.c over the generated C) constraints, Jacobian and
  Hessian of the Lagrangian equal CasADi's AD on the SX graph of the whole NLP (the explicit RK4
  step of `fd` per interval, the terminal rows from fk_hom; 1e-8 relative) at random points and
  multipliers, also after a call at another point (the forward chain is cached per point);
- the MX derivation it implements (rk4_lagrangian_hessian, the non-native path) equals AD
  per interval;
- the solve converges to the optimum of IPOPT on fd_rk4's SX graph (1e-6 relative), and its
  plan satisfies its RK4 steps of Pinocchio's ABA (tests/reference.py's model) to 1e-8, the
  flange (Pinocchio's forward kinematics) at the goal within 1e-6 m, at rest;
- examples/ocp_fd_options.FAST (the adaptive barrier) ends at the default options' optimum in
  fewer iterations.
(The first run compiles the library, 15-35 s of clang; later runs load the cache.)
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


def test_native_nlp_derivatives_against_ad(stages):
    s, n, nx, st, N = stages, stages.n, stages.nx, stages.st, stages.N
    Z, P = ca.SX.sym("z", s.nz), ca.SX.sym("p", nx + 3)
    step = ocp_reach._rk4_fd(s.funcs["fd"], n, s.h)
    gaps = [Z[(k + 1) * st:(k + 1) * st + nx] - step(Z[k * st:k * st + nx], Z[k * st + nx:(k + 1) * st])
            for k in range(N)]
    xN = Z[N * st:]
    term = ca.vertcat(s.funcs["fk_hom"](xN[:n])[:3, 3] - P[nx:], xN[n:])
    g = ca.vertcat(gaps[0], Z[:nx] - P[:nx], *gaps[1:], term)
    f = s.h * sum(ca.sumsqr(Z[k * st + nx:(k + 1) * st]) for k in range(N))
    lf, lg = ca.SX.sym("lf"), ca.SX.sym("lg", g.numel())
    ad = ca.Function("ad", [Z, P, lf, lg], [g, ca.jacobian(g, Z), ca.triu(ca.hessian(lf * f + ca.dot(lg, g), Z)[0])])
    rng = np.random.default_rng(0)
    zs = [s.guess() + 0.3 * rng.standard_normal(s.nz) for _ in range(3)]
    for i, z in enumerate(zs):
        p = s.p() + 0.05 * rng.standard_normal(nx + 3)
        lgv, lfv = 100 * rng.standard_normal(s.ng), 0.5 + rng.random()
        g_ad, J_ad, H_ad = (np.array(ca.densify(m)) for m in ad(z, p, lfv, lgv))
        s.f_jac_g(zs[i - 1], p)          # another point first: the cache must follow z
        g_c, J_c = s.f_jac_g(z, p)
        H_c = np.array(ca.densify(s.f_hess(z, p, lfv, lgv)))
        assert np.abs(np.array(s.f_g(z, p)).ravel() - g_ad.ravel()).max() < 1e-10 * np.abs(g_ad).max()
        assert np.abs(np.array(g_c).ravel() - g_ad.ravel()).max() < 1e-10 * np.abs(g_ad).max()
        assert np.abs(np.array(ca.densify(J_c)) - J_ad).max() < 1e-9 * np.abs(J_ad).max()
        assert np.abs(H_c - H_ad).max() < 1e-8 * np.abs(H_ad).max()
        s.f_hess(zs[i - 1], p, lfv, lgv)  # the Hessian at a point the Jacobian was not called at
        H_other = ad(zs[i - 1], p, lfv, lgv)[2]
        assert np.abs(np.array(ca.densify(s.f_hess(zs[i - 1], p, lfv, lgv))) - np.array(ca.densify(H_other))).max() \
            < 1e-8 * np.abs(np.array(ca.densify(H_other))).max()


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
