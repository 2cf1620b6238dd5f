"""The joint loops of the trees' inverse-dynamics derivatives (kindyngen.algorithms.derivatives_world_frame,
``joint_loops``): the C single call of ``tau_derivatives`` of a tree large enough for them to pay
(kindyngen.codegen.optimize.JOINT_LOOPS_RATIO) runs the kinematics once, then loops over joints and
pairs of joints. Its results equal Pinocchio's computeRNEADerivatives (dtau_dq, dtau_dv) at random
states, built unoptimised and as a user builds it (-O3 -march=native, vectorised and contracted), on
solo12 (floating: four legs on a body) and on a tree written here, fixed and floating (three
branches, one on another branch, prismatic joints, skewed axes, inertias off the axes); the counts
it states equal the operators printed in each piece. A tree too small for them keeps the scalar program. Tolerance per state:
|ours - Pinocchio| <= 1e-12 * max(1, max |Pinocchio's value|) per output."""
from __future__ import annotations

import ctypes
import json
import re

import numpy as np
import pytest

from kindyngen.codegen.pipeline import generate
from kindyngen.readers.urdf import TWO_PENDULUMS, load_urdf, parse_urdf
from kindyngen.runtime.evaluate import compile_shared_library
from tests.codegen.test_count_report import c_function_body, count_c_operations
from tests.reference import random_tree_state
from tests.robot_files import example_robot_data_or_skip

pin = pytest.importorskip("pinocchio")

from tests.algorithms.test_tree_derivatives import pinocchio_tree  # noqa: E402

N, TOLERANCE = 20, 1e-12


def _branch(name: str, parent: str, joints) -> str:
    """URDF links and joints of one branch: (type, xyz, rpy, axis) per joint."""
    out, above = [], parent
    for k, (kind, xyz, rpy, axis) in enumerate(joints):
        link = f"{name}{k}"
        mass = 0.4 + 0.3 * k
        out.append(f"""
  <link name="{link}"><inertial><origin xyz="0.02 {0.01 * k} 0.1" rpy="0.3 0.1 -0.2"/><mass value="{mass}"/>
    <inertia ixx="{0.01 + 0.002 * k}" ixy="0.001" ixz="-0.0005" iyy="0.012" iyz="0.0007" izz="0.008"/></inertial></link>
  <joint name="{link}_joint" type="{kind}"><parent link="{above}"/><child link="{link}"/>
    <origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/><limit lower="-2" upper="2" effort="10" velocity="3"/></joint>""")
        above = link
    return "".join(out)


REVOLUTE, PRISMATIC = "revolute", "prismatic"
THREE_BRANCHES = f"""<?xml version="1.0"?>
<robot name="three_branches">
  <link name="body"><inertial><origin xyz="0.01 -0.02 0.03"/><mass value="5"/>
    <inertia ixx="0.2" ixy="0.01" ixz="0.0" iyy="0.3" iyz="-0.02" izz="0.25"/></inertial></link>
{_branch("a", "body", [(REVOLUTE, "0.2 0 0", "0 0 0", "0 0 1"), (REVOLUTE, "0 0.1 0.3", "0.2 0 0", "0 1 0"),
                       (PRISMATIC, "0 0 0.2", "0 0.3 0", "0.6 0 0.8"), (REVOLUTE, "0.1 0 0.2", "0 0 0.5", "1 0 0"),
                       (REVOLUTE, "0 0 0.15", "0 0 0", "0 0.6 0.8")])}
{_branch("b", "body", [(REVOLUTE, "-0.2 0 0", "0 0 1", "1 0 0"), (PRISMATIC, "0 0 0.1", "0 0 0", "0 0 1"),
                       (REVOLUTE, "0 0.2 0", "0.4 0 0", "0 1 0"), (REVOLUTE, "0.1 0.1 0.1", "0 0 0", "0.8 0 0.6")])}
{_branch("c", "a1", [(REVOLUTE, "0 0.2 0.1", "0 0 0.3", "0 0 1"), (REVOLUTE, "0 0 0.2", "0 0.2 0", "1 0 0"),
                     (REVOLUTE, "0.1 0 0", "0 0 0", "0 1 0")])}
</robot>
"""


def _solo12():
    return load_urdf(example_robot_data_or_skip() / "solo_description" / "robots" / "solo12.urdf", tree=True,
                     floating_base=True)


CASES = {"solo12-floating": _solo12,
         "three_branches-floating": lambda: parse_urdf(THREE_BRANCHES, floating_base=True),
         "three_branches-fixed": lambda: parse_urdf(THREE_BRANCHES, tree=True)}


