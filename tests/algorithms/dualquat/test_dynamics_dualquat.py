"""The dual-quaternion dynamics route (tau_dq, M_dq, g_dq, c_dq, Y_dq of
kindyngen/algorithms/dualquat/dq_dynamics.py), generated in C, Python and CasADi, equals Pinocchio at 1000
random states: rnea (plus the description's friction, offset and armature torques written out
here), crba (plus the armature), computeGeneralizedGravity, nonLinearEffects - gravity, and
Y_dq times the base parameter values of base_params.json equals rnea (+ effects).

Robots: robots/lwr4.yaml and robots/panda.yaml (Pinocchio from tests/reference.py), and a
5-joint arm given by origins and axes (``dh: none``) with a prismatic joint along a tilted
axis, non-axis-aligned origins, friction, armature and a payload (Pinocchio from the same arm
written as URDF text, the payload appended to the last joint).  Also: the symbolic-parameter
build with p = the numeric parameter vector equals the numeric build.

Tolerance: per state, |ours - Pinocchio| <= 1e-9 * max(1, max |Pinocchio's value|).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from tests.harness import ROOT
from kindyngen.runtime.evaluate import load_generated
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot

pin = pytest.importorskip("pinocchio")
from tests.reference import pinocchio_model  # noqa: E402

N = 1000
TOLERANCE = 1e-9
LANGS = ("c", "python", "casadi")
DQ = ("tau_dq", "M_dq", "g_dq", "c_dq")
ONLY = set(DQ) | {"Y_dq", "Y"}

# --------------------------------------------------------------------------- the prismatic arm
# joint: name, type, origin xyz, rpy, axis, lower, upper, (viscous, coulomb, offset), armature
JOINTS = [
    ("turret", "revolute", (0, 0, 0.3), (0, 0, 0), (0, 0, 1), -2.9, 2.9, (0.8, 1.2, 0.1), 0.3),
    ("slide", "prismatic", (0.1, 0.02, 0.2), (0.3, 0, 0), (0, 1, 0), -0.2, 0.3, (20.0, 5.0, -0.5), 2.5),
    ("shoulder", "revolute", (0.05, 0.02, 0.1), (0.2, 0, -0.4), (0, -1, 0), -2.0, 2.0, (0.5, 0.9, 0.0), 0.2),
    ("elbow", "revolute", (0.3, 0, 0), (0, 0, 0), (1, 0, 0), -2.5, 2.5, (0.3, 0.4, 0.05), 0.1),
    ("wrist", "revolute", (0.1, 0, 0.05), (1.5707963267948966, 0, 0), (0, 0, 1), -3.0, 3.0, (0.1, 0.2, 0.0), 0.05),
]
# link: mass, com, inertia about the com (ixx, iyy, izz, ixy, ixz, iyz)
LINKS = [
    (3.0, (0.01, -0.005, 0.12), (0.054, 0.052, 0.0073, 0.0003, -0.0008, 0.0019)),
    (1.5, (0.03, 0.01, 0.02), (0.0031, 0.0042, 0.0037, -0.0004, 0.0005, -0.0003)),
    (2.2, (0.17, 0.004, -0.008), (0.0029, 0.0307, 0.0303, -0.0014, -0.0022, -0.0001)),
    (1.3, (0.14, -0.006, 0.003), (0.0086, 0.0114, 0.0115, -0.0007, 0.0005, 0.0004)),
    (0.5, (0.03, 0.002, 0.04), (0.0030, 0.0042, 0.0042, -0.0002, -0.0005, -0.0001)),
]
PAYLOAD = {"mass": 0.4, "com": [0.01, -0.02, 0.06], "inertia": [0.0004, 0.0005, 0.0003, 0.00002, 0, -0.00001]}


def _description() -> dict:
    joints = [{"name": name, "type": kind, "origin": {"xyz": list(xyz), "rpy": list(rpy)}, "axis": list(axis),
               "lower": lower, "upper": upper, "friction": dict(zip(("viscous", "coulomb", "offset"), friction)),
               "armature": armature}
              for name, kind, xyz, rpy, axis, lower, upper, friction, armature in JOINTS]
    links = [{"mass": m, "com": list(c), "inertia": list(i)} for m, c, i in LINKS]
    return {"name": "dq_slider", "dh": "none", "gravity": [0, 0, -9.81], "joints": joints, "links": links,
            "payload": PAYLOAD}


def _urdf() -> str:
    """The same arm (rigid bodies) as URDF text: link i is joint i's child."""
    def inertial(m, c, i):
        ixx, iyy, izz, ixy, ixz, iyz = i
        return (f'<inertial><origin xyz="{c[0]} {c[1]} {c[2]}" rpy="0 0 0"/><mass value="{m}"/>'
                f'<inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" izz="{izz}"/></inertial>')
    parts = ['<robot name="dq_slider">', '<link name="base"/>']
    parent = "base"
    for k, ((name, kind, xyz, rpy, axis, lower, upper, _, _), link) in enumerate(zip(JOINTS, LINKS)):
        child = f"link{k + 1}"
        parts.append(f'<link name="{child}">{inertial(*link)}</link>')
        parts.append(f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                     f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/>'
                     f'<axis xyz="{" ".join(map(str, axis))}"/>'
                     f'<limit lower="{lower}" upper="{upper}" effort="100" velocity="2"/></joint>')
        parent = child
    parts.append("</robot>")
    return "\n".join(parts)


