"""The tracking MPC and its closed loop (kindyngen/control/mpc.py, closed_loop.py), checked by
independent computations and by the Pinocchio plant (benchmarks/control_plant.py):

- the condensed QP's unconstrained step equals the sparse multiple-shooting KKT solution written
  here in numpy (states and torques unknowns, the linearised dynamics as equality rows);
- the exact penalty: from a state where every limit can be held the slack is 0 and the step is
  the hard-constrained QP's (DAQP on the rows as hard constraints); from a state past a speed
  limit that no torque brings back by the next node the slack is positive and the step the
  least violation;
- the disturbance estimate converges to a constant torque acting on the plant;
- the closed loop on the UR5 (Pinocchio's URDF model as the plant, 1 kHz) tracks the reach
  within the limits and ends within 1 mm of the goal, undisturbed and under a 60 N push; on the
  LWR under a payload of 5 kg likewise;
- the fallback: with every re-solve failing, the shifted plan is applied, then the brake stops
  the arm inside its limits.
(No timing is asserted: the per-step budget is set far above any machine's solve time here.)
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("daqp")

from kindyngen.control.closed_loop import Controller, simulate
from kindyngen.control.integrators import Integrator
from kindyngen.control.mpc import MPCOptions, TrackingMPC
from kindyngen.control.reach import ReachNLP

from .helpers import arm

RELAXED = MPCOptions(budget_s=10.0)


@pytest.fixture(scope="module")
def ur5():
    model, robot, limits, task = arm("ur5")
    rt = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3, margin_position=0.05,
                 margin_torque=0.2)
    ref = ReachNLP(robot, rt).solve()
    assert ref.success
    return model, robot, limits, task, np.hstack([ref.q, ref.qd]), ref.tau


def test_condensed_step_equals_sparse_kkt(ur5):
    model, robot, limits, task, X, U = ur5
    mpc = TrackingMPC(robot, limits, X, U, RELAXED)
    rng = np.random.default_rng(0)
    N, n, nx = mpc.N, mpc.n, mpc.nx
    x0 = X[0] + np.concatenate([0.01 * rng.standard_normal(n), 0.05 * rng.standard_normal(n)])
    Xg, Ug = mpc.initial_guess(0)
    Xg = Xg + 0.01 * rng.standard_normal(Xg.shape)
    Ug = Ug + 0.5 * rng.standard_normal(Ug.shape)
    q = mpc.qp(x0, Xg, Ug, 0)
    du_c = np.linalg.solve(q["H"], -q["g"])
    F, A, B, _, _ = mpc.lib.linearise(x0, Xg, Ug)
    Xr, Ur = mpc.reference_window(0)
    nX, nU = N * nx, N * n
    Hs = np.diag(np.concatenate([mpc.wx, mpc.wu]))
    gs = np.concatenate([mpc.wx * (Xg - Xr).ravel(), mpc.wu * (Ug - Ur).ravel()])
    E = np.zeros((nX, nX + nU))
    rhs = np.zeros(nX)
    for k in range(N):
        E[k * nx:(k + 1) * nx, k * nx:(k + 1) * nx] = np.eye(nx)
        if k > 0:
            E[k * nx:(k + 1) * nx, (k - 1) * nx:k * nx] = -A[k]
        E[k * nx:(k + 1) * nx, nX + k * n:nX + (k + 1) * n] = -B[k]
        rhs[k * nx:(k + 1) * nx] = F[k] - Xg[k]
    K = np.block([[Hs, E.T], [E, np.zeros((nX, nX))]])
    sol = np.linalg.solve(K, np.concatenate([-gs, rhs]))
    assert np.abs(du_c - sol[nX:nX + nU]).max() < 1e-5 * max(1.0, np.abs(sol[nX:nX + nU]).max())
    assert np.abs(q["G"] @ du_c + q["c"] - sol[:nX]).max() < 1e-5 * max(1.0, np.abs(sol[:nX]).max())


def test_exact_penalty(ur5):
    import daqp
    model, robot, limits, task, X, U = ur5
    mpc = TrackingMPC(robot, limits, X, U, RELAXED)
    # feasible: the reference at a speed margin the rows hold; the slack stays 0 and the step is the hard QP's
    Xg, Ug = mpc.initial_guess(3)
    x0 = X[3] + np.concatenate([np.zeros(robot.n), 0.05 * np.ones(robot.n)])
    q = mpc.qp(x0, Xg, Ug, 3)
    du, t, flag, _, _ = mpc.solve_qp(q)
    assert flag > 0 and t == 0.0
    C = q["C"]
    hard, _, hflag, _ = daqp.solve(q["H"], q["g"], C, np.concatenate([q["box_hi"], q["row_hi"]]),
                                   np.concatenate([q["box_lo"], q["row_lo"]]), np.zeros(C.shape[0] + C.shape[1], np.int32))
    assert hflag > 0
    assert np.abs(du - np.asarray(hard)).max() < 1e-6 * max(1.0, np.abs(hard).max())
    # infeasible: joint 1 at 3 times its speed limit; no torque brings it under the limit by the next nodes
    x_bad = x0.copy()
    x_bad[robot.n] = 3.0 * limits.qd_max[0]
    q = mpc.qp(x_bad, Xg, Ug, 3)
    du, t, flag, _, _ = mpc.solve_qp(q)
    assert flag > 0 and t > 0
    v = q["C"] @ du
    excess = max(np.max(q["row_lo"] - v), np.max(v - q["row_hi"]))
    assert abs(excess - t) < 1e-6 * max(1.0, t)       # t is the worst violation, nothing exceeds it


def test_shifted_warm_start_keeps_the_gaps_closed_under_a_disturbance(ur5):
    """The converged plan under a disturbance estimate d, shifted by one interval from the
    state it predicts: every gap is closed, the appended interval's too (it holds the last node
    with the reference torque less d; with the reference torque itself the model's arm falls
    under d there)."""
    model, robot, limits, task, X, U = ur5
    mpc = TrackingMPC(robot, limits, X, U, RELAXED)
    mpc.d = np.array([0.0, 8.0, -5.0, 2.0, 1.0, -1.0])
    i = len(U) - 3                      # near the reference's end: the appended interval holds
    Xg, Ug = mpc.initial_guess(i)
    sol = mpc.solve(X[i], i, Xg, Ug)
    assert sol.status == "converged"
    Xs, Us = mpc.shifted(sol.X, sol.U, i)
    F = mpc.lib.linearise(mpc.predict(X[i], sol.U[0]), Xs, Us, mpc.d)[0]
    assert np.abs(F - Xs).max() < 1e-3


def test_disturbance_estimate_converges(ur5):
    from benchmarks.control_plant import Disturbance, PinocchioPlant
    model, robot, limits, task, X, U = ur5
    mpc = TrackingMPC(robot, limits, X, U, RELAXED)
    d = Disturbance("torque", start=0.0, duration=10.0, joint=2, torque=30.0)
    plant = PinocchioPlant("ur5", model, d)
    ctl = Controller(mpc)
    lg = simulate(ctl, plant, X[0].copy(), 0.3)
    est = np.array(lg.d_hat[-1])
    expected = np.zeros(robot.n)
    expected[2] = 30.0
    assert np.abs(est - expected).max() < 0.3


def _run(name, model, robot, limits, X, U, goal, dist, duration=2.0):
    from benchmarks.control_plant import PinocchioPlant
    mpc = TrackingMPC(robot, limits, X, U, RELAXED)
    plant = PinocchioPlant(name, model, dist)
    lg = simulate(Controller(mpc), plant, X[0].copy(), duration)
    xs = np.array(lg.x)
    n = robot.n
    q, qd = xs[:, :n], xs[:, n:]
    inside = (np.all(q >= limits.array("q_lo") - 1e-6) and np.all(q <= limits.array("q_hi") + 1e-6)
              and np.all(np.abs(qd) <= limits.array("qd_max") + 1e-6)
              and np.all(np.abs(np.array(lg.tau)) <= limits.array("tau_max") + 1e-9))
    return inside, float(np.linalg.norm(plant.flange(q[-1]) - np.asarray(goal))), lg


@pytest.mark.parametrize("case", ["none", "push"])
def test_closed_loop_ur5(ur5, case):
    from benchmarks.control_plant import Disturbance
    model, robot, limits, task, X, U = ur5
    dist = Disturbance() if case == "none" else Disturbance("push", start=0.4, duration=0.3, force=(0.0, 60.0, 0.0))
    inside, err, lg = _run("ur5", model, robot, limits, X, U, task.goal, dist)
    assert inside
    assert err < 1e-3
    assert all(s["mode"] == "mpc" for s in lg.steps)


def test_closed_loop_lwr_payload():
    from benchmarks.control_plant import Disturbance
    model, robot, limits, task = arm("lwr4")
    rt = replace(task, integrator=Integrator("rk4", 2), inner=True, margin_speed=0.3, margin_position=0.05,
                 margin_torque=0.2)
    ref = ReachNLP(robot, rt).solve()
    inside, err, _ = _run("lwr4", model, robot, limits, np.hstack([ref.q, ref.qd]), ref.tau, task.goal,
                          Disturbance("payload", start=0.5, mass_kg=5.0), 2.5)
    assert inside
    assert err < 1e-3


def test_the_loop_runs_without_the_cyclic_garbage_collector(ur5):
    """simulate pauses Python's cyclic garbage collector for the loop (a full collection took
    31 ms, three re-solve budgets) and resumes it after."""
    import gc
    from benchmarks.control_plant import PinocchioPlant
    model, robot, limits, task, X, U = ur5
    plant = PinocchioPlant("ur5", model)
    seen = []
    step = plant.step

    def recording(*args):
        seen.append(gc.isenabled())
        return step(*args)
    plant.step = recording
    assert gc.isenabled()
    simulate(Controller(TrackingMPC(robot, limits, X, U, RELAXED)), plant, X[0].copy(), 0.01)
    assert seen and not any(seen)
    assert gc.isenabled()


def test_fallback_then_brake(ur5, monkeypatch):
    from benchmarks.control_plant import PinocchioPlant
    model, robot, limits, task, X, U = ur5
    mpc = TrackingMPC(robot, limits, X, U, RELAXED)
    ctl = Controller(mpc)
    plant = PinocchioPlant("ur5", model)
    lg = simulate(ctl, plant, X[0].copy(), 0.5)           # undisturbed: the arm is moving
    assert np.abs(np.array(lg.x[-1])[robot.n:]).max() > 0.3
    original = TrackingMPC.solve

    def failing(self, *args, **kwargs):
        sol = original(self, *args, **kwargs)
        sol.status = "fallback"
        return sol
    monkeypatch.setattr(TrackingMPC, "solve", failing)
    x = np.array(lg.x[-1])
    lg2 = simulate(ctl, plant, x, 0.6)
    modes = [s["mode"] for s in lg2.steps[-12:]]
    assert modes[:3] == ["shifted plan"] * 3 and modes[3:] == ["brake"] * 9
    xs = np.array(lg2.x)
    n = robot.n
    assert np.abs(xs[-1, n:]).max() < 1e-2                 # stopped
    assert np.all(np.abs(xs[:, n:]) <= limits.array("qd_max") + 1e-6)
    assert np.all(xs[:, :n] >= limits.array("q_lo")) and np.all(xs[:, :n] <= limits.array("q_hi"))


def _brake_only(robot, limits, x0, plant, monkeypatch, duration, **loop):
    """The loop with every re-solve failing from the start: the brake (and the limit guard) alone."""
    from kindyngen.control.closed_loop import LoopOptions
    n = robot.n
    X = np.tile(np.concatenate([x0[:n], np.zeros(n)]), (21, 1))
    U = np.tile(robot.gravity_torque(x0[:n]), (20, 1))
    mpc = TrackingMPC(robot, limits, X, U, RELAXED)
    original = TrackingMPC.solve

    def failing(self, *args, **kwargs):
        sol = original(self, *args, **kwargs)
        sol.status = "fallback"
        return sol
    monkeypatch.setattr(TrackingMPC, "solve", failing)
    ctl = Controller(mpc, LoopOptions(**loop))
    lg = simulate(ctl, plant, x0, duration)
    assert {s["mode"] for s in lg.steps} == {"brake"}
    return np.array(lg.x), np.array(lg.tau)


def test_brake_stops_short_of_a_position_limit(monkeypatch):
    """No plan, the wrist heading for its position limit at 0.93 of its speed limit, 0.1 rad from
    it: the brake alone (deceleration qd / 50 ms) would need 0.15 rad; the limit guard stops it
    short of the limit, within the torque limits (the plant is Pinocchio's)."""
    from benchmarks.control_plant import PinocchioPlant
    model, robot, limits, task = arm("lwr4")
    n = robot.n
    x0 = np.concatenate([np.asarray(task.q0, float), np.zeros(n)])
    x0[6] = limits.q_hi[6] - 0.1
    x0[n + 6] = 0.93 * limits.qd_max[6]
    xs, tau = _brake_only(robot, limits, x0, PinocchioPlant("lwr4", model), monkeypatch, 0.3)
    assert np.all(xs[:, :n] <= limits.array("q_hi")) and np.all(xs[:, :n] >= limits.array("q_lo"))
    assert np.all(np.abs(tau) <= limits.array("tau_max") + 1e-9)
    assert np.abs(xs[-1, n:]).max() < 1e-2


def test_brake_brings_a_joint_back_inside_its_position_limit(monkeypatch):
    from benchmarks.control_plant import PinocchioPlant
    model, robot, limits, task = arm("lwr4")
    n = robot.n
    x0 = np.concatenate([np.asarray(task.q0, float), np.zeros(n)])
    x0[6] = limits.q_hi[6] + 0.02
    xs, tau = _brake_only(robot, limits, x0, PinocchioPlant("lwr4", model), monkeypatch, 0.5)
    assert xs[-1, 6] <= limits.q_hi[6]
    assert np.all(np.abs(xs[:, n:]) <= limits.array("qd_max") + 1e-6)
    assert np.all(np.abs(tau) <= limits.array("tau_max") + 1e-9)
