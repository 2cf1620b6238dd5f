"""How generation time and operation count of kinematic trees grow with the number of joints,
against the operation counts of Featherstone's algorithms (``python -m benchmarks.tree_scaling
[--quick] [--out DIR]``, writes ``results/tree_scaling.json`` and ``tree_scaling.png``).

Synthetic humanoid-like trees (a torso and ``limbs`` branches of ``per_limb`` revolute joints,
floating base) are written as URDF text and read by :func:`kindyngen.readers.urdf.parse_urdf`;
single-branch fixed-base chains of the same style are the like-for-like case of Featherstone's
formulas, which are stated for unbranched chains. Every function of
:data:`kindyngen.codegen.catalog.TREE_NAMES` is derived and optimised (CSE) separately, each size in
a fresh forked worker so that one that blows up can be stopped; a function stops growing once
its next size is predicted to exceed the budget. The whole ``kindyngen generate`` of the 29-joint
Unitree G1 (example-robot-data, floating base, all languages) is timed as a command
(``--g1-only`` re-measures just that), and :func:`cse_study` measures what chunking CSE
(:data:`kindyngen.codegen.optimize.CSE_CHUNK`) gains and costs (``--cse-only``).

Reference counts (m = multiplications, a = additions, n = degrees of freedom = nv):

* RNEA ``93n-69`` m, ``81n-66`` a; CRBA ``10n^2+22n-32`` m, ``6n^2+37n-43`` a; ABA ``224n-259``
  m, ``205n-248`` a: Featherstone, *Rigid Body Dynamics Algorithms*, Table 10.1 (unbranched
  chains of revolute joints, general geometry). The add formulas of CRBA and ABA come from a
  transcription of the table that was not checked against the book (module constant
  ``FEATHERSTONE``).
* CRBA on a branched tree only computes the entries of joints on one path to the root: the
  chain formula is ``20 P + 32n - 32`` m and ``12 P + 43n - 43`` a with ``P = n(n-1)/2`` pairs
  of joints on one path; for a tree P counts those pairs instead (our reading of the n^2 term,
  not a formula of the book).
* Robotran (symbolic, recursive Newton-Euler) for the COMAN humanoid, 29 degrees of freedom with
  its floating base: 4106 flops for inverse dynamics, 17414 for M and c together.
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import queue
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from kindyngen.json_text import strict_json
from kindyngen.output_folder import replace_files

from .common import RESULTS, machine

FULL = dict(tree_limbs=4, tree_per_limb=tuple(range(2, 16)), chain_sizes=tuple(range(4, 61, 4)) + (80, 100),
            budget_s=60.0, repeats=2, g1_repeats=3)
QUICK = dict(tree_limbs=4, tree_per_limb=(1, 2), chain_sizes=(2, 4), budget_s=10.0, repeats=1, g1_repeats=0)

# Table 10.1 of Featherstone's book, as (mul, add) polynomials in n = nv
FEATHERSTONE = {
    "RNEA": (lambda n: 93 * n - 69, lambda n: 81 * n - 66),
    "CRBA": (lambda n: 10 * n * n + 22 * n - 32, lambda n: 6 * n * n + 37 * n - 43),
    "ABA": (lambda n: 224 * n - 259, lambda n: 205 * n - 248),
}
# dense L^T D L factorisation and solve of an n x n matrix (Table 10.1, same transcription)
FACTOR_SOLVE = (lambda n: round(n ** 3 / 6 + 3 * n * n / 2 - 2 * n / 3), lambda n: round(n ** 3 / 6 + n * n - 7 * n / 6))
# which of our functions computes what each reference algorithm computes
COMPARED = {"tau": "RNEA", "M": "CRBA", "fd": "ABA"}
ROBOTRAN_COMAN = {"nv": 29, "tau_flops": 4106, "M_c_flops": 17414}
G1_URDF = ("g1_description", "urdf", "g1_29dof_rev_1_0.urdf")

_AXES = ("1 0 0", "0 1 0", "0 0 1")


# ------------------------------------------------------------------ synthetic robots

def _inertia(mass: float, size: tuple) -> str:
    """A box's inertia with small products of inertia: a full tensor that a rigid body has
    (the products stay far below the margin of the box's triangle inequality)."""
    a, b, c = size
    ixx, iyy, izz = (mass * (u * u + v * v) / 12 for u, v in ((b, c), (a, c), (a, b)))
    p = 0.03 * min(ixx, iyy, izz)
    return (f'<inertia ixx="{ixx:.6g}" ixy="{p:.6g}" ixz="{-p:.6g}" iyy="{iyy:.6g}" '
            f'iyz="{0.5 * p:.6g}" izz="{izz:.6g}"/>')


def _link(name: str, mass: float, length: float) -> str:
    size = (0.3 * length, 0.25 * length, length)
    return (f'<link name="{name}"><inertial><origin xyz="0.003 -0.002 {-0.45 * length:.6g}" rpy="0.05 0 0.1"/>'
            f'<mass value="{mass:.6g}"/>{_inertia(mass, size)}</inertial></link>')


def _joint(name: str, parent: str, child: str, xyz: tuple, rpy: tuple, axis: str) -> str:
    xyz_text = " ".join(f"{v:.6g}" for v in xyz)
    rpy_text = " ".join(repr(float(v)) for v in rpy)    # full precision: pi/2 is read as exactly pi/2
    return (f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz_text}" rpy="{rpy_text}"/><axis xyz="{axis}"/>'
            f'<limit lower="-2.5" upper="2.5" effort="50" velocity="10"/></joint>')


