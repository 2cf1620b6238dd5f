"""The strongest Pinocchio-based peer ("pinocchio_casadi_c"): Pinocchio's own algorithms traced
with casadi::SX as the scalar (pinocchio_casadi_trace.cpp, a C++ program: the pin wheel has no
pinocchio.casadi module), saved as casadi Functions, turned into C by CasADi's code generator
and compiled with the flags of our "c_native" (gcc -O3 -march=native).

For the derivatives there are two ways a Pinocchio + CasADi user could go, and both are traced:
Pinocchio's analytical derivative algorithms (computeRNEADerivatives, computeABADerivatives)
and CasADi's automatic differentiation of the traced rnea / aba. Both are timed in the same
runs and the faster one (lower minimum) is kept as the peer (:func:`keep_faster`), so the
comparison is against the strongest of them; the note says which one it was.
"""
from __future__ import annotations

import subprocess
import sysconfig
from pathlib import Path

import casadi
import numpy as np

from . import c_harness, casadi_codegen, inputs, pinocchio_cpp
from .build import Built, build, target
from .compiled import C_FLAGS, Timer

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "pinocchio_casadi_trace.cpp"
HEADERS = (pinocchio_cpp.HEADER, pinocchio_cpp.ARGS, HERE / "sx_trace.hpp")
IMPL = "pinocchio_casadi_c"
# -O0: the tracer runs once per robot for well under a second, while optimising the heavily
# templated Pinocchio/Eigen/SX code would add minutes to its cold build.
FLAGS = ["-std=c++17", "-O0", "-DNDEBUG", *pinocchio_cpp.BOOST_FLAGS]

# The generated function -> what the traced Function computes (the candidates of a derivative
# function are listed under CANDIDATES).
NOTES = {
    "fk_hom": "forwardKinematics + updateFramePlacement, traced in SX",
    "jacobian": "computeFrameJacobian LOCAL_WORLD_ALIGNED, traced in SX",
    "M": "crba traced in SX, mirrored to the full matrix",
    "g": "computeGeneralizedGravity traced in SX",
    "c": "rnea(q, qd, 0) on a gravity-free copy, traced in SX",
    "tau": "rnea traced in SX",
    "fd": "aba traced in SX",
    "Minv": "computeMinverse traced in SX, mirrored to the full matrix",
}
# Derivative function -> {traced Function: what it is}; the first is Pinocchio's analytical one.
CANDIDATES = {
    "tau_derivatives": {"tau_derivatives": "computeRNEADerivatives traced in SX",
                        "tau_derivatives_ad": "CasADi jacobian of the traced rnea"},
    "fd_derivatives": {"fd_derivatives": "computeABADerivatives traced in SX",
                       "fd_derivatives_ad": "CasADi jacobian of the traced aba, Minv by computeMinverse traced"},
}


def casadi_dir() -> Path:
    return Path(sysconfig.get_paths()["purelib"]) / "casadi"


def _tracer_build() -> tuple:
    """build()'s arguments for the tracer: header-only Pinocchio, the casadi wheel's CasADi."""
    lib = casadi_dir()
    flags = FLAGS + [f"-I{d}" for d in pinocchio_cpp.include_dirs()] + [f"-I{lib / 'include'}"]
    return ("pinocchio_casadi_trace", "g++", [SOURCE], flags, (f"-L{lib}", "-lcasadi", f"-Wl,-rpath,{lib}"), HEADERS)


def build_tracer() -> Built:
    return build(*_tracer_build())


def tracer_cached() -> bool:
    """Whether build_tracer() would return at once (its slow cold build is done)."""
    return target(*_tracer_build()).exists()


def trace(binary: Path, robot, outdir: Path) -> dict:
    """Run the tracer for ``robot`` into ``outdir``; {name: casadi.Function} of every saved
    Function (the candidates included)."""
    outdir.mkdir(parents=True, exist_ok=True)
    model_file = outdir / f"{robot.identifier}_pinocchio_model.txt"
    model_file.write_text(pinocchio_cpp.model_text(robot))
    subprocess.run([str(binary), str(model_file), str(outdir)], capture_output=True, text=True, check=True)
    names = list(NOTES) + [c for group in CANDIDATES.values() for c in group]
    return {name: casadi.Function.load(str(outdir / f"{name}.casadi")) for name in names}


def samples_for(functions: dict, samples: dict, robot, K: int) -> dict:
    """Inputs per traced Function: the very samples of the generated function of that name
    (a candidate takes those of its function); where generated/ lacks the function (the
    derivatives, until they are generated) or names its ports otherwise, inputs are drawn
    the same way (inputs.sample)."""
    out = {}
    for name, f in functions.items():
        base = next((b for b, group in CANDIDATES.items() if name in group), name)
        if not set(f.name_in()) <= samples.get(base, {}).keys():
            ports = {"inputs": [{"name": f.name_in(i), "shape": [f.size1_in(i)]} for i in range(f.n_in())]}
            samples = {**samples, base: inputs.sample(ports, robot, K)}
        out[name] = samples[base]
    return out


def timer(robot, binary: Path, samples: dict, K: int, workdir: Path) -> Timer:
    """Trace, code-generate and build the peer for ``robot``; its Timer reports every traced
    Function, candidates under their own names (see :func:`keep_faster`)."""
    functions = trace(binary, robot, workdir / f"{robot.identifier}_{IMPL}")
    stem = f"{robot.identifier}_{IMPL}"
    source, prelude, targets = casadi_codegen.generate(functions, samples_for(functions, samples, robot, K),
                                                       workdir, stem)
    prepared = c_harness.prepare(stem, targets, prelude, [source], C_FLAGS[IMPL], workdir)

    def outputs(raw):  # CasADi's non-zeros, column-major -> dense row-major
        return {name: [casadi_codegen.from_casadi_layout(v, functions[name].sparsity_out(i))
                       for i, v in enumerate(values)] for name, values in raw.items()}
    return Timer(run=lambda repeats, target: c_harness.measure(prepared, repeats, target),
                 outputs=outputs, build_seconds=prepared.built.seconds)


def keep_faster(times: dict, outputs: dict) -> tuple[dict, dict, dict]:
    """Collapse the candidates of each derivative function to the faster one (lower minimum over
    the pooled repetitions): (times, outputs, notes) under the generated functions' names.

    By minima, not medians: on a shared machine a load burst during one candidate's rounds
    raises its median and once kept the slower candidate; the minimum is what each one does
    undisturbed, so it picks the stronger peer (and never flatters ours)."""
    times, outputs = dict(times), dict(outputs)
    notes = {name: note for name, note in NOTES.items() if name in times}
    for name, group in CANDIDATES.items():
        timed = {c: np.min(times[c]) for c in group if c in times}
        if not timed:
            continue
        best = min(timed, key=timed.get)
        others = ", ".join(f"{group[c]} {timed[c]:.0f} ns" for c in timed if c != best)
        notes[name] = f"{group[best]} (the faster here by minimum; {others})" if others else group[best]
        times[name], outputs[name] = times[best], outputs.get(best)
        for c in group:
            if c != name:
                times.pop(c, None)
                outputs.pop(c, None)
    return times, {k: v for k, v in outputs.items() if v is not None}, notes
