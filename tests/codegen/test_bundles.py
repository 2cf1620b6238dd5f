"""Bundles (issue 45): one generated function computing several functions' outputs with one CSE.

Each bundle against its members generated beside it, in every target: bit for bit where the
operations are the same, else to 1e-15 of the output's scale (the members themselves are
checked against Pinocchio and numpy elsewhere); its batch variant against its single calls;
its cost against its members'; names and members refused with a clear error; and on the
emulated Cortex-M4F, the controller step's instructions against its members'."""
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from kindyngen.codegen.bundles import Bundle
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot
from kindyngen.runtime import embedded
from kindyngen.runtime.evaluate import compile_shared_library, load_generated
from tests.codegen.test_c_batch import call_batch, call_single
from tests.harness import HANG_GUARD_S, ROOT

BUNDLES = {"step": ("fk_hom", "jacobian", "M", "g", "tau"), "mpc": ("fd", "fd_derivatives"),
           "idrow": ("Y", "tau"), "dynamics": ("fd", "tau", "c")}
MEMBERS = set().union(*BUNDLES.values())
RELATIVE = 1e-15
# outputs through M's inverse (fd_derivatives): its condition number multiplies the roundings of
# a different operand order (measured 1.6e-14; the members' own C lane and scalar programs differ
# as much)
THROUGH_INVERSE = {"dqdd_dq", "dqdd_dqd"}
RELATIVE_THROUGH_INVERSE = 1e-13
COUNT = 20


@pytest.fixture(scope="module")
def lwr4(tmp_path_factory):
    """lwr4's members and bundles in every language (the members as separate functions)."""
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    bundles = tuple(Bundle(name, members, "--bundle") for name, members in BUNDLES.items())
    return generate(model, tmp_path_factory.mktemp("bundles"), progress=False, only=MEMBERS, bundles=bundles)


def _inputs(spec, rng, count=COUNT):
    values = {"q": rng.uniform(-2.5, 2.5, (count, 7)), "qd": rng.uniform(-2, 2, (count, 7)),
              "qdd": rng.uniform(-5, 5, (count, 7)), "tau": rng.uniform(-20, 20, (count, 7))}
    return {p["name"]: values[p["name"]] for p in spec["inputs"]}


def _member_outputs(lib, bundle_spec, members, inputs):
    """The members' outputs under the bundle's output names."""
    out = {}
    names = iter(p["name"] for p in bundle_spec["outputs"])
    for member in members:
        spec = lib.functions[member]
        result = lib.call(member, {p["name"]: inputs[p["name"]] for p in spec["inputs"]})
        for port in spec["outputs"]:
            out[next(names)] = result[port["name"]]
    return out


def _compare(bundle, members, what):
    """Bit for bit, or within RELATIVE of each port's largest entry (RELATIVE_THROUGH_INVERSE
    for THROUGH_INVERSE); returns the ports that were bit-identical."""
    exact = []
    assert set(bundle) == set(members), what
    for port, expected in members.items():
        got = np.asarray(bundle[port], float)
        assert got.shape == np.shape(expected), (what, port)
        if np.array_equal(got, expected):
            exact.append(port)
            continue
        scale = np.max(np.abs(expected))
        bound = RELATIVE_THROUGH_INVERSE if port in THROUGH_INVERSE else RELATIVE
        assert np.max(np.abs(got - expected)) <= bound * scale, (what, port, np.max(np.abs(got - expected)) / scale)
    return exact


@pytest.mark.parametrize("lang", ["c", "python"])
def test_bundles_equal_their_members(lwr4, lang):
    """C and numpy: each bundle's outputs are its members' (bit for bit where the operations
    are printed in the same order, else to 1e-15 of the output's scale), at random states."""
    lib = load_generated(lwr4, lang)
    rng = np.random.default_rng(45)
    identical = {}
    for name, members in BUNDLES.items():
        spec = lib.functions[name]
        inputs = _inputs(spec, rng)
        identical[name] = _compare(lib.call(name, inputs), _member_outputs(lib, spec, members, inputs), (lang, name))
    # the kinematics merge with their operand order unchanged: pose and Jacobian bit for bit
    assert {"T", "J"} <= set(identical["step"]), identical


