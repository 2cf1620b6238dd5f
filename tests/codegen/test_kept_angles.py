"""A URDF read with its angles as written (``--keep-angles``): example-robot-data's UR5, whose
right angles are written 1.57079632679 (4.9e-12 rad off pi/2), so sin and cos of them have no
closed form and every constant computed from them is inexact.

Its constants are held as the exact rationals of their doubles (``geometry.constant``): the
derived DAGs hold no symengine RealDouble, whose hash (the low 32 bits of the double) made
c*X and -c*X alike and symengine's CSE of fd_derivatives compare such nodes structurally,
unshared, for ever (it never finished before). fd_derivatives is generated, costs at most
RATIO times the operations of the same arm with its angles snapped to pi/2 (measured 1.19x:
the kept angles' 4.9e-12 couplings are real terms), and equals Pinocchio's
computeABADerivatives on Pinocchio's own parse of the URDF (which uses the values as written)
at random states, in the C (its lane program) and in Python (the scalar program)."""
from __future__ import annotations

import json

import numpy as np
import pytest
import symengine as se

from kindyngen.codegen.catalog import derive_all
from kindyngen.codegen.pipeline import build_programs, generate
from kindyngen.readers.yaml_description import load_robot
from kindyngen.runtime.evaluate import load_generated
from tests.robot_files import example_robot_data_or_skip

pin = pytest.importorskip("pinocchio")

RATIO = 1.25            # kept over snapped, additions + multiplications after CSE
TOLERANCE = 1e-9        # relative to the largest |reference entry| (at least 1)
STATES = 20


def _ur5():
    return example_robot_data_or_skip() / "ur_description" / "urdf" / "ur5_robot.urdf"


def _real_doubles(exprs) -> int:
    """How many distinct se.RealDouble nodes the DAG of ``exprs`` holds."""
    seen, stack, found = set(), list(exprs), 0
    while stack:
        e = stack.pop()
        if e in seen:
            continue
        seen.add(e)
        found += isinstance(e, se.RealDouble)
        stack.extend(e.args)
    return found


@pytest.fixture(scope="module")
def kept(tmp_path_factory):
    path = _ur5()
    model = load_robot(path, snap_angles=False, tip="tool0")
    assert not [n for n in model.notes if "--keep-angles" in n]      # nothing snapped (the limits' note stays)
    (function,) = derive_all(model, only={"fd_derivatives"})
    sweep = function.lanes
    exprs = [e for port in function.output_exprs for e in port] + list(sweep.exprs) + [e for _, e in sweep.stages]
    # checked before CSE: with a RealDouble in the DAG, the CSE below does not return (and
    # counted apart from the assert, whose report would print the expressions as trees)
    found = _real_doubles(exprs)
    assert found == 0, f"{found} RealDouble constants in fd_derivatives"
    folder = generate(model, tmp_path_factory.mktemp("ur5_kept"), languages=("c", "python"), progress=False,
                      only={"fd_derivatives"})
    return path, model, folder


def test_kept_angles_fd_derivatives_costs_about_what_the_snapped_arm_costs(kept):
    path, _, folder = kept
    after = json.loads((folder / "opcounts.json").read_text())["fd_derivatives"]["after"]
    (snapped,) = build_programs(load_robot(path, tip="tool0"), only={"fd_derivatives"}, progress=False)
    kept_ops, snapped_ops = after["add"] + after["mul"], snapped.after.add + snapped.after.mul
    assert kept_ops <= RATIO * snapped_ops, (kept_ops, snapped_ops)


@pytest.mark.parametrize("lang", ["c", "python"])
def test_kept_angles_fd_derivatives_equal_pinocchio(kept, lang):
    path, model, folder = kept
    pm = pin.buildModelFromUrdf(str(path))
    pd = pm.createData()
    assert [pm.names[k] for k in range(1, pm.njoints)] == [j.name for j in model.joints]
    rng = np.random.default_rng(42)
    n = model.n
    Q = rng.uniform(model.lower, model.upper, size=(STATES, n))
    QD, TAU = rng.uniform(-2, 2, (STATES, n)), rng.uniform(-20, 20, (STATES, n))
    out = load_generated(folder, lang).call("fd_derivatives", {"q": Q, "qd": QD, "tau": TAU})
    for k in range(STATES):
        ref_dq, ref_dqd, ref_minv = (np.array(a) for a in pin.computeABADerivatives(pm, pd, Q[k], QD[k], TAU[k]))
        ref_minv = np.triu(ref_minv) + np.triu(ref_minv, 1).T
        for ours, ref in ((out["dqdd_dq"][k], ref_dq), (out["dqdd_dqd"][k], ref_dqd), (out["Minv"][k], ref_minv)):
            assert np.abs(ours - ref).max() <= TOLERANCE * max(1.0, np.abs(ref).max())
