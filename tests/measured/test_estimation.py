"""Least squares on torque rows with joint effects (kindyngen.measured.effect_columns and .estimation).

The data are simulated by Pinocchio (tests/reference.py builds the arm from the robot
description with its own joint and inertia machinery) at seeded random states; the effect
torques are written out here from their definitions, not taken from measured/effect_columns.py.  Expected
values are the description's parameters mapped to the base (``R.base_map``) and the effect
coefficients the test chose."""
import numpy as np
import pinocchio as pin
import pytest
import sympy

from tests.harness import robot
from tests.reference import pinocchio_model, random_configurations
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.measured.effect_columns import EFFECTS, NONNEGATIVE, effect_columns, effect_names, effect_torques
from kindyngen.measured.estimation import (IdentificationDataError, RankDeficientError, least_squares, predict,
                                           rms_per_joint)
from kindyngen.measured.regressor_rows import TorqueRegressor

N_JOINTS = 7
FRICTION = ("viscous_friction", "coulomb_friction", "torque_offset")
# the test's own coefficients (one per joint)
FV = np.array([1.2, 0.9, 0.7, 0.5, 0.3, 0.2, 0.1])
FC = np.array([2.5, 2.0, 1.5, 1.0, 0.6, 0.4, 0.2])
F0 = np.array([0.3, -0.2, 0.1, -0.15, 0.05, 0.02, -0.04])
IA = np.array([0.4, 0.35, 0.2, 0.15, 0.08, 0.05, 0.03])


@pytest.fixture(scope="module")
def lwr():
    rob = robot("lwr4")
    return rob, TorqueRegressor(rob), pinocchio_model(rob)


def simulate(rob, pin_model, count, seed, speed=1.0):
    """Random states within the limits and the rigid-body torques by Pinocchio's RNEA."""
    model, data, _ = pin_model
    rng = np.random.default_rng(seed)
    Q = random_configurations(rob, count, seed + 1000)
    QD = speed * rng.normal(size=Q.shape)
    QDD = 2 * speed * rng.normal(size=Q.shape)
    tau = np.array([pin.rnea(model, data, Q[k], QD[k], QDD[k]) for k in range(count)])
    return Q, QD, QDD, tau


def friction_torque(QD, eps=None):
    """fv qd + fc sign(qd) (or tanh(qd / eps)) + f0, from the definitions."""
    shape = np.sign(QD) if eps is None else np.tanh(QD / eps)
    return FV * QD + FC * shape + F0


# ------------------------------------------------------------------------------------------
# measured/effect_columns.py against the definitions

def test_effect_names_and_order():
    assert EFFECTS == ("viscous_friction", "coulomb_friction", "torque_offset", "armature")
    # a compliance 1 / stiffness is physically >= 0 as well
    assert set(NONNEGATIVE) == {"viscous_friction", "coulomb_friction", "armature", "motor_side_elasticity"}
    # the effects on the measurement come after the joint effects; they have no columns here
    assert effect_names(("torque_sensor_gain", "viscous_friction", "motor_side_elasticity"), 2) == \
        ("fv1", "fv2", "ce1", "ce2", "gt1", "gt2")
    with pytest.raises(ValueError, match="act on the measurement"):
        effect_columns("encoder_offset", np.zeros((2, 3)), None)
    # EFFECTS order whatever order they are asked in, then joint, 1-based
    assert effect_names(("armature", "viscous_friction"), 3) == ("fv1", "fv2", "fv3", "Ia1", "Ia2", "Ia3")
    assert effect_names(EFFECTS, 2) == ("fv1", "fv2", "fc1", "fc2", "f01", "f02", "Ia1", "Ia2")


