"""The generated derivatives of the dynamics, tau_derivatives and fd_derivatives (and on the LWR,
the Panda and the LWR with effects fd_derivatives_no_minv, the same without Minv), in C, Python
and CasADi, against Pinocchio's analytical derivatives (``computeRNEADerivatives``,
``computeABADerivatives`` with its ``Minv``) and against central finite differences of the
generated tau and fd, at 1000 random states of the LWR and the Panda; plus the LWR with friction
and armature, tests/data/urdf/slider_arm.urdf (a prismatic joint) read by Pinocchio's own URDF
parser, and the example-robot-data arms of tests/algorithms/test_urdf_generated.py (200 states each).

Tolerance against Pinocchio: per state, |ours - Pinocchio| <= 1e-9 * max(1, max |Pinocchio's
value|) over the matrix (as the other dynamics tests). Against central finite differences:
tau and fd are quadratic in qd and fd is linear in tau, so there the differences are exact but
for rounding and take large steps (1e-3, 1e-1); in q the step 1e-5 (rad, m) balances the
truncation error (h^2 times third derivatives) and the rounding error (1e-16 |qdd| / h, with
|qdd| up to ~1e3 on the LWR's light wrist); the bound 1e-7 lies above both and far below any
wrong derivative.
"""
from __future__ import annotations

import numpy as np
import pytest
import symengine as se
import yaml

from tests import harness
from tests.harness import LANGS, ROOT, evaluate, robot
from kindyngen.codegen.catalog import derive_all
from kindyngen.runtime.evaluate import load_generated
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model
from tests.algorithms.test_urdf_generated import ARMS as URDF_ARMS, _Pinocchio as UrdfPinocchio, _urdf_path as urdf_path

pin = pytest.importorskip("pinocchio")

N = 1000
TOLERANCE = 1e-9
FD_TOLERANCE = 1e-7
STEPS = {"q": 1e-5, "qd": 1e-3, "tau": 1e-1}
NEW = ("tau_derivatives", "fd_derivatives")
NO_MINV = "fd_derivatives_no_minv"


def scaled_error(got, expected) -> float:
    """Largest |got - expected| per state, scaled by max(1, largest |expected|) of that state."""
    n = got.shape[0]
    diff = np.abs(got - expected).reshape(n, -1).max(axis=1)
    scale = np.maximum(1.0, np.abs(expected).reshape(n, -1).max(axis=1))
    return float((diff / scale).max())


def symmetric(M):
    """Pinocchio fills only the upper triangle of M and Minv."""
    return np.triu(M) + np.triu(M, 1).T


def pinocchio_derivatives(model, data, Q, QD, QDD, TAU, friction=None):
    """Pinocchio's derivatives at every state. ``friction``: (torques f(qd), df/dqd diagonal)
    of a joint friction the rigid-body model lacks; it enters tau additively and fd as
    ``aba(q, qd, tau - f(qd))``, whose qd derivative gains ``-Minv diag(f')``."""
    out = {k: [] for k in ("dtau_dq", "dtau_dqd", "dqdd_dq", "dqdd_dqd", "Minv")}
    for k, (q, qd, qdd, tau) in enumerate(zip(Q, QD, QDD, TAU)):
        f, df = (np.zeros(len(q)), np.zeros(len(q))) if friction is None else (friction[0][k], friction[1][k])
        dq, dv, _ = pin.computeRNEADerivatives(model, data, q, qd, qdd)
        out["dtau_dq"].append(dq.copy())
        out["dtau_dqd"].append(dv + np.diag(df))
        pin.computeABADerivatives(model, data, q, qd, tau - f)
        Minv = symmetric(data.Minv)
        out["dqdd_dq"].append(data.ddq_dq.copy())
        out["dqdd_dqd"].append(data.ddq_dv - Minv @ np.diag(df))
        out["Minv"].append(Minv)
    return {k: np.array(v) for k, v in out.items()}


def states(n, lower, upper, seed, prismatic=None):
    rng = np.random.default_rng(seed)
    scale = np.ones(n) if prismatic is None else np.where(prismatic, 0.25, 1.0)
    Q = rng.uniform(lower, upper, size=(N, n))
    return Q, rng.uniform(-2, 2, (N, n)) * scale, rng.uniform(-5, 5, (N, n)) * scale, rng.uniform(-20, 20, (N, n))


