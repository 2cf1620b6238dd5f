"""The MATLAB/Octave and JAX targets of the committed generated/ tree, run in the real tools.

Octave: every .m function of lwr4 and panda, and the MEX gateway around the generated C built
with ``mkoctfile --mex``, equal the numpy module at 1e-12 on a batch (one Octave process per
robot: Octave starts slowly). JAX: every function equals the numpy module; jax.jit(jax.vmap(tau))
equals Pinocchio's RNEA on a batch; jax.jacfwd(tau) equals Pinocchio's RNEA derivatives and the
generated tau_derivatives; jax.grad of the kinetic energy equals central finite differences of
the numpy M; jax.jacfwd of fk_hom's position equals the generated geometric Jacobian.
"""
from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from tests.harness import GENERATED, ROOT, robot
from tests.reference import pinocchio_model, random_configurations

ROBOTS = ("lwr4", "panda")
COUNT = 6
TOL = 1e-12


def _manifest(name):
    return json.loads((GENERATED / name / "functions.json").read_text())


def _module(path, name):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _numpy(name):
    return _module(GENERATED / name / "python" / f"{name}.py", f"kdg_test_numpy_{name}")


def _inputs(name, spec, numpy_module, seed=1):
    """A batch of inputs per port: joint values in the limits, poses from fk (so IK has answers)."""
    rng = np.random.default_rng(seed)
    q = random_configurations(robot(name), COUNT, seed)
    values = {"q": q, "q0": q[::-1].copy(), "qd": rng.normal(size=q.shape), "qdd": rng.normal(size=q.shape),
              "tau": rng.normal(size=q.shape) * 5, "theta3": rng.uniform(-1, 1, size=(COUNT, 1)),
              "T": numpy_module.fk_hom(q), "x": numpy_module.fk_dq(q)}
    return [values[p["name"]] for p in spec["inputs"]]


def _straight_line(name):
    return [f for f in _manifest(name)["functions"] if f.get("kind") != "iterative"]


def _assert_close(actual, expected, what):
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    np.testing.assert_allclose(actual, expected, rtol=TOL, atol=TOL * max(1.0, np.nanmax(np.abs(expected))),
                               equal_nan=True, err_msg=what)


# ---- MATLAB / Octave ---------------------------------------------------------------------

def _octave():
    octave = shutil.which("octave-cli") or shutil.which("octave")
    if octave is None:
        pytest.skip("GNU Octave not installed (Debian: apt-get install octave; .ci/run installs it as root)")
    return octave


@pytest.mark.parametrize("name", ROBOTS)
def test_octave_m_files_and_mex_equal_numpy(name, tmp_path):
    from kindyngen.runtime.evaluate import run_octave
    _octave()
    matlab = tmp_path / "matlab"
    shutil.copytree(GENERATED / name / "matlab", matlab)
    shutil.copytree(GENERATED / name / "c", tmp_path / "c")
    mex_built = shutil.which("mkoctfile") is not None
    if mex_built:   # -O0: compile time dominates; strict C99 gives the same IEEE results at any level
        done = subprocess.run(["mkoctfile", "--mex", "-O0", "-I../c", f"{name}_mex.c", f"../c/{name}.c",
                               "-o", f"{name}_mex"], cwd=matlab, capture_output=True, text=True,
                              env={**__import__("os").environ, "CFLAGS": "-O0", "CXXFLAGS": "-O0"})
        assert done.returncode == 0, done.stderr
    numpy_module = _numpy(name)
    calls, expected = [], []
    for spec in _straight_line(name):
        inputs = _inputs(name, spec, numpy_module)
        shapes = [tuple(p["shape"]) for p in spec["outputs"]]
        ref = numpy_module.FUNCTIONS[spec["name"]](*inputs)
        ref = ref if isinstance(ref, tuple) else (ref,)
        calls.append((f"{name}_{spec['name']}", inputs, shapes))
        expected.append((spec["name"], ".m", ref))
        if mex_built:   # the gateway: [outputs] = <robot>_mex('NAME', inputs...)
            calls.append((f"@(varargin) {name}_mex('{spec['name']}', varargin{{:}})", inputs, shapes))
            expected.append((spec["name"], "mex", ref))
    # batch broadcasting: one configuration of q against a batch of qd and qdd
    tau = next(s for s in _straight_line(name) if s["name"] == "tau")
    q, qd, qdd = _inputs(name, tau, numpy_module)
    calls.append((f"{name}_tau", [q[:1], qd, qdd], [tau["outputs"][0]["shape"]]))
    expected.append(("tau", ".m, one q for a batch of qd, qdd", (numpy_module.tau(q[:1], qd, qdd),)))
    results = run_octave(matlab, calls)
    for (fname, where, ref), outs in zip(expected, results):
        for r, o in zip(ref, outs):
            _assert_close(o, r, f"{name} {fname} ({where})")
    assert len(results) == len(calls) and len(expected) >= len(_straight_line(name))


