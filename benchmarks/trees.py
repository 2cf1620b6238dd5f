"""Generated code for kinematic trees with a floating base against Pinocchio C++ and
CasADi-traced Pinocchio: G1 (29 joints) and Solo12 (12 joints), optionally Talos reduced;
writes results/trees.json and results/trees.png.

    python -m benchmarks.trees [--quick] [--out DIR] [--robots g1,solo12,talos]

Per robot, in one run: the model is loaded from example-robot-data's URDF with a free-flyer
base and generated (C and numpy) into benchmarks/build/trees/; the C is timed at -O3 ("c")
and -O3 -march=native ("c_native"); "pinocchio_cpp" times Pinocchio's algorithms in double
(pinocchio_tree_bench.cpp, header-only, -O3 -march=native) on Pinocchio's own
buildModelFromUrdf(path, JointModelFreeFlyer()) model; "pinocchio_casadi_c" traces the same
algorithms on ModelTpl<casadi::SX> (pinocchio_tree_trace.cpp), code-generates them with
CasADi and compiles them -O3 -march=native into the harness that times ours. Every
implementation's outputs for the first input must equal the generated numpy code's to 1e-9
(relative to max(1, |value|)) before anything is timed; a mismatch aborts the run. Times are
medians of per-call times pooled over interleaved rounds; ratios are peer / ours (above 1:
ours is faster). --quick: Solo12, no peers, few repeats (a smoke test well under a minute).
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import sysconfig
import time
from datetime import datetime, timezone
from pathlib import Path

import casadi
import numpy as np

from kindyngen.codegen.pipeline import generate
from kindyngen.json_text import strict_json
from kindyngen.output_folder import replace_files
from kindyngen.readers.urdf import load_urdf

from . import c_harness, casadi_codegen, compiled, pinocchio_casadi, pinocchio_cpp, python_timing
from .build import BUILD, build, compiler_version, target
from .common import RESULTS, machine, summary
from .urdf_vs_yaml import example_robot_data

WORK = BUILD / "trees"
HERE = Path(__file__).resolve().parent
BENCH_SOURCE = HERE / "pinocchio_tree_bench.cpp"
TRACE_SOURCE = HERE / "pinocchio_tree_trace.cpp"
# headers the two include (part of their build cache keys)
BENCH_HEADERS = (HERE / "bench_timing.hpp", HERE / "frame_list.hpp", HERE / "program_args.hpp")
TRACE_HEADERS = (HERE / "sx_trace.hpp", HERE / "frame_list.hpp", HERE / "program_args.hpp")
# key -> (URDF under example-robot-data's robots folder, frames (None: the tree's tips))
ROBOTS = {
    "g1": ("g1_description/urdf/g1_29dof_rev_1_0.urdf", None),
    "solo12": ("solo_description/robots/solo12.urdf", None),
    "talos": ("talos_data/robots/talos_reduced.urdf", ["leg_left_6_link", "arm_right_7_link", "torso_2_link"]),
}
FUNCTIONS = ("fk_hom", "jacobian", "M", "g", "c", "tau", "fd", "com")
OURS = ("c", "c_native")
PEERS = ("pinocchio_cpp", pinocchio_casadi.IMPL)
TOLERANCE = 1e-9
# Many short rounds: the machine is shared, and a burst of load from a neighbour should land
# on every implementation alike rather than on one (see compiled.interleave).
FULL = dict(K=1000, repeats=30, rounds=10, c_target_ns=2e7, robots=("g1", "solo12"), peers=True,
            c_native=True, peer_limit_s=180.0)
QUICK = dict(K=100, repeats=3, rounds=1, c_target_ns=2e5, robots=("solo12",), peers=False,
             c_native=False, peer_limit_s=180.0)
PINOCCHIO_NOTES = {
    "fk_hom": "forwardKinematics + updateFramePlacement of the k frames",
    "jacobian": "computeJointJacobians + getFrameJacobian LOCAL_WORLD_ALIGNED of the k frames",
    "M": "crba (upper triangle only)",
    "g": "computeGeneralizedGravity",
    "c": "nonLinearEffects on a gravity-free model copy",
    "tau": "rnea",
    "fd": "aba",
    "com": "jacobianCenterOfMass (com on the way) + computeCentroidalMap",
}
# Pinocchio's joint variant needs more Boost.MPL room; the serialized model needs its library.
CMEEL_LIB = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "lib"
SERIALIZATION_LIBS = (f"-L{CMEEL_LIB}", "-lboost_serialization", f"-Wl,-rpath,{CMEEL_LIB}")


class WiringError(RuntimeError):
    """An implementation computes something else than the generated numpy code."""


# --- inputs ------------------------------------------------------------------------------
def states(model, count: int, seed: int = 0) -> dict:
    """q, qd, qdd, tau in our layout: base position within 1 m, a unit quaternion, joints
    within their limits clipped to +-pi; velocities, accelerations and torques uniform."""
    rng = np.random.default_rng(seed)
    lower = np.array([max(j.lower, -np.pi) for j in model.joints])
    upper = np.array([min(j.upper, np.pi) for j in model.joints])
    quat = rng.standard_normal((count, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    q = np.hstack([rng.uniform(-1, 1, (count, 3)), quat, rng.uniform(lower, upper, (count, model.n))])
    nv = model.nv
    return {"q": q, "qd": rng.uniform(-2, 2, (count, nv)), "qdd": rng.uniform(-5, 5, (count, nv)),
            "tau": rng.uniform(-20, 20, (count, nv))}


def pinocchio_q(pmodel, q: np.ndarray) -> np.ndarray:
    """Our q -> Pinocchio's: a continuous joint (nq 2) is (cos, sin) of our one angle."""
    columns = [q[:, :7]]
    for j, joint in enumerate(pmodel.joints[2:]):   # 0: universe, 1: the free flyer
        angle = q[:, 7 + j:8 + j]
        columns += [np.cos(angle), np.sin(angle)] if joint.nq == 2 else [angle]
    return np.hstack(columns)


