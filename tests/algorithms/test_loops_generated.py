"""Code generated for trees closed by loops equals Pinocchio's constrained dynamics and an
independent projection, in the independent coordinates.

Robots (``examples/loops/``): ``four_bar.yaml`` (a crank-rocker: the dependent joints by the
dyad's closed form, q the crank's angle), ``palletiser.yaml`` (ten joints, three
parallelograms: G constant, every function of a model with mimic joints, the derivatives and
Y included) and ``delta.urdf`` (three arms, universal elbows, ball joints to a platform on
massless sliders: no closed form, q every joint).

The references share no code with KinDynGen:

* **Pinocchio's model** of the tree: the URDF by ``buildModelFromUrdf``; a YAML tree built here
  from the file as ``yaml.safe_load`` reads it (origins by ``pin.rpy.rpyToMatrix``, axes as
  ``JointModelRevoluteUnaligned``, inertias about the centre of mass); the loops from the file
  (ElementTree or YAML): frames A and B as SE3 on their joints.
* **Pinocchio's constrained dynamics**: ``constraintDynamics`` with one ``CONTACT_3D``
  ``RigidConstraintModel`` per loop (LOCAL: its rows are ``R_A^T (v_B - v_A)``), the torques on
  the independent joints; the independent joints' accelerations compared.
* **An independent projection**: K from Pinocchio's frame Jacobians (the loop's rows of
  ``R_A^T (J_B - J_A)``), ``G = [I; -K_d^-1 K_i]``, the drift from the classical accelerations at
  qdd = 0, and ``G^T M G``, ``G^T g``, ``G^T rnea(q, G qd, G qdd + a0)``, fd by ``solve``, ``J G``,
  the centre of mass and ``J_com G``, ``A_g G``, the derivatives ``G^T (dtau/dq) G`` (G constant).
* **The dependent joints**: Newton's method on Pinocchio's loop residual, along a smooth path of
  the independent joints from the reference (each state from the one before: the branch the
  reference is on).

Every generated function (C and Python) at 200 states; error per state relative to the
reference's largest entry at that state (a part of tau such as c against tau's); tolerance 1e-10.
"""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot
from kindyngen.runtime.evaluate import load_generated

pin = pytest.importorskip("pinocchio")

N = 200
TOLERANCE = 1e-10
EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "loops"
# (file, frames (None: the tips), the independent joints' path: amplitude and centre per joint)
CASES = {
    "four_bar": ("four_bar.yaml", None),
    "palletiser": ("palletiser.yaml", None),
    "delta": ("delta.urdf", None),
}
FAMILY = {"c": "tau", "dtau_dq": "tau", "dtau_dqd": "tau", "dqdd_dq": "qdd", "dqdd_dqd": "qdd"}


# ----------------------------------------------------------------------------- the references

def _number(value) -> float:
    """A YAML number or a constant expression of the test files (-pi/2)."""
    return float(eval(str(value), {"__builtins__": {}}, {"pi": math.pi})) if isinstance(value, str) else float(value)


def _se3(origin) -> "pin.SE3":
    origin = origin or {}
    xyz = [_number(v) for v in origin.get("xyz", [0, 0, 0])]
    rpy = [_number(v) for v in origin.get("rpy", [0, 0, 0])]
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(xyz))


