"""DH lengths given as names stay symbolic: every generated function takes them as a last
input ``lengths`` and, evaluated at the numeric values, equals the numeric robot."""
import json
import subprocess
import sys

import numpy as np
import pytest

from tests.harness import GENERATED, ROOT
from kindyngen.runtime.evaluate import load_generated
from kindyngen.model.robot_model import RobotDescriptionError
from kindyngen.readers.yaml_description import load_robot


@pytest.fixture(scope="module")
def symbolic_lwr(tmp_path_factory):
    root = tmp_path_factory.mktemp("symbolic")
    text = (ROOT / "robots" / "lwr4.yaml").read_text()
    text = text.replace("d: 0.40,", "d: l1,").replace("d: 0.39,", "d: l2,").replace("name: lwr4", "name: lwr4_sym")
    path = root / "lwr4_sym.yaml"
    path.write_text(text)
    subprocess.run([sys.executable, "-m", "kindyngen", "generate", str(path), "--out", str(root), "--quiet",
                    "--lang", "c,python"], check=True, cwd=ROOT)
    return root / "lwr4_sym", path


def test_lengths_are_symbols_in_the_model(symbolic_lwr):
    model = load_robot(symbolic_lwr[1])
    assert [str(s) for s in model.length_symbols] == ["l1", "l2"]


def test_reserved_names_are_refused(tmp_path):
    text = (ROOT / "robots" / "lwr4.yaml").read_text().replace("d: 0.40,", "d: t3,")
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(RobotDescriptionError, match=r"joints\[2\]\.d.*reserved"):
        load_robot(tmp_path / "bad.yaml")


@pytest.mark.parametrize("lang", ["python", "c"])
def test_every_function_equals_the_numeric_robot(symbolic_lwr, lang):
    directory, _ = symbolic_lwr
    numeric = load_generated(GENERATED / "lwr4", lang)
    symbolic = load_generated(directory, lang)
    manifest = json.loads((directory / "functions.json").read_text())
    rng = np.random.default_rng(3)
    lower, upper = load_robot(ROOT / "robots" / "lwr4.yaml").lower, load_robot(ROOT / "robots" / "lwr4.yaml").upper
    checked = 0
    for spec in manifest["functions"]:
        assert spec["inputs"][-1]["name"] == "lengths"
        if spec["name"] not in numeric.functions:
            continue
        inputs = {}
        for port in spec["inputs"][:-1]:
            shape = (20,) + tuple(port["shape"])
            inputs[port["name"]] = rng.uniform(lower, upper, shape) if port["name"] == "q" else rng.normal(size=shape)
        expected = numeric.call(spec["name"], inputs)
        got = symbolic.call(spec["name"], {**inputs, "lengths": np.tile([0.40, 0.39], (20, 1))})
        for name, value in expected.items():
            np.testing.assert_allclose(got[name], value, rtol=1e-9, atol=1e-9, err_msg=spec["name"])
        checked += 1
    assert checked >= 3
