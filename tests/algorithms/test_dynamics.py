"""Dynamics (M, g, c, S, tau, fd and the alternative routes, com) against Pinocchio, plus the
structural properties: M symmetric positive definite, Mdot - 2 S skew-symmetric, both routes
equal, symbolic parameters equal to the baked-in ones, energy conserved by fd."""
from __future__ import annotations


from dataclasses import replace

import numpy as np
import pinocchio as pin
import sympy
import pytest
import symengine as se
from scipy.integrate import solve_ivp

from kindyngen.runtime.evaluate import load_generated
from tests.harness import GENERATED, evaluate_symbolic, robot, symbolic_function
from tests.reference import pinocchio_model, random_configurations

from kindyngen.codegen.catalog import derive_all
from kindyngen.algorithms.lagrange import coriolis_christoffel, gravity_lagrange, mass_matrix_lagrange
from kindyngen.codegen.catalog import forward_dynamics_routes
from kindyngen.algorithms.dynamics import coriolis_tree, gravity_tree, inverse_dynamics_tree, mass_matrix_tree
from kindyngen.model.inertial_parameters import parameter_symbols, parameter_vector
from kindyngen.codegen.optimize import optimize
from kindyngen.model.placement import Placement
from kindyngen.model.robot_model import Link
from kindyngen.readers.yaml_description import parse_robot

ROBOTS = ("lwr4", "panda")
SAMPLES = 200
RTOL = 1e-9
DYNAMICS = ("M", "g", "c", "S", "tau", "fd", "M_lagrange", "g_lagrange", "c_christoffel")


