"""The command line for kinematic trees: `generate` / `count` with --tree, --floating-base and
--frames, and one-line errors for what cannot be served (values are checked against Pinocchio
in tests/algorithms/test_tree_generated.py)."""
from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from kindyngen.cli.main import main

TREE = str(Path(__file__).resolve().parents[1] / "data" / "urdf" / "mobile_slider_tree.urdf")
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
    # --no-batch: the strict -O2 compile below of every function twice took minutes on a loaded
    # 2-core machine once the derivatives came (the batch variants: tests/codegen/test_c_batch.py)
    code, _, err = _run(["generate", TREE, "--floating-base", "--frames", "gripper_frame,foot",
                         "--lang", "c,python", "--no-batch", "--out", str(tmp_path), "--quiet"], capsys, monkeypatch)
    assert code == 0, err
    folder = tmp_path / "mobile_slider_tree"
    interface = json.loads((folder / "functions.json").read_text())
    ports = {f["name"]: f for f in interface["functions"]}
    assert set(ports) == {"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "tau_derivatives", "fd_derivatives",
                          "fd_derivatives_no_minv", "com", "Y"}
    assert ports["fd_derivatives"]["outputs"][2]["shape"] == [11, 11]
    assert [p["name"] for p in ports["fd_derivatives_no_minv"]["outputs"]] == ["dqdd_dq", "dqdd_dqd"]
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


def test_yaml_tree_needs_joints_by_origin_and_axis(tmp_path, capsys, monkeypatch):
    _refused(["generate", str(Path(__file__).resolve().parents[2] / "robots" / "lwr4.yaml"), "--floating-base",
              "--out", str(tmp_path)], capsys, monkeypatch, "a tree gives its joints by origin and axis: dh: none")


@pytest.mark.parametrize("change, message", [
    (lambda d: d["joints"][1].update(parent="nope"), "field 'joints[1].parent': 'nope' is not an earlier joint"),
    (lambda d: d["joints"][1].update(name="hip"), "field 'joints[1].name': 'hip' is also the name of joints[0]"),
    (lambda d: d["joints"][0].update(friction={"viscous": 1}), "field 'joints[0].friction': unknown key"),
    (lambda d: d.update(payload={}), "field 'payload': unknown key"),
])
def test_yaml_tree_errors(change, message, tmp_path, capsys, monkeypatch):
    data = yaml.safe_load(YAML_TREE)
    change(data)
    path = tmp_path / "tree.yaml"
    path.write_text(yaml.safe_dump(data))
    _refused(["generate", str(path), "--tree", "--out", str(tmp_path)], capsys, monkeypatch, message)


def test_floating_joint_in_urdf_is_refused(tmp_path, capsys, monkeypatch):
    path = tmp_path / "p.urdf"
    path.write_text(PENDULUMS.format(kind="floating"))
    _refused(["generate", str(path), "--tree", "--out", str(tmp_path)], capsys, monkeypatch,
             "joint 'right_joint' type': a floating joint is not supported")


def test_params_symbolic_tree_equals_pinocchio(tmp_path, capsys, monkeypatch):
    """generate --floating-base --params symbolic: the C and Python of M, g, c, tau, fd and com
    take p (10 per body, the root body first) and equal Pinocchio with the same random
    parameters (tests/algorithms/test_tree_symbolic_params.py builds them), 20 states, 1e-9."""
    pin = pytest.importorskip("pinocchio")
    from kindyngen.readers.urdf import load_urdf
    from kindyngen.runtime.evaluate import load_generated
    from tests.algorithms.test_tree_derivatives import pinocchio_tree
    from tests.algorithms.test_tree_symbolic_params import parameters_from_pinocchio, pinocchio_values, random_inertia
    functions = ("M", "g", "c", "tau", "fd", "com")
    code, _, err = _run(["generate", TREE, "--floating-base", "--params", "symbolic", "--lang", "c,python",
                         "--no-batch", "--functions", ",".join(functions), "--out", str(tmp_path), "--quiet"],
                        capsys, monkeypatch)
    assert code == 0, err
    folder = tmp_path / "mobile_slider_tree"
    interface = json.loads((folder / "functions.json").read_text())
    assert interface["params"] == "symbolic"
    assert {f["name"]: f["inputs"][-1]["shape"] for f in interface["functions"]} == {name: [60] for name in functions}
    tree = load_urdf(TREE, tree=True, floating_base=True)
    model = pinocchio_tree(tree)
    rng = np.random.default_rng(7)
    for k in range(1, model.njoints):
        model.inertias[k] = random_inertia(rng)
    data = model.createData()
    p = parameters_from_pinocchio(tree, model)
    states = []
    for _ in range(20):
        quat = rng.standard_normal(4)
        q = np.r_[rng.uniform(-1, 1, 3), quat / np.linalg.norm(quat),
                  rng.uniform([max(j.lower, -3) for j in tree.joints], [min(j.upper, 3) for j in tree.joints])]
        states.append((q,) + tuple(rng.uniform(-3, 3, tree.nv) for _ in range(3)))
    for lang in ("c", "python"):
        library = load_generated(folder, lang)
        for q, qd, qdd, tau in states:
            expected = pinocchio_values(model, data, q, qd, qdd, tau)
            inputs = {"q": q, "qd": qd, "qdd": qdd, "tau": tau, "p": p}
            for name in functions:
                spec = next(f for f in interface["functions"] if f["name"] == name)
                got = library.call(name, {port["name"]: inputs[port["name"]] for port in spec["inputs"]})
                for port, value in expected[name].items():
                    error = np.abs(got[port] - value).max() / max(1.0, np.abs(value).max())
                    assert error <= 1e-9, (lang, name, port, error)


