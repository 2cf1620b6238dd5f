"""Ours against Pinocchio's own CppADCodeGen, the traced Pinocchio and Pinocchio C++, in one run:
tau, fd, M, Minv, tau_derivatives and fd_derivatives of lwr4, panda, ur5 and g1, with the
generation and compile times of both code generators; writes results/cppadcg.json and cppadcg.png
(the ratios).

    python -m benchmarks.cppadcg [--quick] [--robots lwr4,panda,ur5,g1] [--out DIR]

Per robot: ours is generated (``kindyngen`` generate of these functions, C only, with their
batch variants as by default: wall and CPU seconds) and its C compiled as ``c_native`` (gcc
-std=gnu99 -O3 -march=native, the compile timed apart), timed as single calls (``c_native``)
and as one ``<name>_batch`` call on all K states (``c_batch``, per state; ``ratios_batch``);
the peer has no batch form, its figure is a call per state either way; the peer ``pinocchio_cppadcg`` is Pinocchio 4.1's
CodeGen* classes on Pinocchio's own model of the same robot, CppADCodeGen's C compiled with the
same flags, and ``pinocchio_cppadcg_ofast`` the same C with CppADCodeGen's flags as Pinocchio's
compileLib sets them (-Ofast -fPIC) (benchmarks/cppadcg_peer.py); ``pinocchio_casadi_c``
(Pinocchio traced in casadi::SX, CasADi's C, -O3 -march=native) and ``pinocchio_cpp``
(Pinocchio's C++ in double, header-only, -O3 -march=native) as in ``make bench``. The arms of
robots/ (lwr4, panda) reach Pinocchio as numbers (pinocchio_cpp.model_text); ur5 (fixed base)
and g1 (floating base) are read from example-robot-data's URDFs by both sides.

Every implementation's outputs for input 0 must equal Pinocchio's double algorithms before
anything is timed (the CppADCodeGen and traced peers and Pinocchio C++ to
cppadcg_peer.TOLERANCE, ours to OURS_TOLERANCE: its model is the description, exact, where
Pinocchio's holds the URDF's decimals); a mismatch aborts the run. Then all binaries run in
interleaved rounds (compiled.interleave), each figure the median ns per call over the pooled
repetitions, with the minimum beside; ratios are peer / ours (above 1: ours faster). The load
average before and after each robot is stored: on a loaded machine the run must be repeated
idle. --quick: lwr4, tau and M, ours and CppADCodeGen only, few repeats (a smoke run; the
generator's cold build still takes minutes).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from kindyngen.codegen.pipeline import generate
from kindyngen.json_text import strict_json
from kindyngen.output_folder import replace_files
from kindyngen.readers.urdf import load_urdf
from kindyngen.readers.yaml_description import load_robot

from . import c_harness, compiled, cppadcg_peer, inputs, pinocchio_casadi, pinocchio_cpp, trees
from .build import BUILD, compiler_version
from .common import RESULTS, ROBOTS, machine, summary
from .urdf_vs_yaml import example_robot_data

WORK = BUILD / "cppadcg_study"
OURS = "c_native"
BATCH = "c_batch"   # our <name>_batch on all K states in one call, the same object as OURS
TRACED = pinocchio_casadi.IMPL
CPP = "pinocchio_cpp"
PEERS = (*cppadcg_peer.IMPLS, TRACED, CPP)
ARMS = ("lwr4", "panda")      # robots/<name>.yaml
# key -> (URDF under example-robot-data's robots folder, frames (None: the tree's tips), floating base)
URDFS = {"ur5": ("ur_description/urdf/ur5_robot.urdf", ["tool0"], False),
         "g1": (trees.ROBOTS["g1"][0], None, True),
         "solo12": (trees.ROBOTS["solo12"][0], None, True)}
FUNCTIONS = cppadcg_peer.FUNCTIONS
OUR_FUNCTIONS = ("tau", "fd", "M", "tau_derivatives", "fd_derivatives")  # no Minv function is generated
DERIVATIVES = ("tau_derivatives", "fd_derivatives")
# The aims of issue 45 against the CppADCodeGen peer at equal flags (by medians).
AIM = {name: 3.0 if name in DERIVATIVES else 1.5 for name in FUNCTIONS}
# Ours against Pinocchio's double algorithms: the URDF's decimals (ur5 writes 1.57079632679 for
# pi/2, 4.9e-12 rad off the exact angle our reader snaps to) move values by ~1e-11.
OURS_TOLERANCE = 1e-9
FULL = dict(K=1000, repeats=30, rounds=10, target_ns=2e7, robots=("lwr4", "panda", "ur5", "g1"),
            functions=FUNCTIONS, peers=True, limit_s=3600.0)
QUICK = dict(K=50, repeats=3, rounds=1, target_ns=2e5, robots=("lwr4",), functions=("tau", "M"),
             peers=False, limit_s=3600.0)


# --- the robots ------------------------------------------------------------------------------
def robot_model(key: str):
    """(our model, path of the URDF or None)."""
    if key in ARMS:
        return load_robot(ROBOTS / f"{key}.yaml"), None
    file, frames, floating = URDFS[key]
    path = example_robot_data() / file
    return load_urdf(path, frames=frames, floating_base=floating), path


def states(model, count: int) -> dict:
    """q, qd, qdd, tau in our layout, the same for every implementation."""
    return trees.states(model, count) if model.floating_base else inputs.dynamics_inputs(model, count)


def pinocchio_side(key: str, model, path, data: dict, workdir: Path) -> tuple[Path, dict]:
    """Pinocchio's model of the robot as a file the C++ programs read, and the states in
    Pinocchio's layout."""
    if path is None:        # a DH arm: the numbers pinocchio_bench.cpp reads
        model_file = workdir / "pinocchio_model.txt"
        model_file.write_text(pinocchio_cpp.model_text(model))
        return model_file, dict(data)
    model_file = workdir / "pinocchio_model.bin"
    pmodel = trees.pinocchio_model(path, model, model_file)
    return model_file, dict(data, q=trees.pinocchio_q(pmodel, data["q"]))


