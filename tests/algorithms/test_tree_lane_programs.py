"""The lane programs of the trees' forward-dynamics derivatives (kindyngen.algorithms.derivatives_world_frame,
``_solved_rows``): the C single calls of ``fd_derivatives`` and ``fd_derivatives_no_minv`` of a
tree print a loop over lanes (lane l: row l of M^-1 from the tree-sparse factor, then row l
of dqdd/dq and dqdd/dqd from the world-frame terms), whose counts equal the operators printed
once and in the loop, and whose results equal Pinocchio's computeABADerivatives (ddq_dq,
ddq_dv, Minv) at random states, built unoptimised and as a user builds it (-O3
-march=native, where the loop is vectorised and contracted), on a floating tree (two
pendulums on a free body), the fixed and floating ``tests/data/urdf/mobile_slider_tree.urdf``
(a prismatic joint, a skewed axis). Tolerance per state: |ours - Pinocchio| <= 1e-12 *
max(1, max |Pinocchio's value|) per output."""
from __future__ import annotations

import ctypes
import json

import numpy as np
import pytest

from kindyngen.codegen.pipeline import generate
from kindyngen.readers.urdf import TWO_PENDULUMS, load_urdf, parse_urdf
from kindyngen.runtime.evaluate import compile_shared_library
from tests.codegen.test_count_report import c_function_body, count_c_operations
from tests.codegen.test_lane_programs import split_body
from tests.harness import ROOT
from tests.reference import random_tree_state

pin = pytest.importorskip("pinocchio")

from tests.algorithms.test_tree_derivatives import pinocchio_tree  # noqa: E402

FUNCTIONS = ("fd_derivatives", "fd_derivatives_no_minv")
N, TOLERANCE = 40, 1e-12
CASES = {"two_pendulums-floating": lambda: parse_urdf(TWO_PENDULUMS, floating_base=True),
         "mobile_slider_tree-fixed": lambda: load_urdf(ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf",
                                                       tree=True),
         "mobile_slider_tree-floating": lambda: load_urdf(ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf",
                                                          tree=True, floating_base=True)}


@pytest.fixture(scope="module", params=sorted(CASES))
def generated(request, tmp_path_factory):
    tree = CASES[request.param]()
    assert not tree.is_chain
    folder = generate(tree, tmp_path_factory.mktemp(request.param), languages=("c",), progress=False,
                      only=set(FUNCTIONS))
    return tree, json.loads((folder / "functions.json").read_text()), folder


def test_tree_lane_counts_equal_the_operators_of_the_generated_c(generated):
    tree, manifest, folder = generated
    source = (folder / "c" / f"{tree.identifier}.c").read_text()
    for spec in manifest["functions"]:
        entry = spec["opcount"]["c_lanes"]
        once, loop, lanes = split_body(c_function_body(source, spec["c_symbol"]))
        once = once.split("int kdg_lane;\n", 1)[1]    # the statements after the sincos kernel's call
        assert entry["used"] == tree.nv and lanes == entry["lanes"] == -(-tree.nv // 4) * 4, spec["name"]
        assert count_c_operations(once) == entry["uniform"], spec["name"]
        assert count_c_operations(loop) == {**entry["per_lane"], "call": 0}, spec["name"]


def _call(lib, spec, arrays):
    fn = getattr(lib, spec["c_symbol"])
    fn.restype = None
    outs = [np.zeros(int(np.prod(p["shape"]))) for p in spec["outputs"]]
    fn(*[np.ascontiguousarray(a, dtype=float).ctypes.data_as(ctypes.c_void_p) for a in arrays],
       *[o.ctypes.data_as(ctypes.c_void_p) for o in outs])
    return {p["name"]: o.reshape(p["shape"]) for p, o in zip(spec["outputs"], outs)}


@pytest.mark.parametrize("flags", [("-O0",), ("-O3", "-march=native")], ids=["O0", "O3-native"])
def test_tree_lane_c_equals_pinocchio(generated, flags):
    tree, manifest, folder = generated
    assert all("c_lanes" in spec["opcount"] for spec in manifest["functions"])   # the single calls print lanes
    lib = ctypes.CDLL(str(compile_shared_library(folder / "c", tree.identifier, flags)))
    model = pinocchio_tree(tree)
    data = model.createData()
    rng = np.random.default_rng(45)
    worst = {}
    for _ in range(N):
        q, qd, _, tau = random_tree_state(tree, rng)
        pin.computeABADerivatives(model, data, q, qd, tau)
        expected = {"dqdd_dq": data.ddq_dq.copy(), "dqdd_dqd": data.ddq_dv.copy(),
                    "Minv": np.triu(data.Minv) + np.triu(data.Minv, 1).T}
        for spec in manifest["functions"]:
            got = _call(lib, spec, [q, qd, tau])
            assert set(got) == ({"dqdd_dq", "dqdd_dqd", "Minv"} if spec["name"] == "fd_derivatives"
                                else {"dqdd_dq", "dqdd_dqd"})
            for name, value in got.items():
                error = float(np.abs(value - expected[name]).max() / max(1.0, np.abs(expected[name]).max()))
                key = f"{spec['name']}.{name}"
                worst[key] = max(worst.get(key, 0.0), error)
    print(tree.name, flags, {k: f"{v:.1e}" for k, v in worst.items()})
    assert all(v <= TOLERANCE for v in worst.values()), worst
