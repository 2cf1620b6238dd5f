"""The batch variants of the generated C (<robot>_<name>_batch, structure-of-arrays) against
count single calls of the same library: bit for bit under the default flags, to 1e-15 with
vectorisation and FMA contraction on; counts around the block and vector widths, and 0. Also
the --trig switch: the kernel's results against libm's, and where the choice is recorded."""
import ctypes
import json
import subprocess
import sys

import numpy as np
import pytest

from tests.harness import ROOT
from kindyngen.runtime.evaluate import compile_shared_library
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot

FUNCTIONS = ("fk_hom", "jacobian", "M", "tau", "fd", "Y_g", "fk_dq", "ik_hom")
COUNTS = (0, 1, 7, 64, 65, 131)


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """lwr4's C for a few functions (one with int outputs, one with half-angle arguments, which
    the kernel serves too), per trig mode: (functions.json, the C folder)."""
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    out = {}
    for trig in ("kernel", "libm"):
        folder = generate(model, tmp_path_factory.mktemp(trig), languages=("c",), progress=False,
                          only=set(FUNCTIONS), trig=trig)
        out[trig] = (json.loads((folder / "functions.json").read_text()), folder / "c")
    return out


def inputs_for(spec, count, rng):
    """Random inputs, (count, size) per port; poses for the IK from the library's own fk."""
    return [rng.uniform(-2.5, 2.5, (count, port_size(p))) for p in spec["inputs"]]


def port_size(port):
    return int(np.prod(port["shape"]))


def call_single(dll, spec, arrays):
    fn = getattr(dll, spec["c_symbol"])
    count = arrays[0].shape[0]
    outs = [np.zeros((count, port_size(p)), dtype=np.int32 if p.get("dtype") == "int" else float)
            for p in spec["outputs"]]
    for k in range(count):
        fn(*[np.ascontiguousarray(a[k]).ctypes.data_as(ctypes.c_void_p) for a in arrays],
           *[o[k].ctypes.data_as(ctypes.c_void_p) for o in outs])
    return outs


def call_batch(dll, spec, arrays, sentinel=7.0):
    """Inputs and outputs transposed to the structure-of-arrays layout (entry k of configuration
    i at [k*count + i]); outputs prefilled with ``sentinel``."""
    fn = getattr(dll, spec["c_symbol"] + "_batch")
    count = arrays[0].shape[0]
    soa = [np.ascontiguousarray(a.T) for a in arrays]
    outs = [np.full((port_size(p), count), sentinel, dtype=np.int32 if p.get("dtype") == "int" else float)
            for p in spec["outputs"]]
    fn(ctypes.c_long(count), *[a.ctypes.data_as(ctypes.c_void_p) for a in soa],
       *[o.ctypes.data_as(ctypes.c_void_p) for o in outs])
    return [o.T for o in outs]


def library(c_dir, flags):
    return ctypes.CDLL(str(compile_shared_library(c_dir, "lwr4", flags)))


def ik_inputs(dll, count, rng):
    """Reachable poses: the fk of random configurations, and their elbow angles theta3."""
    q = rng.uniform(-1.5, 1.5, (count, 7))
    fk = {"c_symbol": "lwr4_fk_hom", "inputs": [{"shape": [7]}], "outputs": [{"shape": [4, 4]}]}
    return [call_single(dll, fk, [q])[0], rng.uniform(-1.0, 1.0, (count, 1))]


@pytest.mark.parametrize("trig", ["kernel", "libm"])
@pytest.mark.parametrize("flags", [("-O2",), ("-O3", "-march=native", "-ffp-contract=fast")], ids=" ".join)
def test_batch_equals_single_calls(generated, trig, flags):
    manifest, c_dir = generated[trig]
    dll = library(c_dir, flags)
    exact = flags == ("-O2",)
    rng = np.random.default_rng(5)
    specs = {f["name"]: f for f in manifest["functions"]}
    assert set(FUNCTIONS) <= specs.keys()
    for name in FUNCTIONS:
        spec = specs[name]
        for count in COUNTS:
            arrays = ik_inputs(dll, count, rng) if name == "ik_hom" else inputs_for(spec, count, rng)
            single, batch = call_single(dll, spec, arrays), call_batch(dll, spec, arrays)
            for port, s, b in zip(spec["outputs"], single, batch):
                assert b.shape == s.shape
                if exact or port.get("dtype") == "int":
                    np.testing.assert_array_equal(b, s, err_msg=f"{name}.{port['name']} count {count}")
                else:
                    np.testing.assert_allclose(b, s, rtol=1e-15, atol=1e-15 * max(1.0, np.abs(s).max(initial=0)),
                                               err_msg=f"{name}.{port['name']} count {count}")