def close(actual, expected, rtol=RTOL):
    """Per-sample max-norm error relative to the sample's largest reference entry (>= 1)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    axes = tuple(range(1, expected.ndim))
    err = np.abs(actual - expected).max(axis=axes)
    scale = np.maximum(np.abs(expected).max(axis=axes), 1.0)
    worst = (err / scale).max()
    assert worst < rtol, f"relative error {worst:.3g} >= {rtol:g}"


def symmetrised_crba(model, data, q):
    M = pin.crba(model, data, q)
    return np.triu(M) + np.triu(M, 1).T


@pytest.fixture(scope="module", params=ROBOTS)
def case(request):
    """(robot name, model, data, q, qd, qdd) with SAMPLES random states."""
    name = request.param
    r = robot(name)
    model, data, _ = pinocchio_model(r)
    rng = np.random.default_rng(7)
    q = random_configurations(r, SAMPLES, seed=3)
    qd = rng.normal(0.0, 1.5, size=q.shape)
    qdd = rng.normal(0.0, 3.0, size=q.shape)
    return name, model, data, q, qd, qdd


def reference(model, data, q, qd, qdd):
    out = {"M": [], "g": [], "c": [], "tau": [], "fd": []}
    for qi, qdi, qddi in zip(q, qd, qdd):
        g = pin.computeGeneralizedGravity(model, data, qi).copy()
        out["M"].append(symmetrised_crba(model, data, qi))
        out["g"].append(g)
        out["c"].append(pin.nonLinearEffects(model, data, qi, qdi) - g)
        out["tau"].append(pin.rnea(model, data, qi, qdi, qddi).copy())
        out["fd"].append(pin.aba(model, data, qi, qdi, qddi).copy())   # qdd plays tau here
    return {k: np.array(v) for k, v in out.items()}


@pytest.fixture(scope="module")
def ref(case):
    _, model, data, q, qd, qdd = case
    return reference(model, data, q, qd, qdd)


# ----------------------------------------------------------------------------- against Pinocchio

@pytest.mark.parametrize("fname", ["M", "M_lagrange"])
def test_inertia_matrix(case, ref, fname):
    name, _, _, q, _, _ = case
    close(evaluate_symbolic(name, fname, q=q)["M"], ref["M"])


@pytest.mark.parametrize("fname", ["g", "g_lagrange"])
def test_gravity(case, ref, fname):
    name, _, _, q, _, _ = case
    close(evaluate_symbolic(name, fname, q=q)["g"], ref["g"])


@pytest.mark.parametrize("fname", ["c", "c_christoffel"])
def test_coriolis(case, ref, fname):
    name, _, _, q, qd, _ = case
    close(evaluate_symbolic(name, fname, q=q, qd=qd)["c"], ref["c"])


def test_inverse_dynamics(case, ref):
    name, _, _, q, qd, qdd = case
    close(evaluate_symbolic(name, "tau", q=q, qd=qd, qdd=qdd)["tau"], ref["tau"])


def test_forward_dynamics(case, ref):
    name, _, _, q, qd, qdd = case
    close(evaluate_symbolic(name, "fd", q=q, qd=qd, tau=qdd)["qdd"], ref["fd"])


def _centroidal(model, data, q):
    return {"com": np.array([pin.centerOfMass(model, data, qi).copy() for qi in q]),
            "J_com": np.array([pin.jacobianCenterOfMass(model, data, qi).copy() for qi in q]),
            "A_g": np.array([pin.computeCentroidalMap(model, data, qi).copy() for qi in q])}


def test_centre_of_mass(case):
    """An arm gets com as a tree does: centre of mass, its Jacobian, the centroidal map."""
    name, model, data, q, _, _ = case
    ours, reference = evaluate_symbolic(name, "com", q=q), _centroidal(model, data, q)
    for port in ("com", "J_com", "A_g"):
        close(ours[port], reference[port])


def test_centre_of_mass_carries_the_payload_not_the_tool(case):
    """The payload is mass on the flange (the last link frame), so it moves com; the tool is a
    frame only. Pinocchio gets the payload as a second body on the last joint."""
    name, model, data, q, _, _ = case
    arm = robot(name)
    payload = Link(sympy.Rational("1.7"), (sympy.Rational("0.02"), sympy.Rational("-0.01"), sympy.Rational("0.09")),
                   tuple(sympy.Rational(v) for v in ("0.004", "0.005", "0.003", "0.0002", "-0.0001", "0.0003")))
    tool = Placement(((("trans", (sympy.Rational("0.1"), sympy.Integer(0), sympy.Rational("0.2")))),))
    loaded = replace(arm, payload=payload, tool=tool)
    f = derive_all(loaded, only={"com"})[0]
    flange = model.frames[model.getFrameId("flange")].placement
    heavier = model.copy()
    heavier.appendBodyToJoint(model.njoints - 1, flange.act(pin.Inertia(
        float(payload.mass), np.array(payload.com, float), payload.inertia_matrix())), pin.SE3.Identity())
    reference = _centroidal(heavier, heavier.createData(), q[:20])
    fn = se.Lambdify([s for syms in f.input_symbols for s in syms], [e for e in f.inlined_outputs()[0]], cse=True)
    close(np.array([np.ravel(fn(qi)) for qi in q[:20]]), reference["com"])
    assert not np.allclose(reference["com"], _centroidal(model, data, q[:20])["com"], atol=1e-3)


# ----------------------------------------------------------------------------- structure

def test_inertia_matrix_spd(case):
    name, _, _, q, _, _ = case
    M = evaluate_symbolic(name, "M", q=q)["M"]
    assert np.array_equal(M, np.swapaxes(M, 1, 2))
    assert np.linalg.eigvalsh(M).min() > 0


def test_christoffel_matrix(case, ref):
    """S qd = c (Newton-Euler and Pinocchio), and Mdot - 2 S is skew-symmetric, with Mdot
    by central differences of M along qd."""
    name, _, _, q, qd, _ = case
    S = evaluate_symbolic(name, "S", q=q, qd=qd)["S"]
    close(np.einsum("bij,bj->bi", S, qd), ref["c"])
    close(np.einsum("bij,bj->bi", S, qd), evaluate_symbolic(name, "c", q=q, qd=qd)["c"])
    h = 1e-6
    Mdot = (evaluate_symbolic(name, "M", q=q + h * qd)["M"] - evaluate_symbolic(name, "M", q=q - h * qd)["M"]) / (2 * h)
    N = Mdot - 2 * S
    scale = np.abs(Mdot).max(axis=(1, 2)) + np.abs(S).max(axis=(1, 2))
    assert (np.abs(N + np.swapaxes(N, 1, 2)).max(axis=(1, 2)) / scale).max() < 1e-7


def test_routes_agree(case):
    """Christoffel c equals Newton-Euler c; Lagrange M, g equal CRBA M and composite g."""
    name, _, _, q, qd, _ = case
    close(evaluate_symbolic(name, "c_christoffel", q=q, qd=qd)["c"], evaluate_symbolic(name, "c", q=q, qd=qd)["c"])
    close(evaluate_symbolic(name, "M_lagrange", q=q)["M"], evaluate_symbolic(name, "M", q=q)["M"])
    close(evaluate_symbolic(name, "g_lagrange", q=q)["g"], evaluate_symbolic(name, "g", q=q)["g"])


def test_tau_consistent(case):
    """tau = M qdd + c + g with the separately derived pieces, and fd inverts tau."""
    name, _, _, q, qd, qdd = case
    M = evaluate_symbolic(name, "M", q=q)["M"]
    c = evaluate_symbolic(name, "c", q=q, qd=qd)["c"]
    g = evaluate_symbolic(name, "g", q=q)["g"]
    tau = evaluate_symbolic(name, "tau", q=q, qd=qd, qdd=qdd)["tau"]
    close(np.einsum("bij,bj->bi", M, qdd) + c + g, tau)
    close(evaluate_symbolic(name, "fd", q=q, qd=qd, tau=tau)["qdd"], qdd)


@pytest.mark.parametrize("fname", DYNAMICS)
def test_symbolic_parameters(case, fname):
    """Symbolic mode with p = the robot's barycentric parameters equals numeric mode."""
    name, _, _, q, qd, qdd = case
    f = symbolic_function(name, fname, "symbolic")
    n = robot(name).n
    assert f.inputs[-1].name == "p" and f.inputs[-1].shape == (10 * n,)
    assert tuple(f.input_symbols[-1]) == parameter_symbols(n)
    k = 40
    inputs = {"q": q[:k], "qd": qd[:k], "qdd": qdd[:k], "tau": qdd[:k]}
    numeric = symbolic_function(name, fname, "numeric")
    used = {p.name: inputs[p.name] for p in numeric.inputs}
    p = np.tile(parameter_vector(robot(name)), (k, 1))
    a = evaluate_symbolic(name, fname, "numeric", **used)
    b = evaluate_symbolic(name, fname, "symbolic", **used, p=p)
    for port in numeric.outputs:
        close(b[port.name], a[port.name])


