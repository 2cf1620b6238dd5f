"""Identification of base parameters: exact recovery from noiseless synthetic data (made by
Pinocchio, not by the code under test), rank-deficient excitations reported with their
unidentifiable directions, bad data refused with clear messages."""
import json

import numpy as np
import pinocchio as pin
import pytest
import sympy

from tests.harness import GENERATED, robot
from tests.reference import pinocchio_model, random_configurations
from kindyngen.measured.estimation import (IdentificationDataError, RankDeficientError, identify,
                                          identify_samples, stacked_regressor)


def pin_data(name, Q, QD=None, QDD=None):
    """g, inertia stack (lower triangle row by row) and tau by Pinocchio."""
    rob = robot(name)
    model, data, _ = pinocchio_model(rob)
    g, m, tau = [], [], []
    for k, q in enumerate(Q):
        g.append(pin.computeGeneralizedGravity(model, data, q).copy())
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        m.append([M[i, j] for i in range(rob.n) for j in range(i + 1)])
        if QD is not None:
            tau.append(pin.rnea(model, data, q, QD[k], QDD[k]).copy())
    return np.array(g), np.array(m), np.array(tau) if QD is not None else None


def committed_values(name, kind):
    return np.array(json.loads((GENERATED / name / "base_params.json").read_text())[kind]["values"])


@pytest.mark.parametrize("name", ["lwr4", "panda"])
def test_exact_recovery_from_noiseless_data(name):
    rob = robot(name)
    rng = np.random.default_rng(1)
    Q = random_configurations(rob, 60, 21)
    QD, QDD = rng.normal(size=Q.shape), rng.normal(size=Q.shape)
    g, m, tau = pin_data(name, Q, QD, QDD)
    for kind, inputs, measured in (("Y_g", {"q": Q}, g), ("Y_m", {"q": Q}, m),
                                   ("Y", {"q": Q, "qd": QD, "qdd": QDD}, tau)):
        est = identify_samples(rob, kind, inputs, measured)
        np.testing.assert_allclose(est.values, committed_values(name, kind), atol=1e-9, rtol=0, err_msg=kind)
        assert est.residual_rms < 1e-12
        assert est.condition_number < 1e3


def test_the_paper_protocol_recovers_pi_g_with_noise():
    """1000 random static configurations within the limits (paper Sect. VI), noisy g."""
    rob = robot("lwr4")
    Q = random_configurations(rob, 1000, 22)
    g, _, _ = pin_data("lwr4", Q)
    noisy = g + np.random.default_rng(2).normal(scale=1e-3, size=g.shape)
    est = identify_samples(rob, "Y_g", {"q": Q}, noisy)
    np.testing.assert_allclose(est.values, committed_values("lwr4", "Y_g"), atol=1e-3)


def test_all_samples_at_one_configuration_is_rank_deficient():
    rob = robot("lwr4")
    q = random_configurations(rob, 1, 23)[0]
    Q = np.tile(q, (50, 1))
    g, _, _ = pin_data("lwr4", Q)
    with pytest.raises(RankDeficientError) as info:
        identify_samples(rob, "Y_g", {"q": Q}, g)
    err = info.value
    assert err.rank < 12 and err.parameters == 12
    assert "rank-deficient" in str(err) and "one configuration" in str(err)
    assert len(err.directions) == 12 - err.rank
    # the named directions really are invisible in the data, and are written in base-parameter names
    names = json.loads((GENERATED / "lwr4" / "base_params.json").read_text())["Y_g"]["names"]
    Y = stacked_regressor(rob, "Y_g", {"q": Q}).reshape(-1, 12)
    for text, vector in zip(err.directions, err.null_space):
        assert np.abs(Y @ vector).max() < 1e-9 * np.abs(Y).max()
        expr = sympy.sympify(text)
        assert {str(s) for s in expr.free_symbols} <= set(names)
        v = np.array([float(expr.coeff(sympy.Symbol(nm))) for nm in names])
        np.testing.assert_allclose(v, vector, rtol=1e-5, atol=1e-9)


def test_static_excitation_cannot_identify_inertias():
    """tau samples with qd = qdd = 0: only gravity parameters are seen; every inertia
    parameter is named among the unidentifiable directions."""
    rob = robot("lwr4")
    Q = random_configurations(rob, 80, 24)
    Z = np.zeros_like(Q)
    g, _, _ = pin_data("lwr4", Q)
    with pytest.raises(RankDeficientError) as info:
        identify_samples(rob, "Y", {"q": Q, "qd": Z, "qdd": Z}, g)
    err = info.value
    assert err.rank == 12
    text = " ".join(err.directions)
    for name in ("Izz7", "Ixy7", "Ixx2R"):
        assert name in text


def test_too_few_samples():
    rob = robot("lwr4")
    Q = random_configurations(rob, 3, 25)
    g, _, _ = pin_data("lwr4", Q)
    with pytest.raises(IdentificationDataError, match="too few samples"):
        identify_samples(rob, "Y", {"q": Q, "qd": Q, "qdd": Q}, g)
    with pytest.raises(IdentificationDataError, match="too few samples"):
        identify(np.ones((3, 5)), np.ones(3))


def test_nan_data_are_refused():
    rob = robot("lwr4")
    Q = random_configurations(rob, 20, 26)
    g, _, _ = pin_data("lwr4", Q)
    g[4, 2] = np.nan
    with pytest.raises(IdentificationDataError, match=r"NaN.*samples \[4\]"):
        identify_samples(rob, "Y_g", {"q": Q}, g)
    Q[7, 0] = np.nan
    with pytest.raises(IdentificationDataError, match="NaN"):
        identify_samples(rob, "Y_g", {"q": Q}, np.zeros((20, 7)))


def test_shapes_are_checked():
    rob = robot("lwr4")
    Q = random_configurations(rob, 20, 27)
    with pytest.raises(IdentificationDataError, match="shape"):
        identify_samples(rob, "Y_g", {"q": Q}, np.zeros((20, 6)))
    with pytest.raises(IdentificationDataError, match="missing"):
        identify_samples(rob, "Y", {"q": Q}, np.zeros((20, 7)))


def test_plain_least_squares_interface():
    rng = np.random.default_rng(4)
    Y = rng.normal(size=(30, 4))
    est = identify(Y, Y @ [1.0, -2.0, 0.5, 3.0], ("a", "b", "c", "d"))
    np.testing.assert_allclose(est.values, [1.0, -2.0, 0.5, 3.0], atol=1e-12)
    assert est.as_dict()["b"] == pytest.approx(-2.0)
    Y[:, 3] = 2 * Y[:, 0] - Y[:, 1]
    with pytest.raises(RankDeficientError) as info:
        identify(Y, Y @ [1.0, -2.0, 0.5, 3.0], ("a", "b", "c", "d"))
    assert info.value.directions == ("a - 0.5*b - 0.5*d",)