def test_batch_of_zero_touches_nothing(generated):
    manifest, c_dir = generated["kernel"]
    dll = library(c_dir, ("-O2",))
    spec = next(f for f in manifest["functions"] if f["name"] == "M")
    fn = getattr(dll, "lwr4_M_batch")
    out = np.full(49, 7.0)
    fn(ctypes.c_long(0), None, out.ctypes.data_as(ctypes.c_void_p))
    assert (out == 7.0).all() and spec["outputs"][0]["shape"] == [7, 7]


def test_kernel_and_libm_agree(generated):
    """The trig switch changes sin/cos by at most 1 ulp: outputs agree to ~1e-15 relative."""
    rng = np.random.default_rng(11)
    dlls = {trig: library(generated[trig][1], ("-O2",)) for trig in generated}
    specs = {f["name"]: f for f in generated["kernel"][0]["functions"]}
    for name in ("fk_hom", "jacobian", "M", "tau", "fd", "fk_dq"):
        arrays = inputs_for(specs[name], 50, rng)
        a, b = (call_single(dlls[t], specs[name], arrays)[0] for t in ("kernel", "libm"))
        scale = np.abs(b).max()
        assert np.abs(a - b).max() <= 1e-13 * scale, name
        assert (a != b).any(), f"{name}: the two libraries computed nothing differently"


def test_trig_choice_recorded_and_applied(generated):
    for trig, (manifest, c_dir) in generated.items():
        source, header = (c_dir / "lwr4.c").read_text(), (c_dir / "lwr4.h").read_text()
        assert manifest["trig"] == trig
        assert f"generated with --trig {trig}" in header
        assert ("kdg_sincos" in source) == (trig == "kernel")
        assert ("sin(q[" in source) == (trig == "libm")
        start = source.index("void lwr4_fk_dq(")
        fk_dq = source[start:source.index("\nvoid ", source.index("void lwr4_fk_dq_batch(") + 1)]
        assert ("sin(" in fk_dq) == (trig == "libm"), "half angles: kernel or libm, in both variants"