def synthetic_urdf(limbs: int, per_limb: int) -> str:
    """The URDF text of a torso with ``limbs`` branches of ``per_limb`` revolute joints: limb
    roots spread around the torso, axes cycling x/y/z, lengths and masses shrinking towards the
    tips, every third joint origin turned by 0.1 rad (not a multiple of pi/12, so not snapped)."""
    parts = [f'<robot name="tree{limbs}x{per_limb}">', _link("torso", 12.0, 0.5)]
    for k in range(limbs):
        angle = 2 * math.pi * k / limbs
        parent = "torso"
        for i in range(per_limb):
            child = f"limb{k}_link{i:02d}"
            length = 0.3 * 0.9 ** i
            if i == 0:
                xyz, rpy = (0.15 * math.cos(angle), 0.15 * math.sin(angle), 0.2 if k % 2 else -0.25), (0, 0, angle)
            else:
                xyz = (0.01 * (i % 2), 0.0, -0.3 * 0.9 ** (i - 1))
                rpy = (0.1, 0, 0) if i % 3 == 0 else (0, 0, 0)
            parts.append(_link(child, 4.0 * 0.8 ** i, length))
            # names sort in chain order: parse_urdf numbers the joints depth first by name
            parts.append(_joint(f"limb{k}_joint{i:02d}", parent, child, xyz, rpy, _AXES[(i + k) % 3]))
            parent = child
    parts.append("</robot>")
    return "\n".join(parts)


def synthetic_tree(limbs: int, per_limb: int, floating: bool = True):
    """A humanoid-like :class:`kindyngen.model.robot_model.RobotModel` tree (:func:`synthetic_urdf`)."""
    from kindyngen.readers.urdf import parse_urdf
    return parse_urdf(synthetic_urdf(limbs, per_limb), tree=True, source=f"<synthetic tree {limbs}x{per_limb}>",
                           floating_base=floating)


def synthetic_chain(n: int, floating: bool = False):
    """A single-branch tree of n joints in the same style: the shape of Featherstone's formulas."""
    return synthetic_tree(1, n, floating=floating)


def path_pairs(parents) -> int:
    """Pairs of joints one of which is an ancestor of the other (CRBA's off-diagonal work);
    n(n-1)/2 for a chain."""
    pairs = 0
    for j in range(len(parents)):
        p = parents[j]
        while p >= 0:
            pairs += 1
            p = parents[p]
    return pairs


def velocity_parents(model) -> list:
    """The parent of each velocity coordinate, a floating base counted as a chain of six."""
    from kindyngen.algorithms.dynamics import expanded_parents
    return list(expanded_parents(model))


# ------------------------------------------------------------------ measuring

def _program(function):
    from kindyngen.codegen.optimize import optimize
    return optimize(function)