# --- ours -------------------------------------------------------------------------------------
def ours(key: str, model, names, data: dict, workdir: Path, log) -> tuple[compiled.Timer, dict]:
    """Generate our C of ``names`` (timed), compile it as c_native (timed apart from the driver)
    and wrap it for the harness; (Timer, {generation and compile seconds})."""
    started, cpu = time.perf_counter(), time.process_time()
    folder = generate(model, WORK / "ours", languages=("c",), progress=False, only=set(names))
    generation = {"wall_s": round(time.perf_counter() - started, 2), "cpu_s": round(time.process_time() - cpu, 2)}
    spec = json.loads((folder / "functions.json").read_text())
    functions = [f for f in spec["functions"] if f["name"] in names]
    source = folder / "c" / f"{model.identifier}.c"
    obj = cppadcg_peer.compile_object(f"cppadcg_ours_{key}", source, [c_harness.C_STD, *compiled.C_FLAGS[OURS]])
    log(f"{key}: ours: generated in {generation['cpu_s']} s CPU ({generation['wall_s']} s wall), C compiled in "
        f"{obj.cpu_seconds:.1f} s CPU ({obj.seconds:.1f} s wall)" + (" (cached)" if obj.cached else ""))
    targets = []
    for f in functions:
        args = [f"{{in{i}}}" for i in range(len(f["inputs"]))] + [f"{{out{i}}}" for i in range(len(f["outputs"]))]
        targets.append(c_harness.CFunction(
            name=f["name"], call=f"{f['c_symbol']}({', '.join(args)})",
            inputs=[np.ascontiguousarray(data[p["name"]].reshape(data[p["name"]].shape[0], -1)) for p in f["inputs"]],
            outputs=[(int(np.prod(p["shape"])), p.get("dtype", "double")) for p in f["outputs"]]))
    prepared = c_harness.prepare(f"{key}_{OURS}", targets, f'#include "{folder / "c" / model.identifier}.h"',
                                 [obj.path], compiled.C_FLAGS[OURS], workdir)
    timer = compiled.Timer(run=lambda repeats, target_ns: c_harness.measure(prepared, repeats, target_ns),
                           outputs=lambda raw: raw, build_seconds=obj.seconds)
    batch = batch_timer(key, folder, functions, data, obj.path, workdir)
    return timer, batch, {"generation": generation, "compile": {"wall_s": round(obj.seconds, 2), "cpu_s": obj.cpu_seconds,
                                                         "cached": obj.cached},
                   "flags": " ".join([c_harness.C_STD, *compiled.C_FLAGS[OURS]])}