def test_generate_help_and_bad_trig():
    cli = [sys.executable, "-m", "kindyngen", "generate"]
    assert "--trig" in subprocess.run(cli + ["--help"], capture_output=True, text=True).stdout
    bad = subprocess.run(cli + ["robots/lwr4.yaml", "--out", "/nonexistent", "--trig", "fast"],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and bad.stderr.startswith("error:") and "Traceback" not in bad.stderr


def test_floating_tree_kernel_skips_the_base(tmp_path):
    """A floating tree's q starts with position and quaternion, which no sin/cos takes: the
    kernel starts at the first angle (here q[8]: q[7] is a prismatic lift), where that saves a
    group of lanes. Single calls and batches (both trig modes) equal the numpy module, which
    calls numpy's sin/cos on every entry."""
    from kindyngen.runtime.evaluate import load_generated
    from kindyngen.readers.urdf import load_urdf
    model = load_urdf(ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf", floating_base=True)
    assert model.nq == 12
    rng = np.random.default_rng(3)
    count = 37
    q = np.hstack([rng.uniform(-1, 1, (count, 3)), rng.standard_normal((count, 4)), rng.uniform(-2, 2, (count, 5))])
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    arrays = {"q": q, "qd": rng.uniform(-2, 2, (count, model.nv)), "tau": rng.uniform(-9, 9, (count, model.nv))}
    for trig in ("kernel", "libm"):
        folder = generate(model, tmp_path / trig, languages=("c", "python"), progress=False,
                          only={"fk_hom", "M", "fd"}, trig=trig)
        manifest = json.loads((folder / "functions.json").read_text())
        source = (folder / "c" / f"{model.identifier}.c").read_text()
        if trig == "kernel":
            assert "if (kdg_sincos_split(4, q + 8, sin_q, cos_q))" in source
            assert "served by one run of the sincos kernel over q[8:]" in " ".join(
                (folder / "c" / f"{model.identifier}.h").read_text().split())
        assert "q + (8 + k)*count + start" in source or "q[(8 + k)*count + start + j]" in source
        dll = ctypes.CDLL(str(compile_shared_library(folder / "c", model.identifier, ("-O2",))))
        reference = load_generated(folder, "python")
        for spec in manifest["functions"]:
            inputs = [arrays[p["name"]] for p in spec["inputs"]]
            expected = reference.call(spec["name"], {p["name"]: arrays[p["name"]] for p in spec["inputs"]})
            single, batch = call_single(dll, spec, inputs), call_batch(dll, spec, inputs)
            for port, s, b in zip(spec["outputs"], single, batch):
                np.testing.assert_array_equal(b, s, err_msg=f"{trig} {spec['name']}.{port['name']}")
                want = expected[port["name"]].reshape(count, -1)
                np.testing.assert_allclose(s, want, rtol=1e-12, atol=1e-12 * np.abs(want).max(),
                                           err_msg=f"{trig} {spec['name']}.{port['name']}")


def test_batches_of_large_outputs_equal_single_calls(tmp_path, monkeypatch):
    """The two routes of batches with large outputs, on a small floating tree with smaller limits
    (the G1 takes them at the real ones: M in place, tau_derivatives and fd_derivatives per
    state): outputs stored in place, their constant entries (structural zeros) filled before a
    loop marked independent; and, where that loop would reference more array entries than
    LOOP_DATAREFS, a loop over the single call (fd_derivatives': its lane program). Both equal
    count single calls bit for bit (-O2), and to 1e-15 vectorised with contraction."""
    from kindyngen.codegen import render
    from kindyngen.readers.urdf import load_urdf
    monkeypatch.setattr(render, "BATCH_STACK", 4096)     # M's 121 entries, the derivatives': in place
    monkeypatch.setattr(render, "LOOP_DATAREFS", 150)    # M's loop under it, the derivatives' over it
    model = load_urdf(ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf", floating_base=True)
    folder = generate(model, tmp_path / "c", languages=("c",), progress=False,
                      only={"M", "tau_derivatives", "fd_derivatives"})
    manifest = json.loads((folder / "functions.json").read_text())
    source = (folder / "c" / f"{model.identifier}.c").read_text()
    prefix = model.identifier

    def body(name):
        start = source.index(f"void {prefix}_{name}_batch(")
        return source[start:source.index("\n}\n", start)]
    assert "KDG_INDEPENDENT" in body("M") and "static const double value[" in body("M")
    for name in ("tau_derivatives", "fd_derivatives"):
        assert f"{prefix}_{name}(in_q, in_qd, " in body(name) and "static const double value[" in body(name)
    assert "kdg_lane" in source[source.index(f"void {prefix}_fd_derivatives("):source.index(f"void {prefix}_fd_derivatives_batch(")]
    rng = np.random.default_rng(8)
    for flags in (("-O2",), ("-O3", "-march=native", "-ffp-contract=fast")):
        dll = ctypes.CDLL(str(compile_shared_library(folder / "c", prefix, flags)))
        for spec in manifest["functions"]:
            for count in COUNTS:
                q = np.hstack([rng.uniform(-1, 1, (count, 3)), rng.standard_normal((count, 4)),
                               rng.uniform(-2, 2, (count, 5))])
                q[:, 3:7] /= np.maximum(np.linalg.norm(q[:, 3:7], axis=1, keepdims=True), 1e-300)
                arrays = [q if p["name"] == "q" else rng.uniform(-3, 3, (count, port_size(p))) for p in spec["inputs"]]
                single, batch = call_single(dll, spec, arrays), call_batch(dll, spec, arrays)
                for port, s, b in zip(spec["outputs"], single, batch):
                    if flags == ("-O2",):
                        np.testing.assert_array_equal(b, s, err_msg=f"{spec['name']}.{port['name']} count {count}")
                    else:
                        np.testing.assert_allclose(b, s, rtol=1e-15, atol=1e-15 * max(1.0, np.abs(s).max(initial=0)),
                                                   err_msg=f"{spec['name']}.{port['name']} count {count}")
