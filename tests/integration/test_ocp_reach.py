"""The LWR reach of examples/ocp_reach.py and the MPC loop of examples/mpc.py, checked by
Pinocchio (tests/reference.py's model), not by the generated code.

- id_rk4 (implicit RK4 with the generated inverse dynamics) must be the explicit RK4 step of
  the forward dynamics at a solution: from every planned node, Pinocchio's ABA integrated by
  the same RK4 step must land on the next planned node (1e-6, IPOPT tol 1e-8).
- the flange (Pinocchio's forward kinematics of the planned last node) at the goal within
  1e-6 m, at rest; torques within their bounds exactly; q and qd at the nodes within 1e-6.
- examples/ocp_stages.py (the per-interval functions compiled to C, IPOPT given the assembled
  derivatives) solves the same discrete problem: the same Pinocchio checks, and its optimum
  equals that of IPOPT on the whole SX graph (1e-6 relative).
- examples/ocp_fatrop.py (fatrop on the same compiled functions) reaches IPOPT's optimum
  (1e-6 relative), with the same Pinocchio checks.
- a short MPC run writes the documented fields; no torque or joint-position violation and no
  failed solve (speed limits hold at the nodes only, so the 1 kHz plant samples may pass them:
  counted, not asserted; see docs/optimal_control.md).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pinocchio")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples"))
import ocp_reach  # noqa: E402


@pytest.fixture(scope="module")
def reach():
    funcs = ocp_reach.load()
    nlp = ocp_reach.reach_problem("id_rk4", "ipopt", 20, funcs)
    res = nlp.solve()
    return nlp.setup, res, ocp_reach.check(nlp.setup, res, funcs), funcs


def test_reach_converged_and_rk4_consistent(reach):
    setup, res, sim, _ = reach
    assert res["success"], res["status"]
    assert sim["plan_step_error"] < 1e-6


def test_reach_goal_by_pinocchio(reach):
    import pinocchio as pin
    from tests.reference import pinocchio_model
    setup, res, sim, _ = reach
    model, data, flange = pinocchio_model(setup["robot"])
    pin.framesForwardKinematics(model, data, res["q"][-1])
    assert np.linalg.norm(data.oMf[flange].translation - setup["goal"]) < 1e-6
    assert np.abs(res["qd"][-1]).max() < 1e-6
    assert np.abs(res["q"][0] - setup["q0"]).max() < 1e-9 and np.abs(res["qd"][0]).max() < 1e-9


def test_reach_limits(reach):
    setup, res, sim, _ = reach
    lim = sim["limit_excess"]
    assert lim["tau"] == 0.0
    assert lim["q_nodes"] < 1e-6 and lim["qd_nodes"] < 1e-6


@pytest.fixture(scope="module")
def stages(reach):
    import ocp_stages
    funcs = reach[3]
    s = ocp_stages.StageReach(20, funcs)
    res = s.solve_ipopt()
    return s.setup, res, ocp_reach.check(s.setup, res, funcs)


def _assert_at_goal_within_limits(setup, res, sim):
    """Pinocchio puts the plan's last node at the goal, at rest; the limits hold at the nodes."""
    import pinocchio as pin
    from tests.reference import pinocchio_model
    model, data, flange = pinocchio_model(setup["robot"])
    pin.framesForwardKinematics(model, data, res["q"][-1])
    assert np.linalg.norm(data.oMf[flange].translation - setup["goal"]) < 1e-6
    assert np.abs(res["qd"][-1]).max() < 1e-6
    lim = sim["limit_excess"]
    assert lim["tau"] == 0.0 and lim["q_nodes"] < 1e-6 and lim["qd_nodes"] < 1e-6


def test_compiled_stages_reach(stages, reach):
    setup, res, sim = stages
    assert res["success"], res["status"]
    assert sim["plan_step_error"] < 1e-6
    _assert_at_goal_within_limits(setup, res, sim)
    assert abs(res["objective"] - reach[1]["objective"]) < 1e-6 * reach[1]["objective"]


def test_fatrop_on_compiled_stages_reach(stages):
    """examples/ocp_fatrop.py: fatrop (its own Riccati-based interior point, structure declared
    by hand) on the same compiled functions reaches the KKT point IPOPT reaches, checked by
    Pinocchio like the others."""
    import ocp_fatrop
    fr = ocp_fatrop.FatropReach(20)
    res = fr.solve()
    setup = fr.s.setup
    sim = ocp_reach.check(setup, res, fr.s.funcs)
    assert res["success"], (res["status"], res["fatrop_return_flag"])
    assert sim["plan_step_error"] < 1e-6
    _assert_at_goal_within_limits(setup, res, sim)
    assert abs(res["objective"] - stages[1]["objective"]) < 1e-6 * stages[1]["objective"]


