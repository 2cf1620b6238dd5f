"""The native stage library (kindyngen/control/native.py, stage_library.c) against independent
computations:

- the reach NLP's constraints, their Jacobian and the Hessian of its Lagrangian equal CasADi's
  algorithmic differentiation of the same NLP written as one SX graph over the generated fd
  (kindyngen.control.reach.sx_reach_nlp), at random points and multipliers, for the LWR with
  one RK4 step per interval and the UR5 (from its URDF) with two RK4 substeps whose inner states
  are NLP rows, and the Panda with the midpoint rule;
- the MPC's linearisation (F, [A B], inner states and their Jacobians) equals that AD too, and
  F equals the integrator's steps of Pinocchio's ABA;
- two libraries (different N, different robots) in one process, called interleaved and from two
  threads at once, give the results each gives alone (no state between calls).

Tolerances: the two sides compute the same derivatives in different orders; 1e-9 relative to
the largest entry is rounding (entries up to ~1e5), a wrong coefficient or a misplaced block is
off by O(1) relative.
"""
from __future__ import annotations

import threading

import numpy as np
import pytest

from kindyngen.control.integrators import Integrator
from kindyngen.control.native import stage_library
from kindyngen.control.reach import sx_reach_nlp

from .helpers import arm, pinocchio_step

CASES = [("lwr4", Integrator("rk4", 1), False), ("ur5", Integrator("rk4", 2), True), ("panda", Integrator("midpoint", 2), True),
         ("ur5", Integrator("rk4", 2), False)]


def _random_point(robot, task, L, rng):
    n = robot.n
    z = np.concatenate([np.concatenate([np.asarray(task.q0) + 0.3 * rng.standard_normal(n), rng.standard_normal(n),
                                        10 * rng.standard_normal(n)]) for _ in range(task.N)]
                       + [np.asarray(task.q0) + 0.3 * rng.standard_normal(n), rng.standard_normal(n)])
    p = np.concatenate([z[:2 * n] + 0.01, np.asarray(task.goal)])
    return z, p, 100 * rng.standard_normal(L.ng)


@pytest.mark.parametrize("name, integrator, inner", CASES, ids=[f"{c[0]}-{c[1].tag}-{'inner' if c[2] else 'nodes'}"
                                                                  for c in CASES])
def test_nlp_functions_equal_casadi_ad(name, integrator, inner):
    import casadi as ca
    from dataclasses import replace
    model, robot, limits, task = arm(name)
    task = replace(task, N=3, T=0.15, integrator=integrator, inner=inner)
    lib = stage_library(robot, task.N, task.h, integrator, inner)
    L = lib.layout
    assert (L.nin > 0) == (inner and integrator.substeps > 1)
    Z, P, g, f = sx_reach_nlp(robot, task)
    lf, lg = ca.SX.sym("lf"), ca.SX.sym("lg", L.ng)
    ref = ca.Function("ref", [Z, P, lf, lg], [g, ca.jacobian(g, Z), ca.triu(ca.hessian(lf * f + ca.dot(lg, g), Z)[0])])
    e = lib.externals
    rng = np.random.default_rng(5)
    for _ in range(2):
        z, p, lam = _random_point(robot, task, L, rng)
        g_ref, J_ref, H_ref = (np.array(ca.densify(v)) for v in ref(z, p, 0.7, lam))
        g_nat = np.array(e["kdg_nlp_g"](z, p)).ravel()
        g2, J = e["kdg_nlp_jac_g"](z, p)
        H = np.array(ca.densify(e["kdg_nlp_hess"](z, p, 0.7, lam)))
        assert np.abs(g_nat - g_ref.ravel()).max() <= 1e-10 * max(1, np.abs(g_ref).max())
        assert np.abs(np.array(g2).ravel() - g_ref.ravel()).max() <= 1e-10 * max(1, np.abs(g_ref).max())
        assert np.abs(np.array(ca.densify(J)) - J_ref).max() <= 1e-9 * np.abs(J_ref).max()
        assert np.abs(H - H_ref).max() <= 1e-9 * np.abs(H_ref).max()
        # the structure is the AD's: no entry of the reference outside the declared pattern
        assert np.abs(H_ref).max() > 0 and np.abs(np.array(ca.densify(J))).max() > 0


