"""An arm (read as an arm, not a tree) with mimic joints and joint effects: friction (smoothed
Coulomb), offsets and armature on every joint, the mimic joints' included, Stribeck friction on
an independent joint and a position ripple on a mimic one (its derivative in q through G).

The reduction folds the effects in as it folds the rigid bodies: ``tau_y = G^T (tau_x + effects
at G q + b, G qd, G qdd)``, the armature inside ``G^T M G``. References: the same description without the
mimic entries (every joint a coordinate; its functions are checked against Pinocchio and the
effect formulas elsewhere), generated and evaluated at ``(G q + b, G qd, G qdd)`` and contracted
with G here in numpy; fd by ``numpy.linalg.solve``; the derivatives by central finite
differences of the generated reduced ``tau`` and ``fd`` (no derivative code involved).
``ik_dls`` of the reduced arm reaches poses of its own fk_hom.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from kindyngen.codegen.catalog import NAMES
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import parse_robot
from kindyngen.runtime.evaluate import load_generated

LINK = {"mass": 1.2, "com": [0.05, 0.01, 0.1], "inertia": [0.012, 0.011, 0.003, 0.0002, 0, 0.0001]}
ARM = {"name": "mimic_arm", "dh": "none", "gravity": [0, 0, -9.81], "coulomb_smoothing": 0.05, "joints": [
    {"name": "a", "axis": [0, 0, 1], "lower": -2, "upper": 2,
     "friction": {"viscous": 0.3, "coulomb": 0.2, "offset": 0.05, "stribeck": 0.15, "stribeck_velocity": 0.1},
     "armature": 0.02},
    {"name": "b", "origin": {"xyz": [0, 0, 0.3]}, "axis": [0, 1, 0], "lower": -2, "upper": 2,
     "friction": {"viscous": 0.2, "coulomb": 0.1}, "armature": 0.01},
    {"name": "c", "origin": {"xyz": [0.3, 0, 0], "rpy": [0.2, 0, 0]}, "axis": [0, 1, 0], "lower": -2, "upper": 2,
     "friction": {"viscous": 0.1, "coulomb": 0.3, "offset": -0.02}, "armature": 0.03,
     "ripple": {"sin": 0.04, "cos": -0.03, "order": 6},
     "mimic": {"joint": "b", "multiplier": -0.5, "offset": 0.1}},
    {"name": "d", "origin": {"xyz": [0.25, 0, 0]}, "axis": [1, 0, 0], "lower": -2, "upper": 2,
     "friction": {"viscous": 0.05}, "armature": 0.005},
    {"name": "e", "type": "prismatic", "origin": {"xyz": [0.1, 0, 0]}, "axis": [1, 0, 0], "lower": 0, "upper": 0.1,
     "friction": {"viscous": 2.0, "coulomb": 1.0}, "armature": 0.1,
     "mimic": {"joint": "d", "multiplier": 0.02, "offset": 0.03}}],
    "links": [LINK] * 5}
G = np.array([[1, 0, 0], [0, 1, 0], [0, -0.5, 0], [0, 0, 1], [0, 0, 0.02]])
B = np.array([0, 0, 0.1, 0, 0.03])
FUNCTIONS = {"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com", "tau_derivatives", "fd_derivatives", "Y"}


@pytest.fixture(scope="module")
def libraries(tmp_path_factory):
    free = copy.deepcopy(ARM)
    for row in free["joints"]:
        row.pop("mimic", None)
    free["name"] = "free_arm"
    out = {}
    for key, data in (("reduced", ARM), ("free", free)):
        model = parse_robot(data, f"{key}.yaml")
        folder = generate(model, tmp_path_factory.mktemp(key), languages=("python",), progress=False,
                          only=FUNCTIONS | {"ik_dls"})
        out[key] = (model, folder, load_generated(folder, "python"))
    return out


def _states(rng, count=50):
    return (rng.uniform(-1.5, 1.5, (count, 3)), rng.uniform(-2, 2, (count, 3)), rng.uniform(-5, 5, (count, 3)),
            rng.uniform(-3, 3, (count, 3)))


def _relative(got, expected):
    return float(np.abs(got - expected).max() / np.abs(expected).max())


def test_functions_of_a_mimic_arm(libraries):
    """The arm keeps the tree functions in its 3 independent joints (not the chain-only routes):
    tau, M, g, c, fd, the Jacobian and the centre of mass equal the reduction of the free arm's."""
    model, folder, lib = libraries["reduced"]
    _, _, free = libraries["free"]
    assert (model.n, model.nv, model.is_tree) == (5, 3, False)
    assert set(lib.functions) == FUNCTIONS | {"ik_dls"} and "S" in NAMES
    Q, QD, QDD, TAU = _states(np.random.default_rng(7))
    X = Q @ G.T + B
    full = {name: free.call(name, inputs) for name, inputs in (
        ("tau", {"q": X, "qd": QD @ G.T, "qdd": QDD @ G.T}), ("M", {"q": X}), ("g", {"q": X}),
        ("c", {"q": X, "qd": QD @ G.T}), ("jacobian", {"q": X}), ("com", {"q": X}), ("fk_hom", {"q": X}))}
    bias = free.call("tau", {"q": X, "qd": QD @ G.T, "qdd": 0 * X})["tau"] @ G     # c + g + friction + offsets
    M = np.einsum("ia,nij,jb->nab", G, full["M"]["M"], G)
    checks = {
        "tau": (lib.call("tau", {"q": Q, "qd": QD, "qdd": QDD})["tau"], full["tau"]["tau"] @ G),
        "M": (lib.call("M", {"q": Q})["M"], M),
        "g": (lib.call("g", {"q": Q})["g"], full["g"]["g"] @ G),
        "c": (lib.call("c", {"q": Q, "qd": QD})["c"], full["c"]["c"] @ G),
        "fd": (lib.call("fd", {"q": Q, "qd": QD, "tau": TAU})["qdd"], np.linalg.solve(M, (TAU - bias)[..., None])[..., 0]),
        "jacobian": (lib.call("jacobian", {"q": Q})["J"], full["jacobian"]["J"] @ G),
        "J_com": (lib.call("com", {"q": Q})["J_com"], full["com"]["J_com"] @ G),
        "fk_hom": (lib.call("fk_hom", {"q": Q})["T"], full["fk_hom"]["T"]),
    }
    errors = {name: _relative(got, expected) for name, (got, expected) in checks.items()}
    assert max(errors.values()) <= 1e-12, errors


