"""Identification of a parallelogram arm in its independent joints: the palletiser of
``examples/loops/palletiser.yaml`` (three parallelograms, four driven joints) simulated by
Pinocchio's constrained forward dynamics, its base parameters recovered by least squares on the
generated regressor ``Y``.

``kindyngen identify`` refuses robots with closed loops (its logs, limits and effect columns are
per joint); this is the regressor path a user takes instead (docs/tutorials/closed_loops.md):
samples ``(q, qd, tau)`` of the driven joints, the accelerations ``qdd`` that Pinocchio's
``constraintDynamics`` gives (one ``CONTACT_3D`` constraint per loop, the torques on the driven
joints, the configuration closed by Newton's method on Pinocchio's residual: no KinDynGen code
in the simulation), and ``tau = Y(q, qd, qdd) pi`` solved for pi.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot
from kindyngen.runtime.evaluate import load_generated
from tests.algorithms.test_loops_generated import EXAMPLES, Reference

pin = pytest.importorskip("pinocchio")

SAMPLES = 400
NOISE = 0.5          # N m, standard deviation of the measured torques


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    path = EXAMPLES / "palletiser.yaml"
    model = load_robot(path, tree=True)
    folder = generate(model, tmp_path_factory.mktemp("palletiser_y"), languages=("python",), only={"Y"},
                      progress=False)
    reference = Reference(path)
    rng = np.random.default_rng(46)
    independent = [model.joints[j] for j in reference.independent]
    lower, upper = np.array([j.lower for j in independent]), np.array([j.upper for j in independent])
    Q, QD, QDD, TAU = [], [], [], []
    for _ in range(SAMPLES):
        qy = rng.uniform(lower, upper)
        q = reference.solve_from_reference(qy)
        qd, tau = rng.uniform(-1.5, 1.5, qy.size), rng.uniform(-200, 200, qy.size)
        tau_x = np.zeros(reference.nq)
        tau_x[reference.independent] = tau
        qdd = reference.constrained_fd(q, reference.G(q) @ qd, tau_x)[reference.independent]
        Q.append(qy)
        QD.append(qd)
        QDD.append(qdd)
        TAU.append(tau)
    Y = load_generated(folder, "python").call("Y", {"q": np.array(Q), "qd": np.array(QD), "qdd": np.array(QDD)})["Y"]
    document = json.loads((folder / "base_params.json").read_text())["Y"]
    return Y.reshape(-1, Y.shape[2]), np.array(TAU).ravel(), document, rng


def test_base_parameters_recovered_without_noise(simulated):
    """Exact torques: least squares gives the base values of base_params.json (computed exactly
    from the description) to 1e-9 relative."""
    Y, tau, document, _ = simulated
    assert np.linalg.matrix_rank(Y) == Y.shape[1] == len(document["names"])
    estimate = np.linalg.lstsq(Y, tau, rcond=None)[0]
    values = np.array(document["values"])
    error = np.abs(estimate - values).max() / np.abs(values).max()
    print(f"palletiser base parameters, noise-free: largest error {error:.1e} of the largest value")
    assert error < 1e-9


def test_base_parameters_recovered_from_noisy_torques(simulated):
    """Torques with Gaussian noise (0.5 N m): every base parameter within five standard errors
    (sigma^2 (Y^T Y)^-1) of its value, and the residual's spread the noise's."""
    Y, tau, document, rng = simulated
    measured = tau + rng.normal(0, NOISE, tau.size)
    estimate, residual, _, _ = np.linalg.lstsq(Y, measured, rcond=None)
    values = np.array(document["values"])
    standard = NOISE * np.sqrt(np.diag(np.linalg.inv(Y.T @ Y)))
    worst = np.abs(estimate - values) / standard
    rms = float(np.sqrt(residual[0] / (Y.shape[0] - Y.shape[1])))
    print(f"palletiser base parameters, noise {NOISE} N m: largest error {worst.max():.2f} standard errors, "
          f"residual rms {rms:.3f} N m")
    assert worst.max() < 5
    assert abs(rms - NOISE) < 0.1 * NOISE
