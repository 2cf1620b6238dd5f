"""The command line for kinematic trees: `generate` / `count` with --tree, --floating-base and
--frames, and one-line errors for what cannot be served (values are checked against Pinocchio
in tests/test_tree_generated.py)."""
from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from kindyngen.cli import main

TREE = str(Path(__file__).resolve().parent / "data" / "urdf" / "mobile_slider_tree.urdf")
PENDULUMS = """<robot name="two_pendulums">
  <link name="body"/><link name="left"/><link name="right"/>
  <joint name="left_joint" type="revolute"><parent link="body"/><child link="left"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="right_joint" type="{kind}"><parent link="body"/><child link="right"/>
    <axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>"""


def _run(argv, capsys, monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return (code,) + capsys.readouterr()


def _refused(argv, capsys, monkeypatch, message):
    code, out, err = _run(argv, capsys, monkeypatch)
    assert code == 2, (code, err)
    assert err.startswith("error: ") and err.count("\n") == 1, repr(err)
    assert message in err, err


def test_generate_floating_base_tree(tmp_path, capsys, monkeypatch):
    code, _, err = _run(["generate", TREE, "--floating-base", "--frames", "gripper_frame,foot",
                         "--lang", "c,python", "--out", str(tmp_path), "--quiet"], capsys, monkeypatch)
    assert code == 0, err
    folder = tmp_path / "mobile_slider_tree"
    interface = json.loads((folder / "functions.json").read_text())
    ports = {f["name"]: f for f in interface["functions"]}
    assert set(ports) == {"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com", "Y"}
    assert ports["tau"]["inputs"][0]["shape"] == [12] and ports["tau"]["outputs"][0]["shape"] == [11]
    assert ports["fk_hom"]["outputs"][0]["shape"] == [2, 4, 4]
    assert ports["jacobian"]["outputs"][0]["shape"] == [2, 6, 11]
    assert "ik_dls" not in ports          # several frames: no single pose to reach
    header = (folder / "c" / "mobile_slider_tree.h").read_text()
    assert "#define MOBILE_SLIDER_TREE_NQ 12" in header and "#define MOBILE_SLIDER_TREE_NV 11" in header
    assert "quaternion (x, y, z, w)" in header
    base = json.loads((folder / "base_params.json").read_text())["Y"]
    assert base["bodies"][0] == "chassis" and base["rank"] == len(base["names"])
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler:        # strict C99, no warning (-O2: the optimiser's own warnings too)
        run = subprocess.run([compiler, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-c",
                              str(folder / "c" / "mobile_slider_tree.c"), "-o", str(tmp_path / "tree.o")],
                             capture_output=True, text=True)
        assert run.returncode == 0, run.stderr


def test_count_tree(capsys, monkeypatch):
    code, out, err = _run(["count", TREE, "--tree", "--only", "tau", "fd"], capsys, monkeypatch)
    assert code == 0, err
    assert "| tau |" in out and "| fd |" in out and "| M |" not in out


@pytest.mark.parametrize("argv, message", [
    (["--frames", "gripper_fram"], "no link named 'gripper_fram' in the URDF; closest: gripper_frame"),
    (["--tree", "--tip", "foot"], "--base and --tip choose one chain"),
    (["--frames", "a,,b"], "expected comma-separated link names"),
])
def test_tree_option_errors(argv, message, tmp_path, capsys, monkeypatch):
    _refused(["generate", TREE, "--out", str(tmp_path)] + argv, capsys, monkeypatch, message)


def test_trees_are_read_from_urdf(tmp_path, capsys, monkeypatch):
    _refused(["generate", str(Path(__file__).resolve().parents[1] / "robots" / "lwr4.yaml"), "--floating-base",
              "--out", str(tmp_path)], capsys, monkeypatch, "trees (--tree, --floating-base, --frames) are read from URDF")


def test_floating_joint_in_urdf_is_refused(tmp_path, capsys, monkeypatch):
    path = tmp_path / "p.urdf"
    path.write_text(PENDULUMS.format(kind="floating"))
    _refused(["generate", str(path), "--tree", "--out", str(tmp_path)], capsys, monkeypatch,
             "joint 'right_joint' type': a floating joint is not supported")


def test_params_symbolic_is_refused_for_trees(tmp_path, capsys, monkeypatch):
    _refused(["generate", TREE, "--tree", "--params", "symbolic", "--out", str(tmp_path)], capsys, monkeypatch,
             "a kinematic tree is generated with its description's parameters only")


def test_help_names_the_tree_options(capsys, monkeypatch):
    code, out, _ = _run(["generate", "--help"], capsys, monkeypatch)
    assert code == 0
    for option in ("--tree", "--floating-base", "--frames"):
        assert option in out
