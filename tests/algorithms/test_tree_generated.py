"""Code generated for kinematic trees, fixed and floating base, equals Pinocchio.

Robots: two humanoids and a quadruped of ``example-robot-data`` (Unitree G1, 29 joints; PAL
Talos reduced, 32 joints; Solo12) and ``tests/data/urdf/mobile_slider_tree.urdf`` (a
prismatic lift carrying an arm beside a leg, a continuous joint on a skewed axis, fixed
links with mass, rpy angles that are not multiples of pi/12), each with a fixed base
(``pin.buildModelFromUrdf(path)``) and a floating one (``JointModelFreeFlyer``). The
generated fk_hom and jacobian of the requested frames, M, g, c, tau, fd and com (centre of
mass, its Jacobian, the centroidal momentum matrix), in C, Python and CasADi, are compared at
1000 random states with Pinocchio's framesForwardKinematics / getFrameJacobian
(LOCAL_WORLD_ALIGNED), crba, computeGeneralizedGravity, nonLinearEffects - g, rnea, aba,
centerOfMass, jacobianCenterOfMass and computeCentroidalMap. Our joints are in Pinocchio's
order (checked by name); a continuous joint is (cos q, sin q) in Pinocchio's configuration.

Tolerance: per state, |ours - Pinocchio| <= 1e-9 * max(1, max |Pinocchio's value|).
"""
from __future__ import annotations

import importlib.metadata
import json
from pathlib import Path

import numpy as np
import pytest

from kindyngen.runtime.evaluate import load_generated
from kindyngen.codegen.interface import manifest
from kindyngen.codegen.optimize import optimize
from kindyngen.codegen.pipeline import generate
from kindyngen.codegen.render import RENDERERS
from kindyngen.algorithms.articulated_body import forward_dynamics_aba
from kindyngen.algorithms.dynamics import forward_dynamics_tree
from kindyngen.readers.urdf import load_urdf

pin = pytest.importorskip("pinocchio")

N = 1000
TOLERANCE = 1e-9
LANGS = ("c", "python", "casadi")
DATA = Path(__file__).resolve().parents[1] / "data" / "urdf"

# (id, file under example-robot-data's robots folder (None: DATA), frames (None: the tips))
ROBOTS = [
    ("g1", "g1_description/urdf/g1_29dof_rev_1_0.urdf", None),
    ("talos", "talos_data/robots/talos_reduced.urdf", ["leg_left_6_link", "arm_right_7_link", "torso_2_link"]),
    ("solo12", "solo_description/robots/solo12.urdf", None),
    ("mobile_slider_tree", None, ["gripper_frame", "foot", "battery", "chassis"]),
]
CASES = [(robot, floating) for robot in ROBOTS for floating in (False, True)]


def _path(file) -> Path:
    if file is None:
        return DATA / "mobile_slider_tree.urdf"
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")) / file


def scaled_error(got, expected) -> float:
    """Largest |got - expected| per state, scaled by max(1, largest |expected|) of that state."""
    n = got.shape[0]
    diff = np.abs(got - expected).reshape(n, -1).max(axis=1)
    scale = np.maximum(1.0, np.abs(expected).reshape(n, -1).max(axis=1))
    return float((diff / scale).max())


def random_states(model, rng):
    """N random states: base anywhere within 1 m, any unit quaternion; joints within limits."""
    Q = rng.uniform(model_lower(model), model_upper(model), size=(N, model.n))
    if model.floating_base:
        quat = rng.standard_normal((N, 4))
        quat /= np.linalg.norm(quat, axis=1, keepdims=True)
        Q = np.hstack([rng.uniform(-1, 1, (N, 3)), quat, Q])
    nv = model.nv
    return Q, rng.uniform(-2, 2, (N, nv)), rng.uniform(-5, 5, (N, nv)), rng.uniform(-20, 20, (N, nv))


def model_lower(model):
    return np.array([max(j.lower, -np.pi) for j in model.joints])


def model_upper(model):
    return np.array([min(j.upper, np.pi) for j in model.joints])


