"""Code generated for robots with mimic joints equals Pinocchio, in the independent coordinates.

Robots: ``examples/mimic/panda_hand.urdf`` (example-robot-data's ``panda.urdf``) read as a tree
(the arm and its hand, whose ``panda_finger_joint2`` mimics ``panda_finger_joint1``),
``examples/mimic/gripper.urdf``
(a Robotiq-2F-85-like gripper: ``finger_joint`` and five joints mimicking it with multipliers
+1 and -1), fixed and floating, and ``tests/data/urdf/mimic_coupled_tree.urdf`` (a prismatic
joint following a revolute one at 0.05 m/rad with an offset, a joint following a joint of
the other branch at -0.5 with an offset, and a mimic of that mimic).

Two references, neither sharing code with KinDynGen:

* **An independent reduction** of Pinocchio's model *without* mimics
  (``buildModelFromUrdf(path)``): the map ``q_full = G q + b`` is read from the URDF's
  ``<mimic>`` tags here (ElementTree, chains followed), and every function is computed from
  the full model at ``(G q + b, G qd, G qdd)``: poses, ``J G``, ``G^T M G``, ``G^T g``,
  ``G^T c``, ``G^T rnea``, fd as ``solve(G^T M G, tau - G^T nle)``, centre of mass, ``J_com G``,
  ``A_g G``, the derivatives ``G^T (dtau/dq) G`` from Pinocchio's analytical
  ``computeRNEADerivatives`` (at ``qdd = G fd`` and times ``-M_red^-1`` for fd's) and ``M_red^-1``.
* **Pinocchio's own mimic support** (``buildModelFromUrdf(path, mimic=True)``, Pinocchio >= 3.4)
  where it has it: ``framesForwardKinematics``, ``getFrameJacobian``, ``crba``,
  ``computeGeneralizedGravity``, ``nonLinearEffects``, ``rnea``, ``centerOfMass``,
  ``jacobianCenterOfMass`` and ``computeCentroidalMap`` (Pinocchio 4.1's ``aba``, the
  derivatives and the regressor refuse mimic joints; its parser refuses a mimic of a mimic
  and a prismatic joint mimicking a revolute one, so the coupled tree has the first reference
  only).

Every generated function (C and Python; CasADi for the gripper) at 300 random states; error
per state relative to the reference's largest entry at that state (the gripper's inertias are
1e-6 kg m^2: an absolute tolerance would hide everything; parts and derivatives of tau and
fd against those too, see FAMILY); tolerance 1e-12.
"""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from kindyngen.codegen.pipeline import generate
from kindyngen.readers.urdf import load_urdf
from kindyngen.runtime.evaluate import load_generated
from tests.harness import ROOT

pin = pytest.importorskip("pinocchio")

N = 300
TOLERANCE = 1e-12
DATA = Path(__file__).resolve().parents[1] / "data" / "urdf"

# (id, file (in the checkout), frames (None: the tips), floating, languages)
CASES = [
    ("panda_hand", "examples/mimic/panda_hand.urdf", ["panda_hand", "panda_leftfinger", "panda_rightfinger"], False, ("c", "python")),
    ("gripper", "examples/mimic/gripper.urdf", ["left_pad", "right_pad", "left_inner_knuckle", "right_outer_finger"], False,
     ("c", "python", "casadi")),
    ("gripper", "examples/mimic/gripper.urdf", ["left_pad", "right_pad"], True, ("c", "python")),
    ("coupled", "tests/data/urdf/mimic_coupled_tree.urdf", ["l4", "m3", "l3"], False, ("c", "python")),
]
OUTPUTS = {"fk_hom": ("T",), "jacobian": ("J",), "M": ("M",), "g": ("g",), "c": ("c",), "tau": ("tau",), "fd": ("qdd",),
           "com": ("com", "J_com", "A_g"), "tau_derivatives": ("dtau_dq", "dtau_dqd"),
           "fd_derivatives": ("dqdd_dq", "dqdd_dqd", "Minv"), "fd_derivatives_no_minv": ("dqdd_dq", "dqdd_dqd")}


def _path(file) -> Path:
    return ROOT / file


# an output that is a part of another (c of tau) or its derivative is measured against the
# larger of its own and that one's largest entry at the state: the gripper's c is identically
# zero (its bodies' inertia about the finger joint does not depend on it: the inner fingers
# translate), and so is dc/dqd, which the references give as rounding noise
FAMILY = {"c": "tau", "dtau_dq": "tau", "dtau_dqd": "tau", "dqdd_dq": "qdd", "dqdd_dqd": "qdd"}


