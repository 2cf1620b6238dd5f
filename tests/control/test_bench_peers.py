"""benchmarks/control_bench.py's side of its peers (acados and Crocoddyl run in their own
environments, not installed here): a stand-in interpreter records what the benchmark passes and
prints a peer's JSON line holding a known plan.

- the peer is given the task's own numbers (start, goal, the planned limits, N, T) and, for
  acados, the robot's generated CasADi module;
- every returned plan is checked by Pinocchio like ours: the UR5's own native plan passes (step
  error < 1e-8), the same plan with one torque moved by 1 N m fails (> 1e-4);
- a crashing peer or a missing environment is reported, not fatal.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import control_bench
from kindyngen.control.reach import ReachNLP

from .helpers import arm


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
def ur5_plan():
    model, robot, limits, task = arm("ur5")
    res = ReachNLP(robot, task).solve()
    assert res.success
    return model, robot, task, res


def _row(res, tau):
    return {"status": 0, "success": True, "iterations": 12, "solve_cpu_s": 0.2, "solve_cpu_s_runs": [0.2],
            "objective": res.objective, "build_s": 1.0, "built_now": False,
            "q": res.q.tolist(), "qd": res.qd.tolist(), "tau": np.asarray(tau).tolist()}


def test_acados_gets_the_task_and_its_plan_is_checked(ur5_plan, tmp_path):
    model, robot, task, res = ur5_plan
    out = {"versions": {"comma-deps-acados": "9.9"}, "options": {}, "row": _row(res, res.tau)}
    venv = _fake_venv(tmp_path, "a log line\n" + json.dumps(out) + "\n")
    got = control_bench.acados_rows("ur5", model, robot, task, venv, True)
    args = (tmp_path / "args.txt").read_text().splitlines()
    problem = json.loads(args[args.index("--problem") + 1])
    lim = task.planned_limits
    assert problem["q0"] == list(task.q0) and problem["goal"] == pytest.approx(list(task.goal), abs=0)
    assert problem["tau_max"] == list(lim.tau_max) and (problem["N"], problem["T"]) == (task.N, task.T)
    assert Path(args[args.index("--module") + 1]) == robot.folder / "casadi" / "ur5_casadi.py"
    assert got["row"]["plan_step_error"] < 1e-8 and got["row"]["goal_error_m"] < 1e-6
    bad = res.tau.copy()
    bad[7, 2] += 1.0
    (tmp_path / "out.txt").write_text(json.dumps(dict(out, row=_row(res, bad))) + "\n")
    got = control_bench.acados_rows("ur5", model, robot, task, venv, True)
    assert got["row"]["plan_step_error"] > 1e-4


def test_crocoddyl_gets_the_task_and_its_plans_are_checked(ur5_plan, tmp_path):
    model, robot, task, res = ur5_plan
    bad = res.tau.copy()
    bad[5, 4] += 1.0

    def peer_row(solver, tau):
        return {"solver": solver, "status": "converged", "success": True, "iterations": 7, "solve_s": 0.6,
                "solve_cpu_s": 0.5, "objective": res.objective, "kkt": 1e-9, "warm_resolve_cpu_s": 0.1,
                "warm_iterations": 3, "q": res.q.tolist(), "qd": res.qd.tolist(), "tau": np.asarray(tau).tolist()}
    out = {"versions": {"crocoddyl": "9.9", "mim-solvers": "8.8"}, "rows": [peer_row("csqp", res.tau),
                                                                            peer_row("csqp tol=1e-2", bad)]}
    venv = _fake_venv(tmp_path, "some log line\n" + json.dumps(out) + "\n")
    got = control_bench.crocoddyl_rows("ur5", model, task, venv, True)
    args = (tmp_path / "args.txt").read_text().splitlines()
    problem = json.loads(args[args.index("--problem") + 1])
    lim = task.planned_limits
    assert problem["q0"] == list(task.q0) and problem["goal"] == pytest.approx(list(task.goal), abs=0)
    assert problem["qd_max"] == list(lim.qd_max) and problem["frame"] == "tool0"
    assert (problem["N"], problem["T"]) == (task.N, task.T)
    assert got["versions"] == out["versions"]
    good, moved = got["rows"]
    assert good["plan_step_error"] < 1e-8 and good["goal_error_m"] < 1e-6
    assert moved["plan_step_error"] > 1e-4


def test_a_crashing_or_missing_peer_is_reported(ur5_plan, tmp_path):
    model, robot, task, res = ur5_plan
    venv = _fake_venv(tmp_path, "", "Segmentation fault\n", 139)
    assert "Segmentation fault" in control_bench.acados_rows("ur5", model, robot, task, venv, True)["error"]
    assert "Segmentation fault" in control_bench.crocoddyl_rows("ur5", model, task, venv, True)["error"]
    assert "no acados environment" in control_bench.acados_rows("ur5", model, robot, task, tmp_path / "x", True)["error"]
    assert "no Crocoddyl environment" in control_bench.crocoddyl_rows("ur5", model, task, tmp_path / "x", True)["error"]
