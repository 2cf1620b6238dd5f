"""kindyngen.algorithms.kinematics on its own: each requested frame's Jacobian equals central
differences of its pose from fk_hom (linear rows: d p / d q; angular rows: vee(dR R^T)), for
the mobile slider tree (a prismatic lift, a continuous elbow, two branches) with a fixed and a
floating base. A floating base is moved along its own axes (position R e_i h, rotation
R exp(h [e_i])), the twist in the base frame that its Jacobian columns stand for."""
from __future__ import annotations

import numpy as np
import pytest
import symengine as se
from scipy.spatial.transform import Rotation

from tests.harness import ROOT
from kindyngen.algorithms.kinematics import fk_hom_tree, jacobian_tree
from kindyngen.readers.urdf import load_urdf

URDF = ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf"
STEP = 1e-6
TOL = 1e-8          # central differences: error ~ step^2 * third derivative


def _numeric(f):
    """q -> the outputs of ``f`` (its named intermediates evaluated in order)."""
    inputs = list(f.input_symbols[0])
    stage_symbols = [s for s, _ in f.stages]
    args = inputs + stage_symbols
    stage_fns = [se.Lambdify(args, [e]) for _, e in f.stages]
    out_fn = se.Lambdify(args, list(f.output_exprs[0]))

    def call(q):
        values = np.concatenate([q, np.zeros(len(stage_symbols))])
        for k, fn in enumerate(stage_fns):
            values[len(inputs) + k] = np.asarray(fn(values)).ravel()[0]
        return np.asarray(out_fn(values), float).reshape(f.outputs[0].shape)
    return call


def _vee(W):
    return np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2


def _moved(model, q, k, h):
    """q moved by h along velocity coordinate k."""
    q = q.copy()
    if not model.floating_base:
        q[k] += h
        return q
    R = Rotation.from_quat(q[3:7])             # x, y, z, w: the layout of q[3:7]
    if k < 3:
        q[0:3] += R.as_matrix()[:, k] * h
    elif k < 6:
        q[3:7] = (R * Rotation.from_rotvec(np.eye(3)[k - 3] * h)).as_quat()
    else:
        q[k + 1] += h
    return q


@pytest.mark.parametrize("floating", (False, True), ids=("fixed", "floating"))
def test_jacobian_is_the_derivative_of_the_poses(floating):
    model = load_urdf(URDF, frames=("gripper_frame", "foot"), floating_base=floating)
    fk, jac = _numeric(fk_hom_tree(model)), _numeric(jacobian_tree(model))
    assert model.nv == model.nq - (1 if floating else 0) == (11 if floating else 5)
    rng = np.random.default_rng(4)
    for _ in range(3):
        q = rng.uniform(-1.5, 1.5, model.nq)
        if floating:
            q[3:7] = Rotation.random(random_state=rng.integers(1 << 30)).as_quat()
        J = jac(q)
        for k in range(model.nv):
            plus, minus = fk(_moved(model, q, k, STEP)), fk(_moved(model, q, k, -STEP))
            T = fk(q)
            for f in range(2):
                dp = (plus[f, :3, 3] - minus[f, :3, 3]) / (2 * STEP)
                dR = (plus[f, :3, :3] - minus[f, :3, :3]) / (2 * STEP)
                w = _vee(dR @ T[f, :3, :3].T)
                np.testing.assert_allclose(J[f, :3, k], dp, atol=TOL, err_msg=f"frame {f}, column {k}, linear")
                np.testing.assert_allclose(J[f, 3:, k], w, atol=TOL, err_msg=f"frame {f}, column {k}, angular")


def test_a_joint_off_the_branch_has_a_zero_column():
    model = load_urdf(URDF, frames=("gripper_frame", "foot"))
    J = _numeric(jacobian_tree(model))(np.random.default_rng(1).uniform(-1, 1, model.nq))
    on_gripper = set(model.ancestors(model.frames[0].body))
    on_foot = set(model.ancestors(model.frames[1].body))
    assert on_gripper and on_foot and not on_gripper & on_foot        # two branches from the chassis
    for j in range(model.nv):
        assert (np.abs(J[0, :, j]).max() == 0) == (j not in on_gripper), j
        assert (np.abs(J[1, :, j]).max() == 0) == (j not in on_foot), j