@pytest.mark.parametrize("source", ["derived", "generated C"])
def test_energy_conservation(case, source):
    """Unforced motion (tau = 0) for 5 s with the derived fd and with the generated C fd:
    T + U (T from Pinocchio's M, U from Pinocchio's potential energy) drifts by less than
    1e-6 of the energy scale."""
    name, model, data, q, _, _ = case
    n = robot(name).n
    zero = np.zeros(n)
    if source == "derived":
        f = symbolic_function(name, "fd")
        lambdified = se.Lambdify([s for syms in f.input_symbols for s in syms], list(f.inlined_outputs()[0]), cse=True)

        def fd(x):
            return np.ravel(lambdified(np.concatenate([x, zero])))
    else:
        library = load_generated(GENERATED / name, "c")

        def fd(x):
            return library.call("fd", {"q": x[:n], "qd": x[n:], "tau": zero})["qdd"]

    def rhs(_, x):
        return np.concatenate([x[n:], fd(x)])

    x0 = np.concatenate([q[0], np.random.default_rng(1).normal(0.0, 0.5, n)])
    sol = solve_ivp(rhs, (0.0, 5.0), x0, method="DOP853", rtol=1e-11, atol=1e-12, dense_output=False,
                    t_eval=np.linspace(0.0, 5.0, 101))
    assert sol.success
    T, U = [], []
    for x in sol.y.T:
        qi, qdi = x[:n], x[n:]
        T.append(0.5 * qdi @ symmetrised_crba(model, data, qi) @ qdi)
        U.append(pin.computePotentialEnergy(model, data, qi))
    E = np.array(T) + np.array(U)
    scale = max(np.max(T), np.max(np.abs(U)))
    assert np.max(T) > 1.0          # the arm actually moves
    drift = np.abs(E - E[0]).max() / scale
    print(f"\nenergy drift {name} ({source} fd), 5 s unforced: {drift:.2e}")   # quoted in the README
    assert drift < 1e-6


# ----------------------------------------------------------------------------- interface