def check(call, Q, QD, QDD, TAU, expected, label, no_minv=False):
    """Both derivative functions (with ``no_minv`` fd_derivatives_no_minv too) against ``expected``."""
    got = call("tau_derivatives", {"q": Q, "qd": QD, "qdd": QDD})
    got.update(call("fd_derivatives", {"q": Q, "qd": QD, "tau": TAU}))
    for key, value in expected.items():
        error = scaled_error(got[key], value)
        print(f"{label} {key}: max scaled error {error:.2e}")
        assert error <= TOLERANCE, f"{label} {key}: max scaled error {error:.3e}"
    if no_minv:
        got = call(NO_MINV, {"q": Q, "qd": QD, "tau": TAU})
        assert sorted(got) == ["dqdd_dq", "dqdd_dqd"]
        for key, value in got.items():
            error = scaled_error(value, expected[key])
            print(f"{label} {NO_MINV} {key}: max scaled error {error:.2e}")
            assert error <= TOLERANCE, f"{label} {NO_MINV} {key}: max scaled error {error:.3e}"


# ----------------------------------------------------------------------------- LWR and Panda

@pytest.fixture(scope="module", params=("lwr4", "panda"))
def arm(request):
    name = request.param
    r = robot(name)
    Q, QD, QDD, TAU = states(r.n, r.lower, r.upper, seed=17)
    model, data, _ = pinocchio_model(r)
    return name, Q, QD, QDD, TAU, pinocchio_derivatives(model, data, Q, QD, QDD, TAU)


@pytest.mark.parametrize("lang", LANGS)
def test_derivatives_match_pinocchio(arm, lang):
    name, Q, QD, QDD, TAU, expected = arm
    check(lambda f, inputs: evaluate(name, lang, f, **inputs), Q, QD, QDD, TAU, expected, f"{name} {lang}",
          no_minv=True)


def central_differences(function, inputs, wrt, output):
    """d output / d inputs[wrt] of a batched function by central differences: (N, n, n)."""
    columns = []
    for j in range(inputs[wrt].shape[1]):
        plus, minus = dict(inputs), dict(inputs)
        plus[wrt], minus[wrt] = inputs[wrt].copy(), inputs[wrt].copy()
        plus[wrt][:, j] += STEPS[wrt]
        minus[wrt][:, j] -= STEPS[wrt]
        columns.append((function(plus)[output] - function(minus)[output]) / (2 * STEPS[wrt]))
    return np.stack(columns, axis=2)


@pytest.mark.parametrize("lang", LANGS)
def test_derivatives_match_finite_differences_of_tau_and_fd(arm, lang):
    """The derivatives are those of the generated tau and fd themselves, in the same language."""
    name, Q, QD, QDD, TAU, _ = arm
    tau = lambda inputs: evaluate(name, lang, "tau", **inputs)        # noqa: E731
    fd = lambda inputs: evaluate(name, lang, "fd", **inputs)          # noqa: E731
    got = evaluate(name, lang, "tau_derivatives", q=Q, qd=QD, qdd=QDD)
    got.update(evaluate(name, lang, "fd_derivatives", q=Q, qd=QD, tau=TAU))
    at_tau, at_fd = {"q": Q, "qd": QD, "qdd": QDD}, {"q": Q, "qd": QD, "tau": TAU}
    expected = {"dtau_dq": central_differences(tau, at_tau, "q", "tau"),
                "dtau_dqd": central_differences(tau, at_tau, "qd", "tau"),
                "dqdd_dq": central_differences(fd, at_fd, "q", "qdd"),
                "dqdd_dqd": central_differences(fd, at_fd, "qd", "qdd"),
                "Minv": central_differences(fd, at_fd, "tau", "qdd")}
    for key, value in expected.items():
        error = scaled_error(got[key], value)
        print(f"{name} {lang} {key} vs finite differences: max scaled error {error:.2e}")
        assert error <= FD_TOLERANCE, f"{name} {lang} {key}: max scaled error {error:.3e}"


def test_outputs_and_units():
    f = {name: load_generated(harness.GENERATED / "lwr4", "python").functions[name] for name in NEW}
    ports = {p["name"]: (p["shape"], p["unit"]) for spec in f.values() for p in spec["outputs"]}
    assert ports == {"dtau_dq": ([7, 7], "N m/rad"), "dtau_dqd": ([7, 7], "N m s/rad"),
                     "dqdd_dq": ([7, 7], "1/s^2"), "dqdd_dqd": ([7, 7], "1/s"), "Minv": ([7, 7], "1/(kg m^2)")}
    assert [p["name"] for p in f["tau_derivatives"]["inputs"]] == ["q", "qd", "qdd"]
    assert [p["name"] for p in f["fd_derivatives"]["inputs"]] == ["q", "qd", "tau"]


# ----------------------------------------------------------------------------- friction and armature

FRICTION = [(0.8, 1.2, 0.1), (0.7, 1.1, -0.2), (0.5, 0.9, 0.0), (0.5, 0.8, 0.05), (0.3, 0.5, 0.0), (0.0, 0.4, 0.0),
            None]
ARMATURE = [0.3, 0.3, 0.2, 0.2, 0.1, 0.1, 0.05]