def samples_for(functions: list, data: dict) -> dict:
    """{function: {port: (K, size)}} for the functions.json entries, from the shared states."""
    return {f["name"]: {p["name"]: data[p["name"]] for p in f["inputs"]} for f in functions}


# --- the wiring check ----------------------------------------------------------------------
def scaled_error(got: np.ndarray, want: np.ndarray) -> float:
    """max |got - want| / max(1, max |want|); inf when the sizes differ or values are not finite."""
    got, want = np.ravel(got), np.ravel(want)
    if got.size != want.size:
        return math.inf
    error = float(np.max(np.abs(got - want), initial=0.0)) / max(1.0, float(np.max(np.abs(want), initial=0.0)))
    return error if np.isfinite(error) else math.inf


def check(robot: str, impl: str, outputs: dict, reference: dict) -> dict:
    """{function: largest scaled error over its outputs}; raises WiringError above TOLERANCE
    or when a function's outputs are missing."""
    errors = {}
    for name, want in reference.items():
        if name not in outputs:
            continue
        got = outputs[name]
        errors[name] = max((scaled_error(g, w) for g, w in zip(got, want)), default=0.0) \
            if len(got) == len(want) else math.inf
    bad = {k: v for k, v in errors.items() if not v <= TOLERANCE}
    if bad:
        raise WiringError(f"{robot}: {impl} disagrees with the generated numpy code on input 0 "
                          f"(scaled error above {TOLERANCE:g}): {bad}")
    return errors


def numpy_reference(module, functions: list, samples: dict) -> dict:
    """{function: [flat outputs]} of the generated numpy code for input 0."""
    out = {}
    for f in functions:
        result = getattr(module, f["name"])(*(samples[f["name"]][p["name"]][0] for p in f["inputs"]))
        result = result if len(f["outputs"]) > 1 else (result,)
        out[f["name"]] = [np.ravel(np.asarray(r, dtype=float)) for r in result]
    return out


