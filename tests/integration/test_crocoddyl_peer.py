"""benchmarks/ocp_bench.py's side of the Crocoddyl peer (benchmarks/crocoddyl_reach.py runs in
its own environment, not installed here): a stand-in interpreter records what ocp_bench passes
and prints a peer's JSON line holding a known plan.

- the peer is given examples/ocp_reach.py's own numbers (limits, start, goal, N, T), so the
  Crocoddyl problem cannot drift from ours;
- every returned plan is checked by Pinocchio like ocp_bench's own rows: a plan that satisfies
  the RK4 steps of Pinocchio's ABA passes (step error < 1e-6), the same plan with one torque
  moved by 1 N m does not (> 1e-4), so the check reads the peer's trajectories;
- a peer that crashes is reported with its last stderr lines, no rows.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("pinocchio")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "examples"))
import ocp_reach  # noqa: E402

from benchmarks import ocp_bench  # noqa: E402


def _fake_venv(tmp_path: Path, stdout: str, stderr: str = "", code: int = 0) -> Path:
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (tmp_path / "out.txt").write_text(stdout)
    (tmp_path / "err.txt").write_text(stderr)
    py = venv / "bin" / "python"
    py.write_text(f"#!/bin/sh\nprintf '%s\\n' \"$@\" > {tmp_path}/args.txt\ncat {tmp_path}/out.txt\n"
                  f"cat {tmp_path}/err.txt >&2\nexit {code}\n")
    py.chmod(0o755)
    return venv


@pytest.fixture(scope="module")
def plan():
    funcs = ocp_reach.load()
    res = ocp_reach.reach_problem("id_rk4", "ipopt", 20, funcs).solve()
    assert res["success"]
    return funcs, ocp_reach.setup_dict(funcs), res


def _peer_row(solver, res, tau):
    return {"solver": solver, "status": "converged", "success": True, "iterations": 7, "solve_cpu_s": 0.5,
            "solve_cpu_s_runs": [0.5], "solve_s": 0.6, "kkt": 1e-9, "crocoddyl_cost": res["objective"],
            "objective": res["objective"], "goal_error_m": 0.0, "final_speed": 0.0,
            "limit_excess": {"tau": 0.0, "qd_nodes": 0.0, "q_nodes": 0.0},
            "q": res["q"].tolist(), "qd": res["qd"].tolist(), "tau": tau.tolist(),
            "warm_resolve_cpu_s": 0.1, "warm_iterations": 3}


def test_peer_gets_our_problem_and_its_plans_are_checked(plan, tmp_path):
    funcs, setup, res = plan
    bad = res["tau"].copy()
    bad[5, 6] += 1.0
    out = {"versions": {"crocoddyl": "9.9", "mim-solvers": "8.8", "pin": "7.7"}, "crocoddyl": "9.9", "pin": "7.7",
           "csqp_options": {}, "maxiter": 200, "repeats": 1,
           "rows": [_peer_row("csqp", res, res["tau"]), _peer_row("csqp tol=1e-2", res, bad),
                    _peer_row("boxfddp", res, res["tau"])]}
    venv = _fake_venv(tmp_path, "some log line\n" + json.dumps(out) + "\n")
    summary, rows = ocp_bench.crocoddyl_peer(venv, funcs, setup)
    args = (tmp_path / "args.txt").read_text().splitlines()
    problem = json.loads(args[args.index("--problem") + 1])
    for key in ("q0", "goal", "tau_max", "qd_max", "q_lo", "q_hi"):
        assert problem[key] == pytest.approx(setup[key].tolist(), abs=0)
    assert (problem["N"], problem["T"], problem["frame"]) == (20, setup["T"], "flange")
    assert summary["versions"] == out["versions"]
    assert summary["row_variants"] == ["crocoddyl csqp", "crocoddyl csqp tol=1e-2", "crocoddyl boxfddp"]
    good, moved, soft = rows
    assert good["plan_step_error"] < 1e-6 and soft["plan_step_error"] < 1e-6
    assert moved["plan_step_error"] > 1e-4
    assert good["formulation"] == "crocoddyl hard (ours)" and soft["formulation"] == "crocoddyl penalty (softer)"
    assert good["limit_excess"]["tau"] == 0.0
    assert good["dynamics"] == "crocoddyl" and good["solver"] == "csqp (mim-solvers 8.8)"


def test_a_crashing_peer_is_reported(plan, tmp_path):
    funcs, setup, _ = plan
    venv = _fake_venv(tmp_path, "", "Fatal Python error: Segmentation fault\n\nCurrent thread 0x1 (most recent call first):\n", 139)
    summary, rows = ocp_bench.crocoddyl_peer(venv, funcs, setup)
    assert rows == [] and "Segmentation fault" in summary["error"]
    summary, rows = ocp_bench.crocoddyl_peer(tmp_path / "nowhere", funcs, setup)
    assert rows == [] and "no Crocoddyl environment" in summary["error"]
