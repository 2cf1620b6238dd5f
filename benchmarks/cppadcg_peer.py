"""Pinocchio's own CppADCodeGen as a peer ("pinocchio_cppadcg"): Pinocchio 4.1's CodeGenRNEA,
CodeGenABA, CodeGenCRBA, CodeGenMinv, CodeGenRNEADerivatives and CodeGenABADerivatives
(pinocchio/codegen/cppadcg-algo.hpp) tape its algorithms with CppAD<CG<double>>, and
CppADCodeGen writes C for them; the generated ``<name>_forward_zero`` is compiled and called
from the C harness that times the generated code (benchmarks/c_harness.py).

Built from the registry's packages (pinned in pyproject's "bench" extra, which `make bench`
installs and `make test` does not need: the peer's test skips with the reason without them)::

    pip install cmeel-cppad==20250000.2 cmeel-cppadcodegen==2.4.3
    # or beside the venv:
    pip install --no-deps --target benchmarks/build/cppadcg-prefix cmeel-cppad==20250000.2 cmeel-cppadcodegen==2.4.3

Pinocchio's CodeGenBase::compileLib would compile the sources with CppADCodeGen's own gcc call
(``-Ofast``, each file ``-x c -fPIC -c``, then ``-shared``) and dlopen the library; its
evalFunction then copies the state into an Eigen vector and calls through CppADCodeGen's C++
model wrapper. Here the sources are written out instead (pinocchio_cppadcg_gen.cpp), and
compiled two ways: with the flags of our ``c_native`` (``-std=gnu99 -O3 -march=native``:
``pinocchio_cppadcg``) and with CppADCodeGen's own flags as Pinocchio sets them (``-Ofast
-fPIC``, gcc's default language mode: ``pinocchio_cppadcg_ofast``); either way the harness
calls the generated C function directly with the state already in its input layout, so
nothing but the generated code is timed. Before any timing, every output for input 0 must
equal Pinocchio's own double algorithms (run by the generator program) to TOLERANCE.

The generator program is a header-only Pinocchio build with CppAD's scalar (minutes, cached in
benchmarks/build/ like the other Pinocchio programs); the generated sources are cached per
robot and function by the content of the model and the generator (benchmarks/build/cppadcg/),
and their objects per flag set by build.py's hash of the source text, so the minutes of a
humanoid's generation and compilation are paid once. The generation and compile seconds
reported are those of the run that built them (``cached`` says whether this run reused them).

    python -m benchmarks.cppadcg_peer [--quick] [--robots lwr4,panda,ur5,g1] [--out DIR]

runs the one-run comparison of ours (``c_native``), this peer with both flag sets, the traced
Pinocchio (``pinocchio_casadi_c``) and Pinocchio C++ (``pinocchio_cpp``) on tau, fd, M, Minv,
tau_derivatives and fd_derivatives, with the generation and compile times of both code
generators, and writes results/cppadcg.json. ``make bench`` (run.py, trees.py) and
head_to_head.py time the peer beside the others too.
"""
from __future__ import annotations

import hashlib
import json
import re
import resource
import shutil
import subprocess
import sysconfig
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import c_harness, pinocchio_cpp
from .build import BUILD, Built, build, target
from .compiled import C_FLAGS, Timer

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "pinocchio_cppadcg_gen.cpp"
HEADERS = (pinocchio_cpp.HEADER,)
IMPL = "pinocchio_cppadcg"              # compiled like our c_native
IMPL_OFAST = "pinocchio_cppadcg_ofast"  # compiled as Pinocchio's compileLib does
IMPLS = (IMPL, IMPL_OFAST)
FLAGS = {IMPL: [c_harness.C_STD, *C_FLAGS["c_native"]],
         # CodeGenBase::compileLib: GccCompiler's flags with its "-O2" replaced by "-Ofast"; the
         # objects are compiled -fPIC for the shared library, in gcc's default language mode
         IMPL_OFAST: ["-Ofast", "-fPIC"]}
