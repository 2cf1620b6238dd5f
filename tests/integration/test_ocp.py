"""Optimal control with the generated CasADi Functions (examples/ocp.py), checked by an
independent simulator (Pinocchio's ABA, fixed-step RK4 with 20 steps per interval).

Tolerances:
- two-link: rockit's timeopt_pathfollowing reports T = 0.821204586734074 s for N = 100 with
  the same discretisation (multiple shooting, one RK4 step per interval, piecewise constant
  controls); we solve N = 100 and require |T - 0.8212046| < 1e-5 s (IPOPT tol 1e-8).
- re-simulation error (max state difference at the nodes): the planner's RK4 and the
  20-substep RK4 re-simulation differ by the planner's integration error. We require it below
  10x the planner's own global error estimate (sum over intervals of |1 RK4 step - 16 steps|)
  plus 1e-6, and below an absolute cap (1e-5 two-link, 2e-2 for the 7-joint arms at N = 10,
  whose light wrists with data-sheet torques make the dynamics fast).
- limits: torques exactly (box bounds); q and qd at the nodes to IPOPT's tolerance (1e-6);
  on the re-simulation (20 RK4 steps per interval), q and qd within their limits up to the
  re-simulation error itself (the plan's states and the integrated ones differ by that much):
  the NLP imposes q and qd at the nodes and at the 3 inner RK4 steps of each interval, the
  velocity backed off by 5 % (without the back-off qd overshot by up to 0.057 rad/s on the LWR
  between the samples, beyond the integration error).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pinocchio")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples"))
import ocp  # noqa: E402

ROCKIT_T = 0.821204586734074


@pytest.fixture(scope="module", params=[("two_link", 100, 1), ("lwr4", 10, 4), ("panda", 10, 4)],
                ids=lambda p: p[0])
def solved(request, tmp_path_factory):
    problem, N, M = request.param
    setup, res, sim = ocp.run(problem, N, substeps=M, workdir=str(tmp_path_factory.mktemp(problem)))
    return problem, setup, res, sim


def test_converged(solved):
    problem, setup, res, sim = solved
    assert res["success"], res["status"]
    assert res["max_defect"] < 1e-7


def test_limits_at_nodes(solved):
    problem, setup, res, sim = solved
    lim = sim["limit_excess"]
    assert lim["tau"] == 0.0
    assert lim["q_nodes"] < 1e-6 and lim["qd_nodes"] < 1e-6


def test_limits_on_resimulation(solved):
    problem, setup, res, sim = solved
    lim = sim["limit_excess"]
    # the re-simulated motion is the planned one up to the integration error, so a limit the
    # plan touches can be exceeded by at most that error
    assert lim["q_resim"] <= sim["resim_error"] + 1e-6
    assert lim["qd_resim"] <= sim["resim_error"] + 1e-6


def test_resimulation_error(solved):
    problem, setup, res, sim = solved
    cap = 1e-5 if problem == "two_link" else 2e-2
    assert sim["resim_error"] < 10 * res["rk4_error_estimate"] + 1e-6
    assert sim["resim_error"] < cap


def test_two_link_reproduces_rockit(solved):
    problem, setup, res, sim = solved
    if problem != "two_link":
        pytest.skip("two-link only")
    assert res["N"] == 100
    assert abs(res["T"] - ROCKIT_T) < 1e-5
    assert sim["resim_path_deviation"] < 1e-5   # end effector stays on the line


def test_lwr_start_goal_from_ik(solved):
    problem, setup, res, sim = solved
    if problem != "lwr4":
        pytest.skip("lwr4 only")
    import casadi as ca
    fk = ca.Function.load(str(ROOT / "generated" / "lwr4" / "casadi" / "fk_hom.casadi"))
    for q, T in zip((res["q"][0], res["q"][-1]), ocp.LWR_POSES):
        assert np.abs(np.array(fk(q)) - T).max() < 1e-9
        assert np.all(q >= setup["q_lo"]) and np.all(q <= setup["q_hi"])


def test_handwritten_peer_matches_generated():
    import casadi as ca
    from handwritten_dynamics import handwritten_fd
    from kindyngen.readers.yaml_description import load_robot
    robot = load_robot(ROOT / "robots" / "lwr4.yaml")
    gen = ca.Function.load(str(ROOT / "generated" / "lwr4" / "casadi" / "fd.casadi"))
    hand = handwritten_fd(robot)
    rng = np.random.default_rng(1)
    for _ in range(3):
        q, qd, tau = rng.uniform(-1, 1, (3, 7))
        assert np.abs(np.array(hand(q, qd, tau)) - np.array(gen(q, qd, tau))).max() < 1e-9
