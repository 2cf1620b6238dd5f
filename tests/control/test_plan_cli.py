"""``kindyngen plan`` (kindyngen/cli/main.py's plan command, kindyngen/control/plan_command.py):
a reach on the UR5 from its URDF written to plan.json and checked there against Pinocchio's
own model of the file; --track writes track.json with the loop inside every limit; bad input is
one ``error:`` line and exit 2, and leaves no output."""
from __future__ import annotations

import json

import pytest

from benchmarks.control_robots import ROOT, UR5_URDF
from kindyngen.cli.main import main

UR5_ARGS = [str(UR5_URDF), "--tip", "tool0", "--q0", "0", "-1.2", "1.5", "-1.5", "-1.5", "0", "--offset", "0.2",
            "0.15", "0.1", "--quiet"]


def _skip_without_ur5():
    if not UR5_URDF.is_file():
        pytest.skip("example-robot-data's UR5 is not installed")


def test_reach_and_track_on_a_urdf(tmp_path):
    _skip_without_ur5()
    out = tmp_path / "ur5"
    assert main(["plan", *UR5_ARGS, "--track", "--settle", "0.5", "--budget-ms", "10000", "--out", str(out)]) == 0
    plan = json.loads((out / "plan.json").read_text())
    assert plan["success"] and plan["n"] == 6 and len(plan["tau"]) == 20
    assert plan["pinocchio"]["plan_step_error"] < 1e-8
    assert plan["pinocchio"]["goal_error_m"] < 1e-6
    track = json.loads((out / "track.json").read_text())
    assert track["violations"] == {"q": 0, "qd": 0}
    assert track["goal_error_final_m"] < 1e-3


@pytest.mark.parametrize("args, message", [
    ([str(ROOT / "robots" / "lwr4.yaml"), "--goal", "0.3", "0.2", "0.5"], "no speed or torque limits"),
    ([str(ROOT / "robots" / "lwr4.yaml"), "--limits", str(ROOT / "examples" / "limits" / "lwr4.yaml"), "--q0", "0", "1",
      "--goal", "0.3", "0.2", "0.5"], "--q0: 2 values for 7 joints"),
    ([str(ROOT / "robots" / "lwr4.yaml"), "--limits", str(ROOT / "examples" / "limits" / "panda.yaml"), "--goal", "0.3",
      "0.2", "0.5", "--N", "0"], "--N"),
    ([str(ROOT / "robots" / "lwr4.yaml"), "--limits", str(ROOT / "robots" / "panda.yaml"), "--goal", "0.3", "0.2", "0.5"],
     "velocity"),
    ([str(ROOT / "robots" / "nowhere.yaml"), "--goal", "0.3", "0.2", "0.5"], "nowhere.yaml"),
])
def test_bad_input_is_one_error_line(args, message, tmp_path, capsys):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) if "--N" in args else _nothing():
        code = main(["plan", *args, "--quiet", "--out", str(out)])
        assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and message in err[0], err
    assert not out.exists()


def test_unreachable_goal(tmp_path, capsys):
    _skip_without_ur5()
    out = tmp_path / "out"
    code = main(["plan", str(UR5_URDF), "--tip", "tool0", "--goal", "3", "3", "3", "--quiet", "--out", str(out)])
    assert code == 2
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if not ln.startswith("note:")]  # the reader's notes
    assert len(err) == 1 and err[0].startswith("error: the reach was not solved")
    assert not out.exists()


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
