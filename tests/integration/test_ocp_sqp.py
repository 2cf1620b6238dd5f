"""examples/ocp_sqp.py (the exact-Hessian SQP of the LWR reach), checked by independent
computations:

- the compiled RK4 step of the generated fd equals the RK4 step of Pinocchio's ABA
  (tests/reference.py's model) at random states and torques;
- the step's Jacobians A, B (from the implicit elimination of the stage accelerations) equal
  central finite differences of the compiled step, and the reduced Hessian of mu' F(x, u)
  equals second differences of mu' F (all N intervals at once: each depends on its own w_k);
- from IPOPT's fd_rk4 solution and its gap multipliers the SQP converges to IPOPT's optimum
  (1e-6 relative), its plan satisfying its RK4 steps of Pinocchio's ABA to 1e-8 and the
  terminal rows by Pinocchio's forward kinematics to 1e-8 m.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pinocchio")
pytest.importorskip("daqp")
ROOT = Path(__file__).resolve().parents[2]
for _p in (str(ROOT / "examples"), str(ROOT)):
    if _p not in sys.path:
        sys.path.insert(0, _p)
import ocp_reach  # noqa: E402
import ocp_sqp  # noqa: E402

N = 20


@pytest.fixture(scope="module")
def sqp():
    funcs = ocp_reach.load()
    return funcs, ocp_sqp.ReachSQP(N, funcs=funcs, tol_du=1e-5, max_iter=30)


def _random_point(s, seed=0):
    rng = np.random.default_rng(seed)
    X = np.tile(np.concatenate([s.setup["q0"], np.zeros(s.n)]), (N + 1, 1)) + 0.3 * rng.standard_normal((N + 1, s.nx))
    U = 20 * rng.standard_normal((N, s.n))
    return X, U, rng.standard_normal((N, s.nx))


def test_step_against_pinocchio(sqp):
    import pinocchio as pin
    from tests.reference import pinocchio_model
    funcs, s = sqp
    model, data, _ = pinocchio_model(funcs["robot"])
    X, U, _ = _random_point(s)
    F = s.evaluate(X, U)[0]
    n, h = s.n, s.h

    def f(x, u):
        return np.concatenate([x[n:], pin.aba(model, data, x[:n], x[n:], u)])
    for k in range(N):
        x, u = X[k], U[k]
        k1 = f(x, u)
        k2 = f(x + h / 2 * k1, u)
        k3 = f(x + h / 2 * k2, u)
        k4 = f(x + h * k3, u)
        ref = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        assert np.abs(F[k] - ref).max() < 1e-9 * max(1.0, np.abs(ref).max())


def test_jacobians_and_hessian_by_finite_differences(sqp):
    _, s = sqp
    X, U, mu = _random_point(s, 1)
    F, Y, J = s.evaluate(X, U)
    dY, AB, Ra = s.eliminate(J)
    H = s.stage_hessians(Y, dY, Ra, mu)
    nx, nw = s.nx, s.nx + s.n

    def step(dw):          # F at every interval's w_k + dw (each F_k depends on its own w_k only)
        Xp, Up = X.copy(), U.copy()
        Xp[:-1] += dw[:nx]
        Up += dw[nx:]
        return np.array(s.ext["reach_sqp_next"](Xp[:-1].T, Up.T)).T
    eps = 1e-6
    E = np.eye(nw)
    Jfd = np.stack([(step(eps * E[j]) - step(-eps * E[j])) / (2 * eps) for j in range(nw)], axis=2)
    assert np.abs(Jfd - AB).max() < 1e-6 * np.abs(AB).max()

    def phi(dw):
        return np.einsum("ka,ka->k", mu, step(dw))
    e2 = 1e-4
    Hfd = np.zeros_like(H)
    for i in range(nw):
        for j in range(i, nw):
            a, b = e2 * E[i], e2 * E[j]
            Hfd[:, i, j] = Hfd[:, j, i] = (phi(a + b) - phi(a - b) - phi(b - a) + phi(-a - b)) / (4 * e2 ** 2)
    assert np.abs(Hfd - H).max() < 1e-4 * np.abs(H).max()


def test_converges_from_ipopt_solution(sqp):
    import pinocchio as pin
    from tests.reference import pinocchio_model
    funcs, s = sqp
    ref = ocp_reach.reach_problem("fd_rk4", "ipopt", N, funcs).solve()
    assert ref["success"], ref["status"]
    X, U, mu = ocp_sqp.ipopt_start(ref, N, s.n)
    res = s.solve(X0=X, U0=U, mu0=mu)
    assert res["success"], (res["status"], res["kkt"])
    assert abs(res["objective"] - ref["objective"]) < 1e-6 * ref["objective"]
    setup = s.setup
    sim = ocp_reach.check(setup, res, funcs)
    assert sim["plan_step_error"] < 1e-8
    model, data, flange = pinocchio_model(setup["robot"])
    pin.framesForwardKinematics(model, data, res["q"][-1])
    assert np.linalg.norm(data.oMf[flange].translation - setup["goal"]) < 1e-8
    assert np.abs(res["qd"][-1]).max() < 1e-8
    assert np.all(np.abs(res["tau"]) <= setup["tau_max"] + 1e-12)
