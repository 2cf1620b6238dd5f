"""Trees with symbolic inertial parameters (``params="symbolic"``: the input p, 10 per body, a
floating base's root body first) equal Pinocchio with the same parameters.

Tree: ``tests/data/urdf/mobile_slider_tree.urdf`` (a prismatic lift carrying an arm beside a
leg, a skewed continuous joint), fixed and floating base. Pinocchio's model is built from
the tree's joint placements (tests/algorithms/test_tree_derivatives.py's ``pinocchio_tree``)
and every body then gets random inertial parameters (positive mass, a CoM off the origin, an
inertia with distinct principal moments on random axes): p is read back from Pinocchio's
``model.inertias`` (each moved from Pinocchio's joint frame into our link frame by the
description's ``after`` placement), so the derivation sees only numbers Pinocchio uses. M, g,
c, tau, fd (both routes), com, tau_derivatives and fd_derivatives are evaluated straight from
the derivation (symengine), 20 random states. Tolerance per state: |ours - Pinocchio| <= 1e-9
* max(1, max |Pinocchio's value|).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import symengine as se

from kindyngen.codegen.catalog import derive_all
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.readers.urdf import load_urdf
from tests.algorithms.test_tree_derivatives import _se3, pinocchio_tree

pin = pytest.importorskip("pinocchio")

from tests.reference import random_tree_state  # noqa: E402

TREE = Path(__file__).resolve().parents[1] / "data" / "urdf" / "mobile_slider_tree.urdf"
N, TOLERANCE = 20, 1e-9
FUNCTIONS = ("M", "g", "c", "tau", "fd", "com", "tau_derivatives", "fd_derivatives")


def random_inertia(rng) -> "pin.Inertia":
    """A rigid body: mass 0.5-3 kg, CoM within 0.1 m, principal moments 0.01-0.05 kg m^2 (the
    triangle inequality holds) on random axes."""
    axes, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    moments = rng.uniform(0.01, 0.05, 3)
    return pin.Inertia(rng.uniform(0.5, 3.0), rng.uniform(-0.1, 0.1, 3), axes @ np.diag(moments) @ axes.T)


def parameters_from_pinocchio(tree, model) -> np.ndarray:
    """p from Pinocchio's body inertias: the root body's (floating base, body 1, base frame)
    first, then each joint's, moved from its joint frame to its link frame."""
    first = 2 if tree.floating_base else 1
    out = [model.inertias[1].toDynamicParameters()] if tree.floating_base else []
    for j, joint in enumerate(tree.joints):
        out.append(_se3(joint.after).actInv(model.inertias[first + j]).toDynamicParameters())
    return np.concatenate(out)


def _lambdified(function):
    args = [s for syms in function.input_symbols for s in syms]
    return se.Lambdify(args, [e for exprs in function.inlined_outputs() for e in exprs], cse=True)


def _call(function, fn, inputs: dict) -> dict:
    row = np.concatenate([np.ravel(inputs[p.name]) for p in function.inputs])
    flat, out, start = np.ravel(fn(row)), {}, 0
    for port in function.outputs:
        out[port.name] = flat[start:start + port.size].reshape(port.shape)
        start += port.size
    return out


def pinocchio_values(model, data, q, qd, qdd, tau) -> dict:
    M = pin.crba(model, data, q)
    g = pin.computeGeneralizedGravity(model, data, q).copy()
    out = {"M": {"M": np.triu(M) + np.triu(M, 1).T}, "g": {"g": g},
           "c": {"c": pin.nonLinearEffects(model, data, q, qd) - g},
           "tau": {"tau": pin.rnea(model, data, q, qd, qdd).copy()},
           "fd": {"qdd": pin.aba(model, data, q, qd, tau).copy()}}
    out["com"] = {"com": pin.centerOfMass(model, data, q).copy(),
                  "J_com": pin.jacobianCenterOfMass(model, data, q).copy(),
                  "A_g": pin.computeCentroidalMap(model, data, q).copy()}
    pin.computeRNEADerivatives(model, data, q, qd, qdd)
    out["tau_derivatives"] = {"dtau_dq": data.dtau_dq.copy(), "dtau_dqd": data.dtau_dv.copy()}
    pin.computeABADerivatives(model, data, q, qd, tau)
    out["fd_derivatives"] = {"dqdd_dq": data.ddq_dq.copy(), "dqdd_dqd": data.ddq_dv.copy(),
                             "Minv": np.triu(data.Minv) + np.triu(data.Minv, 1).T}
    return out