@pytest.mark.parametrize("name, integrator", [("ur5", Integrator("rk4", 2)), ("lwr4", Integrator("euler", 3))])
def test_linearisation_equals_ad_and_pinocchio(name, integrator):
    import casadi as ca
    model, robot, limits, task = arm(name)
    n, N, h = robot.n, 3, 0.02
    lib = stage_library(robot, N, h, integrator, True)
    rng = np.random.default_rng(2)
    x0 = np.concatenate([np.asarray(task.q0) + 0.2 * rng.standard_normal(n), rng.standard_normal(n)])
    X = np.array([x0 + 0.1 * rng.standard_normal(2 * n) for _ in range(N)])
    U = 5 * rng.standard_normal((N, n))
    d = rng.standard_normal(n)
    F, A, B, XI, AXI = lib.linearise(x0, X, U, d)
    xs, us = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n)
    end, inner = integrator.step(robot.fd, n, h, xs, us)
    inner = ca.vertcat(*inner)
    ref = ca.Function("ref", [xs, us], [end, ca.jacobian(end, xs), ca.jacobian(end, us), inner,
                                        ca.jacobian(inner, ca.vertcat(xs, us))])
    step = pinocchio_step(name, model)
    for k in range(N):
        xk = x0 if k == 0 else X[k - 1]
        e, ax, bu, xi, axi = (np.array(v) for v in ref(xk, U[k] + d))
        scale = max(1.0, np.abs(ax).max(), np.abs(bu).max())
        assert np.abs(F[k] - e.ravel()).max() < 1e-10 * max(1, np.abs(e).max())
        assert np.abs(A[k] - ax).max() < 1e-9 * scale and np.abs(B[k] - bu).max() < 1e-9 * scale
        assert np.abs(XI[k] - xi.ravel()).max() < 1e-10 * max(1, np.abs(xi).max())
        assert np.abs(AXI[k] - axi).max() < 1e-9 * max(1, np.abs(axi).max())
        if integrator.method == "rk4":        # the integrator's steps of Pinocchio's ABA
            x = xk
            for _ in range(integrator.substeps):
                x = step(x, U[k] + d, h / integrator.substeps)
            assert np.abs(F[k] - x).max() < 1e-8 * max(1, np.abs(x).max())


@pytest.mark.parametrize("name, integrator", [("lwr4", Integrator("rk4", 1)), ("ur5", Integrator("rk4", 2))])
def test_interval_hessians_and_terminal_equal_ad(name, integrator):
    """``hessians``: per interval the Hessian over (x, u) of the multipliers' sum of the substep
    ends (the exact-Hessian SQP's blocks), and ``terminal``, against CasADi's AD of the
    integrator's step and of the flange position."""
    import casadi as ca
    model, robot, limits, task = arm(name)
    n, N, h = robot.n, 3, 0.05
    lib = stage_library(robot, N, h, integrator, False)
    xs, us, ms = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n), ca.SX.sym("m", 2 * n * integrator.substeps)
    end, inner = integrator.step(robot.fd, n, h, xs, us)
    ends = ca.vertcat(*inner, end)
    w = ca.vertcat(xs, us)
    ref = ca.Function("ref", [xs, us, ms], [ca.hessian(ca.dot(ms, ends), w)[0]])
    rng = np.random.default_rng(4)
    x0 = np.concatenate([np.asarray(task.q0) + 0.2 * rng.standard_normal(n), rng.standard_normal(n)])
    X = np.array([x0 + 0.1 * rng.standard_normal(2 * n) for _ in range(N)])
    U, d = 5 * rng.standard_normal((N, n)), rng.standard_normal(n)
    MU = 50 * rng.standard_normal((N, integrator.substeps, 2 * n))
    H = lib.hessians(x0, X, U, MU, d)
    for k in range(N):
        Hr = np.array(ref(x0 if k == 0 else X[k - 1], U[k] + d, MU[k].ravel()))
        assert np.abs(H[k] - Hr).max() <= 1e-9 * np.abs(Hr).max()
    goal, lt = np.array([0.3, 0.2, 0.5]), rng.standard_normal(3 + n)
    p = robot.fk_hom(xs[:n])[:3, 3]
    t_ref = ca.vertcat(p - goal, xs[n:])
    fr = ca.Function("t", [xs], [t_ref, ca.jacobian(t_ref, xs), ca.hessian(ca.dot(lt, t_ref), xs)[0]])
    t, J, Ht = lib.terminal(X[-1], goal, lt)
    for mine, theirs in zip((t, J, Ht), fr(X[-1])):
        theirs = np.array(theirs).reshape(np.shape(mine))
        assert np.abs(mine - theirs).max() <= 1e-10 * max(1.0, np.abs(theirs).max())


def test_libraries_are_reentrant():
    _, ur5, _, ur5_task = arm("ur5")
    _, lwr, _, lwr_task = arm("lwr4")
    libs = [stage_library(ur5, 4, 0.05, Integrator("rk4", 2), True), stage_library(ur5, 6, 0.05),
            stage_library(lwr, 4, 0.05)]
    rng = np.random.default_rng(9)
    inputs = []
    for lib, task in zip(libs, (ur5_task, ur5_task, lwr_task)):
        n, N = lib.robot.n, lib.N
        x0 = np.concatenate([np.asarray(task.q0), rng.standard_normal(n)])
        X = np.array([x0 + 0.1 * rng.standard_normal(2 * n) for _ in range(N)])
        inputs.append((x0, X, rng.standard_normal((N, n)), np.zeros(n)))
    alone = [lib.linearise(*args) for lib, args in zip(libs, inputs)]
    interleaved = [libs[i % 3].linearise(*inputs[i % 3]) for i in range(6)]
    for i, out in enumerate(interleaved):
        for a, b in zip(out, alone[i % 3]):
            np.testing.assert_array_equal(a, b)
    results = {}

    def work(i):
        results[i] = [libs[j % 3].linearise(*inputs[j % 3]) for j in range(30)]
    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i in range(2):
        for j, out in enumerate(results[i]):
            for a, b in zip(out, alone[j % 3]):
                np.testing.assert_array_equal(a, b)
