"""The generated closed-form IK in every language (C through ctypes, numpy, CasADi) on the
same 10,000 random reachable targets as tests/ik/test_ik.py (which checks the derivation):
every branch not marked unreachable reproduces the target to 1e-10, statuses are
consistent, and the original configuration is among the admissible branches."""
import numpy as np
import pytest

from tests.harness import LANGS, evaluate, robot
from tests.reference import random_configurations
from tests.ik.test_ik import ADMISSIBLE, FORMS, N, angle_diff, check_common, fk_batch, matrix_to_dq


@pytest.fixture(scope="module")
def targets():
    Q = random_configurations(robot("lwr4"), N, seed=11)
    return Q, fk_batch(robot("lwr4"), Q)


def solve(lang, form, T, theta3, rng):
    if form == "ik_hom":
        out = evaluate("lwr4", lang, "ik_hom", T=T, theta3=theta3[:, None])
    else:
        out = evaluate("lwr4", lang, "ik_dq", x=matrix_to_dq(T, rng), theta3=theta3[:, None])
    return out["q"], out["status"].astype(int)


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("lang", LANGS)
def test_own_theta3_recovers_configuration(targets, lang, form):
    Q, T = targets
    q, status = solve(lang, form, T, Q[:, 2], np.random.default_rng(1))
    reach = check_common(robot("lwr4"), q, status, T, Q[:, 2])
    assert reach.all()
    diff = angle_diff(q, Q[:, None, :]).max(axis=-1)
    best = diff.argmin(axis=1)
    assert diff[np.arange(N), best].max() < 1e-7
    assert np.isin(status[np.arange(N), best], ADMISSIBLE).all()


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("lang", LANGS)
def test_random_theta3(targets, lang, form):
    Q, T = targets
    rng = np.random.default_rng(2)
    theta3 = rng.uniform(robot("lwr4").lower[2], robot("lwr4").upper[2], N)
    q, status = solve(lang, form, T, theta3, rng)
    check_common(robot("lwr4"), q, status, T, theta3)
    assert (status == 0).any() and (status == 2).any()


@pytest.mark.parametrize("form", FORMS)
def test_languages_agree_exactly_on_status(targets, form):
    Q, T = targets
    k = slice(0, 2000)
    theta3 = np.random.default_rng(5).uniform(-2.9, 2.9, 2000)
    results = {lang: solve(lang, form, T[k], theta3, np.random.default_rng(9)) for lang in LANGS}
    for lang in LANGS[1:]:
        np.testing.assert_array_equal(results[lang][1], results[LANGS[0]][1])
        np.testing.assert_allclose(results[lang][0], results[LANGS[0]][0], atol=1e-9)