def batch_timer(key: str, folder: Path, functions: list, data: dict, library: Path, workdir: Path) -> compiled.Timer:
    """Our batch variants (``<name>_batch``: all K states in one call, structure-of-arrays, the
    same object as the single calls), timed per state; the outputs of state 0 for the check."""
    n = data["q"].shape[0]
    targets = []
    for f in functions:
        arrays = [data[p["name"]].reshape(n, -1) for p in f["inputs"]]
        args = [f"{{in{i}}}" for i in range(len(arrays))] + [f"{{out{i}}}" for i in range(len(f["outputs"]))]
        targets.append(c_harness.CFunction(
            name=f["name"], call=f"{f['c_symbol']}_batch({n}L, {', '.join(args)})",
            inputs=[np.ascontiguousarray(a.T).reshape(1, -1) for a in arrays],   # one row: all n states
            outputs=[(int(np.prod(p["shape"])) * n, p.get("dtype", "double")) for p in f["outputs"]]))
    prepared = c_harness.prepare(f"{key}_{BATCH}", targets, f'#include "{folder / "c" / folder.name}.h"',
                                 [library], compiled.C_FLAGS[OURS], workdir / BATCH)

    def run(repeats, target_ns):
        times, raw = c_harness.measure(prepared, repeats, target_ns)
        return {name: [t / n for t in values] for name, values in times.items()}, raw   # per state
    return compiled.Timer(run=run, outputs=lambda raw: {name: [o.reshape(-1, n)[:, 0] for o in outs]
                                                        for name, outs in raw.items()})


# --- the traced Pinocchio and Pinocchio C++ ----------------------------------------------------
def other_peers(key: str, model, path, model_file: Path, data: dict, pin_data: dict, names, workdir: Path,
                tools: dict, limit_s: float, log, skip) -> dict:
    """{impl: Timer} of the traced Pinocchio and Pinocchio C++ for this robot."""
    timers = {}
    ours_names = [n for n in names if n in OUR_FUNCTIONS]
    if path is None:        # the arms, by the programs of make bench
        functions = [{"name": n} for n in ours_names]
        timers[CPP] = compiled.pinocchio(model, functions, data, tools["bench"], workdir / CPP)
        samples = {n: {p: data[p] for p in cppadcg_peer.STATE[n]} for n in ours_names}
        timers[TRACED] = pinocchio_casadi.timer(model, tools["tracer"], samples, data["q"].shape[0], workdir)
        return timers
    frames = [f.name for f in model.frames]
    timers[CPP] = trees.pinocchio_timer(tools["tree_bench"], model_file, frames, pin_data, workdir)
    samples = {n: {p: pin_data[p] for p in cppadcg_peer.STATE[n]} for n in names}
    traced = trees.traced_timer(tools["tree_tracer"], model_file, frames, samples, workdir, limit_s,
                                f"{model.identifier}_{TRACED}", log, lambda name, reason: skip(TRACED, name, reason),
                                names=names)
    if traced is not None:
        timers[TRACED] = traced
    return timers


def tools(settings: dict, log) -> tuple[dict, dict]:
    """The Pinocchio programs (built or from the cache): ({name: path}, {name: build record})."""
    paths, records = {}, {}
    builders = {"generator": cppadcg_peer.build_generator}
    if settings["peers"]:
        arms = any(r in ARMS for r in settings["robots"])
        urdfs = any(r not in ARMS for r in settings["robots"])
        builders.update({"bench": pinocchio_cpp.build_binary, "tracer": pinocchio_casadi.build_tracer} if arms else {})
        builders.update({"tree_bench": lambda: trees.build_bench(log), "tree_tracer": lambda: trees.build_tracer(log)}
                        if urdfs else {})
    for name, builder in builders.items():
        log(f"{name}: building (header-only Pinocchio: minutes unless cached)")
        built = builder()
        paths[name] = built.path
        records[name] = {"binary": built.path.name, "cached": built.cached, "seconds": built.seconds}
    return paths, records