# --- Pinocchio C++ -------------------------------------------------------------------------
def _pinocchio_flags(optimise: list) -> list:
    return ["-std=c++17", *optimise, "-DNDEBUG", *pinocchio_cpp.BOOST_FLAGS,
            *(f"-I{d}" for d in pinocchio_cpp.include_dirs())]


def build_bench(log):
    args = ("pinocchio_tree_bench", "g++", [BENCH_SOURCE], _pinocchio_flags(["-O3", "-march=native"]),
            SERIALIZATION_LIBS, BENCH_HEADERS)
    if not target(*args).exists():
        log("pinocchio_cpp: building pinocchio_tree_bench (header-only Pinocchio, minutes)")
    return build(*args)


def build_tracer(log):
    # -O0: the tracer runs a few times per robot, optimising the templated SX code costs minutes.
    lib = pinocchio_casadi.casadi_dir()
    args = ("pinocchio_tree_trace", "g++", [TRACE_SOURCE], _pinocchio_flags(["-O0"]) + [f"-I{lib / 'include'}"],
            (f"-L{lib}", "-lcasadi", f"-Wl,-rpath,{lib}", *SERIALIZATION_LIBS), TRACE_HEADERS)
    if not target(*args).exists():
        log("pinocchio_casadi_c: building pinocchio_tree_trace (header-only Pinocchio with casadi::SX, minutes)")
    return build(*args)


def pinocchio_timer(binary: Path, model_file: Path, frames: list, pin_data: dict, workdir: Path) -> compiled.Timer:
    """Pinocchio's algorithms in double; its check lines are already in our layout."""
    inputs = workdir / "pinocchio_inputs.bin"
    np.concatenate([np.ascontiguousarray(pin_data[k]).ravel() for k in ("q", "qd", "qdd", "tau")]).tofile(inputs)
    K = pin_data["q"].shape[0]
    command = [str(binary), str(model_file), ",".join(frames), str(inputs), str(K)]

    def run(repeats, target_ns):
        out = subprocess.run(command + [str(repeats), str(target_ns)], capture_output=True, text=True, check=True)
        return c_harness.parse(out.stdout)
    return compiled.Timer(run=run, outputs=lambda raw: raw)


# --- CasADi-traced Pinocchio ----------------------------------------------------------------
def _compile_object(name: str, source: Path, limit_s: float) -> Path:
    """``source`` compiled to an object (cached like build()); TimeoutExpired past limit_s."""
    flags = ["-c", c_harness.C_STD, *compiled.C_FLAGS[pinocchio_casadi.IMPL]]
    out = target(name, "gcc", [source], flags)
    if not out.exists():
        BUILD.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(".tmp.o")
        subprocess.run(["gcc", *flags, str(source), "-o", str(tmp)], check=True, capture_output=True,
                       text=True, timeout=limit_s)
        shutil.move(tmp, out)
    return out


def _prelude(functions: dict) -> str:
    """The shared work arrays (sized for the largest function) and the prototypes."""
    size = {key: max(max(getattr(f, f"sz_{key}")() for f in functions.values()), 1) for key in ("arg", "res", "iw", "w")}
    lines = [f"static const double *kb_arg[{size['arg']}];", f"static double *kb_res[{size['res']}];",
             f"static long long int kb_iw[{size['iw']}];", f"static double kb_w[{size['w']}];"]
    lines += [f"int {name}(const double **arg, double **res, long long int *iw, double *w, int mem);"
              for name in functions]
    return "\n".join(lines)