def relative_error(got, expected, floor=None) -> float:
    """Largest |got - expected| per state over the largest |expected| of that state (or of
    ``floor``'s, if larger; 1 where both are zero)."""
    n = got.shape[0]
    diff = np.abs(got - expected).reshape(n, -1).max(axis=1)
    scale = np.abs(expected).reshape(n, -1).max(axis=1)
    if floor is not None:
        scale = np.maximum(scale, np.abs(floor).reshape(n, -1).max(axis=1))
    return float((diff / np.where(scale > 0, scale, 1.0)).max())


def mimic_map(path: Path, pmodel, floating: bool):
    """(G, b, independent joint names) of the URDF's <mimic> tags over Pinocchio's joint order,
    chains followed: q_full = G q + b (joints part; a floating base's 7/6 pass through)."""
    rules = {}
    for joint in ET.parse(path).getroot().findall("joint"):
        mimic = joint.find("mimic")
        if mimic is not None and joint.get("type") != "fixed":
            rules[joint.get("name")] = (mimic.get("joint"), float(mimic.get("multiplier", 1)),
                                        float(mimic.get("offset", 0)))
    names = list(pmodel.names)[2 if floating else 1:]
    independent = [name for name in names if name not in rules]
    base = 6 if floating else 0
    G = np.zeros((base + len(names), base + len(independent)))
    G[:base, :base] = np.eye(base)
    b = np.zeros(len(names))
    for row, name in enumerate(names):
        multiplier, offset = 1.0, 0.0
        while name in rules:
            name, m, o = rules[name]
            multiplier, offset = multiplier * m, offset + multiplier * o
        G[base + row, base + independent.index(name)] = multiplier
        b[row] = offset
    return G, b, independent


def full_configuration(q, G, b, floating: bool):
    base, vbase = (7, 6) if floating else (0, 0)
    return np.r_[q[:base], G[vbase:, vbase:] @ q[base:] + b]


def symmetric(M):
    return np.triu(M) + np.triu(M, 1).T


def independent_reduction(path, floating, frames, Q, QD, QDD, TAU):
    pmodel = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) if floating else pin.buildModelFromUrdf(str(path))
    assert pmodel.nq == pmodel.nv + floating, "a continuous joint: not in these tests"
    data = pmodel.createData()
    G, b, independent = mimic_map(path, pmodel, floating)
    ids = [pmodel.getFrameId(f) for f in frames]
    out = {key: [] for name in OUTPUTS.values() for key in name}
    for q, qd, qdd, tau in zip(Q, QD, QDD, TAU):
        x = full_configuration(q, G, b, floating)
        pin.framesForwardKinematics(pmodel, data, x)
        out["T"].append([data.oMf[f].homogeneous for f in ids])
        pin.computeJointJacobians(pmodel, data, x)
        out["J"].append([pin.getFrameJacobian(pmodel, data, f, pin.LOCAL_WORLD_ALIGNED) @ G for f in ids])
        M = G.T @ symmetric(pin.crba(pmodel, data, x)) @ G
        g = G.T @ pin.computeGeneralizedGravity(pmodel, data, x)
        nle = G.T @ pin.nonLinearEffects(pmodel, data, x, G @ qd)
        out["M"].append(M)
        out["g"].append(g)
        out["c"].append(nle - g)
        out["tau"].append(G.T @ pin.rnea(pmodel, data, x, G @ qd, G @ qdd))
        acc = np.linalg.solve(M, tau - nle)
        out["qdd"].append(acc)
        out["com"].append(pin.centerOfMass(pmodel, data, x).copy())
        out["J_com"].append(pin.jacobianCenterOfMass(pmodel, data, x) @ G)
        out["A_g"].append(pin.computeCentroidalMap(pmodel, data, x) @ G)
        dq, dqd, _ = pin.computeRNEADerivatives(pmodel, data, x, G @ qd, G @ qdd)
        out["dtau_dq"].append(G.T @ dq @ G)
        out["dtau_dqd"].append(G.T @ dqd @ G)
        dq, dqd, _ = pin.computeRNEADerivatives(pmodel, data, x, G @ qd, G @ acc)
        Minv = np.linalg.inv(M)
        out["dqdd_dq"].append(-Minv @ G.T @ dq @ G)
        out["dqdd_dqd"].append(-Minv @ G.T @ dqd @ G)
        out["Minv"].append(Minv)
    return {key: np.array(value) for key, value in out.items()}, independent