class Reference:
    """Pinocchio's model of a test robot, its loops (joint id, placement of A; of B; rows) and
    the independent joints (indices into q)."""

    def __init__(self, path: Path):
        if path.suffix == ".urdf":
            self.model = pin.buildModelFromUrdf(str(path))
            root = ET.parse(path).getroot()
            self.loops = []
            for element in root.findall("loop_joint"):
                ends = element.findall("link1") + element.findall("link2")
                frames = []
                for end in ends:
                    frame = self.model.frames[self.model.getFrameId(end.get("link"))]
                    xyz = np.array([float(v) for v in end.get("xyz", "0 0 0").split()])
                    rpy = [float(v) for v in end.get("rpy", "0 0 0").split()]
                    frames.append((frame.parentJoint, frame.placement * pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz)))
                self.loops.append((frames[0], frames[1], [0, 1, 2]))
            names = [j.get("name") for t in root.findall("transmission") for j in t.findall("joint")]
        else:
            data = yaml.safe_load(path.read_text())
            self.model = pin.Model()
            self.model.gravity = pin.Motion(np.array([_number(g) for g in data["gravity"]]), np.zeros(3))
            ids = {"base": 0}
            for joint, link in zip(data["joints"], data["links"]):
                axis = np.array([_number(v) for v in joint.get("axis", [0, 0, 1])])
                jid = self.model.addJoint(ids[joint.get("parent", "base")],
                                          pin.JointModelRevoluteUnaligned(axis / np.linalg.norm(axis)),
                                          _se3(joint.get("origin")), joint["name"])
                ixx, iyy, izz, ixy, ixz, iyz = (_number(v) for v in link["inertia"])
                inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
                self.model.appendBodyToJoint(jid, pin.Inertia(_number(link["mass"]),
                                                              np.array([_number(v) for v in link["com"]]), inertia),
                                             pin.SE3.Identity())
                ids[joint["name"]] = jid
                self.model.addFrame(pin.Frame(joint["name"], jid, pin.SE3.Identity(), pin.FrameType.BODY))
            self.loops = [((ids[loop["link1"]], _se3(loop.get("origin1"))), (ids[loop["link2"]], _se3(loop.get("origin2"))),
                           ["xyz".index(d) for d in loop.get("directions", ["x", "y", "z"])])
                          for loop in data["loops"]]
            names = data.get("independent") or [data["joints"][0]["name"]]     # the four-bar: its first joint
        self.data = self.model.createData()
        self.nq = self.model.nq
        self.independent = [self.model.getJointId(name) - 1 for name in names]
        self.dependent = [j for j in range(self.nq) if j not in self.independent]
        for k, ((ja, pa), (jb, pb), _) in enumerate(self.loops):
            self.model.addFrame(pin.Frame(f"A{k}", ja, pa, pin.FrameType.OP_FRAME))
            self.model.addFrame(pin.Frame(f"B{k}", jb, pb, pin.FrameType.OP_FRAME))
        self.data = self.model.createData()

    def _frames(self, k):
        return self.model.getFrameId(f"A{k}"), self.model.getFrameId(f"B{k}")

    def residual(self, q):
        pin.framesForwardKinematics(self.model, self.data, q)
        out = []
        for k, (_, _, rows) in enumerate(self.loops):
            a, b = (self.data.oMf[f] for f in self._frames(k))
            out.append((a.rotation.T @ (b.translation - a.translation))[rows])
        return np.concatenate(out)

    def jacobian(self, q):
        """dr/dq at any q: R_A^T (J_B - J_A - w_A x (p_B - p_A)) on the translations."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.framesForwardKinematics(self.model, self.data, q)
        out = []
        for k, (_, _, rows) in enumerate(self.loops):
            fa, fb = self._frames(k)
            a, b = self.data.oMf[fa], self.data.oMf[fb]
            Ja = pin.getFrameJacobian(self.model, self.data, fa, pin.LOCAL_WORLD_ALIGNED)
            Jb = pin.getFrameJacobian(self.model, self.data, fb, pin.LOCAL_WORLD_ALIGNED)
            d = b.translation - a.translation
            out.append((a.rotation.T @ (Jb[:3] - Ja[:3] - np.cross(Ja[3:].T, d).T))[rows])
        return np.vstack(out)

    def solve(self, q_independent, start):
        """Every joint from the independent ones, by Newton's method from ``start``."""
        q = np.array(start, float)
        q[self.independent] = q_independent
        for _ in range(50):
            r = self.residual(q)
            if np.abs(r).max() < 1e-15:
                break
            q[self.dependent] -= np.linalg.lstsq(self.jacobian(q)[:, self.dependent], r, rcond=None)[0]
        assert np.abs(self.residual(q)).max() < 1e-13
        return q

    def solve_from_reference(self, q_independent, steps: int = 20):
        """Every joint from the independent ones, continued from the reference (q = 0) in
        ``steps`` straight steps of the independent joints: the reference's branch."""
        q = np.zeros(self.nq)
        for t in np.linspace(0, 1, steps + 1)[1:]:
            q = self.solve(t * np.asarray(q_independent), q)
        return q

    def G(self, q):
        K = self.jacobian(q)
        G = np.zeros((self.nq, len(self.independent)))
        G[self.independent] = np.eye(len(self.independent))
        G[self.dependent] = -np.linalg.lstsq(K[:, self.dependent], K[:, self.independent], rcond=None)[0]
        return G

    def drift_acceleration(self, q, v):
        """a0 = Gdot qd: the dependent joints' accelerations at qdd_independent = 0."""
        K = self.jacobian(q)
        pin.forwardKinematics(self.model, self.data, q, v, np.zeros(self.nq))
        pin.updateFramePlacements(self.model, self.data)
        gamma = []
        for k, (_, _, rows) in enumerate(self.loops):
            fa, fb = self._frames(k)
            acc = [pin.getFrameClassicalAcceleration(self.model, self.data, f, pin.LOCAL_WORLD_ALIGNED) for f in (fa, fb)]
            vel = [pin.getFrameVelocity(self.model, self.data, f, pin.LOCAL_WORLD_ALIGNED) for f in (fa, fb)]
            R = self.data.oMf[fa].rotation
            dv = vel[1].linear - vel[0].linear
            gamma.append((R.T @ (acc[1].linear - acc[0].linear - 2 * np.cross(vel[0].angular, dv)))[rows])
        a0 = np.zeros(self.nq)
        a0[self.dependent] = -np.linalg.lstsq(K[:, self.dependent], np.concatenate(gamma), rcond=None)[0]
        return a0

    def constrained_fd(self, q, v, tau_x):
        models, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
        for (ja, pa), (jb, pb), _ in self.loops:
            constraint = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, self.model, ja, pa, jb, pb, pin.LOCAL)
            models.append(constraint)
            datas.append(constraint.createData())
        pin.initConstraintDynamics(self.model, self.data, models, datas)
        settings = pin.ProximalSettings(1e-14, 1e-12, 200)
        return pin.constraintDynamics(self.model, self.data, q, v, tau_x, models, datas, settings)