def test_tree_with_named_lengths_gets_every_function_but_the_regressor(tmp_path, capsys, monkeypatch):
    """Named lengths in a tree's origins, as in an arm's: the functions take a ``lengths`` input,
    Y (whose base parameters are decided on numeric samples) is not generated and the run says
    so; count --only Y refuses in one line."""
    path = tmp_path / "named.yaml"
    path.write_text(YAML_TREE.replace("xyz: [0, 0, -0.3]", "xyz: [0, 0, thigh]"))
    code, out, err = _run(["generate", str(path), "--tree", "--functions", "tau,Y", "--lang", "python",
                           "--out", str(tmp_path / "gen")], capsys, monkeypatch)
    assert code == 0, err
    assert "Y does not apply" in err
    functions = json.loads(next((tmp_path / "gen").rglob("functions.json")).read_text())["functions"]
    (tau,) = [f for f in functions if f["name"] == "tau"]
    assert [f["name"] for f in functions] == ["tau"] and tau["inputs"][-1]["name"] == "lengths"
    _refused(["count", str(path), "--tree", "--only", "tau", "Y"], capsys, monkeypatch, "--only: Y not generated")
    code, out, err = _run(["count", str(path), "--tree", "--only", "tau"], capsys, monkeypatch)
    assert code == 0 and "| tau |" in out, err


def test_help_names_the_tree_options(capsys, monkeypatch):
    code, out, _ = _run(["generate", "--help"], capsys, monkeypatch)
    assert code == 0
    for option in ("--tree", "--floating-base", "--frames"):
        assert option in out


YAML_TREE = """
name: yaml_tree
dh: none
gravity: [0, 0, -9.81]
base: {mass: 4.0, com: [0.01, 0.0, 0.02], inertia: [0.05, 0.06, 0.07, 0.001, 0.0, 0.002]}
joints:
  - {name: hip, origin: {xyz: [0.0, 0.1, -0.05], rpy: [0.2, 0, 0]}, axis: [1, 0, 0], lower: -1.5, upper: 1.5}
  - {name: knee, parent: hip, origin: {xyz: [0, 0, -0.3]}, axis: [0, 1, 0], lower: -2.5, upper: 0}
  - {name: arm, origin: {xyz: [0.1, 0, 0.2], rpy: [0, 0.3, "pi/2"]}, axis: [0, 0, 1], lower: -3, upper: 3}
  - {name: slide, parent: arm, type: prismatic, origin: {xyz: [0.2, 0, 0]}, axis: [1, 0, 0], lower: 0, upper: 0.3}
links:
  - {mass: 2.0, com: [0, 0.01, -0.15], inertia: [0.02, 0.021, 0.002, 0, 0.001, 0]}
  - {mass: 1.1, com: [0.01, 0, -0.14], inertia: [0.011, 0.0115, 0.001, 0, 0, 0.0003]}
  - {mass: 1.4, com: [0.15, 0.01, 0], inertia: [0.002, 0.012, 0.011, 0.0001, 0, 0.0002]}
  - {mass: 0.6, com: [0.05, 0, 0.01], inertia: [0.0005, 0.001, 0.001, 0, 0, 0]}
"""


def _urdf_of(data) -> str:
    """The same robot as URDF text (link frames = joint child frames, named <joint>_link)."""
    def inertial(link):
        ixx, iyy, izz, ixy, ixz, iyz = link["inertia"]
        return (f'<inertial><mass value="{link["mass"]}"/><origin xyz="{" ".join(map(str, link["com"]))}"/>'
                f'<inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/></inertial>')
    out = [f'<robot name="{data["name"]}">', f'<link name="base">{inertial(data["base"])}</link>']
    for joint, link in zip(data["joints"], data["links"]):
        rpy = [{"pi/2": np.pi / 2}.get(v, v) for v in joint["origin"].get("rpy", [0, 0, 0])]
        parent = joint.get("parent")
        out.append(f'<link name="{joint["name"]}_link">{inertial(link)}</link>')
        out.append(f'<joint name="{joint["name"]}" type="{joint.get("type", "revolute")}">'
                   f'<parent link="{parent + "_link" if parent else "base"}"/><child link="{joint["name"]}_link"/>'
                   f'<origin xyz="{" ".join(map(str, joint["origin"]["xyz"]))}" rpy="{" ".join(map(repr, rpy))}"/>'
                   f'<axis xyz="{" ".join(map(str, joint["axis"]))}"/>'
                   f'<limit lower="{joint["lower"]}" upper="{joint["upper"]}" effort="1" velocity="1"/></joint>')
    return "".join(out) + "</robot>"


