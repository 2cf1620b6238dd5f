"""The operation counts after CSE of every committed robot (generated/<robot>/opcounts.json)
against the committed ceiling tests/opcount_ceiling.json: no count of any function may rise
above it. Falls pass, with a warning to lower the table (``python tests/opcount_ceiling.py``);
a rise needs the table edited in the same commit. generated/ itself is held to a fresh
generation by tests/integration/test_reproducibility.py, so these are the counts of today's derivation."""
from __future__ import annotations

import warnings

import pytest

from tests.harness import GENERATED
from tests.opcount_ceiling import TABLE, ceiling, compare, generated_counts, lowered

URDF_ONLY = {"panda_urdf"}     # checked where it is derived: tests/readers/test_urdf_panda.py


def test_every_committed_robot_has_a_ceiling():
    robots = set(generated_counts(GENERATED))
    assert robots >= {"lwr4", "panda"}
    assert robots == set(ceiling()) - URDF_ONLY, f"{TABLE.name} and generated/ list different robots"


@pytest.mark.parametrize("robot", sorted(set(ceiling()) - URDF_ONLY))
def test_no_count_rises_above_the_ceiling(robot):
    counts = generated_counts(GENERATED).get(robot, {})
    rises, falls = compare(robot, counts, ceiling())
    assert not rises, "operation counts above tests/opcount_ceiling.json (edit it in this commit if " \
                      "the rise is wanted):\n" + "\n".join(rises)
    if falls:
        warnings.warn("counts fell; lower tests/opcount_ceiling.json (python tests/opcount_ceiling.py):\n"
                      + "\n".join(falls))


# -- the comparison itself, on a hand-made table --------------------------------------------
TABLE_A = {"arm": {"M": {"add": 10, "mul": 20}, "fd": {"add": 30, "mul": 40}}}


def test_a_rise_of_one_operation_fails_and_a_fall_passes():
    rises, falls = compare("arm", {"M": {"add": 11, "mul": 19}, "fd": {"add": 30, "mul": 40}}, TABLE_A)
    assert rises == ["arm.M.add: 11 > ceiling 10"] and falls == ["arm.M.mul: 19 < ceiling 20"]
    assert compare("arm", {"M": {"add": 10, "mul": 20}, "fd": {"add": 29, "mul": 40}}, TABLE_A)[0] == []


def test_new_dropped_or_unknown_functions_fail():
    rises, _ = compare("arm", {"M": {"add": 1, "mul": 1}, "Y": {"add": 1, "mul": 1}}, TABLE_A)
    assert rises == ["arm.Y: new function, not in opcount_ceiling.json",
                     "arm.fd: in opcount_ceiling.json but no longer generated"]
    assert compare("other", {}, TABLE_A)[0] == ["other: not in opcount_ceiling.json; add its counts"]


def test_lowering_never_raises():
    table = lowered(TABLE_A, "arm", {"M": {"add": 12, "mul": 5}, "Y": {"add": 1, "mul": 1}})
    assert table == {"arm": {"M": {"add": 10, "mul": 5}, "fd": {"add": 30, "mul": 40}}}
    assert TABLE_A["arm"]["M"]["mul"] == 20       # the input is left whole
