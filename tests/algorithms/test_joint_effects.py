"""kindyngen.algorithms.effect_torques on its own: the symbolic friction, offset and armature torques of a
description equal the formulas written out in numpy (fv qd + fc sign(qd) + f0 + Ia qdd, or
tanh(qd / eps) in place of sign), with sign(0) = 0; the regressor's effect columns times the
declared coefficients give the same torques; names, values and the M diagonal follow the
declared effects only."""
from __future__ import annotations

import numpy as np
import pytest
import symengine as se
import yaml

from tests.harness import ROOT
from kindyngen.algorithms.effect_torques import (coulomb_shape, effect_columns, effect_parameter_names,
                                     effect_parameter_values, effect_torques, with_armature)
from kindyngen.readers.yaml_description import parse_robot

FRICTION = [(0.8, 1.2, 0.1), (0.7, 1.1, -0.2), None, (0.5, 0.8, 0.05), (0.3, 0.5, 0.0), (0.0, 0.4, 0.0), None]
ARMATURE = [0.3, 0.3, 0.2, 0.0, 0.1, 0.1, 0.05]


def _model(smoothing=None, friction=True, armature=True):
    data = yaml.safe_load((ROOT / "robots" / "lwr4.yaml").read_text())
    for joint, f, a in zip(data["joints"], FRICTION, ARMATURE):
        if friction and f is not None:
            joint["friction"] = dict(zip(("viscous", "coulomb", "offset"), f))
        if armature:
            joint["armature"] = a
    if smoothing is not None:
        data["coulomb_smoothing"] = smoothing
    return parse_robot(data, "lwr4 + effects")


def _numpy_torques(qd, qdd, smoothing=None):
    fv, fc, f0 = (np.array([f[k] if f else 0.0 for f in FRICTION]) for k in range(3))
    shape = np.sign(qd) if smoothing is None else np.tanh(qd / smoothing)
    return fv * qd + fc * shape + f0 + np.array(ARMATURE) * qdd


QD, QDD = se.symbols("qd1:8"), se.symbols("qdd1:8")


def _at(expressions, qd, qdd):
    values = {**dict(zip(QD, qd)), **dict(zip(QDD, qdd))}
    return np.array([float(se.sympify(e).subs(values)) for e in expressions])


@pytest.mark.parametrize("smoothing", (None, 0.05), ids=("sign", "tanh"))
def test_effect_torques_are_the_formulas(smoothing):
    model = _model(smoothing)
    torques = effect_torques(model, QD, QDD)
    rng = np.random.default_rng(11)
    for _ in range(5):
        qd, qdd = rng.uniform(-2, 2, 7), rng.uniform(-5, 5, 7)
        qd[2] = 0.0                                   # sign(0) = 0 (tanh(0) = 0 too)
        np.testing.assert_allclose(_at(torques, qd, qdd), _numpy_torques(qd, qdd, smoothing), rtol=1e-14, atol=1e-14)


def test_columns_times_coefficients_are_the_torques():
    model = _model()
    columns = effect_columns(model, None, QD, QDD)
    values = [float(v) for v in effect_parameter_values(model)]
    names = effect_parameter_names(model)
    assert len(columns) == len(values) == len(names) == 4 * 7
    assert names[:2] == ("fv1", "fv2") and names[7] == "fc1" and names[14] == "f01" and names[21] == "Ia1"
    rng = np.random.default_rng(2)
    qd, qdd = rng.uniform(-2, 2, 7), rng.uniform(-5, 5, 7)
    total = np.zeros(7)
    for (joint, shape), value in zip(columns, values):
        total[joint] += value * _at([shape], qd, qdd)[0]
    np.testing.assert_allclose(total, _numpy_torques(qd, qdd), rtol=1e-14, atol=1e-14)


def test_coulomb_shape_is_sign_with_zero_at_zero():
    v = se.Symbol("v")
    assert [float(coulomb_shape(v, None).subs({v: x})) for x in (-0.3, 0.0, 1e-300)] == [-1.0, 0.0, 1.0]
    assert float(coulomb_shape(v, 0.1).subs({v: 0.05})) == pytest.approx(np.tanh(0.5), rel=1e-15)


def test_only_declared_effects():
    rigid = _model(friction=False, armature=False)
    assert effect_parameter_names(rigid) == () and effect_torques(rigid, QD, QDD) == [0] * 7
    armature_only = _model(friction=False)
    assert effect_parameter_names(armature_only) == tuple(f"Ia{i}" for i in range(1, 8))
    M = [[se.Symbol(f"m{r}{c}") for c in range(7)] for r in range(7)]
    out = with_armature(armature_only, M)
    for r in range(7):
        for c in range(7):
            added = ARMATURE[r] if r == c else 0.0
            assert float((out[r][c] - M[r][c]).subs({})) == pytest.approx(added, abs=0), (r, c)
    assert M[0][0] == se.Symbol("m00")                  # the input is left whole