def test_interface(case):
    name = case[0]
    n = robot(name).n
    expect = {
        "M": (("q",), (("M", (n, n), "kg m^2"),)),
        "g": (("q",), (("g", (n,), "N m"),)),
        "c": (("q", "qd"), (("c", (n,), "N m"),)),
        "S": (("q", "qd"), (("S", (n, n), "N m s"),)),
        "tau": (("q", "qd", "qdd"), (("tau", (n,), "N m"),)),
        "fd": (("q", "qd", "tau"), (("qdd", (n,), "rad/s^2"),)),
    }
    units = {"q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau": "N m"}
    for fname, (ins, outs) in expect.items():
        for params in ("numeric", "symbolic"):
            f = symbolic_function(name, fname, params)
            names = tuple(p.name for p in f.inputs)
            assert names == ins + (("p",) if params == "symbolic" else ())
            for port, syms in zip(f.inputs, f.input_symbols):
                assert port.shape == ((n,) if port.name != "p" else (10 * n,))
                if port.name != "p":
                    assert port.unit == units[port.name]
                    assert tuple(str(s) for s in syms) == tuple(f"{port.name}_{k}" for k in range(n))
            assert tuple((p.name, p.shape, p.unit) for p in f.outputs) == outs
            assert "tau = M(q) qdd + c(q, qd) + g(q)" in f.conventions
            assert "Gravity" in f.conventions
            assert ("Christoffel" in f.summary) or ("Newton-Euler" in f.summary)


# ----------------------------------------------------------------------------- other geometries

SYNTHETIC = {
    "name": "synthetic",
    "gravity": [1.2, -2.5, -9.3],
    "joints": [
        {"a": 0.1, "alpha": "pi/3", "d": 0.2, "offset": 0.3, "lower": -2, "upper": 2},
        {"a": -0.25, "alpha": -0.7, "d": 0.0, "offset": "pi/2", "lower": -2, "upper": 2},
        {"a": 0.0, "alpha": "pi/2", "d": 0.15, "offset": "-pi/4", "lower": -2, "upper": 2},
        {"a": 0.3, "alpha": 0, "d": -0.1, "offset": "pi", "lower": -2, "upper": 2},
        {"a": 0.05, "alpha": "-pi/2", "d": 0.12, "offset": 0, "lower": -2, "upper": 2},
    ],
    "links": [
        {"mass": 3.0 - 0.4 * i, "com": [0.02 * i - 0.03, 0.05 - 0.01 * i, 0.07 * (i % 3) - 0.05],
         "inertia": [0.03 + 0.002 * i, 0.025, 0.02 + 0.001 * i, 0.001, -0.0015, 0.0008 * (i - 2)]}
        for i in range(5)
    ],
}


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_general_geometry(convention):
    """Odd alphas, non-zero a and d, offsets (exact and not), tilted gravity, both DH
    conventions, against Pinocchio; numeric and symbolic parameters."""
    r = parse_robot(dict(SYNTHETIC, dh=convention))
    model, data, _ = pinocchio_model(r)
    rng = np.random.default_rng(5)
    q = rng.uniform(-2, 2, (20, r.n))
    qd = rng.normal(0, 1.5, q.shape)
    qdd = rng.normal(0, 3, q.shape)
    refs = reference(model, data, q, qd, qdd)
    builders = {"M": (mass_matrix_tree, ("q",), "M"), "M_lagrange": (mass_matrix_lagrange, ("q",), "M"),
                "g": (gravity_tree, ("q",), "g"), "g_lagrange": (gravity_lagrange, ("q",), "g"),
                "c": (coriolis_tree, ("q", "qd"), "c"), "c_christoffel": (coriolis_christoffel, ("q", "qd"), "c"),
                "tau": (inverse_dynamics_tree, ("q", "qd", "qdd"), "tau"),
                "fd": (forward_dynamics_routes, ("q", "qd", "tau"), "fd")}
    values = {"q": q, "qd": qd, "qdd": qdd, "tau": qdd}
    for params in ("numeric", "symbolic"):
        for fname, (build, ins, key) in builders.items():
            f = build(r, params)
            fn = se.Lambdify([s for syms in f.input_symbols for s in syms], list(f.inlined_outputs()[0]), cse=True)
            args = np.concatenate([values[k] for k in ins], axis=1)
            if params == "symbolic":
                args = np.concatenate([args, np.tile(parameter_vector(r), (len(q), 1))], axis=1)
            out = np.array([np.ravel(fn(row)) for row in args]).reshape(refs[key].shape)
            close(out, refs[key])