@pytest.mark.parametrize("floating", [False, True], ids=["fixed", "floating"])
def test_symbolic_parameters_equal_pinocchio(floating):
    tree = load_urdf(TREE, tree=True, floating_base=floating)
    functions = {f.name: f for f in derive_all(tree, "symbolic", only=set(FUNCTIONS))}
    assert set(functions) == set(FUNCTIONS)
    bodies = tree.n + floating
    for f in functions.values():
        assert f.inputs[-1].name == "p" and f.inputs[-1].shape == (10 * bodies,)
        assert tuple(map(str, f.input_symbols[-1][:2])) == (("m0", "mx0") if floating else ("m1", "mx1"))
        assert "Inertial parameters: input p, 10 per body" in f.conventions
    model = pinocchio_tree(tree)
    rng = np.random.default_rng(2026)
    for k in range(1, model.njoints):
        model.inertias[k] = random_inertia(rng)
    data = model.createData()
    p = parameters_from_pinocchio(tree, model)
    assert not np.allclose(p, parameter_vector(tree))        # not the description's values
    fns = {name: _lambdified(f) for name, f in functions.items()}
    fd_aba = functions["fd"].alternatives[0]
    fns["fd_aba"], functions["fd_aba"] = _lambdified(fd_aba), fd_aba
    errors = {}
    for _ in range(N):
        q, qd, qdd, tau = random_tree_state(tree, rng)
        expected = pinocchio_values(model, data, q, qd, qdd, tau)
        expected["fd_aba"] = expected["fd"]
        inputs = {"q": q, "qd": qd, "qdd": qdd, "tau": tau, "p": p}
        for name, outputs in expected.items():
            got = _call(functions[name], fns[name], inputs)
            for port, value in outputs.items():
                err = float(np.abs(got[port] - value).max() / max(1.0, np.abs(value).max()))
                errors[f"{name}.{port}"] = max(errors.get(f"{name}.{port}", 0.0), err)
    print({k: f"{v:.1e}" for k, v in errors.items()})
    bad = {k: v for k, v in errors.items() if not v <= TOLERANCE}
    assert not bad, bad


@pytest.mark.parametrize("floating", [False, True], ids=["fixed", "floating"])
def test_p_is_pinocchios_inertias_of_the_urdf(floating):
    """The description's p (parameter_vector: the root body first) is Pinocchio's
    ``model.inertias[1:]`` of ``buildModelFromUrdf`` by toDynamicParameters, as the headers say."""
    tree = load_urdf(TREE, tree=True, floating_base=floating)
    model = (pin.buildModelFromUrdf(str(TREE), pin.JointModelFreeFlyer()) if floating
             else pin.buildModelFromUrdf(str(TREE)))
    p = np.concatenate([model.inertias[k].toDynamicParameters() for k in range(1, model.njoints)])
    assert p.shape == (10 * (tree.n + floating),)
    assert np.abs(p - parameter_vector(tree)).max() <= 1e-12


def test_description_parameters_give_the_numeric_build():
    """p = parameter_vector(tree) (the root body first) reproduces the baked-in numbers."""
    tree = load_urdf(TREE, tree=True, floating_base=True)
    symbolic = derive_all(tree, "symbolic", only={"tau"})[0]
    numeric = derive_all(tree, "numeric", only={"tau"})[0]
    rng = np.random.default_rng(3)
    quat = rng.standard_normal(4)
    state = {"q": np.r_[0.1, -0.2, 0.3, quat / np.linalg.norm(quat), rng.uniform(-0.5, 0.5, tree.n)],
             "qd": rng.uniform(-2, 2, tree.nv), "qdd": rng.uniform(-2, 2, tree.nv), "p": parameter_vector(tree)}
    a = _call(numeric, _lambdified(numeric), state)["tau"]
    b = _call(symbolic, _lambdified(symbolic), state)["tau"]
    assert np.abs(a - b).max() <= 1e-12 * max(1.0, np.abs(a).max())