def test_bundle_output_names(lwr4):
    """Outputs keep their members' names in member order; one named like an input or another
    output is qualified by its member (fd, tau and c: tau is fd's input and qdd tau's, so the
    outputs are tau_tau and fd_qdd); inputs are the members' in order of first use."""
    spec = {f["name"]: f for f in json.loads((lwr4 / "functions.json").read_text())["functions"]}
    assert [p["name"] for p in spec["step"]["outputs"]] == ["T", "J", "M", "g", "tau"]
    assert [p["name"] for p in spec["step"]["inputs"]] == ["q", "qd", "qdd"]
    assert [p["name"] for p in spec["mpc"]["outputs"]] == ["qdd", "dqdd_dq", "dqdd_dqd", "Minv"]
    assert [p["name"] for p in spec["dynamics"]["inputs"]] == ["q", "qd", "tau", "qdd"]
    assert [p["name"] for p in spec["dynamics"]["outputs"]] == ["fd_qdd", "tau_tau", "c"]


@pytest.mark.parametrize("lang", ["casadi", "jax", "python_c", "matlab"])
def test_other_targets_equal_numpy(lwr4, lang):
    """CasADi, JAX, the CPython extension and Octave give each bundle the numpy module's values
    (1e-12 of the scale, the targets' agreement for every function)."""
    rng = np.random.default_rng(7)
    numpy_lib = load_generated(lwr4, "python")
    if lang == "python_c":
        from kindyngen.runtime.python_c import load
        try:
            module = load(lwr4)
        except Exception as exc:        # no compiler: the extension cannot be built here
            pytest.skip(str(exc))
        call = lambda name, inputs: dict(zip([p["name"] for p in numpy_lib.functions[name]["outputs"]],
                                             _tuple(getattr(module, name)(*inputs.values()))))
        count = 1
    else:
        if lang == "matlab" and not (shutil.which("octave-cli") or shutil.which("octave")):
            pytest.skip("GNU Octave not installed")
        lib = load_generated(lwr4, lang)
        call, count = lib.call, 4
    for name in BUNDLES:
        inputs = _inputs(numpy_lib.functions[name], rng, count)
        if lang == "python_c":
            inputs = {k: v[0] for k, v in inputs.items()}
        expected, got = numpy_lib.call(name, inputs), call(name, inputs)
        for port, value in expected.items():
            scale = max(1.0, np.max(np.abs(value)))
            assert np.max(np.abs(np.asarray(got[port], float) - value)) <= 1e-12 * scale, (lang, name, port)


def _tuple(result):
    return result if isinstance(result, tuple) else (result,)


def test_c_batch_variant_equals_single_calls(lwr4):
    """The bundles' <name>_batch equal their single calls bit for bit (strict C99, -O2)."""
    manifest = {f["name"]: f for f in json.loads((lwr4 / "functions.json").read_text())["functions"]}
    dll = __import__("ctypes").CDLL(str(compile_shared_library(lwr4 / "c", "lwr4", ("-O2",))))
    rng = np.random.default_rng(3)
    for name in BUNDLES:
        spec = manifest[name]
        arrays = list(_inputs(spec, rng, 67).values())
        for single, batch in zip(call_single(dll, spec, arrays), call_batch(dll, spec, arrays)):
            assert np.array_equal(single, batch), name


def test_bundle_costs_are_counted(lwr4):
    """functions.json, opcounts.json and the header carry the bundle's count like any function's,
    with its members and their count one by one; sharing the sin/cos of q (and equal
    intermediates) makes the bundle cheaper than its members: fewer calls and operations."""
    manifest = {f["name"]: f for f in json.loads((lwr4 / "functions.json").read_text())["functions"]}
    counts = json.loads((lwr4 / "opcounts.json").read_text())
    header = (lwr4 / "c" / "lwr4.h").read_text()
    for name, members in BUNDLES.items():
        entry = manifest[name]
        after = entry["opcount"]["after"]
        parts = {k: sum(manifest[m]["opcount"]["after"][k] for m in members) for k in ("add", "mul", "call")}
        assert entry["bundle"] == {"members": list(members), "members_after": parts}
        assert counts[name]["members_after"] == parts and counts[name]["after"] == after
        assert after["add"] + after["mul"] < parts["add"] + parts["mul"] and after["call"] < parts["call"], name
        assert f"Cost: {after['add']} add, {after['mul']} mul, {after['call']} call" in header
        assert f"Called one by one they cost {parts['add']} add, {parts['mul']} mul, {parts['call']} call." in header
    assert "## Bundles" in (lwr4 / "opcounts.md").read_text()


def _generate(tmp_path, robot, *options, description=None):
    path = ROOT / "robots" / f"{robot}.yaml"
    if description is not None:
        path = tmp_path / f"{robot}.yaml"
        path.write_text((ROOT / "robots" / f"{robot}.yaml").read_text() + description)
    return subprocess.run([sys.executable, "-m", "kindyngen", "generate", str(path), "--out", str(tmp_path / "out"),
                           "--lang", "c", "--functions", "fk_hom", "--no-batch", "--quiet", *options],
                          capture_output=True, text=True, cwd=ROOT, timeout=HANG_GUARD_S)