def measure(build, model) -> dict | None:
    """Derive one function of ``model``, CSE it, and time both: wall and CPU seconds of this
    process (on a shared machine the CPU time is the steadier measure of the work); None when
    the builder does not apply to ``model``."""
    cpu_start, start = time.process_time(), time.perf_counter()
    function = build(model)
    if function is None:
        return None
    cpu_derived, derived = time.process_time(), time.perf_counter()
    program = _program(function)
    cpu_done, done = time.process_time(), time.perf_counter()
    return {"derive_s": derived - start, "optimize_s": done - derived, "total_s": done - start,
            "derive_cpu_s": cpu_derived - cpu_start, "optimize_cpu_s": cpu_done - cpu_derived,
            "cpu_s": cpu_done - cpu_start, "before": program.before.to_json(), "after": program.after.to_json(),
            # a function with several routes (fd): what each costs; the time covers them all
            **({"route": program.function.metadata.get("route"),
                "routes": {name: count.to_json() for name, count in program.routes}} if program.routes else {})}


def m_and_c(model) -> dict:
    """M and c as one function under one CSE (what Robotran's 'M and c' figure counts)."""
    from dataclasses import replace

    import symengine as se

    from kindyngen.algorithms.dynamics import coriolis_tree, mass_matrix_tree
    mass, bias = mass_matrix_tree(model), coriolis_tree(model)
    # both name their intermediates from _s0: give c's their own names
    rename = {symbol: se.Symbol(f"_c{symbol}") for symbol, _ in bias.stages}
    both = replace(bias, name="M_c", outputs=mass.outputs + bias.outputs,
                   output_exprs=mass.output_exprs + tuple(tuple(e.xreplace(rename) for e in port)
                                                          for port in bias.output_exprs),
                   stages=mass.stages + tuple((rename[s], e.xreplace(rename)) for s, e in bias.stages))
    return _program(both).after.to_json()


def best_of(build, model, repeats: int) -> dict | None:
    """The run of :func:`measure` with the least CPU time out of ``repeats`` (the machine may
    be shared: the least disturbed run), with every run's CPU seconds."""
    rows = [measure(build, model) for _ in range(repeats)]
    if rows[0] is None:
        return None
    best = min(rows, key=lambda row: row["cpu_s"])
    return {**best, "cpu_s_runs": [row["cpu_s"] for row in rows]}


def _worker(series: str, size, names: list, repeats: int, out) -> None:
    """Measure ``names`` at one size in this (fresh, forked) process, announcing each."""
    from kindyngen.codegen.catalog import BUILDERS
    model = _model(series, size)
    builders = {name: (lambda model, build=build: build(model, "numeric")) for name, build in BUILDERS}
    for name in names:
        out.put(("start", name, None))
        try:
            row = best_of(builders[name], model, repeats)
            out.put(("row", name, row) if row else ("error", name, "does not apply to this model"))
        except Exception as exc:  # a function that fails at some size: reported, stops growing
            out.put(("error", name, f"{type(exc).__name__}: {exc}"))
    out.put(("done", None, None))


def _model(series: str, size):
    return synthetic_tree(*size) if series == "tree" else synthetic_chain(size)


def _size_info(series: str, size) -> dict:
    model = _model(series, size)
    return {"joints": model.n, "nv": model.nv, "path_pairs": path_pairs(velocity_parents(model)),
            "depth": max(_depths(model.parents), default=0)}


def _depths(parents) -> list:
    """Number of joints from the root to each joint, itself included."""
    depth = []
    for p in parents:
        depth.append(1 if p < 0 else depth[p] + 1)
    return depth


def _run_size(context, series: str, size, names: list, budget_s: float, repeats: int, log) -> tuple[dict, dict]:
    """({name: row}, {name: why it stopped}) of one size, restarting the worker for the
    remaining functions when one of them is killed for silence."""
    rows, stopped, pending = {}, {}, list(names)
    while pending:
        out = context.Queue()
        worker = context.Process(target=_worker, args=(series, size, pending, repeats, out), daemon=True)
        worker.start()
        current = None
        while True:
            try:
                kind, name, payload = out.get(timeout=budget_s * repeats)
            except queue.Empty:
                worker.kill()
                stopped[current] = f"killed at {size}: no result within {budget_s * repeats:.0f} s"
                log(f"tree_scaling: {series} {size}: {current} {stopped[current]}")
                break
            if kind == "done":
                current = None
                break
            if kind == "start":
                current = name
            elif kind == "row":
                rows[name] = payload
                after = payload["after"]
                log(f"tree_scaling: {series} {size} {name}: {payload['total_s']:.2f} s ({payload['cpu_s']:.2f} s CPU), "
                    f"after CSE {after['add']} add {after['mul']} mul {after['call']} call")
            else:
                stopped[name] = f"error at {size}: {payload}"
                log(f"tree_scaling: {series} {size} {name}: {stopped[name]}")
        worker.join(timeout=5)
        done = set(rows) | set(stopped)
        pending = [name for name in pending if name not in done]
        if current is None:
            break
    return rows, stopped


