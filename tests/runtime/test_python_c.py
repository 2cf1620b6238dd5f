"""The python_c extension (kindyngen/runtime/python_c.py, templates/python_c/) against the numpy module
(an independent implementation of every function, itself checked against Pinocchio elsewhere)
and against the generated C called through ctypes (the wrapper must add nothing: bit-equal).

Tests the committed generated/<robot>/python_c/<robot>_ext.c when it exists (and that it is
what the renderer writes from the committed functions.json); before it is committed, a copy
of the robot folder with the extension rendered from functions.json. Skipped without a C
compiler. Builds go to $KINDYNGEN_CACHE if set, else a per-user folder under the system
temporary directory (hash-keyed, so reruns load in milliseconds).
"""
from __future__ import annotations

import array
import inspect
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

from kindyngen.runtime import python_c
from kindyngen.runtime.evaluate import load_generated
from kindyngen.codegen.render_python_c import render_extension

ROOT = Path(__file__).resolve().parents[2]
GENERATED = ROOT / "generated"
ROBOTS = ("lwr4", "panda", "lwr4_hartl")
SAMPLES = 25

try:
    python_c._command("CC")
except python_c.BuildError as exc:
    pytest.skip(f"no C compiler: {exc}", allow_module_level=True)


@pytest.fixture(scope="module", autouse=True)
def cache():
    """A hash-keyed build cache that outlives the session (unless the user chose one)."""
    with pytest.MonkeyPatch.context() as mp:
        if not os.environ.get("KINDYNGEN_CACHE"):
            mp.setenv("KINDYNGEN_CACHE", str(Path(tempfile.gettempdir()) / f"kindyngen-tests-{os.getuid()}"))
        yield


def _robot_dir(robot: str, tmp_root: Path) -> Path:
    """The committed folder when it has python_c/, else a copy with the extension rendered."""
    committed = GENERATED / robot
    if (committed / "python_c" / f"{robot}_ext.c").is_file():
        return committed
    folder = tmp_root / robot
    (folder / "python_c").mkdir(parents=True)
    shutil.copy(committed / "functions.json", folder)
    shutil.copytree(committed / "c", folder / "c")
    interface = json.loads((committed / "functions.json").read_text())
    for name, text in render_extension(interface).items():
        (folder / "python_c" / name).write_text(text)
    return folder


def _numpy_module(folder: Path):
    return load_generated(folder, "python")._impl.module


@pytest.fixture(scope="module", params=ROBOTS)
def arm(request, tmp_path_factory):
    robot = request.param
    folder = _robot_dir(robot, tmp_path_factory.mktemp("python_c"))
    interface = json.loads((folder / "functions.json").read_text())
    return {"robot": robot, "folder": folder, "interface": interface, "ext": python_c.load(folder),
            "np": _numpy_module(GENERATED / robot), "c": load_generated(GENERATED / robot, "c")}


def _wrapped(interface):
    return [f for f in interface["functions"] if "c" in f.get("languages", ("c",))]


def _inputs(spec, numpy_module, rng):
    """Random inputs of one call: poses from the numpy module's FK (reachable targets), joint
    quantities uniform in [-1.5, 1.5], theta3 within (-1, 1)."""
    n = numpy_module.NDOF
    args = []
    for port in spec["inputs"]:
        shape = tuple(port["shape"])
        if port["name"] == "T" and shape == (4, 4):
            args.append(numpy_module.fk_hom(rng.uniform(-1.5, 1.5, n)))
        elif port["name"] == "x" and shape == (8,):
            args.append(numpy_module.fk_dq(rng.uniform(-1.5, 1.5, n)))
        else:
            args.append(rng.uniform(-1.5, 1.5, shape) * (0.6 if port["name"] == "theta3" else 1.0))
    return args


def _as_tuple(result):
    return result if isinstance(result, tuple) else (result,)


def test_interface_is_the_numpy_modules(arm):
    ext, ref = arm["ext"], arm["np"]
    names = [f["name"] for f in _wrapped(arm["interface"])]
    assert list(ext.FUNCTIONS) == names == list(ref.FUNCTIONS)
    assert ext.NDOF == ref.NDOF == arm["interface"]["n"]
    for name in names:
        assert ext.FUNCTIONS[name] is getattr(ext, name)
        assert list(inspect.signature(getattr(ext, name)).parameters) == \
            list(inspect.signature(getattr(ref, name)).parameters), name