# --- one robot ----------------------------------------------------------------------------------
def bench_robot(key: str, settings: dict, paths: dict, log) -> dict:
    model, path = robot_model(key)
    workdir = WORK / "work" / key
    workdir.mkdir(parents=True, exist_ok=True)
    names = [n for n in settings["functions"]]
    data = states(model, settings["K"])
    model_file, pin_data = pinocchio_side(key, model, path, data, workdir)
    entry = {"nq": model.nq, "nv": model.nv, "floating_base": model.floating_base,
             "source": str(path.relative_to(example_robot_data())) if path else f"robots/{key}.yaml",
             "functions": {n: {} for n in names}, "checks": {}, "skipped": {}}

    def skip(impl, name, reason):
        log(f"{key}: {impl} {name} skipped: {reason}")
        entry["skipped"].setdefault(impl, {})[name] = reason

    timers = {}
    timers[OURS], timers[BATCH], entry["ours_build"] = ours(key, model, [n for n in names if n in OUR_FUNCTIONS], data, workdir, log)
    log(f"{key}: {cppadcg_peer.IMPL}: generating (CppADCodeGen) and compiling")
    peer = cppadcg_peer.build_peer(paths["generator"], model_file, model.identifier, names,
                                   {n: cppadcg_peer.peer_inputs(n, pin_data) for n in names}, model.nv, workdir,
                                   settings["limit_s"], lambda m: log(f"{key}: {m}"),
                                   lambda name, reason: skip(cppadcg_peer.IMPL, name, reason))
    timers.update(peer.timers)
    entry["cppadcg_build"] = peer.times()
    if settings["peers"]:
        timers.update(other_peers(key, model, path, model_file, data, pin_data, names, workdir, paths,
                                  settings["limit_s"], log, skip))

    # The check before any timing: one short run of each, input 0 against Pinocchio in double.
    want = cppadcg_peer.reference(paths["generator"], model_file, {k: v[0] for k, v in pin_data.items()},
                                  names, workdir)
    for impl, timer in timers.items():
        _, raw = timer.run(1, 1e5)
        outputs = timer.outputs(raw)
        # the arms' traced derivative candidates (CasADi's AD, "_ad") are checked as their function
        expected = {n: want[pinocchio_casadi_base(n)] for n in outputs if pinocchio_casadi_base(n) in want}
        tolerance = OURS_TOLERANCE if impl in (OURS, BATCH) else cppadcg_peer.TOLERANCE
        entry["checks"][impl] = cppadcg_peer.check(f"{key}: {impl}", outputs, expected, tolerance)
        log(f"{key}: {impl}: outputs for input 0 equal Pinocchio's (largest scaled error "
            f"{max(entry['checks'][impl].values(), default=0.0):.1e})")

    load_before = os.getloadavg()
    log(f"{key}: timing {', '.join(timers)} in {settings['rounds']} interleaved rounds")
    pooled, _ = compiled.interleave(timers, settings["repeats"], settings["rounds"], settings["target_ns"],
                                    lambda impl, exc: skip(impl, "all", f"{type(exc).__name__}: {exc}"[:500]))
    entry["load_average_before"], entry["load_average_after"] = list(load_before), list(os.getloadavg())
    if TRACED in pooled and path is None:
        pooled[TRACED], _, notes = pinocchio_casadi.keep_faster(pooled[TRACED], {})
    else:
        notes = {}
    for impl, per_function in pooled.items():
        for name, values in per_function.items():
            if name not in entry["functions"]:
                continue                 # the C++ and traced programs time more than compared here
            stats = entry["functions"][name][impl] = summary(values)
            note = {CPP: pinocchio_cpp.note_for(name), TRACED: notes.get(name, ""),
                    cppadcg_peer.IMPL: cppadcg_peer.NOTES.get(name), cppadcg_peer.IMPL_OFAST: cppadcg_peer.NOTES.get(name)}
            if note.get(impl):
                stats["note"] = note[impl]
    entry["ratios"] = ratios(entry["functions"], "median_ns")
    entry["ratios_min"] = ratios(entry["functions"], "min_ns")
    entry["ratios_batch"] = ratios(entry["functions"], "median_ns", BATCH)
    entry["aims"] = aims(entry["ratios"])
    return entry