def traced_timer(tracer: Path, model_file: Path, frames: list, samples: dict, workdir: Path, limit_s: float,
                 stem: str, log, skip) -> compiled.Timer | None:
    """Trace, code-generate and compile each function (each step of one function limited to
    limit_s, else ``skip(function, reason)``), then one harness for those that made it."""
    outdir = workdir / "traced"
    outdir.mkdir(parents=True, exist_ok=True)
    functions, objects, targets = {}, [], []
    for name in FUNCTIONS:
        started = time.perf_counter()
        try:
            subprocess.run([str(tracer), str(model_file), ",".join(frames), str(outdir), name],
                           check=True, capture_output=True, text=True, timeout=limit_s)
            f = casadi.Function.load(str(outdir / f"{name}.casadi"))
            traced = time.perf_counter() - started
            # One C file per function, so that a function too big to compile costs only itself.
            source, _, [one] = casadi_codegen.generate({name: f}, {name: samples[name]}, workdir, f"{stem}_{name}")
            objects.append(_compile_object(f"{stem}_{name}", source, limit_s))
        except subprocess.TimeoutExpired as exc:
            skip(name, f"{'trace' if exc.cmd[0] == str(tracer) else 'C compile'} exceeded {limit_s:.0f} s")
            continue
        except subprocess.CalledProcessError as exc:
            skip(name, f"{Path(exc.cmd[0]).name} failed: {(exc.stderr or '')[-500:]}")
            continue
        log(f"  {name}: traced in {traced:.1f} s, {f.n_instructions()} SX instructions, "
            f"generated and compiled in {time.perf_counter() - started - traced:.1f} s")
        functions[name] = f
        targets.append(one)
    if not targets:
        return None
    prepared = c_harness.prepare(stem, targets, _prelude(functions), objects,
                                 compiled.C_FLAGS[pinocchio_casadi.IMPL], workdir)

    def outputs(raw):  # CasADi's non-zeros, column-major -> dense row-major
        return {name: [casadi_codegen.from_casadi_layout(v, functions[name].sparsity_out(i))
                       for i, v in enumerate(values)] for name, values in raw.items()}
    return compiled.Timer(run=lambda repeats, target_ns: c_harness.measure(prepared, repeats, target_ns),
                          outputs=outputs, build_seconds=prepared.built.seconds)


# --- one robot -----------------------------------------------------------------------------
def urdf_path(key: str) -> Path:
    return example_robot_data() / ROBOTS[key][0]


def pinocchio_model(path: Path, model, model_file: Path):
    """Pinocchio's floating-base model of the URDF, saved for the C++ programs; checks that
    our joints are Pinocchio's, in its order."""
    import pinocchio as pin
    pmodel = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    if list(pmodel.names)[2:] != [j.name for j in model.joints] or pmodel.nv != model.nv:
        raise WiringError(f"{model.name}: Pinocchio's joints differ from ours")
    pmodel.saveToBinary(str(model_file))
    return pmodel