def symmetric(M):
    return np.triu(M) + np.triu(M, 1).T


def relative_error(got, expected, floor=None) -> float:
    n = got.shape[0]
    diff = np.abs(got - expected).reshape(n, -1).max(axis=1)
    scale = np.abs(expected).reshape(n, -1).max(axis=1)
    if floor is not None:
        scale = np.maximum(scale, np.abs(floor).reshape(n, -1).max(axis=1))
    return float((diff / np.where(scale > 0, scale, 1.0)).max())


def path_states(reference: Reference, lower, upper, rng):
    """N states along a smooth path of the independent joints through their ranges (from the
    reference, q = 0), the dependent joints by Newton from the state before."""
    t = np.linspace(0, 1, N)
    centre, half = (lower + upper) / 2, (upper - lower) / 2
    phase = rng.uniform(0, 2 * np.pi, lower.size)
    path = centre + half * np.sin(2 * np.pi * t[:, None] * np.array([1, 2, 3, 5])[:lower.size] + phase) * 0.95
    q = reference.solve_from_reference(path[0])
    Q = []
    for point in path:
        q = reference.solve(point, q)
        Q.append(q.copy())
    return np.array(Q)


def reference_outputs(reference: Reference, Q, QD, QDD, TAU, frames):
    model, data = reference.model, reference.data
    ids = [model.getFrameId(f) for f in frames]
    out = {key: [] for key in ("T", "J", "M", "g", "c", "tau", "qdd", "qdd_pinocchio", "com", "J_com", "A_g",
                               "dtau_dq", "dtau_dqd", "dqdd_dq", "dqdd_dqd", "Minv", "q_all")}
    for q, qd, qdd, tau in zip(Q, QD, QDD, TAU):
        G = reference.G(q)
        v = G @ qd
        a0 = reference.drift_acceleration(q, v)
        pin.framesForwardKinematics(model, data, q)
        out["T"].append([data.oMf[f].homogeneous for f in ids])
        pin.computeJointJacobians(model, data, q)
        out["J"].append([pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED) @ G for f in ids])
        M = symmetric(pin.crba(model, data, q))
        My = G.T @ M @ G
        g = G.T @ pin.computeGeneralizedGravity(model, data, q)
        bias = G.T @ pin.rnea(model, data, q, v, a0)
        out["M"].append(My)
        out["g"].append(g)
        out["c"].append(bias - g)
        out["tau"].append(G.T @ pin.rnea(model, data, q, v, G @ qdd + a0))
        acc = np.linalg.solve(My, tau - bias)
        out["qdd"].append(acc)
        tau_x = np.zeros(reference.nq)
        tau_x[reference.independent] = tau
        out["qdd_pinocchio"].append(reference.constrained_fd(q, v, tau_x)[reference.independent])
        out["com"].append(pin.centerOfMass(model, data, q).copy())
        out["J_com"].append(pin.jacobianCenterOfMass(model, data, q) @ G)
        out["A_g"].append(pin.computeCentroidalMap(model, data, q) @ G)
        # the derivatives (G constant: the palletiser only)
        dq, dqd, _ = pin.computeRNEADerivatives(model, data, q, v, G @ qdd)
        out["dtau_dq"].append(G.T @ dq @ G)
        out["dtau_dqd"].append(G.T @ dqd @ G)
        dq, dqd, _ = pin.computeRNEADerivatives(model, data, q, v, G @ acc)
        Minv = np.linalg.inv(My)
        out["dqdd_dq"].append(-Minv @ G.T @ dq @ G)
        out["dqdd_dqd"].append(-Minv @ G.T @ dqd @ G)
        out["Minv"].append(Minv)
        out["q_all"].append(q)
    return {key: np.array(value) for key, value in out.items()}


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request, tmp_path_factory):
    key = request.param
    file, frames = CASES[key]
    path = EXAMPLES / file
    model = load_robot(path, tree=True, frames=frames)
    folder = generate(model, tmp_path_factory.mktemp(f"loops_{key}"), languages=("c", "python"), progress=False)
    document = json.loads((folder / "functions.json").read_text())
    reference = Reference(path)
    assert [reference.model.names[j + 1] for j in reference.independent] == document["coordinates"]
    rng = np.random.default_rng(20261207)
    independent = [model.joints[j] for j in reference.independent]
    lower = np.array([max(j.lower, -np.pi) for j in independent])
    upper = np.array([min(j.upper, np.pi) for j in independent])
    Q = path_states(reference, lower, upper, rng)
    ny = len(reference.independent)
    QD, QDD, TAU = rng.uniform(-2, 2, (N, ny)), rng.uniform(-5, 5, (N, ny)), rng.uniform(-20, 20, (N, ny))
    frames = [f.name for f in model.frames]
    expected = reference_outputs(reference, Q, QD, QDD, TAU, frames)
    q_in = Q if document["q_input"] == "all joints" else Q[:, reference.independent]
    inputs = {"q": q_in, "qd": QD, "qdd": QDD, "tau": TAU}
    return {"key": key, "model": model, "folder": folder, "document": document, "reference": reference,
            "expected": expected, "inputs": inputs, "Q": Q}