def predicted_next(times: list, sizes: list, next_size: float) -> float:
    """The time at ``next_size`` by the log-log slope of the last two sizes (at least 1:
    a size never gets cheaper; 3 when there is only one point)."""
    if len(times) < 2:
        slope = 3.0
    else:
        slope = max(1.0, math.log(max(times[-1], 1e-3) / max(times[-2], 1e-3)) / math.log(sizes[-1] / sizes[-2]))
    return times[-1] * (next_size / sizes[-1]) ** slope


def series_study(series: str, sizes: list, budget_s: float, repeats: int, log) -> dict:
    """{"sizes": [...size info], "functions": {name: {"rows": [...], "stopped": str|None}}}."""
    from kindyngen.codegen.catalog import TREE_NAMES
    context = multiprocessing.get_context("fork")
    functions = {name: {"rows": [], "stopped": None} for name in TREE_NAMES}
    infos = []
    for index, size in enumerate(sizes):
        info = _size_info(series, size)
        infos.append(info)
        active = [name for name, entry in functions.items() if entry["stopped"] is None]
        if not active:
            break
        log(f"tree_scaling: {series} {size}: {info['joints']} joints, nv={info['nv']}")
        rows, stopped = _run_size(context, series, size, active, budget_s, repeats, log)
        for name in active:
            entry = functions[name]
            if name in stopped:
                entry["stopped"] = stopped[name]
                continue
            entry["rows"].append({**info, **rows[name]})
            if index + 1 < len(sizes):
                ns = [r["nv"] for r in entry["rows"]]
                times = [r["total_s"] for r in entry["rows"]]
                nxt = _size_info(series, sizes[index + 1])["nv"]
                if predicted_next(times, ns, nxt) > budget_s:
                    entry["stopped"] = f"after nv={info['nv']}: nv={nxt} predicted to take over {budget_s:.0f} s"
                    log(f"tree_scaling: {series} {name} stopped {entry['stopped']}")
    return {"sizes": infos, "functions": functions}


# ------------------------------------------------------------------ comparisons

def loglog_slope(xs: list, ys: list) -> float | None:
    """Least-squares slope of log y against log x (None below three points)."""
    points = [(math.log(x), math.log(y)) for x, y in zip(xs, ys) if x > 0 and y > 0]
    if len(points) < 3:
        return None
    mx = statistics.fmean(p[0] for p in points)
    my = statistics.fmean(p[1] for p in points)
    sxx = sum((p[0] - mx) ** 2 for p in points)
    return sum((p[0] - mx) * (p[1] - my) for p in points) / sxx


def slopes(study: dict) -> dict:
    """Growth exponent of generation (CPU) time per function against nv: over all sizes and over
    the upper half (where the constant start-up share no longer flattens the curve); over all
    sizes against the number of joints (the floating base's six not counted); and, over the
    upper half, against the size of the code derived (add + mul after CSE, all routes of
    fd): 1 is a derivation linear in what it produces."""
    out = {}
    for name, entry in study["functions"].items():
        rows = entry["rows"]
        xs, ys = [r["nv"] for r in rows], [r["cpu_s"] for r in rows]
        # the code derived: a function with several routes derives (and CSEs) each of them
        ops = [sum(c["add"] + c["mul"] for c in r.get("routes", {"": r["after"]}).values()) for r in rows]
        half = len(rows) // 2
        out[name] = {"all": loglog_slope(xs, ys), "upper_half": loglog_slope(xs[half:], ys[half:]),
                     "all_vs_joints": loglog_slope([r["joints"] for r in rows], ys),
                     "upper_half_vs_code_size": loglog_slope(ops[half:], ys[half:]),
                     "nv_range": [xs[0], xs[-1]] if xs else None}
    return out