def _inertia_matrix(values):
    ixx, iyy, izz, ixy, ixz, iyz = values
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], float)


def _slider_pinocchio():
    model = pin.buildModelFromXML(_urdf())
    model.gravity = pin.Motion(np.array([0, 0, -9.81]), np.zeros(3))
    body = pin.Inertia(PAYLOAD["mass"], np.array(PAYLOAD["com"], float), _inertia_matrix(PAYLOAD["inertia"]))
    model.appendBodyToJoint(model.njoints - 1, body, pin.SE3.Identity())
    return model


def _slider_effects(qd, qdd):
    """fv qd + fc sign(qd) + f0 + Ia qdd per joint (batched)."""
    fv, fc, f0 = (np.array([j[7][k] for j in JOINTS]) for k in range(3))
    armature = np.array([j[8] for j in JOINTS])
    return fv * qd + fc * np.sign(qd) + f0 + armature * qdd


def _slider_armature():
    return np.diag([j[8] for j in JOINTS])


# --------------------------------------------------------------------------- generated builds

ROBOTS = ("lwr4", "panda", "dq_slider")


@pytest.fixture(scope="module")
def builds(tmp_path_factory):
    root = tmp_path_factory.mktemp("dynamics_dq")
    out = {}
    for name in ROBOTS:
        if name == "dq_slider":
            path = root / "dq_slider.yaml"
            path.write_text(yaml.safe_dump(_description(), sort_keys=False))
            robot = load_robot(path)
            reference = (_slider_pinocchio(), _slider_effects, _slider_armature())
        else:
            robot = load_robot(ROOT / "robots" / f"{name}.yaml")
            model = pinocchio_model(robot)[0]
            reference = (model, lambda qd, qdd: np.zeros_like(qd), np.zeros((robot.n, robot.n)))
        folder = generate(robot, root / "numeric", only=ONLY, progress=False)
        out[name] = robot, folder, reference
    return out