def pinocchio_casadi_base(name: str) -> str:
    """A traced candidate's function: ``tau_derivatives_ad`` -> ``tau_derivatives``.

    >>> pinocchio_casadi_base("fd_derivatives_ad"), pinocchio_casadi_base("tau")
    ('fd_derivatives', 'tau')
    """
    return name[:-3] if name.endswith("_ad") else name


def ratios(functions: dict, statistic: str, ours: str = OURS) -> dict:
    """{function: {"peer/c_native": t(peer) / t(ours)}}: above 1, ours is faster (``ours``: our
    single calls, or our batch, per state).

    >>> ratios({"tau": {"c_native": {"median_ns": 2.0}, "pinocchio_cpp": {"median_ns": 9.0}}}, "median_ns")
    {'tau': {'pinocchio_cpp/c_native': 4.5}}
    """
    return {name: {f"{peer}/{ours}": impls[peer][statistic] / impls[ours][statistic]
                   for peer in PEERS if peer in impls}
            for name, impls in functions.items() if ours in impls}


def aims(robot_ratios: dict) -> dict:
    """{function: {ratio, aim, met}} against CppADCodeGen at equal flags.

    >>> aims({"tau": {"pinocchio_cppadcg/c_native": 1.6}})
    {'tau': {'ratio': 1.6, 'aim': 1.5, 'met': True}}
    """
    key = f"{cppadcg_peer.IMPL}/{OURS}"
    return {name: {"ratio": row[key], "aim": AIM[name], "met": row[key] >= AIM[name]}
            for name, row in robot_ratios.items() if key in row}


# --- the run -------------------------------------------------------------------------------------
def run(settings: dict, log) -> dict:
    started = time.perf_counter()
    load_start = os.getloadavg()
    paths, records = tools(settings, log)
    robots = {}
    for key in settings["robots"]:
        robots[key] = bench_robot(key, settings, paths, log)
    load_end = os.getloadavg()
    notes = []
    if max(load_start[0], load_end[0]) > 1.5:
        notes.append(f"load average {load_start[0]:.1f} at the start, {load_end[0]:.1f} at the end (2 cores): "
                     "the machine was shared, the figures must be re-run idle")
    if not settings["peers"]:
        notes.append("quick mode: the traced Pinocchio and Pinocchio C++ skipped, few repeats (times not meant)")
    notes.append("Minv: no generated function of ours (M^-1 is an output of fd_derivatives); the row times the "
                 "peers only")
    log(f"all robots done in {time.perf_counter() - started:.0f} s")
    return {
        "machine": machine() | {"load_average_start": list(load_start), "load_average_end": list(load_end)},
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()},
        "flags": {OURS: " ".join([c_harness.C_STD, *compiled.C_FLAGS[OURS]]),
                  **{impl: " ".join(cppadcg_peer.FLAGS[impl]) for impl in cppadcg_peer.IMPLS},
                  TRACED: " ".join([c_harness.C_STD, *compiled.C_FLAGS[TRACED]]),
                  CPP: "g++ " + " ".join(pinocchio_cpp.FLAGS[:3]) + " (header-only)",
                  "gcc": compiler_version("gcc")},
        "packages": cppadcg_peer.PACKAGES,
        "tool_builds": records,
        "robots": robots,
        "notes": notes,
    }