def test_tree_with_rank_3_outputs_in_octave_mex_and_jax(tmp_path, jax):
    """A floating-base tree: fk_hom's T is k x 4 x 4 (rank 3, the MEX gateway's third layout),
    q has the quaternion; .m, MEX and JAX equal the numpy module of the same generation."""
    from kindyngen.runtime.evaluate import run_octave
    from kindyngen.codegen.pipeline import generate
    from kindyngen.readers.yaml_description import load_robot
    _octave()
    if shutil.which("mkoctfile") is None:
        pytest.skip("mkoctfile not installed (Debian: liboctave-dev)")
    model = load_robot(ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf", floating_base=True)
    out = generate(model, tmp_path, languages=("c", "python", "jax", "matlab"), progress=False,
                   only={"fk_hom", "jacobian", "tau"})
    robot_id = model.identifier
    numpy_module = _module(out / "python" / f"{robot_id}.py", "kdg_test_tree_numpy")
    jax_module = _module(out / "jax" / f"{robot_id}_jax.py", "kdg_test_tree_jax")
    matlab = out / "matlab"
    done = subprocess.run(["mkoctfile", "--mex", "-O0", "-I../c", f"{robot_id}_mex.c", f"../c/{robot_id}.c",
                           "-o", f"{robot_id}_mex"], cwd=matlab, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    rng = np.random.default_rng(4)
    calls, expected = [], []
    for spec in json.loads((out / "functions.json").read_text())["functions"]:
        inputs = [rng.normal(size=(COUNT,) + tuple(p["shape"])) for p in spec["inputs"]]
        ref = numpy_module.FUNCTIONS[spec["name"]](*inputs)
        ref = ref if isinstance(ref, tuple) else (ref,)
        got = jax_module.FUNCTIONS[spec["name"]](*inputs)
        for r, g in zip(ref, got if isinstance(got, tuple) else (got,)):
            _assert_close(g, r, f"tree {spec['name']} (jax)")
        shapes = [tuple(p["shape"]) for p in spec["outputs"]]
        calls += [(f"{robot_id}_{spec['name']}", inputs, shapes),
                  (f"@(varargin) {robot_id}_mex('{spec['name']}', varargin{{:}})", inputs, shapes)]
        expected += [(spec["name"], ".m", ref), (spec["name"], "mex", ref)]
    assert any(len(shape) == 3 for _, _, shapes in calls for shape in shapes)
    for (fname, where, ref), outs in zip(expected, run_octave(matlab, calls)):
        for r, o in zip(ref, outs):
            _assert_close(o, r, f"tree {fname} ({where})")


def test_octave_refuses_a_misshaped_input(tmp_path):
    from kindyngen.runtime.evaluate import EvaluationError, run_octave
    _octave()
    with pytest.raises(EvaluationError, match="q must be 7 x N"):
        run_octave(GENERATED / "lwr4" / "matlab", [("lwr4_g", [np.zeros((2, 6))], [(7,)])])


def test_m_help_states_shapes_units_and_cost():
    manifest = _manifest("lwr4")
    for spec in _straight_line("lwr4"):
        text = (GENERATED / "lwr4" / "matlab" / f"lwr4_{spec['name']}.m").read_text()
        help_text = text.split("\n%   Generated by")[0]
        cost = spec["opcount"]["after"]
        assert f"{cost['add']} add, {cost['mul']} mul, {cost['call']} call" in help_text
        for p in spec["inputs"] + spec["outputs"]:
            assert f"{p['name']}: {' x '.join(map(str, p['shape']))} x N" in help_text
            assert f"[{p['unit']}]" in help_text
    assert manifest["robot"] == "lwr4"


def test_eval_cli_runs_matlab_and_jax():
    _octave()
    q = random_configurations(robot("lwr4"), 2, 5)
    payload = json.dumps({"q": q.tolist()})
    numpy_g = _numpy("lwr4").g(q)
    for lang in ("matlab", "jax"):
        done = subprocess.run([sys.executable, "-m", "kindyngen", "eval", str(GENERATED / "lwr4"), "g", "--lang", lang],
                              input=payload, capture_output=True, text=True, cwd=ROOT)
        assert done.returncode == 0, done.stderr
        _assert_close(json.loads(done.stdout)["g"], numpy_g, f"eval --lang {lang}")


# ---- JAX ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def jax():
    jax = pytest.importorskip("jax")
    jax.config.update("jax_enable_x64", True)
    return jax


def _jax_module(name):
    return _module(GENERATED / name / "jax" / f"{name}_jax.py", f"kdg_test_jax_{name}")


@pytest.mark.parametrize("name", ROBOTS)
def test_jax_functions_equal_numpy(name, jax):
    module, numpy_module = _jax_module(name), _numpy(name)
    for spec in _straight_line(name):
        inputs = _inputs(name, spec, numpy_module, seed=2)
        ref = numpy_module.FUNCTIONS[spec["name"]](*inputs)
        got = module.FUNCTIONS[spec["name"]](*inputs)
        ref, got = (ref if isinstance(ref, tuple) else (ref,)), (got if isinstance(got, tuple) else (got,))
        for r, g in zip(ref, got):
            _assert_close(g, r, f"{name} {spec['name']} (jax)")


@pytest.mark.parametrize("name", ROBOTS)
def test_jit_vmap_tau_and_jacfwd_equal_pinocchio(name, jax):
    pin = pytest.importorskip("pinocchio")
    module = _jax_module(name)
    model, data, _ = pinocchio_model(robot(name))
    rng = np.random.default_rng(7)
    q = random_configurations(robot(name), 64, 7)
    qd, qdd = rng.normal(size=q.shape), rng.normal(size=q.shape)
    tau = np.asarray(jax.jit(jax.vmap(module.tau))(q, qd, qdd))
    expected = np.array([pin.rnea(model, data, *row) for row in zip(q, qd, qdd)])
    np.testing.assert_allclose(tau, expected, atol=1e-10)
    dtau = jax.jit(jax.jacfwd(module.tau, argnums=(0, 1)))
    generated = _numpy(name).tau_derivatives
    for k in range(3):
        dq, dqd = (np.asarray(a) for a in dtau(q[k], qd[k], qdd[k]))
        pin.computeRNEADerivatives(model, data, q[k], qd[k], qdd[k])
        np.testing.assert_allclose(dq, data.dtau_dq, atol=1e-10)
        np.testing.assert_allclose(dqd, data.dtau_dv, atol=1e-10)
        ref_dq, ref_dqd = generated(q[k], qd[k], qdd[k])
        _assert_close(dq, ref_dq, f"{name} jacfwd(tau) vs tau_derivatives")
        _assert_close(dqd, ref_dqd, f"{name} jacfwd(tau) vs tau_derivatives (qd)")


def test_jax_gradients_equal_finite_differences_and_the_jacobian(jax):
    module, numpy_module = _jax_module("lwr4"), _numpy("lwr4")
    rng = np.random.default_rng(11)
    q, qd = random_configurations(robot("lwr4"), 1, 11)[0], rng.normal(size=7)

    def energy(q):
        return 0.5 * qd @ module.M(q) @ qd

    grad = np.asarray(jax.grad(energy)(q))
    h = 1e-6
    fd = np.array([(0.5 * qd @ numpy_module.M(q + h * e) @ qd - 0.5 * qd @ numpy_module.M(q - h * e) @ qd) / (2 * h)
                   for e in np.eye(7)])
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-8)
    # d(position)/dq of fk_hom is the linear-velocity rows of the geometric Jacobian
    position_jacobian = np.asarray(jax.jacfwd(lambda q: module.fk_hom(q)[:3, 3])(q))
    np.testing.assert_allclose(position_jacobian, numpy_module.jacobian(q)[:3], atol=1e-12)