def _states(robot, seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform(robot.lower, robot.upper, size=(N, robot.n))
    qd, qdd = rng.normal(size=(2, N, robot.n)) * 1.5
    qd[0, :] = 0.0          # sign(0) = 0: no Coulomb torque at rest
    return q, qd, qdd


def _references(model, q, qd, qdd, effects, armature):
    data = model.createData()
    out = {key: [] for key in ("tau", "M", "g", "c")}
    for k in range(len(q)):
        out["tau"].append(pin.rnea(model, data, q[k], qd[k], qdd[k]))
        M = pin.crba(model, data, q[k])
        out["M"].append(np.triu(M) + np.triu(M, 1).T + armature)
        g = pin.computeGeneralizedGravity(model, data, q[k]).copy()
        out["g"].append(g)
        out["c"].append(pin.nonLinearEffects(model, data, q[k], qd[k]) - g)
    out = {key: np.array(v) for key, v in out.items()}
    out["tau"] = out["tau"] + effects(qd, qdd)
    return out


def _close(got, expected, what):
    got, expected = np.asarray(got), np.asarray(expected)
    axes = tuple(range(1, expected.ndim))
    scale = np.maximum(1.0, np.abs(expected).max(axis=axes))
    error = (np.abs(got - expected).max(axis=axes) / scale).max()
    assert error <= TOLERANCE, f"{what}: scaled error {error:.3g}"


@pytest.mark.parametrize("lang", LANGS)
@pytest.mark.parametrize("name", ROBOTS)
def test_dual_quaternion_dynamics_equal_pinocchio(builds, name, lang):
    robot, folder, (model, effects, armature) = builds[name]
    assert model.nv == robot.n
    lib = load_generated(folder, lang)
    q, qd, qdd = _states(robot, seed=ROBOTS.index(name))
    expected = _references(model, q, qd, qdd, effects, armature)
    _close(lib.call("tau_dq", {"q": q, "qd": qd, "qdd": qdd})["tau"], expected["tau"], f"{name} {lang} tau_dq")
    _close(lib.call("M_dq", {"q": q})["M"], expected["M"], f"{name} {lang} M_dq")
    _close(lib.call("g_dq", {"q": q})["g"], expected["g"], f"{name} {lang} g_dq")
    _close(lib.call("c_dq", {"q": q, "qd": qd})["c"], expected["c"], f"{name} {lang} c_dq")
    values = np.array(json.loads((folder / "base_params.json").read_text())["Y"]["values"])
    Y_dq = lib.call("Y_dq", {"q": q, "qd": qd, "qdd": qdd})["Y"]
    _close(Y_dq @ values, expected["tau"], f"{name} {lang} Y_dq")
    # the same regressor as the homogeneous route's, column by column
    _close(Y_dq, lib.call("Y", {"q": q, "qd": qd, "qdd": qdd})["Y"], f"{name} {lang} Y_dq = Y")


def test_regressor_has_the_columns_of_Y(builds):
    for name in ROBOTS:
        functions = {f["name"]: f for f in json.loads((builds[name][1] / "functions.json").read_text())["functions"]}
        assert functions["Y_dq"]["outputs"] == functions["Y"]["outputs"]
        assert functions["Y_dq"]["inputs"] == functions["Y"]["inputs"]


@pytest.mark.parametrize("name", ("panda", "dq_slider"))
def test_symbolic_parameters_equal_numeric(builds, tmp_path, name):
    robot, numeric_folder, _ = builds[name]
    folder = generate(robot, tmp_path, params="symbolic", only=set(DQ), progress=False)
    p = np.tile(parameter_vector(robot), (N, 1))
    q, qd, qdd = _states(robot, seed=7)
    inputs = {"tau_dq": {"q": q, "qd": qd, "qdd": qdd}, "M_dq": {"q": q}, "g_dq": {"q": q}, "c_dq": {"q": q, "qd": qd}}
    for lang in LANGS:
        symbolic, numeric = load_generated(folder, lang), load_generated(numeric_folder, lang)
        for function, args in inputs.items():
            expected = next(iter(numeric.call(function, args).values()))
            got = next(iter(symbolic.call(function, {**args, "p": p}).values()))
            _close(got, expected, f"{name} {lang} {function} symbolic p")