def _compare_with_numpy(ext, ref, interface, rng, samples):
    """Every wrapped function at ``samples`` random inputs against the numpy module.

    Closed-form functions: 1e-12 relative to max(1, |value|) per output (the same expressions
    in the same order; libm's and numpy's sin/cos may differ in the last bit), integer
    outputs exactly. Iterative ones (ik_dls): a last-bit difference may change one accept or
    restart decision and so the path, so the same status and, when converged, a q that
    reaches the target by the numpy module's fk_hom (1e-9)."""
    checked = set()
    for spec in _wrapped(interface):
        name, iterative = spec["name"], spec.get("kind") == "iterative"
        for _ in range(samples):
            args = _inputs(spec, ref, rng)
            got = _as_tuple(getattr(ext, name)(*args))
            want = _as_tuple(ref.FUNCTIONS[name](*args))
            assert len(got) == len(want) == len(spec["outputs"])
            for port, g, w in zip(spec["outputs"], got, want):
                assert type(g) is np.ndarray and g.shape == w.shape == tuple(port["shape"]), (name, port["name"])
                assert g.dtype == w.dtype, (name, port["name"], g.dtype, w.dtype)
                if port["dtype"] == "int":
                    np.testing.assert_array_equal(g, w, err_msg=f"{name}.{port['name']}")
                elif not iterative:
                    err = float(np.max(np.abs(g - w))) / max(1.0, float(np.max(np.abs(w))))
                    assert err <= 1e-12, (name, port["name"], err)
            if iterative and got[1][0] == 0:
                np.testing.assert_allclose(ref.fk_hom(got[0])[:3], args[0][:3], rtol=0, atol=1e-9)
        checked.add(name)
    return checked


def test_every_function_equals_numpy_module(arm):
    checked = _compare_with_numpy(arm["ext"], arm["np"], arm["interface"], np.random.default_rng(7), SAMPLES)
    assert checked == {f["name"] for f in _wrapped(arm["interface"])}


def test_bit_equal_to_the_c_library(arm):
    """The wrapper passes the inputs and returns the C's outputs unchanged (ctypes reference)."""
    rng = np.random.default_rng(11)
    for spec in _wrapped(arm["interface"]):
        args = _inputs(spec, arm["np"], rng)
        got = _as_tuple(getattr(arm["ext"], spec["name"])(*args))
        want = arm["c"].call(spec["name"], {p["name"]: a for p, a in zip(spec["inputs"], args)})
        for port, g in zip(spec["outputs"], got):
            np.testing.assert_array_equal(g, want[port["name"]], err_msg=f"{spec['name']}.{port['name']}")


@pytest.fixture(scope="module")
def lwr4(tmp_path_factory):
    folder = _robot_dir("lwr4", tmp_path_factory.mktemp("python_c_lwr4"))
    return python_c.load(folder), _numpy_module(GENERATED / "lwr4"), folder


def test_input_forms(lwr4):
    """Lists, tuples, other dtypes, strided, Fortran-ordered, byte-swapped arrays, buffers and
    keywords all give the fast path's result."""
    ext, _, _ = lwr4
    q = np.array([0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7])
    qd, qdd = q[::-1].copy(), 2 * q
    ref = ext.tau(q, qd, qdd)
    wide = np.zeros(14)
    wide[::2] = q
    for form in (list(q), tuple(q), wide[::2], q.astype(">f8"),
                 array.array("d", q), memoryview(array.array("d", q))):
        np.testing.assert_array_equal(ext.tau(form, qd, qdd), ref, err_msg=type(form).__name__)
    np.testing.assert_array_equal(ext.tau(qdd=qdd, q=q, qd=qd), ref)
    np.testing.assert_array_equal(ext.tau(q, qd, qdd=qdd), ref)
    np.testing.assert_array_equal(ext.g([0, 1, 0, -1, 0, 1, 0]), ext.g(np.array([0., 1, 0, -1, 0, 1, 0])))
    T = ext.fk_hom(q)
    np.testing.assert_array_equal(ext.ik_hom(np.asfortranarray(T), [0.3])[0], ext.ik_hom(T, np.array([0.3]))[0])