def pinocchio_mimic(path, floating, frames, Q, QD, QDD):
    """What Pinocchio's mimic model gives (None where its parser refuses the file)."""
    try:
        pmodel = (pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer(), mimic=True) if floating
                  else pin.buildModelFromUrdf(str(path), mimic=True))
    except (RuntimeError, ValueError):
        return None
    data, nv = pmodel.createData(), pmodel.nv
    ids = [pmodel.getFrameId(f) for f in frames]
    out = {key: [] for key in ("T", "J", "M", "g", "c", "tau", "com", "J_com", "A_g")}
    for q, qd, qdd in zip(Q, QD, QDD):
        pin.framesForwardKinematics(pmodel, data, q)
        out["T"].append([data.oMf[f].homogeneous for f in ids])
        pin.computeJointJacobians(pmodel, data, q)
        # with one velocity coordinate Pinocchio gives matrices as vectors: shaped back here
        out["J"].append([pin.getFrameJacobian(pmodel, data, f, pin.LOCAL_WORLD_ALIGNED).reshape(6, nv) for f in ids])
        out["M"].append(symmetric(pin.crba(pmodel, data, q).reshape(nv, nv)))
        g = pin.computeGeneralizedGravity(pmodel, data, q).copy()
        out["g"].append(g)
        out["c"].append(pin.nonLinearEffects(pmodel, data, q, qd) - g)
        out["tau"].append(pin.rnea(pmodel, data, q, qd, qdd).copy())
        out["com"].append(pin.centerOfMass(pmodel, data, q).copy())
        out["J_com"].append(pin.jacobianCenterOfMass(pmodel, data, q).reshape(3, nv))
        out["A_g"].append(pin.computeCentroidalMap(pmodel, data, q).reshape(6, nv))
    return {key: np.array(value) for key, value in out.items()}


def random_states(model, rng):
    """N states: the independent joints within their limits, a floating base within 1 m with
    any unit quaternion; velocities, accelerations and torques uniform."""
    Q = rng.uniform(model.lower, model.upper, size=(N, model.nv - (6 if model.floating_base else 0)))
    if model.floating_base:
        quat = rng.standard_normal((N, 4))
        Q = np.hstack([rng.uniform(-1, 1, (N, 3)), quat / np.linalg.norm(quat, axis=1, keepdims=True), Q])
    nv = model.nv
    return Q, rng.uniform(-2, 2, (N, nv)), rng.uniform(-5, 5, (N, nv)), rng.uniform(-1, 1, (N, nv))


@pytest.fixture(scope="module", params=CASES, ids=[f"{c[0]}-{'floating' if c[3] else 'fixed'}" for c in CASES])
def case(request, tmp_path_factory):
    key, file, frames, floating, langs = request.param
    path = _path(file)
    model = load_urdf(path, tree=True, frames=frames, floating_base=floating)
    folder = generate(model, tmp_path_factory.mktemp(f"mimic_{key}"), languages=langs, progress=False)
    rng = np.random.default_rng(20260301)
    Q, QD, QDD, TAU = random_states(model, rng)
    reduction, independent = independent_reduction(path, floating, frames, Q, QD, QDD, TAU)
    inputs = {"fk_hom": {"q": Q}, "jacobian": {"q": Q}, "M": {"q": Q}, "g": {"q": Q}, "com": {"q": Q},
              "c": {"q": Q, "qd": QD}, "tau": {"q": Q, "qd": QD, "qdd": QDD},
              "tau_derivatives": {"q": Q, "qd": QD, "qdd": QDD}, "fd": {"q": Q, "qd": QD, "tau": TAU},
              "fd_derivatives": {"q": Q, "qd": QD, "tau": TAU}, "fd_derivatives_no_minv": {"q": Q, "qd": QD, "tau": TAU}}
    return {"key": key, "model": model, "folder": folder, "langs": langs, "inputs": inputs, "reduction": reduction,
            "independent": independent, "pinocchio": pinocchio_mimic(path, floating, frames, Q, QD, QDD)}