def reference(name: str, nv: int, pairs: int) -> dict | None:
    """Featherstone's counts for what our function ``name`` computes at ``nv``; for M the
    chain formula and the same formula with the tree's path pairs."""
    algorithm = COMPARED.get(name)
    if algorithm is None:
        return None
    mul, add = FEATHERSTONE[algorithm]
    ref = {"algorithm": algorithm, "mul": mul(nv), "add": add(nv)}
    if algorithm == "CRBA":
        ref["tree_mul"] = 20 * pairs + 32 * nv - 32
        ref["tree_add"] = 12 * pairs + 43 * nv - 43
    if algorithm == "ABA" and pairs == nv * (nv - 1) // 2:
        # an unbranched chain: our fd's own route, M by CRBA, c + g by RNEA, then a dense
        # factorisation and solve (Table 10.1's "F&S" row)
        ref["route_mul"] = FEATHERSTONE["CRBA"][0](nv) + FEATHERSTONE["RNEA"][0](nv) + FACTOR_SOLVE[0](nv)
        ref["route_add"] = FEATHERSTONE["CRBA"][1](nv) + FEATHERSTONE["RNEA"][1](nv) + FACTOR_SOLVE[1](nv)
    return ref


def comparisons(study: dict) -> dict:
    """{name: [{nv, ours (after CSE), reference, ratios}]} for tau, M, fd."""
    out = {}
    for name in COMPARED:
        rows = study["functions"].get(name, {}).get("rows", [])
        table = []
        for r in rows:
            ref = reference(name, r["nv"], r["path_pairs"])
            entry = {"nv": r["nv"], "ours": r["after"], "reference": ref,
                     "mul_ratio": r["after"]["mul"] / ref["mul"], "add_ratio": r["after"]["add"] / ref["add"]}
            for key in ("tree", "route"):
                if f"{key}_mul" in ref:
                    entry[f"{key}_mul_ratio"] = r["after"]["mul"] / ref[f"{key}_mul"]
                    entry[f"{key}_add_ratio"] = r["after"]["add"] / ref[f"{key}_add"]
            table.append(entry)
        out[name] = table
    return out


# ------------------------------------------------------------------ the G1 as a command

def g1_urdf() -> Path:
    from .urdf_vs_yaml import example_robot_data
    return example_robot_data().joinpath(*G1_URDF)


def g1_generate(repeats: int, log) -> dict:
    """Wall time of ``kindyngen generate G1 --floating-base`` (all languages) as a command,
    each run into a fresh folder, with its CPU time and the load average (the machine may be
    shared); plus M+c under one CSE (for Robotran's figure)."""
    from kindyngen.readers.urdf import load_urdf
    seconds, cpu, load = [], [], []
    for k in range(repeats):
        with tempfile.TemporaryDirectory() as folder:
            load.append(os.getloadavg()[0])
            children = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "kindyngen", "generate", str(g1_urdf()), "--floating-base",
                            "--quiet", "--out", folder], check=True, capture_output=True, text=True)
            seconds.append(time.perf_counter() - start)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append(after.ru_utime + after.ru_stime - children.ru_utime - children.ru_stime)
            counts = json.loads(next(Path(folder).glob("*/opcounts.json")).read_text())
        log(f"tree_scaling: G1 generate run {k + 1}/{repeats}: {seconds[-1]:.2f} s wall, {cpu[-1]:.2f} s CPU "
            f"(load average {load[-1]:.1f} before it)")
    model = load_urdf(g1_urdf(), floating_base=True)
    functions = g1_functions(model, log)
    return {"functions": functions, "joints": model.n, "nv": model.nv, "seconds": seconds, "median_s": statistics.median(seconds),
            "cpu_seconds": cpu, "median_cpu_s": statistics.median(cpu), "load_average_before": load,
            "opcounts": counts, "M_c_one_cse": m_and_c(model),
            "path_pairs": path_pairs(velocity_parents(model))}


def g1_functions(model, log) -> dict:
    """Derive + CSE time of each function of the G1 in this process: where generate's time
    goes (the rest is rendering and writing the languages)."""
    from kindyngen.codegen.catalog import BUILDERS, TREE_NAMES
    rows = {}
    for name, build in BUILDERS:
        if name not in TREE_NAMES:
            continue
        row = measure(lambda model, build=build: build(model, "numeric"), model)
        if row:
            rows[name] = row
            log(f"tree_scaling: G1 {name}: {row['total_s']:.2f} s ({row['cpu_s']:.2f} s CPU)")
    return rows