@pytest.mark.parametrize("floating", (False, True))
def test_yaml_tree_equals_pinocchio(floating, tmp_path):
    """A tree written in YAML (joints with parent, a prismatic branch, a base body) generates
    functions equal to Pinocchio's on the same robot written as URDF (200 states, 1e-9)."""
    pin = pytest.importorskip("pinocchio")
    from kindyngen.runtime.evaluate import load_generated
    from kindyngen.codegen.pipeline import generate
    from kindyngen.readers.yaml_description import parse_robot
    data = yaml.safe_load(YAML_TREE)
    model = parse_robot(data, "tree.yaml", frames=["knee", "slide"], floating_base=floating)
    assert [j.name for j in model.joints] == ["hip", "knee", "arm", "slide"] and model.parents == (-1, 0, -1, 2)
    urdf = tmp_path / "tree.urdf"
    urdf.write_text(_urdf_of(data))
    pmodel = (pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer()) if floating
              else pin.buildModelFromUrdf(str(urdf)))
    order = [list(pmodel.names).index(j.name) for j in model.joints]     # urdfdom orders children by name
    first = 2 if floating else 1
    base = 7 if floating else 0
    vbase = 6 if floating else 0
    perm_q = list(range(base)) + [base + i - first for i in order]      # Pinocchio's q entries in our order
    perm_v = list(range(vbase)) + [vbase + i - first for i in order]
    lib = load_generated(generate(model, tmp_path / "out", languages=("python",), progress=False), "python")
    data_p = pmodel.createData()
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = np.r_[rng.uniform(-1, 1, 3), rng.standard_normal(4), rng.uniform([-1.5, -2.5, -3, 0], [1.5, 0, 3, 0.3])]
        q = q if floating else q[7:]
        if floating:
            q[3:7] /= np.linalg.norm(q[3:7])
        v, a = rng.standard_normal(model.nv), rng.standard_normal(model.nv)
        pq, pv, pa = np.empty_like(q), np.empty_like(v), np.empty_like(a)
        pq[perm_q], pv[perm_v], pa[perm_v] = q, v, a
        tau = pin.rnea(pmodel, data_p, pq, pv, pa)[perm_v]
        M = pin.crba(pmodel, data_p, pq)
        M = (np.triu(M) + np.triu(M, 1).T)[np.ix_(perm_v, perm_v)]
        pin.framesForwardKinematics(pmodel, data_p, pq)
        T = [data_p.oMf[pmodel.getFrameId(name + "_link")].homogeneous for name in ("knee", "slide")]
        assert np.allclose(lib.call("tau", {"q": q[None], "qd": v[None], "qdd": a[None]})["tau"][0], tau, rtol=0, atol=1e-9)
        assert np.allclose(lib.call("M", {"q": q[None]})["M"][0], M, rtol=0, atol=1e-9)
        assert np.allclose(lib.call("fk_hom", {"q": q[None]})["T"][0], T, rtol=0, atol=1e-9)


def test_readme_tree_example_loads():
    """The handbook's YAML tree (docs/reference/trees.md) is a working description (a hip and
    its knee below the base)."""
    import re
    from kindyngen.readers.yaml_description import parse_robot
    text = (Path(__file__).resolve().parents[2] / "docs" / "reference" / "trees.md").read_text()
    section = text[text.index("## Kinematic trees and floating bases"):]
    block = re.search(r"```yaml\n(.*?)```", section, re.S).group(1)
    model = parse_robot(yaml.safe_load(block), "trees.md", floating_base=True)
    assert model.parents == (-1, 0) and model.nv == 8 and float(model.root.mass) == 4.0


@pytest.mark.parametrize("drop_base", [False, True])
def test_a_tree_description_read_as_an_arm_is_told_to_use_tree(tmp_path, capsys, monkeypatch, drop_base):
    """Without --tree a tree's keys (base, a joint's parent) are the reading's fault, not typos."""
    text = "\n".join(line for line in YAML_TREE.splitlines() if not (drop_base and line.startswith("base:")))
    path = tmp_path / "tree.yaml"
    path.write_text(text)
    code, out, err = _run(["generate", str(path), "--out", str(tmp_path / "out"), "--functions", "M"], capsys,
                          monkeypatch)
    field = "joints[1].parent" if drop_base else "base"
    assert code == 2 and err == f"error: {path}: field '{field}': a key of a tree description: read it as a tree (--tree)\n"