OUTPUTS = {"fk_hom": ("T",), "jacobian": ("J",), "M": ("M",), "g": ("g",), "c": ("c",), "tau": ("tau",),
           "fd": ("qdd",), "com": ("com", "J_com", "A_g"), "tau_derivatives": ("dtau_dq", "dtau_dqd"),
           "fd_derivatives": ("dqdd_dq", "dqdd_dqd", "Minv"), "fd_derivatives_no_minv": ("dqdd_dq", "dqdd_dqd")}
PORTS = {"fk_hom": ("q",), "jacobian": ("q",), "M": ("q",), "g": ("q",), "com": ("q",), "c": ("q", "qd"),
         "tau": ("q", "qd", "qdd"), "tau_derivatives": ("q", "qd", "qdd"), "fd": ("q", "qd", "tau"),
         "fd_derivatives": ("q", "qd", "tau"), "fd_derivatives_no_minv": ("q", "qd", "tau")}
# what each robot gets: G constant (the palletiser) gives the derivatives and Y as well
EXPECTED_FUNCTIONS = {
    "four_bar": {"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com", "loop_residual", "loop_jacobian", "loop_solve"},
    "palletiser": set(OUTPUTS) | {"Y", "loop_residual", "loop_jacobian", "loop_solve"},
    "delta": {"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com", "loop_residual", "loop_jacobian", "loop_solve"},
}


