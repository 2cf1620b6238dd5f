"""The benchmark peer "pinocchio_casadi_c" computes what it claims: every Function traced by
benchmarks/pinocchio_casadi_trace.cpp (Pinocchio with casadi::SX), loaded back with
casadi.Function.load, equals double-precision Pinocchio from Python on a model built
independently from the DH table (tests/reference.py), for a standard-DH (lwr4) and a
modified-DH arm (panda). The derivatives are also held against central differences of
Pinocchio's rnea / aba, so a derivative traced wrongly in both forms cannot pass. Also: the
derivatives Pinocchio C++ (pinocchio_bench) prints for the wiring check are Pinocchio's.

The tracer is a C++ program (the pin wheel has no pinocchio.casadi module) built header-only;
benchmarks/build.py caches the build. The cold build takes minutes (see benchmarks/README.md),
so these tests use a cached build when there is one (`make bench` leaves one) and build only
on demand: KINDYNGEN_BUILD_PEERS=1 (likewise pinocchio_bench). Without a C++ compiler they are
skipped.
"""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from benchmarks import inputs, pinocchio_casadi, pinocchio_cpp   # the benchmark code under test
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

ROBOTS = Path(__file__).resolve().parents[2] / "robots"

RTOL = 1e-9  # double rounding of differently ordered sums; a wrong term is off by far more
STEP = 1e-6  # central differences: error ~ step^2 * third derivative, well under FD_TOL
FD_TOL = 1e-5


def _tracer():
    if shutil.which("g++") is None:
        pytest.skip("no C++ compiler (g++): the Pinocchio + casadi::SX tracer cannot be built")
    if not pinocchio_casadi.tracer_cached() and os.environ.get("KINDYNGEN_BUILD_PEERS") != "1":
        pytest.skip("benchmark-only: the pinocchio_casadi tracer is not built yet and its cold build "
                    "takes minutes; run `make bench` or set KINDYNGEN_BUILD_PEERS=1")
    return pinocchio_casadi.build_tracer().path


@pytest.fixture(scope="module", params=["lwr4", "panda"])
def traced(request, tmp_path_factory):
    robot = load_robot(ROBOTS / f"{request.param}.yaml")
    functions = pinocchio_casadi.trace(_tracer(), robot, tmp_path_factory.mktemp(request.param))
    model, data, flange = pinocchio_model(robot)
    rng = np.random.default_rng(7)
    points = [(rng.uniform(robot.lower, robot.upper), *rng.uniform(-2.0, 2.0, (2, robot.n))) for _ in range(4)]
    return functions, model, data, flange, points


def _call(function, *args) -> list[np.ndarray]:
    out = function(*args)
    return [np.array(o) for o in (out if isinstance(out, (list, tuple)) else [out])]


def _close(got, want, tol=RTOL):
    got, want = np.asarray(got, float), np.asarray(want, float)
    assert got.shape == want.shape
    scale = 1.0 + np.abs(want).max()
    assert np.abs(got - want).max() <= tol * scale, np.abs(got - want).max() / scale


def _full(upper_or_full: np.ndarray) -> np.ndarray:
    """Pinocchio's symmetric matrices from their upper triangle, whatever the binding fills."""
    return np.triu(upper_or_full) + np.triu(upper_or_full, 1).T


def _central(f, x, step=STEP):
    columns = []
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = step
        columns.append((f(x + dx) - f(x - dx)) / (2 * step))
    return np.column_stack(columns)


def test_traced_functions_have_the_generated_names_and_ports(traced):
    functions = traced[0]
    ports = {"fk_hom": (["q"], ["T"]), "jacobian": (["q"], ["J"]), "M": (["q"], ["M"]), "g": (["q"], ["g"]),
             "c": (["q", "qd"], ["c"]), "tau": (["q", "qd", "qdd"], ["tau"]), "fd": (["q", "qd", "tau"], ["qdd"]),
             "Minv": (["q"], ["Minv"]),
             "tau_derivatives": (["q", "qd", "qdd"], ["dtau_dq", "dtau_dqd"]),
             "fd_derivatives": (["q", "qd", "tau"], ["dqdd_dq", "dqdd_dqd", "Minv"])}
    for name, (ins, outs) in ports.items():
        for candidate in pinocchio_casadi.CANDIDATES.get(name, [name]):
            f = functions[candidate]
            assert (f.name(), f.name_in(), f.name_out()) == (candidate, ins, outs)