FUNCTIONS = ("tau", "fd", "M", "Minv", "tau_derivatives", "fd_derivatives")
PACKAGES = {"cmeel-cppad": "20250000.2", "cmeel-cppadcodegen": "2.4.3"}
SIDE_PREFIX = BUILD / "cppadcg-prefix"
WORK = BUILD / "cppadcg"
# Pinocchio's double algorithms against the generated library on input 0: max |got - want| /
# max(1, max |want|). The two evaluate the same operations in another order (the generated
# code after CppAD's tape optimisation, -Ofast reassociating), so they differ by rounding:
# measured up to 1e-14 on the arms; the bound leaves two orders of magnitude for the trees.
TOLERANCE = 1e-12
NOTES = {
    "tau": "CodeGenRNEA (rnea)",
    "fd": "CodeGenABA (aba)",
    "M": "CodeGenCRBA (crba, upper triangle)",
    "Minv": "CodeGenMinv (computeMinverse, upper triangle)",
    "tau_derivatives": "CodeGenRNEADerivatives (dtau/dq, dtau/dv and dtau/da = M)",
    "fd_derivatives": "CodeGenABADerivatives (dqdd/dq, dqdd/dv, Minv)",
}
# The state ports each generated function reads, in the order of its input vector x.
STATE = {"tau": ("q", "qd", "qdd"), "fd": ("q", "qd", "tau"), "M": ("q",), "Minv": ("q",),
         "tau_derivatives": ("q", "qd", "qdd"), "fd_derivatives": ("q", "qd", "tau")}


class WiringError(RuntimeError):
    """An implementation does not compute what Pinocchio's algorithms compute."""


# --- the packages ----------------------------------------------------------------------------
def include_dirs() -> list[Path] | None:
    """Pinocchio's headers, Eigen and CppAD + CppADCodeGen (the venv's cmeel prefix, else the side
    prefix); None when CppADCodeGen's headers are in neither."""
    for prefix in (Path(sysconfig.get_paths()["purelib"]), SIDE_PREFIX):
        include = prefix / "cmeel.prefix" / "include"
        if (include / "cppad" / "cg.hpp").exists():
            return [include, *pinocchio_cpp.include_dirs()]
    return None


def unavailable() -> str | None:
    """Why the peer cannot be built here, or None."""
    pins = " ".join(f"{name}=={version}" for name, version in PACKAGES.items())
    if include_dirs() is None:
        return (f"CppADCodeGen's headers not found (pip install -e '.[bench]', which pins {pins}; or "
                f"pip install --no-deps --target {SIDE_PREFIX} {pins})")
    if not (pinocchio_cpp.include_dirs()[0] / "pinocchio" / "codegen" / "cppadcg-algo.hpp").exists():
        return "Pinocchio's codegen headers (pinocchio/codegen/cppadcg-algo.hpp) not found"
    return None


# --- the generator program -------------------------------------------------------------------
def _generator_build() -> tuple:
    """build()'s arguments: header-only Pinocchio with CppAD<CG<double>>, -O2 (it tapes and
    generates the humanoid's derivatives: an unoptimised build would multiply those minutes);
    libboost_serialization for the URDF models, which come serialized as for the tree bench."""
    lib = pinocchio_cpp.include_dirs()[0].parent / "lib"
    flags = ["-std=c++17", "-O2", "-DNDEBUG", *pinocchio_cpp.BOOST_FLAGS, *(f"-I{d}" for d in include_dirs())]
    return ("pinocchio_cppadcg_gen", "g++", [SOURCE], flags,
            (f"-L{lib}", "-lboost_serialization", f"-Wl,-rpath,{lib}"), HEADERS)


def build_generator() -> Built:
    return build(*_generator_build())


def generator_cached() -> bool:
    """Whether build_generator() would return at once (its slow cold build is done)."""
    return include_dirs() is not None and target(*_generator_build()).exists()


# --- generation (cached by content) -----------------------------------------------------------
@dataclass(frozen=True)
class Generated:
    """One function's C sources from CppADCodeGen, and what generating them took."""

    name: str
    folder: Path
    seconds: dict        # tape_s, source_s, tape_cpu_s, source_cpu_s
    cached: bool

    @property
    def forward_zero(self) -> Path:
        return self.folder / f"{self.name}_forward_zero.c"