@pytest.mark.parametrize("lang", ("c", "python"))
def test_every_function_equals_the_projection(case, lang):
    """Every generated function equals the independent projection of Pinocchio's tree, and fd
    equals Pinocchio's constrained forward dynamics."""
    library = load_generated(case["folder"], lang)
    names = {f["name"] for f in case["document"]["functions"]}
    assert names == EXPECTED_FUNCTIONS[case["key"]], names
    errors = {}
    for function, ports in OUTPUTS.items():
        if function not in names:
            continue
        out = library.call(function, {p: case["inputs"][p] for p in PORTS[function]})
        for port in ports:
            expected = case["expected"][port]
            assert out[port].shape == expected.shape, f"{function}.{port}: {out[port].shape} != {expected.shape}"
            floor = case["expected"][FAMILY[port]] if port in FAMILY else None
            errors[f"{function}.{port}"] = relative_error(out[port], expected, floor)
    fd = library.call("fd", {p: case["inputs"][p] for p in PORTS["fd"]})["qdd"]
    errors["fd against constraintDynamics"] = relative_error(fd, case["expected"]["qdd_pinocchio"])
    errors["projection against constraintDynamics"] = relative_error(case["expected"]["qdd"],
                                                                     case["expected"]["qdd_pinocchio"])
    print(case["key"], lang, {k: f"{v:.1e}" for k, v in errors.items()})
    bad = {k: v for k, v in errors.items() if not v <= TOLERANCE}
    assert not bad, f"{case['key']} {lang}: relative errors above {TOLERANCE:g}: {bad}"


def test_loop_solve_closes_the_loops(case):
    """The generated loop_solve (the closed form; the delta's: eight unrolled Newton steps from
    q_guess = 0, the reference, over its arms' whole range) gives the dependent joints Newton's method finds along the path
    (angles to within a turn), and over the whole range of the independent joints (1000 random
    states) its configurations close every loop: Pinocchio's residual below 1e-12 (and the
    Newton form's own r says so)."""
    reference = case["reference"]
    newton = case["key"] == "delta"
    Q = case["Q"]
    path_inputs = {"q": Q[:, reference.independent], **({"q_guess": np.zeros_like(Q)} if newton else {})}
    got = load_generated(case["folder"], "python").call("loop_solve", path_inputs)["q_all"]
    turns = (got - Q) / (2 * np.pi)
    assert np.abs(turns - np.round(turns)).max() * 2 * np.pi < 1e-10
    rng = np.random.default_rng(7)
    independent = [case["model"].joints[j] for j in reference.independent]
    lower = np.array([max(j.lower, -np.pi) for j in independent])
    upper = np.array([min(j.upper, np.pi) for j in independent])
    samples = rng.uniform(lower, upper, (1000, len(independent)))
    inputs = {"q": samples, **({"q_guess": np.zeros((1000, reference.nq))} if newton else {})}
    out = load_generated(case["folder"], "c").call("loop_solve", inputs)
    worst = max(np.abs(reference.residual(q)).max() for q in out["q_all"])
    print(case["key"], f"largest residual {worst:.1e}")
    assert worst < 1e-12
    if newton:
        assert np.abs(out["r"]).max() < 1e-12