def test_kinematics_and_dynamics_equal_pinocchio(traced):
    functions, model, data, flange, points = traced
    for q, qd, x in points:
        pin.framesForwardKinematics(model, data, q)
        _close(_call(functions["fk_hom"], q)[0], data.oMf[flange].homogeneous)
        J = pin.computeFrameJacobian(model, data, q, flange, pin.LOCAL_WORLD_ALIGNED)
        _close(_call(functions["jacobian"], q)[0], J)
        _close(_call(functions["M"], q)[0], _full(pin.crba(model, data, q)))
        g = pin.computeGeneralizedGravity(model, data, q)
        _close(_call(functions["g"], q)[0].ravel(), g)
        _close(_call(functions["c"], q, qd)[0].ravel(), pin.nonLinearEffects(model, data, q, qd) - g)
        _close(_call(functions["tau"], q, qd, x)[0].ravel(), pin.rnea(model, data, q, qd, x))
        _close(_call(functions["fd"], q, qd, x)[0].ravel(), pin.aba(model, data, q, qd, x))
        _close(_call(functions["Minv"], q)[0], _full(pin.computeMinverse(model, data, q)))


@pytest.mark.parametrize("candidate", list(pinocchio_casadi.CANDIDATES["tau_derivatives"]))
def test_tau_derivatives_equal_pinocchio_and_differences(traced, candidate):
    functions, model, data, _, points = traced
    for q, qd, qdd in points:
        dq, dqd = _call(functions[candidate], q, qd, qdd)
        want_dq, want_dqd, _ = pin.computeRNEADerivatives(model, data, q, qd, qdd)
        _close(dq, want_dq)
        _close(dqd, want_dqd)
        _close(dq, _central(lambda x: pin.rnea(model, data, x, qd, qdd), q), FD_TOL)
        _close(dqd, _central(lambda x: pin.rnea(model, data, q, x, qdd), qd), FD_TOL)


@pytest.mark.parametrize("candidate", list(pinocchio_casadi.CANDIDATES["fd_derivatives"]))
def test_fd_derivatives_equal_pinocchio_and_differences(traced, candidate):
    functions, model, data, _, points = traced
    for q, qd, tau in points:
        dq, dqd, minv = _call(functions[candidate], q, qd, tau)
        want_dq, want_dqd, want_minv = pin.computeABADerivatives(model, data, q, qd, tau)
        _close(dq, want_dq)
        _close(dqd, want_dqd)
        _close(minv, _full(want_minv))
        _close(minv @ _full(pin.crba(model, data, q)), np.eye(model.nv))
        _close(dq, _central(lambda x: pin.aba(model, data, x, qd, tau), q), FD_TOL)
        _close(dqd, _central(lambda x: pin.aba(model, data, q, x, tau), qd), FD_TOL)


@pytest.mark.parametrize("name", ["lwr4", "panda"])
def test_pinocchio_cpp_prints_its_derivatives_in_the_generated_layout(name, tmp_path):
    """pinocchio_bench's check lines (what run.py compares with the generated code) are the
    derivatives and M^-1 Pinocchio computes from Python, row-major, Minv full."""
    if shutil.which("g++") is None:
        pytest.skip("no C++ compiler (g++): pinocchio_bench cannot be built")
    if not pinocchio_cpp.binary_cached() and os.environ.get("KINDYNGEN_BUILD_PEERS") != "1":
        pytest.skip("benchmark-only: pinocchio_bench is not built yet and its cold build takes minutes; "
                    "run `make bench` or set KINDYNGEN_BUILD_PEERS=1")
    robot = load_robot(ROBOTS / f"{name}.yaml")
    data_in = inputs.dynamics_inputs(robot, 2)
    prepared = pinocchio_cpp.prepare(robot, data_in, tmp_path)
    times, checks = pinocchio_cpp.measure(pinocchio_cpp.build_binary().path, prepared, 1, 1e4)
    assert {"Minv", "tau_derivatives", "fd_derivatives"} <= times.keys()
    model, data, _ = pinocchio_model(robot)
    q, qd, qdd, tau = (data_in[k][0] for k in ("q", "qd", "qdd", "tau"))
    dq, dqd, _ = pin.computeRNEADerivatives(model, data, q, qd, qdd)
    assert len(checks["tau_derivatives"]) == 2
    for got, want in zip(checks["tau_derivatives"], (dq, dqd)):
        _close(got, want.ravel())
    dq, dqd, minv = pin.computeABADerivatives(model, data, q, qd, tau)
    assert len(checks["fd_derivatives"]) == 3
    for got, want in zip(checks["fd_derivatives"], (dq, dqd, _full(minv))):
        _close(got, want.ravel())
    _close(checks["Minv"][0], _full(pin.computeMinverse(model, data, q)).ravel())