@pytest.fixture(scope="module", params=sorted(CASES))
def generated(request, tmp_path_factory):
    tree = CASES[request.param]()
    assert not tree.is_chain
    folder = generate(tree, tmp_path_factory.mktemp(request.param), languages=("c",), progress=False,
                      only={"tau_derivatives"})
    spec = json.loads((folder / "functions.json").read_text())["functions"][0]
    return tree, spec, folder


@pytest.mark.parametrize("flags", [("-O0",), ("-O3", "-march=native")], ids=["O0", "O3-native"])
def test_joint_loops_equal_pinocchio(generated, flags):
    tree, spec, folder = generated
    assert "c_loops" in spec["opcount"]                    # the single call runs joint loops
    lib = ctypes.CDLL(str(compile_shared_library(folder / "c", tree.identifier, flags)))
    fn = getattr(lib, spec["c_symbol"])
    fn.restype = None
    model = pinocchio_tree(tree)
    data = model.createData()
    rng = np.random.default_rng(46)
    nv = tree.nv
    for _ in range(N):
        q, qd, qdd, _ = random_tree_state(tree, rng)
        outs = [np.zeros(nv * nv), np.zeros(nv * nv)]
        fn(*[np.ascontiguousarray(a, dtype=float).ctypes.data_as(ctypes.c_void_p) for a in (q, qd, qdd)],
           *[o.ctypes.data_as(ctypes.c_void_p) for o in outs])
        pin.computeRNEADerivatives(model, data, q, qd, qdd)
        for name, ours, ref in zip(("dtau_dq", "dtau_dqd"), outs, (data.dtau_dq, data.dtau_dv)):
            error = np.max(np.abs(ours.reshape(nv, nv) - ref))
            assert error <= TOLERANCE * max(1.0, np.max(np.abs(ref))), (name, error)


PIECE = re.compile(r"^    /\* (once|body|columns|joint|lower|upper|row|root): .*?\*/\n(.*?)(?=^    /\* |\Z)", re.S | re.M)


def _statements(text: str) -> str:
    """The statements of a piece without loop headers, braces and index arithmetic."""
    lines = [line for line in text.splitlines()
             if line.strip() and not line.strip().startswith(("for (", "{", "}", "/*"))]
    return "\n".join(re.sub(r"(?<!sin_q)(?<!cos_q)\[[^\[\]]*\]", "[0]", line) for line in lines)


def test_joint_loop_counts_equal_the_operators_printed(generated):
    tree, spec, folder = generated
    parts = spec["opcount"]["c_loops"]["parts"]
    body = c_function_body((folder / "c" / f"{tree.identifier}.c").read_text(), spec["c_symbol"])
    printed = {m.group(1): count_c_operations(_statements(m.group(2))) for m in PIECE.finditer(body)}
    assert set(printed) == set(parts) - {"sums"}
    for piece, counted in printed.items():
        assert counted == {k: parts[piece][k] for k in ("add", "mul", "call")}, piece
    edges = sum(1 for p in tree.parents if p >= 0 or tree.floating_base)
    assert parts["sums"]["add"] == edges * 43
    executed = {k: sum(p[k] * p["runs"] for p in parts.values()) for k in ("add", "mul", "call")}
    assert executed == spec["opcount"]["c_loops"]["executed"]
    report = (folder / "opcounts.md").read_text()
    assert "| tau_derivatives | executed | {add} / {mul} / {call} | |".format(**executed) in report


def test_a_small_tree_keeps_the_scalar_program(tmp_path):
    tree = parse_urdf(TWO_PENDULUMS, floating_base=True)
    folder = generate(tree, tmp_path, languages=("c",), progress=False, only={"tau_derivatives"})
    spec = json.loads((folder / "functions.json").read_text())["functions"][0]
    assert "c_loops" not in spec["opcount"]
    assert "joint loops" not in (folder / "c" / f"{tree.identifier}.c").read_text()


def test_no_lanes_prints_the_scalar_program(tmp_path):
    tree = parse_urdf(THREE_BRANCHES, floating_base=True)
    folder = generate(tree, tmp_path, languages=("c",), progress=False, only={"tau_derivatives"}, lanes=False)
    spec = json.loads((folder / "functions.json").read_text())["functions"][0]
    source = (folder / "c" / f"{tree.identifier}.c").read_text()
    assert "c_loops" not in spec["opcount"] and "kdg_table" not in source
    assert "joint loops instead" not in (folder / "c" / f"{tree.identifier}.h").read_text()