@pytest.mark.parametrize("call, error, message", [
    (lambda m: m.fk_hom(np.zeros(6)), ValueError, r"^fk_hom: argument q: expected shape \(7,\), got shape \(6,\)$"),
    (lambda m: m.fk_hom(np.zeros((3, 7))), ValueError,
     r"^fk_hom: argument q: expected shape \(7,\), got shape \(3, 7\) \(one configuration per call: "
     r"evaluate batches with the numpy module\)$"),
    (lambda m: m.fk_hom(1.0), ValueError, r"^fk_hom: argument q: expected shape \(7,\), got shape \(\)$"),
    (lambda m: m.ik_hom(np.zeros(16), [0.0]), ValueError, r"^ik_hom: argument T: expected shape \(4, 4\), got shape \(16,\)$"),
    (lambda m: m.tau(np.zeros(7), np.zeros(7), np.zeros(8)), ValueError, r"^tau: argument qdd: expected shape \(7,\)"),
    (lambda m: m.fk_hom(None), TypeError, r"^fk_hom: argument q: expected a float64 array of shape \(7,\), got None$"),
    (lambda m: m.fk_hom(["a"] * 7), TypeError, r"^fk_hom: argument q: expected a float64 array of shape \(7,\), got list "
                                               r"that does not convert \(could not convert string to float: 'a'\)$"),
    (lambda m: m.fk_hom(np.zeros(7, complex)), TypeError, r"^fk_hom: argument q: .* got numpy.ndarray that does not convert"),
    (lambda m: m.fk_hom([[0.0] * 3, [0.0] * 4]), TypeError, r"^fk_hom: argument q: .* got list that does not convert"),
    (lambda m: m.fk_hom(object()), TypeError, r"^fk_hom: argument q: .* got object that does not convert"),
    (lambda m: m.fk_hom(), TypeError, r"^fk_hom\(q\) missing argument 'q'$"),
    (lambda m: m.tau(np.zeros(7), np.zeros(7)), TypeError, r"^tau\(q, qd, qdd\) missing argument 'qdd'$"),
    (lambda m: m.tau(*[np.zeros(7)] * 4), TypeError, r"^tau\(q, qd, qdd\) takes 3 arguments, 4 given$"),
    (lambda m: m.fk_hom(np.zeros(7), q=np.zeros(7)), TypeError, r"^fk_hom\(q\) got multiple values for argument 'q'$"),
    (lambda m: m.fk_hom(qq=np.zeros(7)), TypeError, r"^fk_hom\(q\) got an unexpected keyword argument 'qq'$"),
])
def test_errors(lwr4, call, error, message):
    with pytest.raises(error, match=message):
        call(lwr4[0])


def test_outputs_are_fresh_and_inputs_untouched(lwr4):
    ext, _, _ = lwr4
    q = np.linspace(-1, 1, 7)
    kept = q.copy()
    first, second = ext.M(q), ext.M(q)
    assert first is not second and not np.shares_memory(first, second) and not np.shares_memory(first, q)
    assert first.flags.owndata and first.flags.writeable and first.flags.c_contiguous
    first[:] = 0.0
    np.testing.assert_array_equal(ext.M(q), second)
    np.testing.assert_array_equal(q, kept)
    qs, status = ext.ik_hom(ext.fk_hom(q), [q[2]])
    qs2, status2 = ext.ik_hom(ext.fk_hom(q), [q[2]])
    assert not np.shares_memory(qs, qs2) and not np.shares_memory(status, status2)


def test_threads_get_their_own_results(lwr4):
    """Re-entrant: concurrent callers (the GIL is held per call) each get their own answer."""
    ext, ref, _ = lwr4
    qs = np.random.default_rng(3).uniform(-1, 1, (4, 7))
    expected = [ext.tau(q, q, q) for q in qs]
    failures = []

    def worker(k):
        for _ in range(2000):
            if not np.array_equal(ext.tau(qs[k], qs[k], qs[k]), expected[k]):
                failures.append(k)
                return

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not failures


def test_extension_source_is_rendered_from_the_interface(lwr4):
    """Deterministic: the committed (or rendered) source is exactly what the renderer writes
    from functions.json, rendering twice gives the same bytes."""
    _, _, folder = lwr4
    interface = json.loads((folder / "functions.json").read_text())
    text = (folder / "python_c" / "lwr4_ext.c").read_text()
    assert render_extension(interface) == render_extension(interface) == {"lwr4_ext.c": text}
    assert '#include "../c/lwr4.c"' in text