def test_tracer_rejects_bad_arguments_with_a_message(tmp_path):
    binary = _tracer()
    bad = tmp_path / "bad.txt"
    bad.write_text("7\n0 0 -9.81\n1 0 0\n")  # cut short after the first joint's first numbers
    done = subprocess.run([str(binary), str(bad), str(tmp_path)], capture_output=True, text=True)
    assert done.returncode == 1 and "cannot read model file" in done.stderr
    good = tmp_path / "lwr4.txt"
    good.write_text(pinocchio_cpp.model_text(load_robot(ROBOTS / "lwr4.yaml")))
    done = subprocess.run([str(binary), str(good), str(tmp_path / "missing")], capture_output=True, text=True)
    assert done.returncode == 1 and "no such directory" in done.stderr  # CasADi's save would not say
    done = subprocess.run([str(binary), "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "usage:" in done.stdout


def test_keep_faster_keeps_the_lower_minimum_under_the_generated_name():
    # tau_derivatives: the analytical candidate has the lower minimum (18) though a burst gave
    # it the higher median (30 > 21): the minimum decides
    times = {"fd": [5.0], "tau_derivatives": [30.0, 31.0, 18.0], "tau_derivatives_ad": [20.0, 21.0, 22.0],
             "fd_derivatives": [40.0], "fd_derivatives_ad": [60.0]}
    outputs = {name: [np.full(1, i)] for i, name in enumerate(times)}
    kept, out, notes = pinocchio_casadi.keep_faster(times, outputs)
    assert kept == {"fd": [5.0], "tau_derivatives": [30.0, 31.0, 18.0], "fd_derivatives": [40.0]}
    assert out["tau_derivatives"] is outputs["tau_derivatives"]
    assert out["fd_derivatives"] is outputs["fd_derivatives"]
    assert notes["tau_derivatives"].startswith("computeRNEADerivatives") and "CasADi jacobian" in notes["tau_derivatives"]
    assert "20 ns" in notes["tau_derivatives"]  # the other candidate's minimum
    assert notes["fd_derivatives"].startswith("computeABADerivatives") and "60 ns" in notes["fd_derivatives"]


def test_samples_for_reuses_the_generated_inputs_and_draws_the_missing_ones():
    import casadi
    robot = load_robot(ROBOTS / "lwr4.yaml")
    x = {p: casadi.SX.sym(p, robot.n) for p in ("q", "qd", "qdd")}
    functions = {name: casadi.Function(name, list(x.values()), [x["q"]], list(x), ["out"])
                 for name in ("tau", "tau_derivatives", "tau_derivatives_ad")}
    given = {"tau": inputs.sample({"inputs": [{"name": p, "shape": [robot.n]} for p in x]}, robot, 5)}
    got = pinocchio_casadi.samples_for(functions, given, robot, 5)
    assert got["tau"] is given["tau"]  # the generated function's very inputs
    assert got["tau_derivatives"] is got["tau_derivatives_ad"]  # both candidates on the same inputs
    assert {p: a.shape for p, a in got["tau_derivatives"].items()} == {p: (5, robot.n) for p in x}
    assert set(given) == {"tau"}  # the caller's samples are left alone