def pinocchio_references(path, model, Q, QD, QDD, TAU):
    pmodel = (pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) if model.floating_base
              else pin.buildModelFromUrdf(str(path)))
    first = 2 if model.floating_base else 1
    assert list(pmodel.names)[first:] == [j.name for j in model.joints], "joint order differs from Pinocchio's"
    assert pmodel.nv == model.nv
    data = pmodel.createData()
    frames = [pmodel.getFrameId(f.name) for f in model.frames]
    base = 7 if model.floating_base else 0
    out = {key: [] for key in ("T", "J", "M", "g", "c", "tau", "qdd", "com", "J_com", "A_g")}
    for q, qd, qdd, tau in zip(Q, QD, QDD, TAU):
        pq = list(q[:base])
        for j in range(model.n):
            idx = pmodel.joints[first + j].nq
            pq += [np.cos(q[base + j]), np.sin(q[base + j])] if idx == 2 else [q[base + j]]
        pq = np.array(pq)
        pin.framesForwardKinematics(pmodel, data, pq)
        out["T"].append([data.oMf[f].homogeneous for f in frames])
        pin.computeJointJacobians(pmodel, data, pq)
        out["J"].append([pin.getFrameJacobian(pmodel, data, f, pin.LOCAL_WORLD_ALIGNED) for f in frames])
        M = pin.crba(pmodel, data, pq)
        out["M"].append(np.triu(M) + np.triu(M, 1).T)
        g = pin.computeGeneralizedGravity(pmodel, data, pq).copy()
        out["g"].append(g)
        out["c"].append(pin.nonLinearEffects(pmodel, data, pq, qd) - g)
        out["tau"].append(pin.rnea(pmodel, data, pq, qd, qdd).copy())
        out["qdd"].append(pin.aba(pmodel, data, pq, qd, tau).copy())
        out["com"].append(pin.centerOfMass(pmodel, data, pq).copy())
        out["J_com"].append(pin.jacobianCenterOfMass(pmodel, data, pq).copy())
        out["A_g"].append(pin.computeCentroidalMap(pmodel, data, pq).copy())
    return {key: np.array(value) for key, value in out.items()}


@pytest.fixture(scope="module", params=CASES, ids=[f"{r[0]}-{'floating' if f else 'fixed'}" for r, f in CASES])
def case(request, tmp_path_factory):
    (key, file, frames), floating = request.param
    path = _path(file)
    model = load_urdf(path, tree=True, frames=frames, floating_base=floating)
    # the derivatives of these trees are checked in test_tree_derivatives.py (a humanoid's take minutes)
    folder = generate(model, tmp_path_factory.mktemp(f"tree_{key}"), languages=LANGS, progress=False,
                      only={"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com", "Y"})
    rng = np.random.default_rng(20261129)
    Q, QD, QDD, TAU = random_states(model, rng)
    ref = pinocchio_references(path, model, Q, QD, QDD, TAU)
    calls = {"fk_hom": ({"q": Q}, {"T": ref["T"]}), "jacobian": ({"q": Q}, {"J": ref["J"]}),
             "M": ({"q": Q}, {"M": ref["M"]}), "g": ({"q": Q}, {"g": ref["g"]}),
             "c": ({"q": Q, "qd": QD}, {"c": ref["c"]}), "tau": ({"q": Q, "qd": QD, "qdd": QDD}, {"tau": ref["tau"]}),
             "fd": ({"q": Q, "qd": QD, "tau": TAU}, {"qdd": ref["qdd"]}),
             "com": ({"q": Q}, {name: ref[name] for name in ("com", "J_com", "A_g")})}
    return {"key": key, "model": model, "folder": folder, "calls": calls}


@pytest.mark.parametrize("lang", LANGS)
def test_generated_tree_equals_pinocchio(case, lang):
    library = load_generated(case["folder"], lang)
    errors = {}
    for function, (inputs, expected) in case["calls"].items():
        out = library.call(function, inputs)
        for name, value in expected.items():
            assert out[name].shape == value.shape, f"{function}.{name}: shape {out[name].shape} != {value.shape}"
            errors[f"{function}.{name}"] = scaled_error(out[name], value)
    print(case["key"], lang, {k: f"{v:.1e}" for k, v in errors.items()})
    bad = {k: v for k, v in errors.items() if not v <= TOLERANCE}
    assert not bad, f"{case['key']} {lang}: scaled errors above {TOLERANCE:g}: {bad}"