@pytest.fixture(scope="module", params=(None, 0.05), ids=("sign", "tanh"))
def effects_arm(request, tmp_path_factory):
    """The LWR with friction (sign or smoothed Coulomb) and armature, generated in C, Python
    and CasADi (only the functions tested here: an arm with effects must get them in
    fd_derivatives_no_minv too)."""
    smoothing = request.param
    data = yaml.safe_load((ROOT / "robots" / "lwr4.yaml").read_text())
    data["name"] = "lwr4_effects"
    for joint, friction, armature in zip(data["joints"], FRICTION, ARMATURE):
        if friction is not None:
            joint["friction"] = dict(zip(("viscous", "coulomb", "offset"), friction))
        joint["armature"] = armature
    if smoothing is not None:
        data["coulomb_smoothing"] = smoothing
    root = tmp_path_factory.mktemp("effects")
    path = root / "lwr4_effects.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    model = load_robot(path)
    folder = generate(model, root / "out", progress=False, only=set(NEW) | {NO_MINV})
    return model, folder, smoothing


@pytest.mark.parametrize("lang", LANGS)
def test_effects_match_pinocchio(effects_arm, lang):
    model, folder, smoothing = effects_arm
    pmodel, pdata, _ = pinocchio_model(model)
    pmodel.armature = np.array(ARMATURE)
    Q, QD, QDD, TAU = states(model.n, model.lower, model.upper, seed=5)
    fv, fc, f0 = (np.array([f[k] if f else 0.0 for f in FRICTION]) for k in range(3))
    if smoothing is None:
        shape, dshape = np.sign(QD), np.zeros_like(QD)
    else:
        shape = np.tanh(QD / smoothing)
        dshape = (1 - shape ** 2) / smoothing
    friction = (fv * QD + fc * shape + f0, fv + fc * dshape)
    expected = pinocchio_derivatives(pmodel, pdata, Q, QD, QDD, TAU, friction)
    lib = load_generated(folder, lang)
    check(lib.call, Q, QD, QDD, TAU, expected, f"effects ({'sign' if smoothing is None else 'tanh'}) {lang}",
          no_minv=True)
    note = "fc sign(qd) contributes 0 to the qd derivatives"
    assert (note in lib.functions["fd_derivatives"]["conventions"]) == (smoothing is None)


# ----------------------------------------------------------------------------- prismatic joint

@pytest.fixture(scope="module")
def slider_arm(tmp_path_factory):
    """tests/data/urdf/slider_arm.urdf: a prismatic lift in the middle of the chain, a fixed
    sensor block inside it, a tool; Pinocchio's own URDF parser is the reference."""
    path = ROOT / "tests" / "data" / "urdf" / "slider_arm.urdf"
    model = load_robot(path)
    folder = generate(model, tmp_path_factory.mktemp("slider"), progress=False, only=set(NEW))
    pmodel = pin.buildModelFromUrdf(str(path))
    assert [pmodel.names[i] for i in range(1, pmodel.njoints)] == [j.name for j in model.joints]
    assert np.allclose(pmodel.gravity.linear, [float(g) for g in model.gravity])
    return model, folder, pmodel


@pytest.mark.parametrize("lang", LANGS)
def test_prismatic_joint_matches_pinocchio(slider_arm, lang):
    model, folder, pmodel = slider_arm
    prismatic = np.array([j.prismatic for j in model.joints])
    assert prismatic.any()
    Q, QD, QDD, TAU = states(model.n, model.lower, model.upper, seed=8, prismatic=prismatic)
    expected = pinocchio_derivatives(pmodel, pmodel.createData(), Q, QD, QDD, TAU)
    lib = load_generated(folder, lang)
    check(lib.call, Q, QD, QDD, TAU, expected, f"slider_arm {lang}")
    units = {p["name"]: p["unit"] for name in NEW for p in lib.functions[name]["outputs"]}
    assert units["dtau_dq"].startswith("N m/rad between revolute joints; entry (i, j) is N m (revolute joint i) "
                                       "or N (prismatic) per rad (revolute joint j) or m (prismatic)")
    assert all(unit.endswith("prismatic joints 1 (0-based)") for unit in units.values())


# ----------------------------------------------------------------------------- URDF arms

URDF_STATES = 200


@pytest.fixture(scope="module", params=[arm[0] for arm in URDF_ARMS if arm[1] is not None])
def urdf_arm(request, tmp_path_factory):
    """The URDF arms of tests/algorithms/test_urdf_generated.py (UR5, xArm7, Z1, Kinova with continuous
    joints, ...) against Pinocchio's own parse of the same file, reduced to our chain."""
    key, file, tip, tip_frame, snap = next(arm for arm in URDF_ARMS if arm[0] == request.param)
    path = urdf_path(file)
    model = load_robot(path, snap_angles=snap, tip=tip)
    folder = generate(model, tmp_path_factory.mktemp(f"urdf_{key}"), progress=False, only=set(NEW))
    return key, model, folder, UrdfPinocchio(path, model, tip_frame)