@pytest.mark.parametrize("eps", [None, 0.05])
def test_effect_columns_match_the_formulas(eps):
    rng = np.random.default_rng(3)
    QD, QDD = rng.normal(size=(40, 4)), rng.normal(size=(40, 4))
    QD[5, 2] = 0.0                                   # sign(0) = 0
    C = effect_columns(EFFECTS, QD, QDD, eps)
    assert C.shape == (40, 4, 16)
    names = effect_names(EFFECTS, 4)
    coulomb = np.sign(QD) if eps is None else np.tanh(QD / eps)
    expected = {"fv": QD, "fc": coulomb, "f0": np.ones_like(QD), "Ia": QDD}
    for col, name in enumerate(names):
        prefix, joint = name[:2], int(name[2:]) - 1
        want = np.zeros((40, 4))
        want[:, joint] = expected[prefix][:, joint]
        np.testing.assert_array_equal(C[:, :, col], want, err_msg=name)
    if eps is None:
        assert C[5, 2, names.index("fc3")] == 0.0
    # torques: a dict by name and an array give the same as the formulas
    values = rng.uniform(0.1, 1.0, size=16)
    want = sum(values[names.index(f"{p}{j + 1}")] * expected[p][:, j, None] * np.eye(4)[j]
               for p in ("fv", "fc", "f0", "Ia") for j in range(4))
    np.testing.assert_allclose(effect_torques(EFFECTS, values, QD, QDD, eps), want, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(effect_torques(EFFECTS, dict(zip(names, values)), QD, QDD, eps), want,
                               rtol=1e-14, atol=1e-14)


def test_unknown_effect_names_the_closest():
    with pytest.raises(ValueError, match="unknown effect 'coulomb'.*did you mean 'coulomb_friction'"):
        effect_columns(("viscous_friction", "coulomb"), np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="did you mean 'armature'"):
        effect_names(["armatures"], 3)
    with pytest.raises(ValueError, match="needs qdd"):
        effect_columns("armature", np.zeros((2, 3)), None)
    with pytest.raises(ValueError, match="eps"):
        effect_columns("coulomb_friction", np.zeros((2, 3)), None, eps=0.0)


# ------------------------------------------------------------------------------------------
# ordinary least squares, noise-free

@pytest.mark.parametrize("eps", [None, 0.05])
def test_ols_recovers_base_parameters_and_friction(lwr, eps):
    rob, R, pm = lwr
    Q, QD, QDD, tau = simulate(rob, pm, 150, 11)
    measured = tau + friction_torque(QD, eps)
    Y = np.concatenate([R(Q, QD, QDD), effect_columns(FRICTION, QD, QDD, eps)], axis=2)
    fit = least_squares(Y, measured, R.names + effect_names(FRICTION, N_JOINTS))
    p = len(R.names)
    truth = R.base_map @ parameter_vector(rob)
    base = fit.values[:p]
    assert np.linalg.norm(base - truth) <= 1e-8 * np.linalg.norm(truth)
    np.testing.assert_allclose(base, truth, rtol=0, atol=1e-8 * np.abs(truth).max())
    np.testing.assert_allclose(fit.values[p:], np.concatenate([FV, FC, F0]), rtol=0, atol=1e-8)
    assert fit.rms.shape == (N_JOINTS,) and fit.rms.max() < 1e-11 * np.abs(measured).max()
    assert fit.method == "ols" and fit.weights is None
    assert fit.std.max() < 1e-9                       # noise-free: no uncertainty to speak of
    assert fit.condition_number < 1e3 and fit.condition_number_scaled < fit.condition_number
    assert fit.as_dict()["fc3"] == pytest.approx(FC[2], abs=1e-9)
    np.testing.assert_allclose(predict(Y, fit.values), measured, rtol=0, atol=1e-10)


def test_armature_of_joints_1_and_2_is_refused_with_the_direction(lwr):
    """Joint 1's axis is fixed in the base, so its armature has the column qdd1 on row 1 -- the
    same as link 1's inertia about that axis; joint 2's axis meets joint 1's at a right angle
    (a = d = 0 between them), so link 2's inertia about axis 2 enters M22 only and its base
    column is qdd2 on row 2 again.  Joints 3..7 have no such twin."""
    rob, R, pm = lwr
    Q, QD, QDD, tau = simulate(rob, pm, 150, 12)
    measured = tau + friction_torque(QD) + IA * QDD
    effects = FRICTION + ("armature",)
    names = R.names + effect_names(effects, N_JOINTS)
    Y = np.concatenate([R(Q, QD, QDD), effect_columns(effects, QD, QDD)], axis=2)
    with pytest.raises(RankDeficientError) as info:
        least_squares(Y, measured, names)
    err = info.value
    assert len(err.directions) == 2 and "armature" in str(err) and "drop Ia1, Ia2" in str(err)
    stacked = Y.reshape(-1, len(names))
    involved = set()
    for text in err.directions:
        expr = sympy.sympify(text)
        v = np.array([float(expr.coeff(sympy.Symbol(nm))) for nm in names])
        assert np.abs(stacked @ v).max() < 1e-9 * np.abs(stacked).max()   # really invisible
        involved |= {str(s) for s in expr.free_symbols}
    assert {"Ia1", "Ia2"} <= involved and not involved & {f"Ia{j}" for j in range(3, 8)}

    # without Ia1 and Ia2 the fit works: the two inertia parameters absorb the armatures
    keep = [k for k, nm in enumerate(names) if nm not in ("Ia1", "Ia2")]
    fit = least_squares(Y[:, :, keep], measured, [names[k] for k in keep])
    truth = R.base_map @ parameter_vector(rob)
    got = fit.as_dict()
    axis1, axis2 = [nm for nm in err.names if nm in involved and not nm.startswith("Ia")]
    assert got[axis1] == pytest.approx(truth[R.names.index(axis1)] + IA[0], abs=1e-9)
    assert got[axis2] == pytest.approx(truth[R.names.index(axis2)] + IA[1], abs=1e-9)
    np.testing.assert_allclose([got[f"Ia{j}"] for j in range(3, 8)], IA[2:], rtol=0, atol=1e-9)
    np.testing.assert_allclose([got[f"fv{j}"] for j in range(1, 8)], FV, rtol=0, atol=1e-9)


def test_least_squares_reuses_the_refusals(lwr):
    rob, R, pm = lwr
    Q, QD, QDD, tau = simulate(rob, pm, 30, 13)
    Y = R(Q, QD, QDD)
    bad = tau.copy()
    bad[4, 1] = np.nan
    with pytest.raises(IdentificationDataError, match=r"NaN.*samples \[4\]"):
        least_squares(Y, bad, R.names)
    with pytest.raises(IdentificationDataError, match="too few samples"):
        least_squares(Y[:5], tau[:5], R.names)
    # qd = qdd = 0: only gravity is seen; the directions are named
    Z = np.zeros_like(Q)
    with pytest.raises(RankDeficientError) as info:
        least_squares(R(Q, Z, Z), tau, R.names)
    assert info.value.rank == 12 and "Izz7" in " ".join(info.value.directions)
    assert "armature" not in str(info.value)


# ------------------------------------------------------------------------------------------
# weighted least squares with per-joint noise

SIGMA = np.array([0.4, 0.25, 0.15, 0.1, 0.05, 0.02, 0.01])    # N m, per joint


@pytest.fixture(scope="module")
def noisy_rows(lwr):
    rob, R, pm = lwr
    Q, QD, QDD, tau = simulate(rob, pm, 2000, 14)
    Y = np.concatenate([R(Q, QD, QDD), effect_columns(FRICTION, QD, QDD)], axis=2)
    return Y, tau + friction_torque(QD), R.names + effect_names(FRICTION, N_JOINTS)


def test_wls_weights_recover_the_noise_levels(noisy_rows):
    Y, clean, names = noisy_rows
    measured = clean + SIGMA * np.random.default_rng(15).normal(size=clean.shape)
    fit = least_squares(Y, measured, names, weighted=True)
    assert fit.method == "wls" and fit.weights.shape == (N_JOINTS,)
    # one pass (Gautier): sigma_j comes from the ordinary fit, whose error (driven by the noisy
    # joints) adds to the quiet joints' residuals; at a 40:1 noise ratio that is ~10 % on joint 7
    np.testing.assert_allclose(1 / fit.weights, SIGMA, rtol=0.15)
    np.testing.assert_allclose(fit.weights / fit.weights[0], SIGMA[0] / SIGMA, rtol=0.15)
    assert np.all(np.diff(fit.weights) > 0)                  # the order of the noise levels
    np.testing.assert_allclose(fit.rms, SIGMA, rtol=0.15)
    ols = least_squares(Y, measured, names)
    assert ols.weights is None and np.allclose(ols.sigma, ols.sigma[0])
    # the common sigma of OLS is the pooled noise level
    assert ols.sigma[0] == pytest.approx(np.sqrt(np.mean(SIGMA ** 2)), rel=0.05)


def test_std_shrinks_like_one_over_root_n(noisy_rows):
    Y, clean, names = noisy_rows
    measured = clean + SIGMA * np.random.default_rng(16).normal(size=clean.shape)
    small = least_squares(Y[:500], measured[:500], names, weighted=True)
    large = least_squares(Y, measured, names, weighted=True)
    ratio = small.std_percent / large.std_percent          # 4 times the samples: about 2
    assert 1.7 < np.median(ratio) < 2.3
    assert np.all(np.isfinite(large.std_percent)) and (large.std_percent > 0).all()
    assert large.std_percent == pytest.approx(100 * large.std / np.abs(large.values))


def test_reported_std_matches_the_spread_over_noise_draws(noisy_rows):
    """Monte Carlo: 30 noise draws on one excitation; the reported std (WLS) agrees with the
    observed spread of the estimates, and WLS spreads less than OLS (the noise is unequal)."""
    Y, clean, names = noisy_rows
    Y, clean = Y[:300], clean[:300]
    rng = np.random.default_rng(17)
    wls, ols, reported = [], [], []
    for _ in range(30):
        measured = clean + SIGMA * rng.normal(size=clean.shape)
        w = least_squares(Y, measured, names, weighted=True)
        wls.append(w.values)
        reported.append(w.std)
        ols.append(least_squares(Y, measured, names).values)
    spread_w, spread_o = np.std(wls, axis=0, ddof=1), np.std(ols, axis=0, ddof=1)
    ratio = np.mean(reported, axis=0) / spread_w
    assert 0.8 < np.median(ratio) < 1.25 and ratio.min() > 0.5 and ratio.max() < 2.0
    assert np.median(spread_w / spread_o) < 0.8


def test_predict_and_rms_per_joint():
    Y = np.arange(24.0).reshape(2, 3, 4)
    v = np.array([1.0, 0.0, -1.0, 0.5])
    np.testing.assert_array_equal(predict(Y, v), np.einsum("sjk,k->sj", Y, v))
    tau = np.array([[1.0, 2.0, 3.0], [1.0, 0.0, 3.0]])
    np.testing.assert_allclose(rms_per_joint(tau, np.array([[0.0, 2.0, 0.0], [2.0, 0.0, 0.0]])), [1.0, 0.0, 3.0])
    with pytest.raises(IdentificationDataError):
        predict(Y, v[:3])
