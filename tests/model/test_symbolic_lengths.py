"""DH lengths given as names stay symbolic: every generated function takes them as a last
input ``lengths`` and, evaluated at the numeric values, equals the numeric robot."""
import json
import string
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


TREE_WITH_NAMES = """
name: named_tree
dh: none
gravity: [0.3, -0.2, -9.81]
base: {mass: 4.0, com: [0.01, 0.0, 0.02], inertia: [0.05, 0.06, 0.07, 0.001, 0.0, 0.002]}
joints:
  - {name: hip, origin: {xyz: [0.0, $w, -0.05], rpy: [0.2, 0, 0]}, axis: [1, 0, 0], lower: -1.5, upper: 1.5}
  - {name: knee, parent: hip, origin: {xyz: [0, 0.02, $thigh]}, axis: [0, 1, 0], lower: -2.5, upper: 0}
  - {name: arm, origin: {xyz: [0.1, 0, 0.2], rpy: [0, 0.3, "pi/2"]}, axis: [0, 0, 1], lower: -3, upper: 3}
  - {name: slide, parent: arm, type: prismatic, origin: {xyz: [$reach, 0, 0]}, axis: [1, 0, 0], lower: 0, upper: 0.3}
links:
  - {mass: 2.0, com: [0, 0.01, -0.15], inertia: [0.02, 0.021, 0.002, 0, 0.001, 0]}
  - {mass: 1.1, com: [0.01, 0, -0.14], inertia: [0.011, 0.0115, 0.001, 0, 0, 0.0003]}
  - {mass: 0.8, com: [0.05, 0.01, 0], inertia: [0.001, 0.004, 0.0045, 0, 0, 0.0002]}
  - {mass: 0.5, com: [0.02, 0, 0.01], inertia: [0.0004, 0.0006, 0.0007, 0, 0.00001, 0]}
"""
TREE_LENGTHS = {"w": 0.1, "thigh": -0.3, "reach": 0.2}


@pytest.mark.parametrize("floating, params", [(False, "numeric"), (True, "numeric"), (True, "symbolic")])
def test_tree_origins_with_names_equal_pinocchio(floating, params):
    """A YAML tree's origins may name lengths (as a DH table's a and d): every derived function
    but the regressor Y takes them as the last input ``lengths`` and, at the values, equals
    Pinocchio's model of the tree written with the numbers (with symbolic parameters too)."""
    import symengine as se
    import yaml
    from kindyngen.codegen.catalog import NAMES, derive_all
    from kindyngen.model.inertial_parameters import parameter_vector
    from kindyngen.readers.yaml_description import parse_robot
    from tests.algorithms.test_tree_derivatives import pinocchio_tree
    from tests.algorithms.test_tree_symbolic_params import pinocchio_values
    pin = pytest.importorskip("pinocchio")
    template = string.Template(TREE_WITH_NAMES)
    named = parse_robot(yaml.safe_load(template.substitute({k: k for k in TREE_LENGTHS})), "named_tree.yaml",
                        tree=True, floating_base=floating)
    numbers = parse_robot(yaml.safe_load(template.substitute(TREE_LENGTHS)), "numbers.yaml", tree=True,
                          floating_base=floating)
    assert [str(s) for s in named.length_symbols] == list(TREE_LENGTHS) and not numbers.length_symbols
    # Y's base parameters are decided on numeric samples: not with symbolic lengths (see docs)
    functions = derive_all(named, params, only=set(NAMES) - {"Y"})
    assert {f.name for f in functions} >= {"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com", "fd_derivatives"}
    model = pinocchio_tree(numbers)
    data = model.createData()
    frames = []
    for frame in numbers.frames:            # the tips' link frames: joint frame moved by `after`
        j = [j.name for j in numbers.joints].index(frame.name)
        placement = numbers.joints[j].after
        R, p = placement.matrix()
        frames.append(model.addFrame(pin.Frame(frame.name, j + 1 + floating, 0,
                                               pin.SE3(np.array(R.evalf(), float), np.array(p.evalf(), float).ravel()),
                                               pin.FrameType.OP_FRAME)))
    data = model.createData()
    rng = np.random.default_rng(8)
    for _ in range(10):
        qj = rng.uniform(numbers.lower, numbers.upper)
        quat = rng.standard_normal(4)
        q = np.r_[rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat), qj] if floating else qj
        qd, qdd, tau = (rng.uniform(-3, 3, numbers.nv) for _ in range(3))
        expected = pinocchio_values(model, data, q, qd, qdd, tau)
        pin.framesForwardKinematics(model, data, q)
        pin.computeJointJacobians(model, data, q)
        expected["fk_hom"] = {"T": np.array([data.oMf[f].homogeneous for f in frames])}
        expected["jacobian"] = {"J": np.array([pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED)
                                               for f in frames])}
        inputs = {"q": q, "qd": qd, "qdd": qdd, "tau": tau, "p": parameter_vector(numbers),
                  "lengths": list(TREE_LENGTHS.values())}
        for f in functions:
            if f.name not in expected:
                continue
            assert f.inputs[-1].name == "lengths" and f.inputs[-1].shape == (3,)
            args = [s for syms in f.input_symbols for s in syms]
            fn = se.Lambdify(args, [e for exprs in f.inlined_outputs() for e in exprs], cse=True)
            flat = np.ravel(fn(np.concatenate([np.ravel(inputs[p.name]) for p in f.inputs])))
            start = 0
            for port in f.outputs:
                value = expected[f.name][port.name]
                got = flat[start:start + port.size].reshape(value.shape)
                start += port.size
                assert np.abs(got - value).max() <= 1e-9 * max(1.0, np.abs(value).max()), (f.name, port.name)


