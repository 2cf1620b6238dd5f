"""The command line with mimic joints: `generate --tree` of the gripper writes functions of its
one independent joint and says so; a chain with a mimic pair split by --tip and `excite` of a
robot with mimic joints are refused in one line (values: tests/algorithms/test_mimic_generated.py)."""
from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import yaml

from kindyngen.cli.main import main
from tests.harness import ROOT

DATA = Path(__file__).resolve().parents[1] / "data" / "urdf"
GRIPPER = str(ROOT / "examples" / "mimic" / "gripper.urdf")
COUPLED = str(DATA / "mimic_coupled_tree.urdf")


def _run(argv, capsys, monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return (code,) + capsys.readouterr()


def test_generate_gripper(tmp_path, capsys, monkeypatch):
    code, _, err = _run(["generate", GRIPPER, "--tree", "--functions", "M,fd", "--lang", "python", "--out",
                         str(tmp_path), "--quiet"], capsys, monkeypatch)
    assert code == 0, err
    assert "note: " in err and "5 mimic joint(s) (left_inner_finger_joint, left_inner_knuckle_joint, " \
                               "right_inner_knuckle_joint, ...) follow others" in err
    document = json.loads((tmp_path / "mimic_gripper" / "functions.json").read_text())
    assert document["coordinates"] == ["finger_joint"] and document["nv"] == 1 and document["n"] == 6
    assert {m["joint"]: (m["mimics"], m["multiplier"]) for m in document["mimics"]} == {
        "left_inner_finger_joint": ("finger_joint", -1.0), "left_inner_knuckle_joint": ("finger_joint", 1.0),
        "right_inner_knuckle_joint": ("finger_joint", 1.0), "right_outer_knuckle_joint": ("finger_joint", 1.0),
        "right_inner_finger_joint": ("finger_joint", -1.0)}
    assert [f["outputs"][0]["shape"] for f in document["functions"]] == [[1, 1], [1]]


def test_chain_split_and_excite_refused(tmp_path, capsys, monkeypatch):
    code, _, err = _run(["count", COUPLED, "--tip", "l4"], capsys, monkeypatch)
    assert code == 2 and err.count("\n") == 1, err
    assert "field 'joint 'k2' mimic joint': 'k2' is not on the chain but follows 'j1'" in err
    arm = {"name": "pair", "dh": "none", "gravity": [0, 0, -9.81], "joints": [
        {"name": "a", "lower": -1, "upper": 1},
        {"name": "b", "origin": {"xyz": [0.3, 0, 0]}, "lower": -1, "upper": 1, "mimic": {"joint": "a"}}],
        "links": [{"mass": 1, "com": [0.1, 0, 0], "inertia": [0.01, 0.01, 0.01, 0, 0, 0]}] * 2}
    robot = tmp_path / "pair.yaml"
    robot.write_text(yaml.safe_dump(arm))
    code, _, err = _run(["excite", "--robot", str(robot), "--harmonics", "2", "--iterations", "2", "--out",
                         str(tmp_path / "out"), "--quiet"], capsys, monkeypatch)
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1, err
    assert "field 'joint 'b' mimic': identify, discover and excite take robots without mimic joints" in err
