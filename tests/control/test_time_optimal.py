"""The time-optimal point-to-point NLP (kindyngen/control/time_optimal.py) on the native
time-optimal library (kindyngen/control/time_library.c), checked by independent computations:

- its constraints, their Jacobian and the Hessian of its Lagrangian (with h = T / N a variable:
  the arrowhead of T) equal CasADi's AD of the same NLP written as one SX integrator step mapped
  over the intervals in MX (examples/ocp.py's mx_map form), at random points and multipliers,
  for one, two and four RK4 substeps (inner rows) on the UR5, the Panda and the LWR. Tolerance:
  the two sides evaluate the same derivatives in a different order; entries reach ~1e6 (the
  LWR's wrist), 1e-9 relative to the largest is rounding, a wrong term is O(1);
- the solve converges to the optimum of IPOPT on the mx_map NLP (T to 1e-7 relative), the plan
  satisfies its RK4 substeps of Pinocchio's ABA from each node (1e-7), ends at qf at rest and
  holds the torque limits and the backed-off speed limits at the nodes (UR5).
"""
from __future__ import annotations

import numpy as np
import pytest

from kindyngen.control.integrators import Integrator
from kindyngen.control.time_optimal import TimeOptimalNLP, solve_time_optimal

from .helpers import arm, pinocchio_step


@pytest.mark.parametrize("name, N, substeps", [("ur5", 3, 2), ("panda", 2, 4), ("lwr4", 3, 1)])
def test_native_derivatives_equal_ad(name, N, substeps):
    import casadi as ca
    model, robot, limits, task = arm(name)
    qf = np.asarray(task.q0) + 0.3
    nlp = TimeOptimalNLP(robot, limits, task.q0, qf, N=N, integrator=Integrator("rk4", substeps))
    ref = nlp.mx_nlp()
    V, g = ref["x"], ref["g"]
    lf, lg = ca.MX.sym("lf"), ca.MX.sym("lg", g.numel())
    fr = ca.Function("ref", [V, lf, lg], [g, ca.jacobian(g, V), ca.triu(ca.hessian(lf * ref["f"] + ca.dot(lg, g), V)[0])])
    rng = np.random.default_rng(1)
    for _ in range(2):
        v = nlp.guess + 0.3 * rng.standard_normal(nlp.guess.size)
        v[0] = N * (0.02 + 0.03 * rng.random())          # T: intervals of 20-50 ms
        lam = 10 * rng.standard_normal(g.numel())
        G, J, H = (np.array(ca.densify(m)) for m in fr(v, 0.7, lam))
        g2, J2 = nlp.f_jac_g(v, nlp.p)
        H2 = np.array(ca.densify(nlp.f_hess(v, nlp.p, 0.7, lam)))
        assert np.abs(np.array(g2).ravel() - G.ravel()).max() <= 1e-10 * max(1.0, np.abs(G).max())
        assert np.abs(np.array(ca.densify(J2)) - J).max() <= 1e-9 * np.abs(J).max()
        assert np.abs(H2 - H).max() <= 1e-9 * np.abs(H).max()
        assert np.abs(H[0, 1:]).max() > 0               # T couples every interval: the arrowhead is there


def test_solves_like_the_ad_route_and_pinocchio():
    model, robot, limits, task = arm("ur5")
    qf = np.asarray(task.q0) + np.array([0.8, -0.4, 0.5, 0.3, -0.6, 0.9])
    kw = dict(N=8, integrator=Integrator("rk4", 2))
    res = solve_time_optimal(robot, limits, task.q0, qf, **kw)
    ref = solve_time_optimal(robot, limits, task.q0, qf, native=False, **kw)
    assert res["success"] and ref["success"], (res["status"], ref["status"])
    assert res["route"] == "native" and ref["route"] == "mx_map"
    assert abs(res["T"] - ref["T"]) < 1e-7 * ref["T"]
    step = pinocchio_step("ur5", model)
    X = np.hstack([res["q"], res["qd"]])
    h = res["T"] / 8
    for k in range(8):
        x = step(step(X[k], res["tau"][k], h / 2), res["tau"][k], h / 2)
        assert np.abs(x - X[k + 1]).max() < 1e-7 * max(1.0, np.abs(x).max())
    assert np.all(np.abs(res["tau"]) <= limits.array("tau_max") + 1e-9)
    assert np.all(np.abs(res["qd"]) <= 0.95 * limits.array("qd_max") + 1e-7)
    assert np.abs(res["q"][-1] - qf).max() < 1e-9 and np.abs(res["qd"][-1]).max() < 1e-9