ARM_BY_ORIGIN = """
name: named_arm
dh: none
gravity: [0, 0, -9.81]
joints:
  - {origin: {xyz: [0, 0, 0.1]}, axis: [0, 0, 1], lower: -3, upper: 3}
  - {origin: {xyz: [0, 0, $upper]}, axis: [0, 1, 0], lower: -2, upper: 2}
  - {origin: {xyz: [$fore, 0, 0], rpy: [0.3, 0, 0]}, axis: [0, 1, 0], lower: -2, upper: 2}
links:
  - {mass: 2.0, com: [0, 0.01, 0.05], inertia: [0.02, 0.021, 0.002, 0, 0.001, 0]}
  - {mass: 1.1, com: [0.01, 0, 0.14], inertia: [0.011, 0.0115, 0.001, 0, 0, 0.0003]}
  - {mass: 0.8, com: [0.05, 0.01, 0], inertia: [0.001, 0.004, 0.0045, 0, 0, 0.0002]}
tool: {xyz: [0, 0, $tool]}
"""
ARM_LENGTHS = {"upper": 0.4, "fore": 0.35, "tool": 0.12}


def test_arm_origins_and_tool_with_names_equal_pinocchio():
    """An arm by origin and axis may name lengths in its origins and its tool (once a traceback
    in generation): fk_hom, M, tau and fd take them and equal Pinocchio's model of the arm
    written with the numbers, the flange moved by the tool."""
    import symengine as se
    import yaml
    from kindyngen.codegen.catalog import derive_all
    from kindyngen.readers.yaml_description import parse_robot
    from tests.algorithms.test_tree_derivatives import pinocchio_tree
    pin = pytest.importorskip("pinocchio")
    template = string.Template(ARM_BY_ORIGIN)
    named = parse_robot(yaml.safe_load(template.substitute({k: k for k in ARM_LENGTHS})), "named_arm.yaml")
    numbers = parse_robot(yaml.safe_load(template.substitute(ARM_LENGTHS)), "numbers.yaml")
    assert [str(s) for s in named.length_symbols] == list(ARM_LENGTHS)
    model = pinocchio_tree(numbers)
    R, p = (numbers.joints[-1].after * numbers.tool).matrix()
    flange = model.addFrame(pin.Frame("flange", numbers.n, 0, pin.SE3(np.array(R.evalf(), float),
                                                                     np.array(p.evalf(), float).ravel()),
                                      pin.FrameType.OP_FRAME))
    data = model.createData()
    functions = derive_all(named, only={"fk_hom", "M", "tau", "fd"})
    assert all(f.inputs[-1].name == "lengths" for f in functions) and len(functions) == 4
    rng = np.random.default_rng(9)
    for _ in range(10):
        q = rng.uniform(numbers.lower, numbers.upper)
        qd, qdd, tau = (rng.uniform(-3, 3, numbers.n) for _ in range(3))
        pin.framesForwardKinematics(model, data, q)
        M = pin.crba(model, data, q)
        expected = {"fk_hom": data.oMf[flange].homogeneous.copy(), "M": np.triu(M) + np.triu(M, 1).T,
                    "tau": pin.rnea(model, data, q, qd, qdd).copy(), "fd": pin.aba(model, data, q, qd, tau).copy()}
        inputs = {"q": q, "qd": qd, "qdd": qdd, "tau": tau, "lengths": list(ARM_LENGTHS.values())}
        for f in functions:
            args = [s for syms in f.input_symbols for s in syms]
            fn = se.Lambdify(args, [e for exprs in f.inlined_outputs() for e in exprs], cse=True)
            got = np.ravel(fn(np.concatenate([np.ravel(inputs[p.name]) for p in f.inputs])))
            value = expected[f.name]
            assert np.abs(got.reshape(value.shape) - value).max() <= 1e-9 * max(1.0, np.abs(value).max()), f.name