def bench_robot(key: str, settings: dict, tools: dict, log) -> dict:
    """Generate, build, check and time every implementation for one robot."""
    path = urdf_path(key)
    model = load_urdf(path, frames=ROBOTS[key][1], floating_base=True)
    started = time.perf_counter()
    # only the timed functions: the regressor Y would double the C file's compile time
    folder = generate(model, WORK, languages=("c", "python"), progress=False, only=set(FUNCTIONS))
    log(f"{key}: generated {model.identifier} (nq {model.nq}, nv {model.nv}, frames "
        f"{[f.name for f in model.frames]}) in {time.perf_counter() - started:.1f} s")
    spec = json.loads((folder / "functions.json").read_text())
    functions = [f for f in spec["functions"] if f["name"] in FUNCTIONS]
    data = states(model, settings["K"])
    samples = samples_for(functions, data)
    module = python_timing.load_module(folder / "python" / f"{model.identifier}.py")
    reference = numpy_reference(module, functions, samples)
    frames = [f.name for f in model.frames]
    workdir = WORK / "work" / key
    workdir.mkdir(parents=True, exist_ok=True)
    entry = {"nq": model.nq, "nv": model.nv, "joints": model.n, "frames": frames,
             "identifier": model.identifier, "functions": {f["name"]: {} for f in functions},
             "opcounts": {f["name"]: f.get("opcount", {}).get("after") for f in functions},
             "checks": {}, "build_seconds": {}, "skipped": {}}

    timers = {}
    for impl in OURS:
        if impl == "c_native" and not settings["c_native"]:
            continue
        log(f"{key}: {impl}: building the generated C ({' '.join(compiled.C_FLAGS[impl])})")
        timers[impl] = compiled.generated_c(model.identifier, impl, folder, functions, samples, workdir)
    if settings["peers"]:
        model_file = workdir / "pinocchio_model.bin"
        pmodel = pinocchio_model(path, model, model_file)
        pin_data = dict(data, q=pinocchio_q(pmodel, data["q"]))
        timers["pinocchio_cpp"] = pinocchio_timer(tools["bench"], model_file, frames, pin_data, workdir)
        log(f"{key}: {pinocchio_casadi.IMPL}: tracing, generating C and compiling each function "
            f"(limit {settings['peer_limit_s']:.0f} s per step)")

        def skip(name, reason):
            log(f"  {name}: skipped: {reason}")
            entry["skipped"].setdefault(pinocchio_casadi.IMPL, {})[name] = reason
        traced = traced_timer(tools["tracer"], model_file, frames, samples_for(functions, pin_data), workdir,
                              settings["peer_limit_s"], f"{model.identifier}_{pinocchio_casadi.IMPL}", log, skip)
        if traced is not None:
            timers[pinocchio_casadi.IMPL] = traced

    # The wiring check, before any timing: one short run of each, input 0 against numpy.
    for impl, timer in timers.items():
        _, raw = timer.run(1, 1e5)
        entry["checks"][impl] = check(key, impl, timer.outputs(raw), reference)
        log(f"{key}: {impl}: outputs for input 0 match numpy (largest scaled error "
            f"{max(entry['checks'][impl].values()):.1e})")
        if timer.build_seconds is not None:
            entry["build_seconds"][impl] = round(timer.build_seconds, 2)

    log(f"{key}: timing {', '.join(timers)} in {settings['rounds']} interleaved rounds")

    def failed(impl, exc):
        entry["skipped"].setdefault(impl, {})["all"] = f"{type(exc).__name__}: {exc}"[:500]
        log(f"{key}: {impl} failed during timing and was dropped: {exc}")
    pooled, _ = compiled.interleave(timers, settings["repeats"], settings["rounds"], settings["c_target_ns"], failed)
    for impl, per_function in pooled.items():
        for name, values in per_function.items():
            stats = entry["functions"][name][impl] = summary(values)
            if impl == "pinocchio_cpp":
                stats["note"] = PINOCCHIO_NOTES[name]
    entry["ratios"] = ratios(entry["functions"])
    # The fastest repetitions too: on a loaded machine they show what each code costs when
    # it runs alone, which the medians (the headline) blur.
    entry["ratios_min"] = ratios(entry["functions"], "min_ns")
    return entry


def ratios(functions: dict, statistic: str = "median_ns") -> dict:
    """{function: {"peer/ours": t(peer) / t(ours)}}: above 1, ours is faster."""
    return {name: {f"{peer}/{ours}": impls[peer][statistic] / impls[ours][statistic]
                   for peer in PEERS if peer in impls for ours in OURS if ours in impls}
            for name, impls in functions.items()}


# --- the run -------------------------------------------------------------------------------
def run(settings: dict, log) -> dict:
    """Every robot of ``settings`` (FULL or QUICK, possibly edited): the results document."""
    started = time.perf_counter()
    tools, notes = {}, []
    if settings["peers"]:
        built = build_bench(log)
        tools["bench"] = built.path
        tracer = build_tracer(log)
        tools["tracer"] = tracer.path
        tool_builds = {"pinocchio_tree_bench": {"binary": built.path.name, "seconds": built.seconds},
                       "pinocchio_tree_trace": {"binary": tracer.path.name, "seconds": tracer.seconds}}
    else:
        tool_builds = {}
        notes.append("peers skipped (quick mode: their header-only builds take minutes)")
    robots = {key: bench_robot(key, settings, tools, log) for key in settings["robots"]}
    for key, entry in robots.items():
        for impl, skipped in entry["skipped"].items():
            notes += [f"{key}: {impl} {name} skipped: {reason}" for name, reason in skipped.items()]
    log(f"all robots done in {time.perf_counter() - started:.0f} s")
    return {
        "machine": machine(),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()},
        "compile_flags": {**{impl: " ".join(compiled.C_FLAGS[impl]) for impl in (*OURS, pinocchio_casadi.IMPL)},
                          "pinocchio_cpp": "g++ -O3 -march=native (header-only)", "gcc": compiler_version("gcc")},
        "model_source": "pin.buildModelFromUrdf(path, pin.JointModelFreeFlyer()) in Python, passed to the C++ "
                        "programs with Model.saveToBinary (see pinocchio_tree_bench.cpp)",
        "tool_builds": tool_builds,
        "robots": robots,
        "notes": notes,
    }


