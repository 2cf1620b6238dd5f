"""`kindyngen describe`: a robot read from a URDF, written as a YAML description (joints by
origin and axis), loads again to the same arm: same FK, Jacobian, M and tau at random states
(the URDF models themselves are checked against Pinocchio in test_urdf_generated.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import symengine as se

from kindyngen.codegen.catalog import derive_all
from kindyngen.cli.main import main
from kindyngen.readers.yaml_description import load_robot
from tests.robot_files import example_robot_data_or_skip

DATA = Path(__file__).resolve().parents[1] / "data" / "urdf"
# (file under example-robot-data's robots folder, or None: the slider arm of tests/data; tip)
ARMS = [("panda_description/urdf/panda.urdf", "panda_hand"), ("ur_description/urdf/ur5_robot.urdf", "tool0"),
        ("xarm_description/urdf/xarm7.urdf", None), ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector"),
        (None, None)]


def _path(file):
    if file is None:
        return DATA / "slider_arm.urdf"
    return example_robot_data_or_skip() / file


def _values(model, names, inputs):
    out = {}
    for f in derive_all(model, only=set(names)):
        fn = se.Lambdify([s for syms in f.input_symbols for s in syms], [e for exprs in f.inlined_outputs() for e in exprs],
                         cse=True)
        x = np.concatenate([inputs[p.name] for p in f.inputs], axis=1)
        out[f.name] = np.array([fn(row) for row in x])
    return out


@pytest.mark.parametrize("file, tip", ARMS, ids=[Path(f or "slider_arm").stem for f, _ in ARMS])
def test_describe_writes_a_description_that_loads_to_the_same_arm(file, tip, tmp_path, capsys):
    path = _path(file)
    out = tmp_path / "arm.yaml"
    argv = ["describe", str(path), "--out", str(out)] + (["--tip", tip] if tip else [])
    assert main(argv) == 0, capsys.readouterr().err
    original, reloaded = load_robot(path, tip=tip), load_robot(out)
    assert reloaded.convention == "frames" and [j.name for j in reloaded.joints] == [j.name for j in original.joints]
    assert [j.kind for j in reloaded.joints] == [j.kind for j in original.joints]
    rng = np.random.default_rng(5)
    n = original.n
    inputs = {"q": rng.uniform(original.lower, original.upper, size=(50, n)), "qd": rng.uniform(-1, 1, (50, n)),
              "qdd": rng.uniform(-2, 2, (50, n))}
    names = ("fk_hom", "jacobian", "M", "tau")
    a, b = _values(original, names, inputs), _values(reloaded, names, inputs)
    for name in names:
        scale = max(1.0, np.abs(a[name]).max())
        np.testing.assert_allclose(b[name], a[name], rtol=0, atol=1e-12 * scale, err_msg=name)


def test_a_standard_dh_table_is_refused(capsys):
    root = Path(__file__).resolve().parents[2]
    assert main(["describe", str(root / "robots" / "lwr4.yaml")]) == 2
    assert "off the joint axis" in capsys.readouterr().err