def test_shifted_warm_start_is_stationary(stages):
    """The MPC's warm start (examples/ocp_stages.py shifted, shifted_lam, shifted_lam_x): the
    converged plan and its constraint and bound multipliers moved one interval earlier, with the
    initial state moved to the plan's node 1, satisfy the Lagrangian's stationarity
    grad f + J' lam_g + lam_x = 0 on every variable but the appended interval's; the gradient
    of f = h sum |tau_k|^2 is written here in numpy, J is finite differences of the constraints."""
    import ocp_stages
    setup, res, _ = stages
    s = ocp_stages.StageReach(20)          # the cached library
    z, p = s.shifted(res["z"]), s.p(np.concatenate([res["q"][1], res["qd"][1]]))
    lam_g, lam_x = s.shifted_lam(res["lam_g"]), s.shifted_lam_x(res["lam_x"])
    grad = np.zeros(s.nz)
    for k in range(s.N):
        i = k * s.st + s.nx
        grad[i:i + s.n] = 2 * s.h * z[i:i + s.n]
    g = lambda zz: np.array(s.f_g(zz, p)).ravel()
    eps, jt_lam = 1e-6, np.zeros(s.nz)
    for i in range((s.N - 1) * s.st):   # J' lam by central differences, the kept variables only
        e = np.zeros(s.nz)
        e[i] = eps
        jt_lam[i] = lam_g @ (g(z + e) - g(z - e)) / (2 * eps)
    kept = slice(0, (s.N - 1) * s.st)
    resid = grad[kept] + jt_lam[kept] + lam_x[kept]
    assert np.abs(resid).max() < 1e-4 * max(1.0, np.abs(grad).max())
    # the shifted point satisfies the constraints (the appended interval holds the goal at rest)
    assert np.abs(g(z)).max() < 1e-6


def test_mpc_short_run(tmp_path, stages):
    """Two steps with the compiled per-interval functions (the fastest solver; N = 20 reuses
    the library the `stages` fixture built, another N would compile another)."""
    out = tmp_path / "mpc"
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "mpc.py"), "--problem", "lwr4", "--out", str(out),
                        "--steps", "2", "--N", "20", "--solver", "stages"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "mpc.json").read_text())
    assert len(doc["solve_ms"]) == 2 and doc["steps"] == 2
    for key in ("tracking_rms", "violations", "solve_ms_median", "solve_ms_p95", "solve_ms_worst"):
        assert key in doc
    kinds = doc["violations_by_kind"]
    assert kinds["tau"] == 0 and kinds["q"] == 0 and kinds["failed_solves"] == 0
    assert np.isfinite(doc["tracking_rms"]) and doc["tracking_rms"] < 1e-1
    assert (out / "mpc.png").exists()


@pytest.mark.parametrize("script,args", [("ocp.py", ["--problem", "lwr4_reach", "--N", "0", "--out", "x"]),
                                         ("mpc.py", ["--problem", "panda", "--out", "x"]),
                                         ("mpc.py", ["--problem", "lwr4", "--steps", "0", "--out", "x"]),
                                         ("mpc.py", ["--problem", "lwr4", "--max-iter", "0", "--out", "x"])])
def test_bad_arguments(script, args, tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "examples" / script), *args], capture_output=True, text=True,
                       cwd=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:")


def test_stage_hessian_is_the_lagrangians(reach):
    """examples/ocp_stages.py builds the interval's Hessian from one inverse dynamics' Hessian
    (sum_i L_i' H_i L_i); CasADi's AD of the interval's whole Lagrangian is the reference."""
    import casadi as ca
    import ocp_stages
    funcs = reach[3]
    n, h, N = 7, 0.05, 20
    stage = ocp_reach._id_rk4_stage(funcs["tau"], n, h)
    v = ca.SX.sym("v", 5 * n + 2 * n + 2 * n)
    xn, r = stage(v[:2 * n], v[2 * n:7 * n])
    c = ca.vertcat(v[7 * n:] - xn, r)
    lam, sigma = ca.SX.sym("lam", c.numel()), ca.SX.sym("sigma")
    w = v[:7 * n]
    ref = ca.Function("ref", [v, lam, sigma],
                      [ca.hessian(sigma * h * ca.sumsqr(w[2 * n:3 * n]) + ca.dot(lam, c), w)[0]])
    ours = ca.Function("ours", [v, lam, sigma], [ocp_stages.lagrangian_hessian(funcs["tau"], n, h, w, lam, sigma)])
    rng = np.random.default_rng(3)
    for _ in range(3):
        vv, ll = rng.standard_normal(v.numel()), 10 * rng.standard_normal(c.numel())
        a, b = np.array(ref(vv, ll, 1.7)), np.array(ours(vv, ll, 1.7))
        assert np.abs(a - b).max() < 1e-9 * max(1.0, np.abs(a).max())
