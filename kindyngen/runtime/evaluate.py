"""Run generated code in any of its languages, from Python, with named array inputs.

``load_generated(directory, lang).call(name, {"q": ...})`` evaluates the code that was
written, not the derivation: the C through a shared library compiled on first use (cached
by a hash of the sources), the Python module imported from its file, the CasADi Functions
loaded from their ``.casadi`` files, the JAX module through ``jax.jit`` (64-bit), the MATLAB
``.m`` files in GNU Octave (``octave-cli``, one process per call; :func:`run_octave` runs many
calls in one). Each input may carry one leading batch dimension.

Example:

>>> lib = load_generated("generated/lwr4", "python")            # doctest: +SKIP
>>> float(lib.call("fk_hom", {"q": [0, 0, 0, 0, 0, 0, 0]})["T"][2, 3])  # doctest: +SKIP
0.79
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ..model.user_text import is_identifier, octave_string
from .python_c import cache_root


class EvaluationError(ValueError):
    """Bad request to a generated function: unknown name, missing or mis-shaped input."""


class GeneratedLibrary:
    """The generated functions of one robot in one language."""

    def __init__(self, directory: Path, lang: str):
        self.directory = Path(directory)
        self.lang = lang
        manifest_path = self.directory / "functions.json"
        if not manifest_path.is_file():
            raise EvaluationError(f"{manifest_path}: not found (is {directory} a generated robot folder?)")
        try:
            self.manifest = json.loads(manifest_path.read_text())
            self.functions = {f["name"]: f for f in self.manifest["functions"]}
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            raise EvaluationError(f"{manifest_path}: not a KinDynGen interface file ({exc})") from None
        # the robot's identifier and the function names become paths, module names and Octave
        # function handles: only identifiers (kindyngen.model.user_text) are taken
        for what in [self.manifest.get("robot")] + list(self.functions):
            if not isinstance(what, str) or not is_identifier(what):
                raise EvaluationError(f"{manifest_path}: {what!r} is not an identifier (not a KinDynGen "
                                      f"interface file, or one edited by hand)")
        self._impl = {"python": _PythonBackend, "c": _CBackend, "casadi": _CasadiBackend,
                      "jax": _JaxBackend, "matlab": _MatlabBackend}[lang](self)

    def call(self, name: str, inputs: dict) -> dict:
        """Evaluate ``name`` on named inputs; returns named outputs (numpy arrays)."""
        if name not in self.functions:
            raise EvaluationError(f"no function '{name}' in {self.directory}; available: {', '.join(self.functions)}")
        spec = self.functions[name]
        if self.lang not in spec.get("languages", (self.lang,)) or (
                self.lang in ("jax", "matlab") and spec.get("kind") == "iterative"):
                raise EvaluationError(f"{name} is not generated for {self.lang} (it exists in "
                                  f"{', '.join(spec.get('languages', ()))})")
        arrays, batch = _check_inputs(name, spec, inputs)
        outputs = self._impl.call(spec, arrays, batch)
        if batch is None:
            outputs = {k: v[0] for k, v in outputs.items()}
        return outputs


def _check_inputs(name, spec, inputs):
    unknown = set(inputs) - {p["name"] for p in spec["inputs"]}
    if unknown:
        raise EvaluationError(f"{name}: unknown input(s) {sorted(unknown)}; expected {[p['name'] for p in spec['inputs']]}")
    arrays, batch = [], None
    for port in spec["inputs"]:
        if port["name"] not in inputs:
            raise EvaluationError(f"{name}: missing input '{port['name']}' (shape {port['shape']})")
        try:
            a = np.asarray(inputs[port["name"]], dtype=float)
        except (TypeError, ValueError) as exc:
            raise EvaluationError(f"{name}: input '{port['name']}' is not numeric") from exc
        shape = tuple(port["shape"])
        if a.shape == shape:
            this_batch = None
            a = a[None]
        elif a.shape[1:] == shape and a.ndim == len(shape) + 1:
            this_batch = a.shape[0]
        else:
            raise EvaluationError(f"{name}: input '{port['name']}' has shape {list(a.shape)}; expected "
                                  f"{list(shape)} or [N, {', '.join(map(str, shape))}]")
        if batch is not None and this_batch is not None and batch != this_batch:
            raise EvaluationError(f"{name}: inputs disagree on the batch size ({batch} vs {this_batch})")
        batch = this_batch if this_batch is not None else batch
        arrays.append(a)
    count = batch or 1
    arrays = [np.broadcast_to(a, (count,) + a.shape[1:]) for a in arrays]
    return arrays, batch


class _PythonBackend:
    def __init__(self, lib: GeneratedLibrary):
        robot = lib.manifest["robot"]
        path = lib.directory / "python" / f"{robot}.py"
        spec = importlib.util.spec_from_file_location(f"kindyngen_generated_{robot}", path)
        self.module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(self.module)

    def call(self, spec, arrays, batch):
        result = self.module.FUNCTIONS[spec["name"]](*arrays)
        result = result if isinstance(result, tuple) else (result,)
        return {p["name"]: np.asarray(r) for p, r in zip(spec["outputs"], result)}


def _cache_dir() -> Path:
    """``eval``'s libraries live under the one cache root of compiled generated code, beside
    the python_c extensions (:func:`kindyngen.runtime.python_c.cache_root`, ``$KINDYNGEN_CACHE``)."""
    path = cache_root() / "eval"
    path.mkdir(parents=True, exist_ok=True)
    return path


def compile_shared_library(c_dir: Path, robot: str, flags=("-O0",)) -> Path:
    """Compile the generated C into a shared library (cached by source hash and flags).

    Unoptimised by default: `eval` and the tests call each function a few thousand times, so
    compile time dominates (the LWR's library with its batch variants and derivatives takes
    18 s at -O2, 1.6 s at -O0), and strict C99 gives the same IEEE results at every
    optimisation level (no contraction). Optimised builds are tested by the strict-C99 check
    (-O2) and the batch tests (-O2, -O3 -march=native)."""
    source, header = c_dir / f"{robot}.c", c_dir / f"{robot}.h"
    digest = hashlib.sha256(source.read_bytes() + header.read_bytes() + " ".join(flags).encode()).hexdigest()[:16]
    target = _cache_dir() / f"{robot}-{digest}.so"
    if not target.exists():
        tmp = target.with_suffix(f".{os.getpid()}.tmp")
        cmd = [os.environ.get("CC", "cc"), "-std=c99", *flags, "-shared", "-fPIC", "-o", str(tmp), str(source), "-lm"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise EvaluationError(f"compiling {source} failed:\n{done.stderr}")
        os.replace(tmp, target)
    return target


class _CBackend:
    def __init__(self, lib: GeneratedLibrary):
        robot = lib.manifest["robot"]
        self.dll = ctypes.CDLL(str(compile_shared_library(lib.directory / "c", robot)))
        # --scalar float: every C port is float; inputs are rounded to float, outputs widened
        self.real = np.float32 if lib.manifest.get("c_scalar", "double") == "float" else np.float64

    def call(self, spec, arrays, batch):
        fn = getattr(self.dll, spec["c_symbol"])
        fn.restype = None
        count = arrays[0].shape[0]
        ins = [np.ascontiguousarray(a.reshape(count, -1), dtype=self.real) for a in arrays]
        outs = [np.zeros((count, int(np.prod(p["shape"]))), dtype=np.intc if p["dtype"] == "int" else self.real)
                for p in spec["outputs"]]
        for k in range(count):
            fn(*[a[k].ctypes.data_as(ctypes.c_void_p) for a in ins],
               *[o[k].ctypes.data_as(ctypes.c_void_p) for o in outs])
        return {p["name"]: o.reshape((count,) + tuple(p["shape"])).astype(np.int64 if p["dtype"] == "int" else float)
                for p, o in zip(spec["outputs"], outs)}


class _CasadiBackend:
    def __init__(self, lib: GeneratedLibrary):
        import casadi
        self.casadi = casadi
        self.directory = lib.directory / "casadi"
        self.loaded = {}

    def call(self, spec, arrays, batch):
        name = spec["name"]
        if name not in self.loaded:
            path = self.directory / f"{name}.casadi"
            if not path.is_file():
                raise EvaluationError(f"{path}: not found (generate the robot with --lang casadi)")
            self.loaded[name] = self.casadi.Function.load(str(path))
        fn = self.loaded[name]
        count = arrays[0].shape[0]
        outs = {p["name"]: np.zeros((count,) + tuple(p["shape"])) for p in spec["outputs"]}
        for k in range(count):
            args = [self.casadi.DM(a[k].reshape(a[k].shape[0], -1) if a[k].ndim == 2 else a[k]) for a in arrays]
            result = fn(*args)
            result = result if isinstance(result, (list, tuple)) else [result]
            for p, r in zip(spec["outputs"], result):
                outs[p["name"]][k] = np.array(r.full()).reshape(p["shape"])
        for p in spec["outputs"]:
            if p["dtype"] == "int":
                outs[p["name"]] = np.rint(outs[p["name"]]).astype(np.int64)
        return outs


class _JaxBackend:
    def __init__(self, lib: GeneratedLibrary):
        try:
            import jax
        except ImportError:
            raise EvaluationError("--lang jax needs JAX (pip install jax)") from None
        jax.config.update("jax_enable_x64", True)   # the generated code is derived for doubles
        self.jax = jax
        robot = lib.manifest["robot"]
        path = lib.directory / "jax" / f"{robot}_jax.py"
        if not path.is_file():
            raise EvaluationError(f"{path}: not found (generate the robot with --lang jax)")
        spec = importlib.util.spec_from_file_location(f"kindyngen_generated_{robot}_jax", path)
        self.module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(self.module)

    def call(self, spec, arrays, batch):
        result = self.jax.jit(self.module.FUNCTIONS[spec["name"]])(*arrays)
        result = result if isinstance(result, tuple) else (result,)
        return {p["name"]: np.asarray(r).astype(np.int64 if p["dtype"] == "int" else float)
                for p, r in zip(spec["outputs"], result)}


def _octave_layout(array: np.ndarray) -> np.ndarray:
    """(N, s1, ..., sd) row-major as the bytes of MATLAB's s1 x ... x sd x N column-major array."""
    return np.ascontiguousarray(np.transpose(array, (0,) + tuple(range(array.ndim - 1, 0, -1))), dtype=np.float64)