def table(result: dict) -> str:
    """The medians (ns) and their ratios (in brackets: the ratios of the minima) as Markdown."""
    lines = ["| robot | function | ops after CSE | c | c_native | pinocchio_cpp | pinocchio_casadi_c "
             "| pinocchio_cpp / c_native (min) | pinocchio_casadi_c / c_native (min) |", "|---" * 9 + "|"]
    for key, entry in result["robots"].items():
        for name, impls in entry["functions"].items():
            ops = entry["opcounts"].get(name) or {}
            cells = [f"{impls[i]['median_ns']:.0f}" if i in impls else "-" for i in (*OURS, *PEERS)]
            row, low = entry["ratios"].get(name, {}), entry["ratios_min"].get(name, {})
            ratio = [f"{row[f'{p}/c_native']:.2f} ({low[f'{p}/c_native']:.2f})" if f"{p}/c_native" in row else "-"
                     for p in PEERS]
            lines.append(f"| {key} | {name} | {sum(ops.values())} | " + " | ".join(cells + ratio) + " |")
    return "\n".join(lines)


def plot(result: dict, path: Path) -> None:
    """Grouped bars (ns per call, log scale) per function, one panel per robot."""
    import matplotlib
    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt
    robots = result["robots"]
    fig, axes = plt.subplots(len(robots), 1, figsize=(11, 3.6 * len(robots)), squeeze=False)
    impls = [i for i in (*OURS, *PEERS) if any(i in row for e in robots.values() for row in e["functions"].values())]
    width = 0.8 / len(impls)
    for ax, (key, entry) in zip(axes[:, 0], robots.items()):
        names = list(entry["functions"])
        x = np.arange(len(names))
        for i, impl in enumerate(impls):
            values = [entry["functions"][n].get(impl, {}).get("median_ns", np.nan) for n in names]
            ax.bar(x + (i - (len(impls) - 1) / 2) * width, values, width, label=impl)
        ax.set_yscale("log")
        ax.set_xticks(x, names)
        ax.set_ylabel("ns per call (median)")
        ax.set_title(f"{key}: floating base, nv = {entry['nv']}, {len(entry['frames'])} frames")
        ax.grid(axis="y", which="both", alpha=0.3)
    axes[0, 0].legend(ncol=len(impls), fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write(result: dict, out: Path, log=print) -> None:
    """trees.json and trees.png in ``out``, both or neither (kindyngen.output_folder.replace_files)."""
    def both(folder):
        (folder / "trees.json").write_text(strict_json(result, indent=1) + "\n")
        plot(result, folder / "trees.png")
    replace_files(out, both)
    log(f"wrote {out / 'trees.json'} and {out / 'trees.png'}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("--quick", action="store_true",
                        help="smoke test: Solo12 only, no Pinocchio peers, few repeats")
    parser.add_argument("--out", type=Path, default=RESULTS, help="directory for trees.json and trees.png")
    parser.add_argument("--robots", help=f"comma-separated robots among {', '.join(ROBOTS)} "
                        "(default: g1,solo12; --quick: solo12)")
    args = parser.parse_args(argv)
    settings = dict(QUICK if args.quick else FULL)
    if args.robots:
        unknown = set(args.robots.split(",")) - ROBOTS.keys()
        if unknown:
            parser.error(f"unknown robots {sorted(unknown)}; known: {', '.join(ROBOTS)}")
        settings["robots"] = tuple(args.robots.split(","))

    def log(message):
        print(message, flush=True)
    try:
        result = run(settings, log)
    except WiringError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    write(result, args.out, log)
    log(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
