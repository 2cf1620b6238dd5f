"""The catalog decides by structure, not by how a file was read: a fixed-base unbranched
chain read as a tree gets exactly the functions the same chain read as an arm gets (the
dual-quaternion, Lagrange and regressor routes, S, com, fd_derivatives_no_minv), with the same
values; a branched tree or a floating base gets none of the chain-only routes.

Robot: ``tests/data/urdf/slider_arm.urdf`` (a prismatic lift, a fixed sensor block inside the
chain, a fixed tool link with mass), read as an arm (flange: the tool link) and as a tree with
the tool link as its one frame of interest. Values at 5 random states, evaluated straight
from the derivations (symengine); both reads' Y times their base values equal the arm's tau.
Pinocchio checks each route on arms elsewhere (tests/algorithms/).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import symengine as se

from kindyngen.algorithms.regressors import base_params_document
from kindyngen.codegen.catalog import TREE_NAMES, derive_all
from kindyngen.readers.urdf import load_urdf

DATA = Path(__file__).resolve().parents[1] / "data" / "urdf"


def _values(function, inputs: dict) -> dict:
    args = [s for syms in function.input_symbols for s in syms]
    fn = se.Lambdify(args, [e for exprs in function.inlined_outputs() for e in exprs], cse=True)
    row = np.concatenate([np.ravel(inputs[p.name]) for p in function.inputs])
    flat, out, start = np.ravel(fn(row)), {}, 0
    for port in function.outputs:
        out[port.name] = flat[start:start + port.size]
        start += port.size
    return out


def _quaternion_product(p, q):
    """Hamilton product of (w, x, y, z) quaternions."""
    return np.array([p[0] * q[0] - p[1:] @ q[1:], *(p[0] * q[1:] + q[0] * p[1:] + np.cross(p[1:], q[1:]))])


def test_chain_read_as_tree_gets_the_arm_functions_with_the_same_values():
    path = DATA / "slider_arm.urdf"
    arm = load_urdf(path)
    tree = load_urdf(path, tree=True, frames=["tool"])
    assert tree.is_tree and tree.is_chain and not arm.is_tree
    arm_functions = {f.name: f for f in derive_all(arm)}
    tree_functions = {f.name: f for f in derive_all(tree)}
    assert set(tree_functions) == set(arm_functions)
    assert {"fk_dq", "S", "M_lagrange", "tau_dq", "Y_g", "Y_m", "Y_dq", "com",
            "fd_derivatives_no_minv"} <= set(tree_functions)
    for name in ("tau_derivatives", "fd_derivatives", "fd_derivatives_no_minv"):     # the chain's sweeps on both
        assert tree_functions[name].summary == arm_functions[name].summary
    rng = np.random.default_rng(11)
    for _ in range(5):
        state = {"q": rng.uniform(arm.lower, arm.upper), "qd": rng.uniform(-2, 2, arm.n),
                 "qdd": rng.uniform(-3, 3, arm.n), "tau": rng.uniform(-5, 5, arm.n)}
        for name, f in arm_functions.items():
            if name == "Y":       # base columns of either regressor: compared through tau below
                continue
            a, t = _values(f, state), _values(tree_functions[name], state)
            for port in a:
                assert np.allclose(t[port], a[port], rtol=1e-12, atol=1e-12), (name, port)
        tau = _values(arm_functions["tau"], state)["tau"]
        for model, functions in ((arm, arm_functions), (tree, tree_functions)):
            Y = _values(functions["Y"], state)["Y"].reshape(arm.n, -1)
            assert np.allclose(Y @ np.array(base_params_document(model)["Y"]["values"], float), tau, atol=1e-10)


def test_chain_flange_is_its_one_frame_on_the_last_link():
    """A chain read as a tree with its frame on the last link (default: the leaf joint's link)
    has fk_dq of that frame; with several frames of interest there is no flange and no flange
    functions, but the chain's dynamics routes stay."""
    path = DATA / "slider_arm.urdf"
    tree = load_urdf(path, tree=True)
    functions = {f.name: f for f in derive_all(tree, only={"fk_hom", "fk_dq"})}
    q = np.random.default_rng(4).uniform(tree.lower, tree.upper)
    T = _values(functions["fk_hom"], {"q": q})["T"].reshape(4, 4)
    x = _values(functions["fk_dq"], {"q": q})["x"]
    (w, a, b, c), dual = x[:4], x[4:]
    R = np.array([[1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b)],
                  [2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a)],
                  [2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)]])
    translation = 2 * _quaternion_product(dual, np.array([w, -a, -b, -c]))[1:]
    assert np.allclose(R, T[:3, :3], atol=1e-12) and np.allclose(translation, T[:3, 3], atol=1e-12)
    several = load_urdf(path, tree=True, frames=["tool", "forearm"])
    names = {f.name for f in derive_all(several, only={"fk_dq", "ik_dls", "S", "M_lagrange", "fk_hom"})}
    assert names == {"fk_hom", "S", "M_lagrange"}


def test_branched_or_floating_trees_get_no_chain_routes():
    for floating in (False, True):
        tree = load_urdf(DATA / "mobile_slider_tree.urdf", tree=True, floating_base=floating)
        assert not tree.is_chain and tree.flange_chain is None
        assert {f.name for f in derive_all(tree, only=set(TREE_NAMES) | {"fk_dq", "S"})} <= set(TREE_NAMES)
    floating_chain = load_urdf(DATA / "slider_arm.urdf", floating_base=True)
    assert not floating_chain.is_chain
    assert not {f.name for f in derive_all(floating_chain, only={"fk_dq", "S", "M_lagrange", "Y_g"})}


def test_chain_read_as_tree_with_symbolic_parameters():
    """The chain-only routes take p on a chain read as a tree as on the arm: same values at a
    random p (not the description's)."""
    path = DATA / "slider_arm.urdf"
    arm, tree = load_urdf(path), load_urdf(path, tree=True, frames=["tool"])
    only = {"tau", "S", "M_lagrange", "tau_dq", "fd_derivatives"}
    arm_functions = {f.name: f for f in derive_all(arm, "symbolic", only=only)}
    tree_functions = {f.name: f for f in derive_all(tree, "symbolic", only=only)}
    assert set(arm_functions) == set(tree_functions) == only
    rng = np.random.default_rng(12)
    p = np.concatenate([np.r_[rng.uniform(0.5, 2), rng.uniform(-0.1, 0.1, 3), 0.05, 0.001, 0.04, -0.002, 0.001, 0.03]
                        for _ in range(arm.n)])
    state = {"q": rng.uniform(arm.lower, arm.upper), "qd": rng.uniform(-2, 2, arm.n),
             "qdd": rng.uniform(-3, 3, arm.n), "tau": rng.uniform(-5, 5, arm.n), "p": p}
    for name, f in arm_functions.items():
        assert tree_functions[name].inputs[-1].name == "p"
        a, t = _values(f, state), _values(tree_functions[name], state)
        for port in a:
            assert np.allclose(t[port], a[port], rtol=1e-12, atol=1e-12), (name, port)