@pytest.mark.parametrize("option, needle", [
    ("step=fk_hom,fk_hum", "fk_hum is no function"),
    ("step=fk_hom,ik_dls", "ik_dls is iterative"),
    ("step=fk_hom", "at least two functions"),
    ("step=fk_hom,M,fk_hom", "fk_hom given twice"),
    ("M=fk_hom,jacobian", "'M' is a function's name"),
    ("fk_hom_batch=M,g", "batch variant"),
    ("np=M,g", "name of the generated code"),
    ("float=M,g", "reserved"),
    ("9step=M,g", "ASCII letters"),
    ("step fk_hom,M", "expected NAME=FUNCTION"),
])
def test_bad_bundle_options_are_refused(tmp_path, option, needle):
    """--bundle checks its name and members before anything is derived: one error line, exit 2."""
    done = _generate(tmp_path, "lwr4", "--bundle", option)
    assert done.returncode == 2 and needle in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


@pytest.mark.parametrize("section, field, needle", [
    ("bundles:\n  step: [fk_hom, nope]\n", "bundles.step", "nope is no function"),
    ("bundles:\n  step: [fk_hom, 3]\n", "bundles.step", "expected function names"),
    ("bundles: [fk_hom, M]\n", "bundles", "expected a mapping"),
    ("bundles:\n  tau: [fk_hom, M]\n", "bundles.tau", "'tau' is a function's name"),
    ("bundles:\n  ik: [ik_hom, fk_hom]\n", "bundles.ik", "ik_hom does not apply to"),
])
def test_bad_bundle_sections_are_refused(tmp_path, section, field, needle):
    """A description's bundles: section: the error names the file and the field (panda has no
    closed-form IK, so ik_hom does not apply to it)."""
    done = _generate(tmp_path, "panda", description="\n" + section)
    assert done.returncode == 2 and needle in done.stderr and f"field '{field}'" in done.stderr, done.stderr
    assert "panda.yaml" in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_description_bundle_and_option_of_one_name_are_refused(tmp_path):
    done = _generate(tmp_path, "lwr4", "--bundle", "step=M,g", description="\nbundles:\n  step: [fk_hom, M]\n")
    assert done.returncode == 2 and "already asked for" in done.stderr, done.stderr


def test_description_bundle_is_generated(tmp_path):
    """A description's bundles: section is generated like --bundle (and the function list
    --functions gives is not narrowed by it)."""
    done = _generate(tmp_path, "lwr4", description="\nbundles:\n  step: fk_hom, M\n")
    assert done.returncode == 0, done.stderr
    names = [f["name"] for f in json.loads((tmp_path / "out" / "lwr4" / "functions.json").read_text())["functions"]]
    assert names == ["fk_hom", "step"]


SKIP_BOARD = embedded.missing_tools()


def test_controller_step_on_the_m4f(tmp_path):
    """Float C on the emulated Cortex-M4F: the step bundle's outputs are the host's bit for bit,
    and it executes at most 60 % of the instructions of its five members called one by one
    (measured: docs/embedded.md)."""
    if SKIP_BOARD:
        pytest.skip(SKIP_BOARD)
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    folder = generate(model, tmp_path / "float", ("c",), progress=False, only=set(BUNDLES["step"]), scalar="float",
                      batch=False, bundles=(Bundle("step", BUNDLES["step"], "--bundle"),))
    r = embedded.figures(folder, "m4f", tmp_path / "work", model.lower, model.upper)
    assert set(embedded.agreement(r).values()) == {"bit-exact"}, embedded.agreement(r)
    parts = sum(r["instructions"][m] for m in BUNDLES["step"])
    assert r["instructions"]["step"] <= 0.6 * parts, (r["instructions"], parts)


def test_describe_keeps_the_bundles_section(tmp_path):
    """kindyngen describe writes a description's bundles back, and they read the same (panda:
    describe keeps a standard DH table such as lwr4's as it is)."""
    path = tmp_path / "panda.yaml"
    path.write_text((ROOT / "robots" / "panda.yaml").read_text() + "\nbundles:\n  step: [fk_hom, M]\n  row: Y, tau\n")
    done = subprocess.run([sys.executable, "-m", "kindyngen", "describe", str(path), "--out", str(tmp_path / "out.yaml")],
                          capture_output=True, text=True, cwd=ROOT, timeout=HANG_GUARD_S)
    assert done.returncode == 0, done.stderr
    assert load_robot(tmp_path / "out.yaml").bundles == (("step", ("fk_hom", "M")), ("row", ("Y", "tau")))