def test_derivatives_by_finite_differences(libraries):
    """tau_derivatives and fd_derivatives (friction and Stribeck derivatives included, the mimic
    joints' friction at G qd, a mimic joint's position ripple at G q + b) equal central differences of the generated reduced tau and fd."""
    _, _, lib = libraries["reduced"]
    Q, QD, QDD, TAU = _states(np.random.default_rng(8), 5)
    h = 1e-6
    for q, qd, qdd, tau in zip(Q, QD, QDD, TAU):
        d_tau = lib.call("tau_derivatives", {"q": q, "qd": qd, "qdd": qdd})
        d_fd = lib.call("fd_derivatives", {"q": q, "qd": qd, "tau": tau})
        for port, which, f, inputs in (("dtau_dq", "q", "tau", {"q": q, "qd": qd, "qdd": qdd}),
                                       ("dtau_dqd", "qd", "tau", {"q": q, "qd": qd, "qdd": qdd}),
                                       ("dqdd_dq", "q", "fd", {"q": q, "qd": qd, "tau": tau}),
                                       ("dqdd_dqd", "qd", "fd", {"q": q, "qd": qd, "tau": tau})):
            columns = []
            for k in range(3):
                step = np.eye(3)[k] * h
                plus = lib.call(f, {**inputs, which: inputs[which] + step})
                minus = lib.call(f, {**inputs, which: inputs[which] - step})
                out = "tau" if f == "tau" else "qdd"
                columns.append((plus[out] - minus[out]) / (2 * h))
            expected = np.stack(columns, axis=-1)
            got = (d_tau if f == "tau" else d_fd)[port]
            assert _relative(got, expected) <= 1e-6, (port, got, expected)


def test_ik_dls_reaches_poses_of_the_reduced_arm(libraries):
    """ik_dls of the mimic arm takes the 3 independent joints and reaches poses its fk_hom gives."""
    _, _, lib = libraries["reduced"]
    rng = np.random.default_rng(9)
    reached = 0
    for q in rng.uniform(-1.2, 1.2, (10, 3)):
        T = lib.call("fk_hom", {"q": q})["T"]
        out = lib.call("ik_dls", {"T": T, "q0": q + rng.uniform(-0.2, 0.2, 3)})
        assert out["q"].shape == (3,)
        if out["status"][0] == 0:
            reached += 1
            assert np.abs(lib.call("fk_hom", {"q": out["q"]})["T"] - T).max() < 1e-6
    assert reached >= 8, reached