@pytest.mark.parametrize("lang", ("c", "python", "casadi"))
def test_every_function_equals_the_independent_reduction(case, lang):
    """Every function the catalog gives a tree, generated, equals the reduction of Pinocchio's
    model without mimics; the interface lists exactly these functions."""
    if lang not in case["langs"]:
        pytest.skip(f"{lang} is checked on another case")
    library = load_generated(case["folder"], lang)
    names = {f["name"] for f in json.loads((case["folder"] / "functions.json").read_text())["functions"]}
    assert names == set(OUTPUTS) | {"Y"}, names
    errors = {}
    for function, ports in OUTPUTS.items():
        out = library.call(function, case["inputs"][function])
        for port in ports:
            expected = case["reduction"][port]
            assert out[port].shape == expected.shape, f"{function}.{port}: {out[port].shape} != {expected.shape}"
            floor = case["reduction"][FAMILY[port]] if port in FAMILY else None
            errors[f"{function}.{port}"] = relative_error(out[port], expected, floor)
    print(case["key"], lang, {k: f"{v:.1e}" for k, v in errors.items()})
    bad = {k: v for k, v in errors.items() if not v <= TOLERANCE}
    assert not bad, f"{case['key']} {lang}: relative errors above {TOLERANCE:g}: {bad}"


def test_pinocchio_mimic_model_agrees(case):
    """Where Pinocchio's own mimic model works, the generated functions equal it too (and so
    does the independent reduction: the two references agree)."""
    reference = case["pinocchio"]
    if reference is None:
        assert case["key"] == "coupled", "Pinocchio's parser refused a file it should read"
        pytest.skip("Pinocchio refuses a mimic of a mimic and a prismatic joint mimicking a revolute one")
    library = load_generated(case["folder"], "python")
    errors = {}
    for function in ("fk_hom", "jacobian", "M", "g", "c", "tau", "com"):
        out = library.call(function, case["inputs"][function])
        for port in OUTPUTS[function]:
            floor = reference[FAMILY[port]] if port in FAMILY else None
            errors[port] = relative_error(out[port], reference[port], floor)
            assert relative_error(case["reduction"][port], reference[port], floor) <= TOLERANCE, port
    print(case["key"], {k: f"{v:.1e}" for k, v in errors.items()})
    assert max(errors.values()) <= TOLERANCE, errors


@pytest.mark.parametrize("lang", ("c", "python"))
def test_regressor_in_reduced_coordinates(case, lang):
    """Y(q, qd, qdd) times the base values of base_params.json is the reduced torque, with full
    column rank on the samples and fewer columns than the 10 per body. Where a grouping
    coefficient is irrational (the coupled tree's rpy 0.3: cos(0.3)^2) base_params.json keeps it
    to 12 significant digits and says "exact": false (Y itself is exact): tolerance 1e-10 there."""
    document = json.loads((case["folder"] / "base_params.json").read_text())["Y"]
    assert "unavailable" not in document, document.get("unavailable")
    Y = load_generated(case["folder"], lang).call("Y", case["inputs"]["tau"])["Y"]
    assert Y.shape[1:] == (case["model"].nv, len(document["names"]))
    assert len(document["names"]) == document["rank"] < document["full_columns"]
    error = relative_error(Y @ np.array(document["values"]), case["reduction"]["tau"])
    print(case["key"], lang, "Y", f"{error:.1e}", "exact" if document["exact"] else "12 digits")
    assert error <= (TOLERANCE if document["exact"] else 1e-10), f"{case['key']} {lang}: {error:.3e}"
    assert np.linalg.matrix_rank(Y[:40].reshape(-1, Y.shape[2])) == Y.shape[2]


def test_interface_names_the_inputs_and_the_mimics(case):
    """functions.json and the C header say which joints are inputs (by name, in order) and
    which mimic which; every q port has the independent joints' size."""
    model = case["model"]
    document = json.loads((case["folder"] / "functions.json").read_text())
    assert document["coordinates"] == case["independent"]
    rules = {m["joint"]: m["mimics"] for m in document["mimics"]}
    assert set(rules) == {j.name for j in model.joints} - set(case["independent"])
    assert set(rules.values()) <= set(case["independent"])
    for function in document["functions"]:
        for port in function["inputs"]:
            if port["name"] == "q":
                assert port["shape"] == [model.nq] and ", ".join(case["independent"]) in port["description"]
        assert "Mimic joints:" in function["conventions"]
    header = " ".join((case["folder"] / "c" / f"{model.identifier}.h").read_text().replace(" * ", " ").split())
    first = next(j for j in model.joints if j.mimic is not None)
    assert f"{first.name} = " in header and "mimic" in header
