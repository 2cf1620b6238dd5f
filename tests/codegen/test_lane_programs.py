"""The lane programs of the derivatives' C single calls (:class:`kindyngen.codegen.optimize.LaneProgram`):
the counts they report equal the operators of the C printed once and inside the loop over
lanes (by the tokenizer of tests/codegen/test_count_report.py, which knows nothing of the
counter); the lane C equals the scalar program that ``generate --no-lanes`` prints, at random
states, unoptimised and built as a user builds it (-O3 -march=native, where the loop is
vectorised and contracted); ``--no-lanes`` is recorded and prints no loop. That both equal
Pinocchio's derivatives is tests/algorithms/test_dynamics_derivatives.py's check of the C."""
from __future__ import annotations

import ctypes
import json
import re

import numpy as np
import pytest

from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot
from kindyngen.runtime.evaluate import compile_shared_library
from tests.codegen.test_count_report import c_function_body, count_c_operations, two_joint_report
from tests.harness import ROOT

FUNCTIONS = ("tau_derivatives", "fd_derivatives", "fd_derivatives_no_minv")
LOOP = re.compile(r"^    for \(kdg_lane = 0; kdg_lane < (\d+); \+\+kdg_lane\) \{\n(.*?)^    \}\n", re.S | re.M)


def split_body(body: str) -> tuple[str, str, int]:
    """(the statements before the lane loop, the loop's body, its lane count)."""
    match = LOOP.search(body)
    assert match, "no lane loop"
    return body[:match.start()], match.group(2), int(match.group(1))


@pytest.fixture(scope="module")
def two_joints():
    model, _, source, counts = two_joint_report(FUNCTIONS)
    return model, source, counts


def test_lane_counts_equal_the_operators_of_the_generated_c(two_joints):
    model, source, counts = two_joints
    for name in FUNCTIONS:
        once, loop, lanes = split_body(c_function_body(source, f"{model.identifier}_{name}"))
        entry = counts[name]["c_lanes"]
        assert lanes == entry["lanes"] == 4 and entry["used"] == 2, name
        assert count_c_operations(once) == entry["uniform"], name
        assert count_c_operations(loop) == {**entry["per_lane"], "call": 0}, name
        executed = {k: entry["uniform"][k] + lanes * entry["per_lane"][k] for k in ("add", "mul")}
        assert executed == {k: entry["executed"][k] for k in ("add", "mul")}, name
        assert entry["per_lane"]["add"] + entry["per_lane"]["mul"] > 0


def _library(folder, robot, flags):
    return ctypes.CDLL(str(compile_shared_library(folder / "c", robot, flags)))


def _call(lib, spec, arrays):
    fn = getattr(lib, spec["c_symbol"])
    fn.restype = None
    outs = [np.zeros(int(np.prod(p["shape"]))) for p in spec["outputs"]]
    fn(*[np.ascontiguousarray(a).ctypes.data_as(ctypes.c_void_p) for a in arrays],
       *[o.ctypes.data_as(ctypes.c_void_p) for o in outs])
    return np.concatenate(outs)


@pytest.fixture(scope="module")
def lwr4_both(tmp_path_factory):
    """lwr4's derivatives generated with and without lanes: (functions.json, folder) each."""
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    out = {}
    for lanes in (True, False):
        folder = generate(model, tmp_path_factory.mktemp(f"lanes_{lanes}"), languages=("c",), progress=False,
                          only=set(FUNCTIONS), lanes=lanes)
        out[lanes] = (json.loads((folder / "functions.json").read_text()), folder)
    return model, out


@pytest.mark.parametrize("flags", [("-O0",), ("-O3", "-march=native")])
def test_lane_c_equals_the_scalar_program(lwr4_both, flags):
    model, out = lwr4_both
    manifest, folder = out[True]
    scalar_manifest, scalar_folder = out[False]
    lanes, scalar = _library(folder, "lwr4", flags), _library(scalar_folder, "lwr4", ("-O0",))
    rng = np.random.default_rng(3)
    for spec, scalar_spec in zip(manifest["functions"], scalar_manifest["functions"]):
        assert spec["name"] == scalar_spec["name"] and "c_lanes" in spec["opcount"]
        worst = 0.0
        for _ in range(200):
            arrays = [rng.uniform(model.lower, model.upper), rng.uniform(-2, 2, model.n), rng.uniform(-20, 20, model.n)]
            got, want = _call(lanes, spec, arrays), _call(scalar, scalar_spec, arrays)
            worst = max(worst, float(np.abs(got - want).max() / max(1.0, np.abs(want).max())))
        assert worst <= 1e-12, (spec["name"], flags, worst)


def test_no_lanes_prints_the_scalar_program_and_says_so(lwr4_both):
    _, out = lwr4_both
    manifest, folder = out[False]
    source = (folder / "c" / "lwr4.c").read_text()
    header = (folder / "c" / "lwr4.h").read_text()
    assert manifest["c_lanes"] is False and "kdg_lane" not in source and "lane program" not in header
    assert all("c_lanes" not in f["opcount"] for f in manifest["functions"])
    manifest, folder = out[True]
    assert "c_lanes" not in manifest
    header = (folder / "c" / "lwr4.h").read_text()
    for f in manifest["functions"]:
        lanes = f["opcount"]["c_lanes"]
        assert (f"runs a lane program instead: {lanes['uniform']['add']} add, {lanes['uniform']['mul']} mul, "
                f"{lanes['uniform']['call']} call once, then {lanes['lanes']} lanes ({lanes['used']} kept)") in header