def robotran(g1: dict | None, tree: dict) -> dict:
    """Our inverse dynamics and M+c flops (add + mul) beside Robotran's COMAN figures: the G1
    (nv 35) and the synthetic trees' tau interpolated linearly in nv at nv = 29."""
    out = {"robotran_coman": ROBOTRAN_COMAN}
    rows = tree["functions"].get("tau", {}).get("rows", [])
    below = [r for r in rows if r["nv"] <= ROBOTRAN_COMAN["nv"]]
    above = [r for r in rows if r["nv"] >= ROBOTRAN_COMAN["nv"]]
    if below and above:
        a, b = below[-1], above[0]
        flops = [r["after"]["add"] + r["after"]["mul"] for r in (a, b)]
        t = 0 if b["nv"] == a["nv"] else (ROBOTRAN_COMAN["nv"] - a["nv"]) / (b["nv"] - a["nv"])
        out["synthetic_tau_flops_at_nv29"] = flops[0] + t * (flops[1] - flops[0])
    if g1:
        tau = g1["opcounts"]["tau"]["after"] if "after" in g1["opcounts"].get("tau", {}) else None
        out["g1"] = {"nv": g1["nv"], "tau_flops": tau and tau["add"] + tau["mul"],
                     "M_c_flops_one_cse": g1["M_c_one_cse"]["add"] + g1["M_c_one_cse"]["mul"]}
    return out


# ------------------------------------------------------------------ output

def write(result: dict, out: Path) -> None:
    """tree_scaling.json and tree_scaling.png in ``out``, both or neither
    (kindyngen.output_folder.replace_files)."""
    def both(folder):
        (folder / "tree_scaling.json").write_text(strict_json(result, indent=1) + "\n")
        plot(result, folder / "tree_scaling.png")
    replace_files(out, both)


