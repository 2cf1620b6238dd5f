"""The generated dynamics, in every language, against Pinocchio at 1000 random states;
and the symbolic-parameter build against the numeric one."""
import json
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

from kindyngen.runtime.evaluate import load_generated
from kindyngen.model.inertial_parameters import parameter_vector
from tests.harness import GENERATED, LANGS, ROOT, evaluate, robot
from tests.reference import pinocchio_model, random_configurations

N = 1000


@pytest.fixture(scope="module", params=("lwr4", "panda"))
def states(request):
    name = request.param
    rng = np.random.default_rng(7)
    Q = random_configurations(robot(name), N, seed=7)
    QD = rng.uniform(-2, 2, Q.shape)
    QDD = rng.uniform(-5, 5, Q.shape)
    model, data, _ = pinocchio_model(robot(name))
    ref = {"M": [], "g": [], "c": [], "tau": [], "qdd": [], "tau_in": []}
    for q, qd, qdd in zip(Q, QD, QDD):
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        g = pin.computeGeneralizedGravity(model, data, q)
        ref["M"].append(M)
        ref["g"].append(g.copy())
        ref["c"].append(pin.nonLinearEffects(model, data, q, qd) - g)
        tau = pin.rnea(model, data, q, qd, qdd).copy()
        ref["tau"].append(tau)
        tau_in = tau + rng.normal(size=len(q))
        ref["tau_in"].append(tau_in)
        ref["qdd"].append(pin.aba(model, data, q, qd, tau_in).copy())
    return name, Q, QD, QDD, {k: np.array(v) for k, v in ref.items()}


def assert_relative(got, expected, tol=1e-9):
    scale = np.maximum(np.abs(expected).max(axis=tuple(range(1, expected.ndim)), keepdims=True), 1.0)
    assert np.all(np.abs(got - expected) <= tol * scale), np.abs(got - expected).max()


@pytest.mark.parametrize("lang", LANGS)
def test_dynamics_match_pinocchio(states, lang):
    name, Q, QD, QDD, ref = states
    assert_relative(evaluate(name, lang, "M", q=Q)["M"], ref["M"])
    assert_relative(evaluate(name, lang, "g", q=Q)["g"], ref["g"])
    assert_relative(evaluate(name, lang, "c", q=Q, qd=QD)["c"], ref["c"])
    assert_relative(evaluate(name, lang, "tau", q=Q, qd=QD, qdd=QDD)["tau"], ref["tau"])
    assert_relative(evaluate(name, lang, "fd", q=Q, qd=QD, tau=ref["tau_in"])["qdd"], ref["qdd"])


@pytest.mark.parametrize("lang", LANGS)
def test_paper_routes_match_pinocchio(states, lang):
    name, Q, QD, _, ref = states
    k = slice(0, 200)
    assert_relative(evaluate(name, lang, "M_lagrange", q=Q[k])["M"], ref["M"][k])
    assert_relative(evaluate(name, lang, "g_lagrange", q=Q[k])["g"], ref["g"][k])
    assert_relative(evaluate(name, lang, "c_christoffel", q=Q[k], qd=QD[k])["c"], ref["c"][k])
    S = evaluate(name, lang, "S", q=Q[k], qd=QD[k])["S"]
    assert_relative(np.einsum("kij,kj->ki", S, QD[k]), ref["c"][k])


@pytest.fixture(scope="module")
def symbolic_build(tmp_path_factory):
    out = tmp_path_factory.mktemp("symbolic_params")
    subprocess.run([sys.executable, "-m", "kindyngen", "generate", str(ROOT / "robots" / "lwr4.yaml"), "--out",
                    str(out), "--params", "symbolic", "--lang", "c,python", "--quiet"], check=True, cwd=ROOT)
    return out / "lwr4"


@pytest.mark.parametrize("lang", ["python", "c"])
def test_symbolic_parameters_equal_numeric(symbolic_build, lang):
    manifest = json.loads((symbolic_build / "functions.json").read_text())
    symbolic, numeric = load_generated(symbolic_build, lang), load_generated(GENERATED / "lwr4", lang)
    p = parameter_vector(robot("lwr4"))
    rng = np.random.default_rng(11)
    Q = random_configurations(robot("lwr4"), 50, seed=11)
    checked = 0
    for spec in manifest["functions"]:
        names = [port["name"] for port in spec["inputs"]]
        if names[-1] != "p":
            continue
        inputs = {"q": Q, **{n: rng.normal(size=Q.shape) for n in names if n in ("qd", "qdd", "tau")}}
        expected = numeric.call(spec["name"], inputs)
        got = symbolic.call(spec["name"], {**inputs, "p": np.tile(p, (len(Q), 1))})
        for key, value in expected.items():
            assert_relative(got[key], value)
        checked += 1
    assert checked >= 6