@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_extension_is_strict_c99(lwr4, compiler, tmp_path):
    """No warning under -std=c99 -Wall -Wextra -Werror -pedantic (Python's and numpy's own
    headers are system headers: their code is theirs to keep pedantic)."""
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} is not installed")
    _, _, folder = lwr4
    cmd = [compiler, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-fPIC",
           "-isystem", sysconfig.get_paths()["include"], "-isystem", np.get_include(),
           "-c", str(folder / "python_c" / "lwr4_ext.c"), "-o", str(tmp_path / "ext.o")]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_urdf_arm_with_a_prismatic_joint(tmp_path_factory):
    """A URDF arm generated through the pipeline with python_c: every function equals the
    numpy module (the renderer is generic over the interface, not a list of names)."""
    from kindyngen.codegen.pipeline import generate
    from kindyngen.readers.yaml_description import load_robot
    model = load_robot(ROOT / "tests" / "data" / "urdf" / "slider_arm.urdf")
    folder = generate(model, tmp_path_factory.mktemp("slider"), languages=("c", "python", "python_c"),
                      progress=False, only={"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "Y"})
    ext, ref = python_c.load(folder), _numpy_module(folder)
    interface = json.loads((folder / "functions.json").read_text())
    assert list(ext.FUNCTIONS) == list(ref.FUNCTIONS)
    assert _compare_with_numpy(ext, ref, interface, np.random.default_rng(5), 10) == set(ref.FUNCTIONS)


def test_floating_tree(tmp_path_factory):
    """A floating-base tree through the pipeline with python_c: every function equals the numpy
    module, and the module says what the robot is and that gravity is in the world frame."""
    from kindyngen.codegen.pipeline import generate
    from kindyngen.readers.urdf import load_urdf
    model = load_urdf(ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf", floating_base=True)
    # the derivatives left out: compiling them took minutes (checked in C in test_tree_derivatives.py)
    folder = generate(model, tmp_path_factory.mktemp("tree"), languages=("c", "python", "python_c"),
                      progress=False, only={"fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com", "Y"})
    ext, ref = python_c.load(folder), _numpy_module(folder)
    interface = json.loads((folder / "functions.json").read_text())
    assert (interface["nq"], interface["nv"]) == (12, 11) and "floating base" in interface["structure"]
    assert list(ext.FUNCTIONS) == list(ref.FUNCTIONS)
    assert _compare_with_numpy(ext, ref, interface, np.random.default_rng(5), 10) == set(ref.FUNCTIONS)
    doc = " ".join(ext.__doc__.split())
    assert f"({model.structure_text})" in doc and "gravity in the world frame" in doc


def test_load_caches_and_reuses(lwr4):
    _, _, folder = lwr4
    target = python_c.build(folder)
    assert target.parent.parent == python_c.cache_root() / "python_c"
    assert python_c.load(folder) is lwr4[0]


def test_no_compiler_points_to_the_numpy_module(lwr4, monkeypatch, tmp_path):
    _, _, folder = lwr4
    monkeypatch.setenv("CC", "kindyngen-no-such-compiler")
    monkeypatch.setenv("KINDYNGEN_CACHE", str(tmp_path))
    with pytest.raises(python_c.BuildError, match=r"no C compiler found .*pure-numpy module .*lwr4\.py"):
        python_c.load(folder)


def test_unwritable_cache_is_a_clear_error(lwr4, monkeypatch, tmp_path):
    _, _, folder = lwr4
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("KINDYNGEN_CACHE", str(blocker / "cache"))
    with pytest.raises(python_c.BuildError, match=r"cannot create the build cache .*KINDYNGEN_CACHE"):
        python_c.build(folder)


def test_cli_build_python(lwr4, tmp_path):
    _, _, folder = lwr4
    run = lambda *a: subprocess.run([sys.executable, "-m", "kindyngen", "build-python", *a],
                                    capture_output=True, text=True, env={**os.environ})
    done = run(str(folder))
    assert done.returncode == 0 and Path(done.stdout.strip()) == python_c.build(folder), done.stderr
    missing = run(str(tmp_path))
    assert missing.returncode == 2 and missing.stderr.startswith("error: ") and "functions.json" in missing.stderr
    assert "Traceback" not in missing.stderr
    assert run("--help").returncode == 0
