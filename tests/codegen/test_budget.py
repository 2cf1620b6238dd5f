"""The estimate and the limits of a run (kindyngen/codegen/budget.py): its table is the
measurement it cites (benchmarks/results/generation_cost.json), every function that grows with
the robot has a cost, the robots the project generates (the shipped arms, the G1 humanoid) stay
whole, and a long chain leaves out what its cost rules out."""
from __future__ import annotations

import json

import pytest

from kindyngen.codegen.budget import (COSTS, CPU_LIMIT_S, MEMORY_LIMIT_MB, LimitError, estimate, plan,
                                      power_law)
from kindyngen.codegen.catalog import BUILDERS, applicable_names
from kindyngen.readers.yaml_description import load_robot
from benchmarks.generation_cost import TREE_FUNCTIONS, write_chain
from tests.harness import ROOT
from tests.robot_files import example_robot_data_or_skip

RESULTS = ROOT / "benchmarks" / "results" / "generation_cost.json"


def test_the_table_is_the_measurement():
    result = json.loads(RESULTS.read_text())
    expected = {}
    for kind, suffix in (("chain", ""), ("tree", " (world frame)")):
        for name, entry in result[kind].items():
            rows = entry["rows"]
            expected[name + suffix] = (tuple(r["nv"] for r in rows), tuple(r["cpu_s"] for r in rows),
                                       tuple(r["peak_mb"] for r in rows),
                                       entry["failed"]["size"] if entry["failed"] else None)
    table = {name: (c.sizes, c.cpu_s, c.peak_mb, c.failed) for name, c in COSTS.items()}
    assert table == expected


def test_every_function_that_grows_has_a_cost():
    # every function a chain or a tree can get, but the closed-form IK (7 joints, no more) and a
    # closed mechanism's loop functions (catalog.LOOP_FUNCTIONS, not in BUILDERS)
    assert set(COSTS) == ({n for n, _ in BUILDERS if n not in ("ik_hom", "ik_dq")}
                          | {f"{n} (world frame)" for n in TREE_FUNCTIONS})


def test_between_and_beyond_the_measured_sizes():
    # straight on log-log axes: halfway (geometrically) between 10 -> 1 and 40 -> 16 is 20 -> 4
    assert power_law((10, 40), (1.0, 16.0), 20) == pytest.approx(4.0)
    # beyond: the last power, never below 1 (a size never gets cheaper)
    assert power_law((10, 20), (4.0, 2.0), 40) == pytest.approx(4.0)
    assert power_law((10, 20), (1.0, 8.0), 40) == pytest.approx(64.0)


@pytest.mark.parametrize("name", ["lwr4", "panda", "lwr4_hartl"])
def test_the_shipped_arms_get_every_function(name):
    model = load_robot(ROOT / "robots" / f"{name}.yaml")
    names = applicable_names(model)
    chosen = plan(model, names, asked=True)           # asked: anything above a limit would raise
    assert chosen.names == names and chosen.notes(name) == []


def test_the_g1_humanoid_gets_every_function():
    path = example_robot_data_or_skip() / "g1_description" / "urdf" / "g1_29dof_rev_1_0.urdf"
    model = load_robot(path, tree=True, floating_base=True)
    names = applicable_names(model)
    chosen = plan(model, names, asked=True)
    assert chosen.names == names and "fd_derivatives" in names
    assert len(chosen.notes(model.name)) == 1            # the estimate only (35 degrees of freedom)


def test_a_long_chain_leaves_out_what_is_above_the_limits(tmp_path):
    model = load_robot(write_chain(40, tmp_path))
    names = applicable_names(model)
    chosen = plan(model, names, asked=False)
    left = {e.name for e in chosen.left_out}
    assert left and set(chosen.names) == set(names) - left
    for e in chosen.estimates:
        cost = COSTS[e.name]
        over = e.cpu_s > CPU_LIMIT_S or e.peak_mb > MEMORY_LIMIT_MB or (cost.failed is not None and cost.failed <= 40)
        assert (e.name in left) == over, e
    with pytest.raises(LimitError, match="--allow-large") as refused:
        plan(model, names, asked=True)
    assert all(name in str(refused.value) for name in left)
    assert plan(model, names, asked=True, allow_large=True).names == names
    assert estimate("fk_hom", 40).within_limit


def test_a_bundle_member_above_its_limit_is_refused_whatever_the_selection(tmp_path):
    model = load_robot(write_chain(20, tmp_path))     # fd_derivatives did not finish at 20 joints
    assert not estimate("fd_derivatives", 20).within_limit
    with pytest.raises(LimitError, match="fd_derivatives: did not finish at 20"):
        plan(model, ("fk_hom",), asked=True, required=("fk_hom", "fd_derivatives"))
    with pytest.raises(LimitError, match="fd_derivatives"):      # left out of the selection, a bundle needs it
        plan(model, applicable_names(model), asked=False, required=("fd_derivatives",))
    chosen = plan(model, ("fk_hom",), asked=True, required=("fd_derivatives",), allow_large=True)
    assert chosen.names == ("fk_hom",)
