"""Mimic joints with symbolic inertial parameters (``--params symbolic``): the reduced functions
take ``p`` (10 per body, every body's, the mimic joints' links included) and equal the reduction
of Pinocchio's model without mimics whose inertias are set to the same random parameters.

Robot: ``tests/data/urdf/mimic_coupled_tree.urdf`` with a floating base (general multipliers,
offsets, a prismatic joint following a revolute one, a mimic of a mimic). The derived
expressions are evaluated directly (no code is generated), at 20 states.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from kindyngen.algorithms.regressors import evaluate_dag
from kindyngen.codegen.catalog import derive_all
from kindyngen.readers.urdf import load_urdf

pin = pytest.importorskip("pinocchio")

PATH = Path(__file__).resolve().parents[1] / "data" / "urdf" / "mimic_coupled_tree.urdf"
FUNCTIONS = ("M", "tau", "fd", "com", "tau_derivatives")


def _map(pmodel):
    """q_full = G q + b from the URDF's tags (chains followed), Pinocchio's joint order."""
    rules = {j.get("name"): (j.find("mimic").get("joint"), float(j.find("mimic").get("multiplier", 1)),
                             float(j.find("mimic").get("offset", 0)))
             for j in ET.parse(PATH).getroot().findall("joint") if j.find("mimic") is not None}
    names = list(pmodel.names)[2:]
    independent = [name for name in names if name not in rules]
    G, b = np.zeros((6 + len(names), 6 + len(independent))), np.zeros(len(names))
    G[:6, :6] = np.eye(6)
    for row, name in enumerate(names):
        m, o = 1.0, 0.0
        while name in rules:
            name, mi, oi = rules[name]
            m, o = m * mi, o + m * oi
        G[6 + row, 6 + independent.index(name)], b[row] = m, o
    return G, b


def _random_parameters(rng, bodies: int) -> np.ndarray:
    """Physical barycentric parameters (Pinocchio's order) of random bodies."""
    out = []
    for _ in range(bodies):
        A = rng.uniform(-0.1, 0.1, (3, 3))
        inertia = pin.Inertia(rng.uniform(0.5, 2.0), rng.uniform(-0.1, 0.1, 3), A @ A.T + 0.01 * np.eye(3))
        out.append(inertia.toDynamicParameters())
    return np.concatenate(out)


def test_symbolic_parameters_equal_pinocchio_with_the_same_parameters():
    model = load_urdf(PATH, floating_base=True)
    functions = {f.name: f for f in derive_all(model, "symbolic", only=set(FUNCTIONS))}
    assert all(f.inputs[-1].name == "p" and f.inputs[-1].shape == (10 * (model.n + 1),) for f in functions.values())
    pmodel = pin.buildModelFromUrdf(str(PATH), pin.JointModelFreeFlyer())
    data = pmodel.createData()
    G, b = _map(pmodel)
    rng = np.random.default_rng(46)
    p = _random_parameters(rng, model.n + 1)
    for k in range(model.n + 1):
        pmodel.inertias[k + 1] = pin.Inertia.FromDynamicParameters(p[10 * k:10 * k + 10])
    count = 20
    quat = rng.standard_normal((count, 4))
    Q = np.hstack([rng.uniform(-1, 1, (count, 3)), quat / np.linalg.norm(quat, axis=1, keepdims=True),
                   rng.uniform(-1.5, 1.5, (count, model.nq - 7))])
    QD, QDD, TAU = (rng.uniform(-2, 2, (count, model.nv)) for _ in range(3))
    reference = {key: [] for key in ("M", "tau", "qdd", "com", "J_com", "dtau_dq", "dtau_dqd")}
    for q, qd, qdd, tau in zip(Q, QD, QDD, TAU):
        x = np.r_[q[:7], G[6:, 6:] @ q[7:] + b]
        full = pin.crba(pmodel, data, x)
        M = G.T @ (np.triu(full) + np.triu(full, 1).T) @ G
        reference["M"].append(M)
        reference["tau"].append(G.T @ pin.rnea(pmodel, data, x, G @ qd, G @ qdd))
        reference["qdd"].append(np.linalg.solve(M, tau - G.T @ pin.nonLinearEffects(pmodel, data, x, G @ qd)))
        reference["com"].append(pin.centerOfMass(pmodel, data, x).copy())
        reference["J_com"].append(pin.jacobianCenterOfMass(pmodel, data, x) @ G)
        dq, dqd, _ = pin.computeRNEADerivatives(pmodel, data, x, G @ qd, G @ qdd)
        reference["dtau_dq"].append(G.T @ dq @ G)
        reference["dtau_dqd"].append(G.T @ dqd @ G)
    inputs = {"q": Q, "qd": QD, "qdd": QDD, "tau": TAU, "p": np.broadcast_to(p, (count, p.size))}
    errors = {}
    for f in functions.values():
        values = {s: inputs[port.name][:, k] for port, syms in zip(f.inputs, f.input_symbols) for k, s in enumerate(syms)}
        for port, exprs in zip(f.outputs, f.inlined_outputs()):
            if port.name not in reference:
                continue
            got = np.stack([np.broadcast_to(v, (count,)) for v in evaluate_dag(list(exprs), values)], axis=1)
            expected = np.array(reference[port.name]).reshape(count, -1)
            errors[port.name] = float((np.abs(got - expected).max(axis=1) / np.abs(expected).max(axis=1)).max())
    print({k: f"{v:.1e}" for k, v in errors.items()})
    assert set(errors) == set(reference), errors
    assert max(errors.values()) <= 1e-12, errors