def _digest(generator: Path, model_file: Path, name: str) -> str:
    digest = hashlib.sha256()
    for part in (generator.name.encode(), model_file.read_bytes(), name.encode()):
        digest.update(part + b"\0")
    return digest.hexdigest()[:16]


def generate(generator: Path, model_file: Path, stem: str, name: str, limit_s: float) -> Generated:
    """Function ``name``'s sources for the robot in ``model_file``: from the cache when the same
    generator made them for the same model, else by running the generator (TimeoutExpired past
    ``limit_s``)."""
    folder = WORK / f"{stem}_{name}-{_digest(generator, model_file, name)}"
    record = folder / "generation.json"
    if record.exists():
        return Generated(name, folder / name, json.loads(record.read_text()), True)
    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    out = subprocess.run([str(generator), "generate", str(model_file), str(tmp), name], capture_output=True,
                         text=True, check=True, timeout=limit_s)
    fields = next(line.split()[2:] for line in out.stdout.splitlines() if line.startswith(f"generated {name} "))
    seconds = dict(zip(("tape_s", "source_s", "tape_cpu_s", "source_cpu_s"), map(float, fields)))
    (tmp / "generation.json").write_text(json.dumps(seconds) + "\n")
    shutil.rmtree(folder, ignore_errors=True)
    tmp.rename(folder)          # only a finished generation carries the cache name
    for stale in WORK.glob(f"{stem}_{name}-*"):
        if stale != folder and not stale.name.endswith(".tmp"):
            shutil.rmtree(stale, ignore_errors=True)
    return Generated(name, folder / name, seconds, False)


def reference(generator: Path, model_file: Path, state: dict, names, workdir: Path) -> dict:
    """{function: [row-major outputs]}: Pinocchio's double algorithms for one state (q in
    Pinocchio's layout, qd, qdd, tau), in the generated functions' layout."""
    workdir.mkdir(parents=True, exist_ok=True)
    path = workdir / "reference_state.bin"
    np.concatenate([np.ravel(state[k]) for k in ("q", "qd", "qdd", "tau")]).astype(np.float64).tofile(path)
    out = subprocess.run([str(generator), "reference", str(model_file), str(path), *names],
                         capture_output=True, text=True, check=True)
    return c_harness.parse(out.stdout)[1]


def reference_for(generator: Path, model_file: Path, inputs: dict, nq: int, nv: int, workdir: Path) -> dict:
    """Pinocchio's double results for input 0 of each function's own input vectors x
    ({function: (K, len(x))}, as :func:`peer_inputs` makes them), where functions were given
    different states."""
    out = {}
    for name, x in inputs.items():
        q, rest = x[0, :nq], x[0, nq:]
        v, third = (rest[:nv], rest[nv:]) if rest.size else (np.zeros(nv), np.zeros(nv))
        out.update(reference(generator, model_file, {"q": q, "qd": v, "qdd": third, "tau": third}, [name], workdir))
    return out


# --- compiling and timing ----------------------------------------------------------------------
def _cpu_children() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@dataclass(frozen=True)
class Compiled:
    """An object file and what compiling it took when it was built (wall and CPU seconds: on a
    shared machine the wall time grows with the load, the CPU time much less)."""

    path: Path
    seconds: float
    cpu_seconds: float
    cached: bool


def compile_object(name: str, source: Path, flags: list) -> Compiled:
    """``source`` compiled to an object with build() (cached by content), its compiler's CPU
    time recorded beside the wall time build() keeps."""
    before = _cpu_children()
    built = build(name, "gcc", [source], [*flags, "-c"])
    record = Path(f"{built.path}.cpu_seconds")
    if not built.cached:
        record.write_text(f"{_cpu_children() - before:.2f}\n")
    cpu = float(record.read_text()) if record.exists() else float("nan")
    return Compiled(built.path, built.seconds or 0.0, cpu, built.cached)