def table(result: dict) -> str:
    """The medians (ns) and the ratios peer / ours as Markdown."""
    impls = (OURS, BATCH, *PEERS)
    lines = ["| robot | function | " + " | ".join(impls) + " | " + " | ".join(f"{p} / ours" for p in PEERS) + " |",
             "|---" * (2 + len(impls) + len(PEERS)) + "|"]
    for key, entry in result["robots"].items():
        for name, row in entry["functions"].items():
            cells = [f"{row[i]['median_ns']:.0f}" if i in row else "-" for i in impls]
            ratio = entry["ratios"].get(name, {})
            cells += [f"{ratio[f'{p}/{OURS}']:.2f}" if f"{p}/{OURS}" in ratio else "-" for p in PEERS]
            lines.append(f"| {key} | {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(result: dict, path: Path) -> None:
    """Per robot, each function's ratio peer / ours by medians (log scale; above 1: ours
    faster), one bar per peer, the issue's aims against CppADCodeGen at equal flags dashed."""
    import matplotlib
    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt
    robots = result["robots"]
    fig, axes = plt.subplots(len(robots), 1, figsize=(10, 3.4 * len(robots)), squeeze=False)
    for ax, (key, entry) in zip(axes[:, 0], robots.items()):
        names = [n for n in entry["functions"] if n in entry["ratios"]]
        peers = [p for p in PEERS if any(f"{p}/{OURS}" in entry["ratios"][n] for n in names)]
        width = 0.8 / max(1, len(peers))
        x = np.arange(len(names))
        for i, peer in enumerate(peers):
            values = [entry["ratios"][n].get(f"{peer}/{OURS}", np.nan) for n in names]
            ax.bar(x + (i - (len(peers) - 1) / 2) * width, values, width, label=f"{peer} / ours")
        for i, n in enumerate(names):
            ax.hlines(AIM[n], i - 0.45, i + 0.45, colors="k", linestyles="dashed", linewidth=1)
        ax.axhline(1.0, color="grey", linewidth=0.8)
        ax.set_yscale("log")
        ax.set_xticks(x, names)
        ax.set_ylabel("t(peer) / t(ours), medians")
        ax.set_title(f"{key} (nv = {entry['nv']}): above 1, ours is faster; dashed: the aim against "
                     f"{cppadcg_peer.IMPL}", fontsize="medium")
        ax.grid(axis="y", which="both", alpha=0.3)
    axes[0, 0].legend(fontsize="small", ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write(result: dict, out: Path) -> None:
    """cppadcg.json and cppadcg.png in ``out``, both or neither (kindyngen.output_folder.replace_files)."""
    def both(folder):
        (folder / "cppadcg.json").write_text(strict_json(result, indent=1) + "\n")
        plot(result, folder / "cppadcg.png")
    replace_files(out, both)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.cppadcg", description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="smoke run: lwr4, tau and M, ours and CppADCodeGen only, few repeats")
    parser.add_argument("--robots", help=f"comma-separated robots among {', '.join((*ARMS, *URDFS))} "
                        "(default: lwr4,panda,ur5,g1; --quick: lwr4)")
    parser.add_argument("--functions", help=f"comma-separated functions among {', '.join(FUNCTIONS)} "
                        "(default: all; --quick: tau,M)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="directory for cppadcg.json and cppadcg.png")
    args = parser.parse_args(argv)
    settings = dict(QUICK if args.quick else FULL)
    if args.robots:
        unknown = set(args.robots.split(",")) - {*ARMS, *URDFS}
        if unknown:
            parser.error(f"unknown robots {sorted(unknown)}; known: {', '.join((*ARMS, *URDFS))}")
        settings["robots"] = tuple(args.robots.split(","))
    if args.functions:
        unknown = set(args.functions.split(",")) - set(FUNCTIONS)
        if unknown:
            parser.error(f"unknown functions {sorted(unknown)}; known: {', '.join(FUNCTIONS)}")
        settings["functions"] = tuple(args.functions.split(","))
    reason = cppadcg_peer.unavailable()
    if reason:
        print(f"error: the CppADCodeGen peer cannot be built: {reason}", file=sys.stderr)
        return 2

    def log(message):
        print(message, flush=True)
    try:
        result = run(settings, log)
    except cppadcg_peer.WiringError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    write(result, args.out)
    log(table(result))
    log(f"wrote {args.out / 'cppadcg.json'} and {args.out / 'cppadcg.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
