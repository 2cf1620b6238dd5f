"""The benchmark peer "pinocchio_cppadcg" computes what it claims: Pinocchio's own CppADCodeGen
generators (benchmarks/pinocchio_cppadcg_gen.cpp) write C for lwr4's tau and M, which,
compiled and called from the C harness exactly as the benchmarks call it (both flag sets),
equals double-precision Pinocchio from Python on a model built independently from the DH table
(tests/reference.py); the generator's own reference values (what benchmarks.cppadcg checks
every implementation against before timing) are Pinocchio's too. No timing assertions.

Cheap by choice: tau and M only (the derivatives take longer to generate and compile, and go
through the same code path). The generator is a header-only Pinocchio build with CppAD's scalar
whose cold build takes minutes and gigabytes, so like the other Pinocchio peers' tests these
run only when a cached build exists (`make bench` or `python -m benchmarks.cppadcg` leaves
one) or with KINDYNGEN_BUILD_PEERS=1; without the cmeel-cppad / cmeel-cppadcodegen packages
they are skipped with the reason.
"""
from __future__ import annotations

import doctest
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from benchmarks import cppadcg, cppadcg_peer, inputs, pinocchio_cpp   # the benchmark code under test
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

ROBOTS = Path(__file__).resolve().parents[2] / "robots"
RTOL = 1e-12  # the generated code and Pinocchio in double round differently, by ~1e-15 here


def _generator() -> Path:
    reason = cppadcg_peer.unavailable()
    if reason:
        pytest.skip(f"the CppADCodeGen peer cannot be built: {reason}")
    if shutil.which("g++") is None or shutil.which("gcc") is None:
        pytest.skip("no C/C++ compiler (gcc, g++)")
    if not cppadcg_peer.generator_cached() and os.environ.get("KINDYNGEN_BUILD_PEERS") != "1":
        pytest.skip("benchmark-only: the CppADCodeGen generator is not built yet and its cold build takes "
                    "minutes; run `python -m benchmarks.cppadcg --quick` or set KINDYNGEN_BUILD_PEERS=1")
    return cppadcg_peer.build_generator().path


@pytest.fixture(scope="module")
def lwr4(tmp_path_factory):
    robot = load_robot(ROBOTS / "lwr4.yaml")
    workdir = tmp_path_factory.mktemp("cppadcg")
    model_file = workdir / "lwr4_pinocchio_model.txt"
    model_file.write_text(pinocchio_cpp.model_text(robot))
    state = inputs.dynamics_inputs(robot, 3, seed=5)
    return robot, _generator(), model_file, state, workdir


def _close(got, want, tol=RTOL):
    got, want = np.ravel(np.asarray(got, float)), np.ravel(np.asarray(want, float))
    assert got.shape == want.shape
    scale = 1.0 + np.abs(want).max()
    assert np.abs(got - want).max() <= tol * scale, np.abs(got - want).max() / scale


def _full(upper: np.ndarray) -> np.ndarray:
    return np.triu(upper) + np.triu(upper, 1).T


@pytest.mark.parametrize("impl", cppadcg_peer.IMPLS)
def test_generated_tau_and_M_equal_pinocchio(lwr4, impl):
    robot, generator, model_file, state, workdir = lwr4
    names = ("tau", "M")
    skipped = []
    peer = cppadcg_peer.build_peer(generator, model_file, "lwr4_test", names,
                                   {n: cppadcg_peer.peer_inputs(n, state) for n in names}, robot.n, workdir / impl,
                                   limit_s=1800.0, log=lambda _: None,
                                   skip=lambda name, reason: skipped.append((name, reason)), impls=(impl,))
    assert not skipped
    assert set(peer.generated) == set(names)
    assert all(g.seconds["tape_s"] >= 0 and g.forward_zero.exists() for g in peer.generated.values())
    assert set(peer.compile_seconds[impl]) == set(names)
    _, raw = peer.timers[impl].run(1, 1e4)
    got = peer.timers[impl].outputs(raw)
    model, data, _ = pinocchio_model(robot)
    q, qd, qdd = (state[k][0] for k in ("q", "qd", "qdd"))   # the harness prints input 0's outputs
    _close(got["tau"][0], pin.rnea(model, data, q, qd, qdd))
    _close(got["M"][0], _full(pin.crba(model, data, q)))


def test_reference_values_are_pinocchios(lwr4):
    robot, generator, model_file, state, workdir = lwr4
    first = {k: v[1] for k, v in state.items()}
    want = cppadcg_peer.reference(generator, model_file, first, cppadcg_peer.FUNCTIONS, workdir / "reference")
    model, data, _ = pinocchio_model(robot)
    q, qd, qdd, tau = (first[k] for k in ("q", "qd", "qdd", "tau"))
    _close(want["tau"][0], pin.rnea(model, data, q, qd, qdd))
    _close(want["fd"][0], pin.aba(model, data, q, qd, tau))
    _close(want["M"][0], _full(pin.crba(model, data, q)))
    _close(want["Minv"][0], _full(pin.computeMinverse(model, data, q)))
    dq, dqd, _ = pin.computeRNEADerivatives(model, data, q, qd, qdd)
    assert len(want["tau_derivatives"]) == 2
    _close(want["tau_derivatives"][0], dq)
    _close(want["tau_derivatives"][1], dqd)
    dq, dqd, minv = pin.computeABADerivatives(model, data, q, qd, tau)
    assert len(want["fd_derivatives"]) == 3
    for got, expected in zip(want["fd_derivatives"], (dq, dqd, _full(minv))):
        _close(got, expected)


def test_check_refuses_a_wrong_value():
    want = {"tau": [np.array([1.0, 2.0])]}
    assert cppadcg_peer.check("x", {"tau": [np.array([1.0, 2.0 + 1e-13])]}, want, 1e-12)["tau"] < 1e-12
    with pytest.raises(cppadcg_peer.WiringError, match="tau"):
        cppadcg_peer.check("x", {"tau": [np.array([1.0, 2.001])]}, want, 1e-12)
    with pytest.raises(cppadcg_peer.WiringError, match="tau"):       # an output missing
        cppadcg_peer.check("x", {"tau": []}, want, 1e-12)


def test_generator_rejects_bad_arguments_with_a_message(lwr4, tmp_path):
    _, generator, model_file, _, _ = lwr4
    bad = tmp_path / "bad.txt"
    bad.write_text("7\n0 0 -9.81\n1 0 0\n")  # cut short after the first joint's first numbers
    done = subprocess.run([str(generator), "generate", str(bad), str(tmp_path), "tau"], capture_output=True, text=True)
    assert done.returncode == 1 and "cannot load" in done.stderr
    done = subprocess.run([str(generator), "generate", str(model_file), str(tmp_path), "nonsense"],
                          capture_output=True, text=True)
    assert done.returncode == 2 and "unknown function nonsense" in done.stderr
    done = subprocess.run([str(generator), "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "usage:" in done.stdout
    done = subprocess.run([str(generator)], capture_output=True, text=True)
    assert done.returncode == 2 and "usage:" in done.stderr


@pytest.mark.parametrize("module", [cppadcg_peer, cppadcg])
def test_docstring_examples(module):
    failed, attempted = doctest.testmod(module)
    assert attempted > 0 and failed == 0