def compile_objects(generated: Generated, stem: str, impl: str) -> tuple[Path, dict]:
    """Every C file CppADCodeGen wrote for the function compiled with ``impl``'s flags, as
    Pinocchio's compileLib would (one object per file); (the forward_zero object, {wall_s, cpu_s:
    all files' compiles when they were built, cached: whether all came from the cache})."""
    totals, forward = {"wall_s": 0.0, "cpu_s": 0.0, "cached": True}, None
    for source in sorted(generated.folder.glob("*.c")):
        done = compile_object(f"cppadcg_{stem}_{impl}_{source.stem}", source, FLAGS[impl])
        totals["wall_s"] += done.seconds
        totals["cpu_s"] += done.cpu_seconds
        totals["cached"] &= done.cached
        if source == generated.forward_zero:
            forward = done.path
    if forward is None:
        raise FileNotFoundError(f"CppADCodeGen wrote no {generated.forward_zero.name} in {generated.folder}")
    return forward, {k: round(v, 2) if isinstance(v, float) else v for k, v in totals.items()}


def atomic_struct(source: Path) -> str:
    """The ``struct LangCAtomicFun`` definition (and the ``Array`` type it names) CppADCodeGen
    puts into every generated file (its calling convention passes one by value), for the
    driver's prototypes."""
    match = re.search(r"typedef struct Array \{.*?\} Array;\s*struct LangCAtomicFun \{.*?\};", source.read_text(), re.S)
    if match is None:
        raise ValueError(f"no struct LangCAtomicFun in {source}")
    return match.group(0)


def peer_inputs(name: str, state: dict) -> np.ndarray:
    """(K, nq [+ 2 nv]): the generated function's one input vector x, from the state arrays
    (q in Pinocchio's layout)."""
    return np.ascontiguousarray(np.hstack([state[port] for port in STATE[name]]), dtype=np.float64)


def _symmetric(packed: np.ndarray, n: int) -> np.ndarray:
    """The upper triangle row by row (CodeGenCRBA, CodeGenMinv) -> the full matrix, flat.

    >>> _symmetric(np.array([1.0, 2.0, 3.0]), 2)
    array([1., 2., 2., 3.])
    """
    full = np.zeros((n, n))
    full[np.triu_indices(n)] = packed
    return (full + np.triu(full, 1).T).ravel()


def ours_layout(name: str, y: np.ndarray, nv: int) -> list[np.ndarray]:
    """The peer's output vector -> the generated function's outputs (row-major); the peer's
    tau_derivatives also returns dtau/da = M, which the generated function does not.

    >>> [a.tolist() for a in ours_layout("tau_derivatives", np.arange(3.0), 1)]
    [[0.0], [1.0]]
    """
    if name in ("M", "Minv"):
        return [_symmetric(y, nv)]
    if name == "tau_derivatives":
        return [y[:nv * nv], y[nv * nv:2 * nv * nv]]
    if name == "fd_derivatives":
        return [y[:nv * nv], y[nv * nv:2 * nv * nv], y[2 * nv * nv:]]
    return [y]


@dataclass
class PeerBuild:
    """The peer for one robot: its generated functions and, per flag set, its Timer and the
    compile seconds."""

    generated: dict                         # name -> Generated
    timers: dict = field(default_factory=dict)
    compile_seconds: dict = field(default_factory=dict)   # impl -> {name: {wall_s, cpu_s, cached}}

    def times(self) -> dict:
        """Generation and compile seconds, per function, for the results file."""
        return {"generation": {name: dict(g.seconds, cached=g.cached) for name, g in self.generated.items()},
                "compile": self.compile_seconds}


