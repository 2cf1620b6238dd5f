"""The reach over any robot (kindyngen/control/reach.py), checked by Pinocchio (the arms' own
models, benchmarks/control_robots.py: the UR5 by Pinocchio's URDF parser):

- the native IPOPT solve converges; the plan satisfies its integrator steps of Pinocchio's ABA
  (from each node, the RK4 steps land on the next node, 1e-8), the flange is at the goal by
  Pinocchio's kinematics (1e-6 m) and at rest; torques within their limits, q and qd at the
  nodes within the planned limits (IPOPT relaxes bounds by 1e-8 relative: 1e-7);
- with two RK4 substeps and the inner states as rows, the inner speeds hold the limits too;
- on the LWR the native solve and the Opti baseline reach the same objective (1e-6 relative);
  the inverse-dynamics form (UR5) reaches a KKT point of the same discrete problem, fatrop the
  native solve's optimum (the time-optimal NLP: test_time_optimal.py).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kindyngen.control.integrators import Integrator
from kindyngen.control.reach import ReachNLP, inverse_dynamics_reach, rollout, solve_baseline, solve_sx

from .helpers import arm, pinocchio_step


def _check_plan(name, model, task, res):
    import pinocchio as pin
    from benchmarks.control_robots import pinocchio_plant_model
    step = pinocchio_step(name, model)
    M = task.integrator.substeps
    X = np.hstack([res.q, res.qd])
    for k in range(task.N):
        x = X[k]
        for _ in range(M):
            x = step(x, res.tau[k], task.h / M)
        assert np.abs(x - X[k + 1]).max() < 1e-8 * max(1.0, np.abs(X[k + 1]).max()), k
    pm, frame = pinocchio_plant_model(name, model)
    pd = pm.createData()
    pin.framesForwardKinematics(pm, pd, res.q[-1])
    assert np.linalg.norm(pd.oMf[frame].translation - np.asarray(task.goal)) < 1e-6
    assert np.abs(res.qd[-1]).max() < 1e-7
    lim = task.planned_limits
    assert np.all(np.abs(res.tau) <= lim.array("tau_max") + 1e-9)
    assert np.all(res.q[1:] >= lim.array("q_lo") - 1e-7) and np.all(res.q[1:] <= lim.array("q_hi") + 1e-7)
    assert np.all(np.abs(res.qd[1:]) <= lim.array("qd_max") + 1e-7)


@pytest.mark.parametrize("name", ["lwr4", "panda", "ur5"])
def test_native_reach_against_pinocchio(name):
    model, robot, limits, task = arm(name)
    res = ReachNLP(robot, task).solve()
    assert res.success, res.status
    _check_plan(name, model, task, res)


def test_inner_rows_hold_the_speed_limit_between_nodes():
    """Two RK4 substeps with a 30 % speed margin: the plan's nodes and its inner substep ends
    within 0.7 qd_max, checked by re-integrating each half interval with Pinocchio."""
    model, robot, limits, task = arm("ur5")
    task = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3)
    res = ReachNLP(robot, task).solve()
    assert res.success, res.status
    _check_plan("ur5", model, task, res)
    step = pinocchio_step("ur5", model)
    vmax = task.planned_limits.array("qd_max")
    X = np.hstack([res.q, res.qd])
    peak = 0.0
    for k in range(task.N):
        xm = step(X[k], res.tau[k], task.h / 2)
        peak = max(peak, float(np.max(np.abs(xm[robot.n:]) / vmax)))
    assert peak <= 1 + 1e-6, peak
    assert peak > 0.9          # the margin is what holds it: the plan uses the speed it has
    # between the substep ends too, integrated finely by Pinocchio (check_between_nodes): the
    # data-sheet limits hold with the margin left over
    import pinocchio as pin
    from benchmarks.control_robots import pinocchio_plant_model
    from kindyngen.control.reach import check_between_nodes
    pm, _ = pinocchio_plant_model("ur5", model)
    pd = pm.createData()
    out = check_between_nodes(lambda q, v, u: pin.aba(pm, pd, q, v, u), res, limits, 20)
    assert out["speed_excess"] < 0 and out["position_excess"] < 0, out


def test_lwr_native_and_baseline_agree():
    """The native solve and the Opti baseline (fd on MX, IPOPT's defaults) reach the same optimum
    (the native functions equal the SX graph's AD: test_native.py)."""
    model, robot, limits, task = arm("lwr4")
    nlp = ReachNLP(robot, task)
    res = nlp.solve()
    base = solve_baseline(robot, task)
    assert base.success
    assert abs(res.objective - base.objective) < 1e-6 * base.objective
    # rollout of the plan's torques with the library's own step reproduces its nodes
    X = rollout(lambda x, u, dt: nlp.lib.step(x, u), np.concatenate([res.q[0], res.qd[0]]), res.tau, 1, task.h)
    assert np.abs(X - np.hstack([res.q, res.qd])).max() < 1e-7


def test_adaptive_barrier_reaches_the_defaults_optimum_in_fewer_iterations():
    """IPOPT's adaptive barrier (FAST, ReachNLP's default) ends at the KKT point of IPOPT's
    defaults in fewer iterations (LWR: 23 against 45; objective 1e-8 relative, torques 1e-3 N m of
    up to 176)."""
    model, robot, limits, task = arm("lwr4")
    fast = ReachNLP(robot, task).solve()
    plain = ReachNLP(robot, task, adaptive=False).solve()
    assert fast.success and plain.success
    assert fast.iterations < plain.iterations
    assert abs(fast.objective - plain.objective) < 1e-8 * plain.objective
    assert np.abs(fast.tau - plain.tau).max() < 1e-3
    _check_plan("lwr4", model, task, fast)


def test_sx_graph_reaches_the_native_optimum():
    """IPOPT on the same NLP as one SX graph (CasADi's AD, solve_sx) ends where the native
    library's solve does (UR5, N = 10: the SX graph's Hessian is most of the test's time)."""
    model, robot, limits, task = arm("ur5")
    task = replace(task, N=10)
    native, sx = ReachNLP(robot, task).solve(), solve_sx(robot, task)
    assert native.success and sx.success
    assert abs(native.objective - sx.objective) < 1e-8 * sx.objective
    assert np.abs(native.tau - sx.tau).max() < 1e-4 * np.abs(sx.tau).max()


def test_shifted_warm_start_is_stationary():
    """ReachNLP.shifted and shifted_multipliers: the converged plan and its constraint and bound
    multipliers moved one interval earlier, the start moved to the plan's node 1, satisfy the
    Lagrangian's stationarity grad f + J' lam_g + lam_x = 0 on every variable but the appended
    interval's (grad f written here in numpy, J' lam_g by central differences of the
    constraints), and the constraints themselves."""
    model, robot, limits, task = arm("ur5")
    nlp = ReachNLP(robot, task)
    res = nlp.solve()
    L = nlp.layout
    z = nlp.shifted(res.z)
    p = nlp.p(np.concatenate([res.q[1], res.qd[1]]))
    lam_g, lam_x = nlp.shifted_multipliers(res.lam_g, res.lam_x)
    grad = np.zeros(L.nz)
    for k in range(task.N):
        i = k * L.nw + L.nx
        grad[i:i + robot.n] = 2 * task.h * z[i:i + robot.n]

    def g(zz):
        return np.array(nlp.f_g(zz, p)).ravel()
    kept = (task.N - 1) * L.nw
    eps, jt_lam = 1e-6, np.zeros(kept)
    for i in range(kept):
        e = np.zeros(L.nz)
        e[i] = eps
        jt_lam[i] = lam_g @ (g(z + e) - g(z - e)) / (2 * eps)
    resid = grad[:kept] + jt_lam + lam_x[:kept]
    assert np.abs(resid).max() < 1e-4 * max(1.0, np.abs(grad).max())
    assert np.abs(g(z)).max() < 1e-6


def test_inverse_dynamics_form_is_the_same_discrete_problem():
    model, robot, limits, task = arm("ur5")
    res = inverse_dynamics_reach(robot, task)
    assert res.success, res.status
    _check_plan("ur5", model, task, res)


def test_fatrop_reaches_the_native_optimum():
    from kindyngen.control.reach import solve_fatrop
    model, robot, limits, task = arm("ur5")
    task = replace(task, N=10)         # the SX graph's size: fatrop's part of the suite's time
    ref = ReachNLP(robot, task).solve()
    res = solve_fatrop(robot, task)
    assert res.success, res.status
    assert abs(res.objective - ref.objective) < 1e-5 * ref.objective
    step = pinocchio_step("ur5", model)
    X = np.hstack([res.q, res.qd])
    err = max(np.abs(step(X[k], res.tau[k], task.h) - X[k + 1]).max() for k in range(task.N))
    assert err < 1e-5          # fatrop stops at tol 1e-4 (its dual residual stalls above 1e-6): gaps of ~3e-6


def test_fatrop_on_the_inverse_dynamics_form_converges():
    """fatrop on the inverse-dynamics form converges to tol 1e-6 at IPOPT's KKT point of the
    same NLP (1e-7 relative), its plan on Pinocchio's RK4 steps (1e-7)."""
    from kindyngen.control.reach import solve_fatrop
    model, robot, limits, task = arm("ur5")
    task = replace(task, N=10)
    ref = inverse_dynamics_reach(robot, task)
    res = solve_fatrop(robot, task, formulation="inverse-dynamics")
    assert ref.success and res.success, res.status
    assert abs(res.objective - ref.objective) < 1e-7 * ref.objective
    step = pinocchio_step("ur5", model)
    X = np.hstack([res.q, res.qd])
    assert max(np.abs(step(X[k], res.tau[k], task.h) - X[k + 1]).max() for k in range(task.N)) < 1e-7


def test_two_robots_in_one_process():
    """Two reach solvers (the UR5 and the LWR, each on its own library) solving in turn give the
    iterates each gives alone: nothing is shared between libraries or calls."""
    _, ur5, _, ur5_task = arm("ur5")
    _, lwr, _, lwr_task = arm("lwr4")
    a, b = ReachNLP(ur5, ur5_task), ReachNLP(lwr, lwr_task)
    alone_a, alone_b = a.solve(), b.solve()
    for _ in range(2):
        ra, rb = a.solve(), b.solve()
        np.testing.assert_array_equal(ra.z, alone_a.z)
        np.testing.assert_array_equal(rb.z, alone_b.z)
        assert (ra.iterations, rb.iterations) == (alone_a.iterations, alone_b.iterations)


def test_warm_resolve_from_the_shifted_solution():
    """The MPC's re-solve of the reach: from the solution and its multipliers shifted by one
    interval (ReachNLP.shifted, shifted_multipliers), the start moved to node 1, IPOPT's warm
    start ends at the optimum a cold solve from that start finds, in fewer iterations."""
    model, robot, limits, task = arm("ur5")
    nlp = ReachNLP(robot, task)
    res = nlp.solve()
    x1 = np.concatenate([res.q[1], res.qd[1]])
    cold = nlp.solve(x1)
    warm_solver = nlp.build(dict(nlp.options, **{"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                                                 "ipopt.warm_start_bound_push": 1e-6,
                                                 "ipopt.warm_start_mult_bound_push": 1e-6}))
    lam_g, lam_x = nlp.shifted_multipliers(res.lam_g, res.lam_x)
    warm = nlp.solve(x1, z0=nlp.shifted(res.z), lam_g0=lam_g, lam_x0=lam_x, solver=warm_solver)
    assert cold.success and warm.success
    assert abs(warm.objective - cold.objective) < 1e-8 * cold.objective
    assert np.abs(warm.tau - cold.tau).max() < 1e-4 * np.abs(cold.tau).max()
    assert warm.iterations < cold.iterations