def test_loop_residual_and_jacobian(case):
    """loop_residual and loop_jacobian at any configuration (closing no loop) equal the rows
    R_A^T (p_B - p_A) and their derivative by Pinocchio's Jacobians."""
    library = load_generated(case["folder"], "c")
    rng = np.random.default_rng(11)
    Q = rng.uniform(-1, 1, (50, case["reference"].nq))
    r = library.call("loop_residual", {"q": Q})["r"]
    K = library.call("loop_jacobian", {"q": Q})["K"]
    reference = case["reference"]
    assert relative_error(r, np.array([reference.residual(q) for q in Q])) < 1e-12
    assert relative_error(K, np.array([reference.jacobian(q) for q in Q])) < 1e-12


def test_regressor_of_the_parallelogram_arm(case):
    """The palletiser's Y (on the base parameters of the reduced regressor) times the base values
    of base_params.json is the reduced torque; the other robots have a q-dependent G and no Y,
    with base_params.json saying why."""
    document = json.loads((case["folder"] / "base_params.json").read_text())["Y"]
    if case["key"] != "palletiser":
        assert "configuration-dependent G" in document["unavailable"]
        return
    Y = load_generated(case["folder"], "c").call("Y", {p: case["inputs"][p] for p in ("q", "qd", "qdd")})["Y"]
    assert len(document["names"]) == document["rank"] == Y.shape[2] < document["full_columns"]
    error = relative_error(Y @ np.array(document["values"]), case["expected"]["tau"])
    print("palletiser Y", f"{error:.1e}")
    assert error < TOLERANCE


def test_interface_names_the_coordinates_and_the_loops(case):
    """functions.json and the C header say which joints are inputs and which loops close."""
    document, model = case["document"], case["model"]
    reference = case["reference"]
    assert document["nv"] == len(reference.independent) == len(model.joints) - len(document["dependent"])
    assert [loop["name"] for loop in document["loops"]] == [loop.name for loop in model.loops]
    closed = {"four_bar": "dyad", "palletiser": "linear", "delta": None}[case["key"]]
    assert {loop["closed_form"] for loop in document["loops"]} == {closed}
    assert document["q_input"] == ("all joints" if closed is None else "independent joints")
    header = " ".join((case["folder"] / "c" / f"{model.identifier}.h").read_text().replace(" * ", " ").split())
    assert f"Independent joints: {', '.join(document['coordinates'])}" in header or "independent joints" in header
    for loop in model.loops:
        assert loop.name in header


def test_float_build_of_a_loop_model(tmp_path):
    """--scalar float: the delta robot's float C against its double C at configurations closed
    by its own loop_solve (the functions take every joint) and Newton steps from the reference:
    every function's error within the acceptable 1e-3 of its output's scale (the loop
    constraint at arbitrary configurations; loop_solve's residual in m)."""
    model = load_robot(EXAMPLES / "delta.urdf", tree=True, frames=["platform"])
    folder = generate(model, tmp_path, languages=("c",), scalar="float", progress=False)
    report = json.loads((folder / "opcounts.json").read_text())
    errors = {name: entry["float_error"] for name, entry in report.items() if "float_error" in entry}
    assert set(errors) == EXPECTED_FUNCTIONS["delta"], set(errors)
    print({name: error["max"] for name, error in errors.items()})
    assert all(error["acceptable"] and error["max"] < 1e-3 for error in errors.values()), errors