def build_peer(generator: Path, model_file: Path, stem: str, names, states: dict, nv: int, workdir: Path,
               limit_s: float, log, skip, impls=IMPLS) -> PeerBuild:
    """Generate (or reuse) every function in ``names`` and build one timing driver per flag set.
    ``states``: {function: (K, len(x)) inputs}; a function whose generation or compile fails or
    exceeds ``limit_s`` is passed to ``skip(name, reason)`` and left out."""
    generated = {}
    for name in names:
        try:
            generated[name] = generate(generator, model_file, stem, name, limit_s)
        except subprocess.TimeoutExpired:
            skip(name, f"CppADCodeGen generation exceeded {limit_s:.0f} s")
            continue
        except subprocess.CalledProcessError as exc:
            skip(name, f"generation failed: {(exc.stderr or '')[-500:]}")
            continue
        g = generated[name]
        log(f"  {IMPL}: {name}: {'cached' if g.cached else 'generated'} (tape {g.seconds['tape_s']:.1f} s, "
            f"C {g.seconds['source_s']:.1f} s)")
    peer = PeerBuild(generated)
    if not generated:
        return peer
    prelude = atomic_struct(next(iter(generated.values())).forward_zero) + "\nstatic struct LangCAtomicFun kb_atomic;\n"
    prelude += "\n".join(f"void {name}_forward_zero(double const *const *in, double *const *out, "
                         "struct LangCAtomicFun atomicFun);" for name in generated)
    for impl in impls:
        objects, targets, seconds = [], [], {}
        for name, g in generated.items():
            obj, seconds[name] = compile_objects(g, stem, impl)
            objects.append(obj)
            x = states[name]
            targets.append(c_harness.CFunction(
                name=name, inputs=[x], outputs=[(_output_size(name, nv), "double")],
                call=(f"{{{{ const double *kb_x[1] = {{{{ {{in0}} }}}}; double *kb_y[1] = {{{{ {{out0}} }}}}; "
                      f"{name}_forward_zero(kb_x, kb_y, kb_atomic); }}}}")))
        peer.compile_seconds[impl] = seconds
        log(f"  {impl}: compiled ({' '.join(FLAGS[impl])}): " + ", ".join(
            f"{n} {t['cpu_s']:.1f} s CPU{' (cached)' if t['cached'] else ''}" for n, t in seconds.items()))
        # the driver itself is built with c_native's flags for both: only the objects differ
        prepared = c_harness.prepare(f"{stem}_{impl}", targets, prelude, objects, C_FLAGS["c_native"], workdir)

        def outputs(raw, nv=nv):
            return {name: ours_layout(name, values[0], nv) for name, values in raw.items()}
        peer.timers[impl] = Timer(run=lambda repeats, target_ns, p=prepared: c_harness.measure(p, repeats, target_ns),
                                  outputs=outputs, build_seconds=sum(t["wall_s"] for t in seconds.values()))
    return peer


def _output_size(name: str, nv: int) -> int:
    """Length of the peer's output vector.

    >>> _output_size("M", 7), _output_size("fd_derivatives", 7)
    (28, 147)
    """
    if name in ("M", "Minv"):
        return nv * (nv + 1) // 2
    if name in ("tau_derivatives", "fd_derivatives"):
        return 3 * nv * nv
    return nv


# --- the wiring check ---------------------------------------------------------------------------
def scaled_error(got, want) -> float:
    """max |got - want| / max(1, max |want|); inf when the sizes differ or a value is not finite.

    >>> scaled_error([1.0, 2.0], [1.0, 2.5]), scaled_error([1.0], [1.0, 2.0])
    (0.2, inf)
    """
    got, want = np.ravel(got), np.ravel(want)
    if got.size != want.size:
        return float("inf")
    error = float(np.max(np.abs(got - want), initial=0.0)) / max(1.0, float(np.max(np.abs(want), initial=0.0)))
    return error if np.isfinite(error) else float("inf")


def check(label: str, outputs: dict, want: dict, tolerance: float) -> dict:
    """{function: largest scaled error over its outputs} against Pinocchio's double results;
    WiringError above ``tolerance``."""
    errors = {}
    for name, expected in want.items():
        if name not in outputs:
            continue
        got = outputs[name]
        errors[name] = (max((scaled_error(g, w) for g, w in zip(got, expected)), default=0.0)
                        if len(got) == len(expected) else float("inf"))
    bad = {k: v for k, v in errors.items() if not v <= tolerance}
    if bad:
        raise WiringError(f"{label} disagrees with Pinocchio's double algorithms on input 0 "
                          f"(scaled error above {tolerance:g}): {bad}")
    return errors
