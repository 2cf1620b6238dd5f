"""Tree dynamics derivatives (kindyngen.algorithms.derivatives_world_frame, world-frame formulation) equal
Pinocchio's computeRNEADerivatives / computeABADerivatives (ddq_dq, ddq_dv, Minv), fixed and
floating base, on ``tests/data/urdf/mobile_slider_tree.urdf`` (a prismatic lift carrying an
arm beside a leg, a skewed continuous joint), on Solo12 (example-robot-data, floating base) and on
the LWR IV+ wrapped as a one-branch tree.

Python code on all, C code on the floating tree. Pinocchio's model is built here from the tree's joint placements and link inertias (floats),
sharing nothing with the derivation but the description. Tolerance per state: |ours -
Pinocchio| <= 1e-9 * max(1, max |Pinocchio's value|), 50 random states.
"""
from __future__ import annotations

import importlib.metadata
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from kindyngen.codegen.optimize import optimize
from kindyngen.codegen.render import RENDERERS
from kindyngen.codegen.interface import manifest
from kindyngen.runtime.evaluate import load_generated
from kindyngen.readers.yaml_description import load_robot
from kindyngen.algorithms.derivatives_world_frame import fd_derivatives_tree, tau_derivatives_tree
from kindyngen.model.robot_model import Frame, RobotModel
from kindyngen.readers.urdf import load_urdf

pin = pytest.importorskip("pinocchio")

from tests.reference import random_tree_state  # noqa: E402

ROOT = Path(__file__).resolve().parents[1].parent
N, TOLERANCE = 50, 1e-9


def arm_as_tree(robot) -> RobotModel:
    """A serial arm read as the tree whose parent of joint j is j - 1 (no joint effects: the
    world-frame derivatives of a tree carry none)."""
    joints = tuple(replace(joint, friction=None, armature=None) for joint in robot.joints)
    return replace(robot, name=robot.name + "_tree", convention="tree", joints=joints, payload=None,
                   frames=(Frame("tip", robot.n - 1),), base_name="base")


def _se3(placement) -> "pin.SE3":
    R, p = placement.matrix()
    return pin.SE3(np.array(R.evalf(), float), np.array(p.evalf(), float).ravel())


def _inertia(link) -> "pin.Inertia":
    ixx, iyy, izz, ixy, ixz, iyz = (float(v) for v in link.inertia)
    return pin.Inertia(float(link.mass), np.array([float(c) for c in link.com]),
                       np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]))


def pinocchio_tree(tree: RobotModel):
    """pin.Model of the tree: joint j on its parent's joint (placement ``after_parent * before
    * motion(offset)``), its link's inertia placed by ``after``."""
    model = pin.Model()
    model.gravity = pin.Motion(np.array([float(g) for g in tree.gravity]), np.zeros(3))
    root = 0
    if tree.floating_base:
        root = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
        model.appendBodyToJoint(root, _inertia(tree.root), pin.SE3.Identity())
    ids = []
    for joint, parent in zip(tree.joints, tree.parents):
        above = _se3(tree.joints[parent].after) if parent >= 0 else pin.SE3.Identity()
        offset = float(joint.offset)
        if joint.prismatic:
            motion, kind = pin.SE3(np.eye(3), np.array([0, 0, offset])), pin.JointModelPZ()
        else:
            motion, kind = pin.SE3(pin.utils.rotate("z", offset), np.zeros(3)), pin.JointModelRZ()
        jid = model.addJoint(ids[parent] if parent >= 0 else root, kind, above * _se3(joint.before) * motion,
                             joint.name or f"j{len(ids)}")
        model.appendBodyToJoint(jid, _se3(joint.after).act(_inertia(tree.links[len(ids)])), pin.SE3.Identity())
        ids.append(jid)
    return model


def _library(tmp_path, tree, functions, lang):
    programs = [optimize(f) for f in functions]
    for filename, text in RENDERERS[lang](tree, programs).items():
        (tmp_path / lang).mkdir(exist_ok=True)
        (tmp_path / lang / filename).write_text(text)
    (tmp_path / "functions.json").write_text(json.dumps(manifest(tree, programs, "numeric")))
    return load_generated(tmp_path, lang)


def _error(got, expected):
    return float(np.abs(got - expected).max() / max(1.0, np.abs(expected).max()))


# the C (compiled at -O0) on one case, the Python on all: the renderers are generic over the ports
CASES = [("mobile_slider_tree", False, "python"), ("mobile_slider_tree", True, "c"), ("lwr4", False, "python"),
         ("solo12", True, "python")]


@pytest.mark.parametrize("key,floating,lang", CASES,
                         ids=[f"{k}-{'floating' if f else 'fixed'}-{lang}" for k, f, lang in CASES])
def test_tree_derivatives_equal_pinocchio(key, floating, lang, tmp_path):
    if key == "lwr4":
        tree = arm_as_tree(load_robot(ROOT / "robots" / "lwr4.yaml"))
    elif key == "solo12":
        try:
            dist = importlib.metadata.distribution("example-robot-data")
        except importlib.metadata.PackageNotFoundError:
            pytest.skip("example-robot-data is not installed")
        path = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots/solo_description/robots/solo12.urdf"))
        tree = load_urdf(path, tree=True, floating_base=floating)
    else:
        tree = load_urdf(ROOT / "tests" / "data" / "urdf" / f"{key}.urdf", tree=True, floating_base=floating)
    functions = [tau_derivatives_tree(tree), fd_derivatives_tree(tree), fd_derivatives_tree(tree, "fd_der_no_minv", False)]
    library = _library(tmp_path, tree, functions, lang)
    model = pinocchio_tree(tree)
    data = model.createData()
    rng = np.random.default_rng(30)
    errors = {}
    for _ in range(N):
        q, qd, qdd, tau = random_tree_state(tree, rng)
        pq = q.copy()
        pin.computeRNEADerivatives(model, data, pq, qd, qdd)
        expected = {"tau_derivatives": {"dtau_dq": data.dtau_dq.copy(), "dtau_dqd": data.dtau_dv.copy()}}
        pin.computeABADerivatives(model, data, pq, qd, tau)
        Minv = np.triu(data.Minv) + np.triu(data.Minv, 1).T
        fd = {"dqdd_dq": data.ddq_dq.copy(), "dqdd_dqd": data.ddq_dv.copy()}
        expected["fd_derivatives"] = {**fd, "Minv": Minv}
        expected["fd_der_no_minv"] = fd
        inputs = {"tau_derivatives": {"q": q[None], "qd": qd[None], "qdd": qdd[None]}}
        inputs["fd_derivatives"] = inputs["fd_der_no_minv"] = {"q": q[None], "qd": qd[None], "tau": tau[None]}
        for function, outputs in expected.items():
            got = library.call(function, inputs[function])
            for name, value in outputs.items():
                key_ = f"{function}.{name}"
                errors[key_] = max(errors.get(key_, 0.0), _error(got[name][0], value))
    print(key, floating, {k: f"{v:.1e}" for k, v in errors.items()})
    bad = {k: v for k, v in errors.items() if not v <= TOLERANCE}
    assert not bad, bad
