"""The exact-Hessian SQP of the reach (kindyngen/control/reach_sqp.py) over any robot, checked
against IPOPT on the same task (kindyngen.control.reach.ReachNLP) and by Pinocchio:

- from IPOPT's solution and its gap multipliers it converges (KKT residuals 1e-9 primal, 1e-5
  dual) to IPOPT's objective (1e-6 relative); its plan satisfies its RK4 steps of Pinocchio's
  ABA (1e-8), the flange is at the goal by Pinocchio's kinematics (1e-8 m) and at rest, the
  torques within their limits (LWR and UR5);
- from that solution shifted by one interval (the receding-horizon re-solve, start moved to the
  plan's node 1) it ends at the objective IPOPT finds cold from there (1e-6 relative) with its
  gaps closed, in at most 30 iterations (it creeps there: docs/optimal_control.md; the example
  it was ported from measured 570.0047 after 30, dual residual 2.8e-3);
- a task with inner rows is refused.
(The interval Hessians it uses are checked against CasADi's AD in test_native.py.)
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("daqp")

from kindyngen.control.reach import ReachNLP
from kindyngen.control.reach_sqp import ReachSQP
from kindyngen.control.robot import ControlError

from .helpers import arm, pinocchio_step


def _solved(name):
    model, robot, limits, task = arm(name)
    task = replace(task, inner=False)
    nlp = ReachNLP(robot, task)
    res = nlp.solve()
    assert res.success
    return model, robot, task, nlp, res


@pytest.mark.parametrize("name", ["lwr4", "ur5"])
def test_converges_from_ipopt_solution(name):
    import pinocchio as pin
    from benchmarks.control_robots import pinocchio_plant_model
    model, robot, task, nlp, res = _solved(name)
    sqp = ReachSQP(robot, task, tol_du=1e-5, max_iter=30)
    out = sqp.solve(X0=np.hstack([res.q, res.qd]), U0=res.tau, mu0=sqp.gap_multipliers(nlp, res))
    assert out.success, (out.status, out.kkt)
    assert abs(out.objective - res.objective) < 1e-6 * res.objective
    step = pinocchio_step(name, model)
    X = np.hstack([out.q, out.qd])
    for k in range(task.N):
        assert np.abs(step(X[k], out.tau[k], task.h) - X[k + 1]).max() < 1e-8 * max(1.0, np.abs(X[k + 1]).max())
    pm, frame = pinocchio_plant_model(name, model)
    pd = pm.createData()
    pin.framesForwardKinematics(pm, pd, out.q[-1])
    assert np.linalg.norm(pd.oMf[frame].translation - np.asarray(task.goal)) < 1e-8
    assert np.abs(out.qd[-1]).max() < 1e-8
    assert np.all(np.abs(out.tau) <= task.planned_limits.array("tau_max") + 1e-12)


def test_shifted_resolve_reaches_ipopts_optimum():
    model, robot, task, nlp, res = _solved("lwr4")
    sqp = ReachSQP(robot, task, tol_du=1e-5, max_iter=30)
    mu = sqp.gap_multipliers(nlp, res)
    x1 = np.concatenate([res.q[1], res.qd[1]])
    z, L = nlp.shifted(res.z), nlp.layout
    X = np.array([z[k * L.nw:k * L.nw + L.nx] for k in range(task.N + 1)])
    U = np.array([z[k * L.nw + L.nx:(k + 1) * L.nw] for k in range(task.N)])
    out = sqp.solve(x_init=x1, X0=X, U0=U, mu0=np.vstack([mu[1:], mu[-1:]]))
    cold = nlp.solve(x1)
    assert cold.success
    assert abs(out.objective - cold.objective) < 1e-6 * cold.objective
    assert out.kkt["inf_pr"] < 1e-8
    assert out.iterations <= 30


def test_inner_rows_refused():
    from kindyngen.control.integrators import Integrator
    model, robot, limits, task = arm("ur5")
    with pytest.raises(ControlError, match="inner=False"):
        ReachSQP(robot, replace(task, integrator=Integrator("rk4", 2), inner=True))