def run_octave(matlab_dir, calls, timeout: float = 600.0) -> list[list[np.ndarray]]:
    """Evaluate generated .m functions in one GNU Octave process. ``calls``: (function name as
    the .m file is named, or an Octave function handle starting with ``@``; list of input
    arrays, each (N,) + port shape or (1,) + port shape; list of output shapes); returns per
    call the output arrays, each (N,) + shape."""
    octave = shutil.which("octave-cli") or shutil.which("octave")
    if octave is None:
        raise EvaluationError("--lang matlab runs the .m files in GNU Octave, which is not installed "
                              "(Debian: apt-get install octave)")
    with tempfile.TemporaryDirectory(prefix="kindyngen-octave-") as tmp:
        tmp = Path(tmp)
        lines = [f'addpath("{octave_string(str(Path(matlab_dir).resolve()))}");']
        where = octave_string(str(tmp))
        for c, (name, inputs, shapes) in enumerate(calls):
            args = []
            for k, a in enumerate(inputs):
                _octave_layout(a).tofile(tmp / f"in{c}_{k}.bin")
                dims = ", ".join(str(s) for s in (tuple(a.shape[1:]) + (a.shape[0],)))
                lines.append(f"fid = fopen(\"{where}/in{c}_{k}.bin\"); a{k} = reshape(fread(fid, Inf, 'double'), [{dims}]); "
                             "fclose(fid);")
                args.append(f"a{k}")
            outs = ", ".join(f"o{k}" for k in range(len(shapes)))
            writes = " ".join(f"fid = fopen(\"{where}/out{c}_{k}.bin\", 'w'); fwrite(fid, double(o{k}), 'double'); fclose(fid);"
                              for k in range(len(shapes)))
            handle = name if name.startswith("@") else "@" + name
            lines.append(f"try\n  fn = {handle};\n  [{outs}] = fn({', '.join(args)});\n  {writes}\ncatch err\n"
                         f"  fid = fopen(\"{where}/err{c}.txt\", 'w'); fputs(fid, err.message); fclose(fid);\nend")
        (tmp / "run.m").write_text("\n".join(lines) + "\n")
        done = subprocess.run([octave, "--no-init-file", "--quiet", "--no-window-system", str(tmp / "run.m")],
                              capture_output=True, text=True, timeout=timeout)
        results = []
        for c, (name, inputs, shapes) in enumerate(calls):
            if (tmp / f"err{c}.txt").exists():
                raise EvaluationError(f"octave: {name}: {(tmp / f'err{c}.txt').read_text()}")
            count = max([a.shape[0] for a in inputs] or [1])
            outs = []
            for k, shape in enumerate(shapes):
                path = tmp / f"out{c}_{k}.bin"
                if not path.exists():
                    raise EvaluationError(f"octave failed on {name}: {done.stderr.strip()[-500:]}")
                flat = np.fromfile(path, dtype=np.float64).reshape((count,) + tuple(reversed(shape)))
                outs.append(np.transpose(flat, (0,) + tuple(range(len(shape), 0, -1))))
            results.append(outs)
        return results


class _MatlabBackend:
    def __init__(self, lib: GeneratedLibrary):
        self.directory = lib.directory / "matlab"
        self.robot = lib.manifest["robot"]
        if not self.directory.is_dir():
            raise EvaluationError(f"{self.directory}: not found (generate the robot with --lang matlab)")

    def call(self, spec, arrays, batch):
        shapes = [tuple(p["shape"]) for p in spec["outputs"]]
        outs = run_octave(self.directory, [(f"{self.robot}_{spec['name']}", list(arrays), shapes)])[0]
        return {p["name"]: o.astype(np.int64) if p["dtype"] == "int" else o for p, o in zip(spec["outputs"], outs)}


EVAL_LANGS = ("c", "python", "casadi", "jax", "matlab")


def load_generated(directory, lang: str) -> GeneratedLibrary:
    if lang not in EVAL_LANGS:
        raise EvaluationError(f"unknown language '{lang}': choose {', '.join(EVAL_LANGS)}")
    return GeneratedLibrary(Path(directory), lang)