def plot(result: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 5))
    tree, colours = result["tree"]["functions"], {}
    for name, entry in tree.items():
        rows = entry["rows"]
        if rows:
            line, = left.plot([r["nv"] for r in rows], [r["cpu_s"] for r in rows], "o-", ms=3, label=name)
            colours[name] = line.get_color()
    for name, entry in result["chain"]["functions"].items():
        if name in COMPARED and entry["rows"]:
            left.plot([r["nv"] for r in entry["rows"]], [r["cpu_s"] for r in entry["rows"]], "x:", ms=4,
                      color=colours.get(name), label=f"{name} (chain)")
    left.set(xscale="log", yscale="log", xlabel="nv", ylabel="generation time, derive + CSE [CPU s]",
             title="trees, 4 limbs, floating base (o); fixed-base chains (x)")
    for name, algorithm in COMPARED.items():
        rows = tree.get(name, {}).get("rows", [])
        chain_rows = result["chain"]["functions"].get(name, {}).get("rows", [])
        if not rows and not chain_rows:
            continue
        line, = right.plot([r["nv"] for r in rows], [r["after"]["mul"] for r in rows], "o-", ms=3,
                           label=f"{name} mul (tree)")
        colour = line.get_color()
        right.plot([r["nv"] for r in chain_rows], [r["after"]["mul"] for r in chain_rows], "x:", ms=4, color=colour,
                   label=f"{name} mul (chain)")
        ns = sorted({r["nv"] for r in rows + chain_rows})
        right.plot(ns, [FEATHERSTONE[algorithm][0](n) for n in ns], "--", color=colour, alpha=0.6,
                   label=f"{algorithm} mul, Featherstone")
        if algorithm == "CRBA" and rows:
            right.plot([r["nv"] for r in rows], [20 * r["path_pairs"] + 32 * r["nv"] - 32 for r in rows], "-.",
                       color=colour, alpha=0.6, label="CRBA mul, tree path pairs")
    right.set(xscale="log", yscale="log", xlabel="nv", ylabel="multiplications after CSE",
              title="ours (markers) vs Featherstone Table 10.1 (dashed)")
    for ax in (left, right):
        ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(base=10, subs=(1.0, 2.0, 3.0, 5.0)))
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.grid(which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def markdown(result: dict) -> str:
    """The n / time / counts table and the comparisons, for the console."""
    lines = ["| series | nv | joints | function | CPU [s] | wall [s] | add | mul | call |",
             "|---|---|---|---|---|---|---|---|---|"]
    for series in ("tree", "chain"):
        for name, entry in result[series]["functions"].items():
            for r in entry["rows"]:
                a = r["after"]
                lines.append(f"| {series} | {r['nv']} | {r['joints']} | {name} | {r['cpu_s']:.2f} | {r['total_s']:.2f} | "
                             f"{a['add']} | {a['mul']} | {a['call']} |")
    lines += ["", "| series | function | slope (all) | slope (upper half) | slope vs code size (upper half) | stopped |",
              "|---|---|---|---|---|---|"]
    for series in ("tree", "chain"):
        for name, s in result[series]["slopes"].items():
            fmt = (lambda v: "-" if v is None else f"{v:.2f}")
            lines.append(f"| {series} | {name} | {fmt(s['all'])} | {fmt(s['upper_half'])} | "
                         f"{fmt(s['upper_half_vs_code_size'])} | {result[series]['functions'][name]['stopped'] or ''} |")
    lines += ["", "| series | function | nv | mul ours/ref | add ours/ref | mul/add vs tree CRBA or CRBA+RNEA+F&S |",
              "|---|---|---|---|---|---|"]
    for series in ("tree", "chain"):
        for name, table in result[series]["comparisons"].items():
            for e in table:
                key = next((k for k in ("tree", "route") if f"{k}_mul_ratio" in e), None)
                tree_ratio = f"{e[key + '_mul_ratio']:.2f} / {e[key + '_add_ratio']:.2f}" if key else ""
                lines.append(f"| {series} | {name} vs {e['reference']['algorithm']} | {e['nv']} | "
                             f"{e['mul_ratio']:.2f} | {e['add_ratio']:.2f} | {tree_ratio} |")
    return "\n".join(lines)


def study(settings: dict, log=print) -> dict:
    """The whole study for ``settings`` (FULL or QUICK here; benchmarks/run.py may pass its
    own dict with the same keys)."""
    started, load_start = time.perf_counter(), os.getloadavg()[0]
    # the first derivation pays imports and caches; the forked workers inherit them warm
    from kindyngen.codegen.catalog import BUILDERS
    measure(lambda model: dict(BUILDERS)["tau"](model, "numeric"), synthetic_tree(2, 1))
    limbs = settings["tree_limbs"]
    budget, repeats = settings["budget_s"], settings["repeats"]
    tree = series_study("tree", [(limbs, k) for k in settings["tree_per_limb"]], budget, repeats, log)
    chain = series_study("chain", list(settings["chain_sizes"]), budget, repeats, log)
    for series in (tree, chain):
        series["slopes"] = slopes(series)
        series["comparisons"] = comparisons(series)
    g1 = g1_generate(settings["g1_repeats"], log) if settings["g1_repeats"] else None
    cse = cse_study(log) if settings["g1_repeats"] else None
    return {"settings": {k: list(v) if isinstance(v, tuple) else v for k, v in settings.items()},
            "machine": machine(), "tree": tree, "chain": chain, "g1": g1, "robotran": robotran(g1, tree),
            "cse": cse, "featherstone_note": "Table 10.1 of Rigid Body Dynamics Algorithms, unbranched chains, n = nv; "
                                 "CRBA/ABA add formulas from an unchecked transcription; tree CRBA = 20 P + 32n - 32 "
                                 "m, 12 P + 43n - 43 a with P the ancestor pairs (our reading)",
            "load_average": {"start": load_start, "end": os.getloadavg()[0]},
            "seconds": time.perf_counter() - started}


# ------------------------------------------------------------------ CSE chunks

CSE_CHAINS = (40, 80, 120)          # chain M: its named intermediates and outputs, one cse or chunked
CSE_G1_CHUNKS = (1024, 2048, 4096)  # what the chunk size costs on the G1


def cse_study(log) -> dict:
    """Why :data:`kindyngen.codegen.optimize.CSE_CHUNK` is what it is: CPU time of ``optimize`` on a
    chain's M with one symengine cse call and with chunks (how cse grows with the number of
    expressions), and the G1's add + mul summed over every function (both fd routes) and the
    CPU time, per chunk size."""
    import kindyngen.codegen.optimize as optimize_module
    from kindyngen.codegen.catalog import BUILDERS, TREE_NAMES
    from kindyngen.algorithms.articulated_body import forward_dynamics_aba
    from kindyngen.algorithms.dynamics import forward_dynamics_tree, mass_matrix_tree
    from kindyngen.readers.urdf import load_urdf
    default = optimize_module.CSE_CHUNK

    def timed(function, chunk):
        optimize_module.CSE_CHUNK = chunk
        start = time.process_time()
        try:
            program = optimize_module.optimize(function)
        finally:
            optimize_module.CSE_CHUNK = default
        return time.process_time() - start, program.after

    chains = []
    for n in CSE_CHAINS:
        f = mass_matrix_tree(synthetic_chain(n))
        exprs = [e for _, e in f.stages] + [e for port in f.output_exprs for e in port]
        row = {"joints": n, "expressions": sum(1 for e in exprs if not (e.is_Symbol or e.is_Number))}
        for key, chunk in (("one_cse", 10 ** 9), ("chunked", default)):
            seconds, after = timed(f, chunk)
            row[key] = {"cpu_s": seconds, "after": after.to_json()}
        log(f"tree_scaling: cse, chain M of {n}: {row['expressions']} expressions, one cse "
            f"{row['one_cse']['cpu_s']:.2f} s, chunks of {default} {row['chunked']['cpu_s']:.2f} s")
        chains.append(row)
    model = load_urdf(g1_urdf(), floating_base=True)
    functions = [build(model, "numeric") for name, build in BUILDERS if name in TREE_NAMES and name != "fd"]
    functions += [forward_dynamics_tree(model), forward_dynamics_aba(model)]
    g1 = []
    for chunk in CSE_G1_CHUNKS:
        runs = [timed(f, chunk) for f in functions if f is not None]
        g1.append({"chunk": chunk, "cpu_s": sum(t for t, _ in runs), "add_mul": sum(a.add + a.mul for _, a in runs)})
        log(f"tree_scaling: cse, G1 with chunks of {chunk}: {g1[-1]['add_mul']} add + mul, {g1[-1]['cpu_s']:.2f} s")
    return {"chunk": default, "chain_M": chains, "g1_chunks": g1}


def _update_cse(path: Path, log) -> int:
    """The CSE-chunk part of the study again, written into ``path``."""
    result = json.loads(path.read_text())
    result["cse"] = cse_study(log)
    path.write_text(strict_json(result, indent=1) + "\n")
    log(f"wrote {path}")
    return 0


def _update_g1(path: Path, log) -> int:
    """The G1 part of the study again, written into ``path`` beside the series it keeps."""
    result = json.loads(path.read_text())
    g1 = g1_generate(5, log)
    g1["measured"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    result["g1"], result["robotran"] = g1, robotran(g1, result["tree"])
    path.write_text(strict_json(result, indent=1) + "\n")
    log(f"G1: median {g1['median_s']:.2f} s wall over {len(g1['seconds'])} runs; derive + CSE, CPU s: "
        + ", ".join(f"{k} {v['cpu_s']:.2f}" for k, v in g1["functions"].items()) + f"; wrote {path}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.tree_scaling", description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes, no G1 (a smoke test, under 30 s)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="folder for tree_scaling.json and .png")
    parser.add_argument("--g1-only", action="store_true",
                        help="re-measure only the G1 generate (5 runs) and its functions, updating the G1 and "
                             "Robotran entries of the existing tree_scaling.json (the series stay as measured)")
    parser.add_argument("--cse-only", action="store_true",
                        help="re-measure only the CSE-chunk study (a chain's M with one cse call and in chunks; "
                             "the G1 per chunk size), updating the existing tree_scaling.json")
    args = parser.parse_args(argv)
    if args.cse_only:
        return _update_cse(args.out / "tree_scaling.json", log=lambda text: print(text, flush=True))
    if args.g1_only:
        return _update_g1(args.out / "tree_scaling.json", log=lambda text: print(text, flush=True))
    settings = QUICK if args.quick else FULL
    result = study(settings, log=lambda text: print(text, flush=True))
    write(result, args.out)
    print(markdown(result))
    if result["g1"]:
        g1 = result["g1"]
        print(f"\nG1 ({g1['joints']} joints, nv {g1['nv']}): kindyngen generate --floating-base, all languages: "
              f"median {g1['median_s']:.2f} s wall, {g1['median_cpu_s']:.2f} s CPU over {len(g1['seconds'])} runs "
              f"(load averages before: {', '.join(f'{v:.1f}' for v in g1['load_average_before'])}); derive + CSE, "
              "CPU s: " + ", ".join(f"{k} {v['cpu_s']:.2f}" for k, v in g1["functions"].items()))
    print(strict_json(result["robotran"], indent=1))
    print(f"wrote {args.out / 'tree_scaling.json'} and tree_scaling.png ({result['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