def test_inertia_between_branches_is_exactly_zero(case):
    """M's entries between joints on different branches are exact zeros in the generated
    code (not computed), and so are the fd factor's: the cost follows the tree."""
    model = case["model"]
    base = 6 if model.floating_base else 0
    library = load_generated(case["folder"], "python")
    Q = np.array([np.r_[[0.1, 0.2, 0.3, 0, 0, 0, 1] if model.floating_base else [], model_lower(model) * 0.5]])
    M = library.call("M", {"q": Q})["M"][0]
    for i in range(model.n):
        for j in range(model.n):
            related = i in model.ancestors(j) or j in model.ancestors(i)
            if not related:
                assert M[base + i, base + j] == 0.0
    assert np.all(np.linalg.eigvalsh(M) > 0)


@pytest.mark.parametrize("lang", ("c", "python"))
def test_tree_regressor_on_base_parameters_equals_pinocchio(case, lang):
    """Y(q, qd, qdd) times the base values of base_params.json is Pinocchio's rnea; the base
    parameters are fewer than the full 10 per body and Y has full column rank on the samples."""
    document = json.loads((case["folder"] / "base_params.json").read_text())["Y"]
    assert "unavailable" not in document, document.get("unavailable")
    inputs, expected = case["calls"]["tau"]
    Y = load_generated(case["folder"], lang).call("Y", inputs)["Y"]
    assert Y.shape[2] == len(document["names"]) == document["rank"] < document["full_columns"]
    error = scaled_error(Y @ np.array(document["values"]), expected["tau"])
    assert error <= TOLERANCE, f"{case['key']} {lang}: max scaled error {error:.3e}"
    stacked = Y[:40].reshape(-1, Y.shape[2])
    assert np.linalg.matrix_rank(stacked) == Y.shape[2]


def test_both_fd_routes_equal_pinocchio_and_the_cheaper_is_generated(case, tmp_path):
    """fd's two routes, the sparse L^T D L and the articulated-body algorithm, equal Pinocchio's
    aba: the generated ``fd`` is one of them (checked in every language above); the other is
    derived again here, rendered as its own function (C and Python) and checked the same way
    (deriving the chosen one again would only repeat generate's work). The generated ``fd`` is
    the route with fewer additions + multiplications after CSE among the routes opcounts.json
    records, the re-derived one's count among them, and its header says so."""
    model = case["model"]
    recorded = json.loads((case["folder"] / "opcounts.json").read_text())["fd"]
    routes = {"sparse L^T D L": lambda: forward_dynamics_tree(model, name="fd_ltdl"),
              "articulated-body": lambda: forward_dynamics_aba(model, name="fd_aba")}
    assert set(recorded["routes"]) == set(routes) and recorded["route"] in routes
    other = next(name for name in routes if name != recorded["route"])
    program = optimize(routes[other]())
    assert program.after.to_json() == recorded["routes"][other], "the route derived here is not generate's"
    (tmp_path / "functions.json").write_text(json.dumps(manifest(model, [program], "numeric")))
    for lang in ("c", "python"):
        for filename, text in RENDERERS[lang](model, [program]).items():
            (tmp_path / lang).mkdir(exist_ok=True)
            (tmp_path / lang / filename).write_text(text)
    inputs, expected = case["calls"]["fd"]
    for lang in ("c", "python"):
        error = scaled_error(load_generated(tmp_path, lang).call(program.function.name, inputs)["qdd"], expected["qdd"])
        assert error <= TOLERANCE, f"{case['key']} {program.function.name} {lang}: {error:.3e}"
    costs = {name: count["add"] + count["mul"] for name, count in recorded["routes"].items()}
    assert recorded["after"]["add"] + recorded["after"]["mul"] == costs[recorded["route"]] == min(costs.values())
    if costs[other] == costs[recorded["route"]]:
        assert recorded["route"] == "sparse L^T D L"          # a tie keeps the first route
    ltdl, aba = recorded["routes"]["sparse L^T D L"], recorded["routes"]["articulated-body"]
    header = (case["folder"] / "c" / f"{model.identifier}.h").read_text()
    assert "Route chosen by the fewest additions + multiplications after CSE: sparse L^T D L " \
        f"{ltdl['add']} + {ltdl['mul']}; articulated-body {aba['add']} + {aba['mul']}." in " ".join(header.split())