@pytest.mark.parametrize("lang", LANGS)
def test_urdf_arms_match_pinocchio(urdf_arm, lang):
    key, model, folder, reference = urdf_arm
    prismatic = np.array([j.prismatic for j in model.joints])
    rng = np.random.default_rng(31)
    Q = rng.uniform(model.lower, model.upper, size=(URDF_STATES, model.n))
    QD, QDD, TAU = (rng.uniform(-a, a, (URDF_STATES, model.n)) for a in (2, 5, 20))
    QD, QDD = QD * np.where(prismatic, 0.25, 1.0), QDD * np.where(prismatic, 0.4, 1.0)
    idx = [joint.idx_v for joint in reference.joints]
    out = {k: [] for k in ("dtau_dq", "dtau_dqd", "dqdd_dq", "dqdd_dqd", "Minv")}
    pmodel, pdata = reference.model, reference.data
    for q, qd, qdd, tau in zip(Q, QD, QDD, TAU):
        config, v = reference.q(q), reference.v(qd)
        dq, dv, _ = pin.computeRNEADerivatives(pmodel, pdata, config, v, reference.v(qdd))
        out["dtau_dq"].append(dq[np.ix_(idx, idx)])
        out["dtau_dqd"].append(dv[np.ix_(idx, idx)])
        pin.computeABADerivatives(pmodel, pdata, config, v, reference.v(tau))
        out["dqdd_dq"].append(pdata.ddq_dq[np.ix_(idx, idx)])
        out["dqdd_dqd"].append(pdata.ddq_dv[np.ix_(idx, idx)])
        out["Minv"].append(symmetric(pdata.Minv)[np.ix_(idx, idx)])
    expected = {k: np.array(v) for k, v in out.items()}
    check(load_generated(folder, lang).call, Q, QD, QDD, TAU, expected, f"{key} {lang}")


# ----------------------------------------------------------------------------- the derivation itself

DERIVED_STATES = 200


def derived_call(functions, extra):
    """Evaluate derived SymbolicFunctions (symengine Lambdify, no generated code) on batches;
    ``extra``: the inputs beyond the joint-space ones (p, lengths), the same for every state."""
    compiled = {f.name: (f, se.Lambdify([s for syms in f.input_symbols for s in syms],
                                        [e for exprs in f.inlined_outputs() for e in exprs], cse=True)) for f in functions}

    def call(name, inputs):
        f, fn = compiled[name]
        rows = [np.concatenate([np.ravel(inputs[p.name][k]) if p.name in inputs else np.ravel(extra[p.name])
                                for p in f.inputs]) for k in range(len(inputs["q"]))]
        out = np.array([fn(row) for row in rows])
        result, start = {}, 0
        for p in f.outputs:
            result[p.name] = out[:, start:start + p.size].reshape((len(rows),) + p.shape)
            start += p.size
        return result
    return call


@pytest.mark.parametrize("params", ("numeric", "symbolic"))
def test_derivation_matches_pinocchio(params):
    """The derived expressions in both params modes (symbolic: p = the description's values)."""
    r = robot("lwr4")
    Q, QD, QDD, TAU = (x[:DERIVED_STATES] for x in states(r.n, r.lower, r.upper, seed=23))
    model, data, _ = pinocchio_model(r)
    expected = pinocchio_derivatives(model, data, Q, QD, QDD, TAU)
    extra = {"p": parameter_vector(r)} if params == "symbolic" else {}
    call = derived_call(derive_all(r, params, only=set(NEW)), extra)
    check(call, Q, QD, QDD, TAU, expected, f"derived lwr4 ({params} parameters)")


def test_symbolic_lengths_match_pinocchio(tmp_path):
    """DH lengths given as names (input ``lengths``), evaluated at the LWR's values."""
    text = (ROOT / "robots" / "lwr4.yaml").read_text().replace("d: 0.40,", "d: l1,").replace("d: 0.39,", "d: l2,")
    path = tmp_path / "lwr4_lengths.yaml"
    path.write_text(text)
    symbolic, r = load_robot(path), robot("lwr4")
    assert [str(s) for s in symbolic.length_symbols] == ["l1", "l2"]
    Q, QD, QDD, TAU = (x[:DERIVED_STATES] for x in states(r.n, r.lower, r.upper, seed=29))
    model, data, _ = pinocchio_model(r)
    expected = pinocchio_derivatives(model, data, Q, QD, QDD, TAU)
    call = derived_call(derive_all(symbolic, "numeric", only=set(NEW)), {"lengths": np.array([0.40, 0.39])})
    check(call, Q, QD, QDD, TAU, expected, "derived lwr4 (symbolic lengths)")
