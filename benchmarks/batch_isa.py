"""The C batch variants against single calls per instruction set: the same generated C built
with gcc and clang at -O3 for -march=x86-64-v2 (SSE4.2), x86-64-v3 (AVX2, FMA), x86-64-v4
(AVX-512) and native, always with -ffp-contract=off (as the generated CMake file builds it, so
every build gives the same bits), ns per configuration; and what the compiler made of each
batch loop (objdump: instructions on zmm, ymm and xmm registers, gathers, scatters, calls).

    python -m benchmarks.batch_isa [--robots lwr4,panda] [--functions tau,fd,...] [--rounds 5]
        -> results/batch_isa.json, results/batch_isa.png

The library is generated afresh with ``--lang c --functions ...`` (seconds to compile instead
of a minute per build); every function it holds must be the same text as in ``generated/``
(checked, the run stops otherwise), so the figures are those of the committed code.
``--generated DIR`` times another tree instead; ``--baseline DIR`` times a second tree (e.g. the
code before a template change) in the same rounds, its builds labelled "before: ...", and checks
its outputs bit for bit against the first build's.
Single calls and batches (N configurations in structure-of-arrays layout) are timed by
benchmarks/c_batch.py's two drivers, every build in every round, rounds interleaved; the
ratio single / batch is taken within the run. Not part of `make bench`.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from collections import Counter
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from kindyngen.json_text import strict_json
from kindyngen.output_folder import replace_files
from kindyngen.readers.yaml_description import load_robot

from . import c_batch, c_harness, inputs
from .build import BUILD, build, compiler_version
from .common import GENERATED, RESULTS, ROBOTS, cpu_identity, cpu_model, manifest, summary

FUNCTIONS = ("fk_hom", "M", "tau", "fd", "fd_derivatives")
MARCHES = ("x86-64-v2", "x86-64-v3", "x86-64-v4", "native", "icelake-server",
           "icelake-server -mprefer-vector-width=512")
"""-march values (and extra flags after a space). icelake-server is an Intel AVX-512 server
core: both compilers' tuning for it (as for every Intel AVX-512 core, and clang's for
x86-64-v4) prefers 256-bit vectors, which is what -march=native gives on such a host; run here
it shows the code an Intel build gets, timed on this core, not on Intel's."""
COMPILERS = ("gcc", "clang")
OPT = ["-O3", "-ffp-contract=off"]


def log(text: str) -> None:
    print(f"batch_isa: {text}", file=sys.stderr, flush=True)


def definitions(source: str) -> dict:
    """{function name: its text} of a generated C file's top-level definitions.

    >>> sorted(definitions("static int f(void)\\n{\\n    return 1;\\n}\\n\\nvoid g(long n)\\n{\\n}\\n"))
    ['f', 'g']
    """
    pieces = re.split(r"\n(?=(?:static |void |int )[^\n]*\)\n\{)", "\n" + source)
    found = {}
    for piece in pieces[1:]:
        head = piece.split("\n", 1)[0]
        found[re.search(r"(\w+)\(", head).group(1)] = piece.split("\n}\n", 1)[0]
    return found


def subset_tree(robots: list[str], names: list[str], out: Path) -> Path:
    """Generate only ``names`` (C) for ``robots`` into ``out`` and check that every definition
    there is the same text as in generated/."""
    subprocess.run([sys.executable, "-m", "kindyngen", "generate", *(str(ROBOTS / f"{r}.yaml") for r in robots),
                    "--lang", "c", "--functions", ",".join(names), "--out", str(out), "--quiet"], check=True)
    for robot in robots:
        ours = definitions((out / robot / "c" / f"{robot}.c").read_text())
        committed = definitions((GENERATED / robot / "c" / f"{robot}.c").read_text())
        changed = [name for name, text in ours.items() if committed.get(name) != text]
        if changed:
            raise SystemExit(f"batch_isa: {robot}: {', '.join(changed)} differ from generated/ "
                             "(regenerate generated/ or pass --generated)")
    return out


_REGISTER = re.compile(r"%([xyz])mm\d+")


def vector_profile(objdump: str, symbol: str) -> dict:
    """Counts over the instructions of ``symbol`` in ``objdump -d`` text: those naming a zmm,
    ymm or only xmm registers (packed "pd" and scalar "sd" apart), gathers, scatters, and the
    call targets (``objdump -dr`` of an object file: a call's target is its relocation), the
    stack frame it allocates and its vector loads and stores on the stack (local arrays and
    spilled registers alike).

    >>> text = ("0000000000000000 <f>:\\n   0:\\tsub    $0x100,%rsp\\n"
    ...         "   4:\\tvmulpd %zmm1,%zmm2,%zmm3\\n   a:\\tvmovapd %zmm3,0x40(%rsp)\\n"
    ...         "  12:\\tvaddsd %xmm1,%xmm2,%xmm3\\n  16:\\tcall   1b <f+0x1b>\\n"
    ...         "\\t\\t\\t17: R_X86_64_PLT32\\tkdg_sincos8-0x4\\n")
    >>> p = vector_profile(text, "f"); p["zmm"], p["xmm_sd"], p["calls"], p["frame_bytes"], p["stack_vector_moves"]
    (2, 1, {'kdg_sincos8': 1}, 256, 1)
    """
    counts, calls, inside, frame, pending = Counter(), Counter(), False, 0, None
    for line in objdump.splitlines():
        if line.endswith(">:"):
            inside = line.split("<", 1)[1][:-2] == symbol
            continue
        if inside and "R_X86_64_" in line and pending is not None:
            calls[line.split()[-1].split("-")[0].split("+")[0]] += 1   # the call's relocation: its target
            pending = None
            continue
        if pending is not None:
            calls[pending] += 1
            pending = None
        if not inside or ":\t" not in line:
            continue
        text = line.split(":\t", 1)[1].strip()
        mnemonic = text.split()[0] if text else ""
        counts["instructions"] += 1
        widths = set(_REGISTER.findall(text))
        if "z" in widths:
            counts["zmm"] += 1
        elif "y" in widths:
            counts["ymm"] += 1
        elif "x" in widths:
            counts["xmm_sd" if mnemonic.endswith(("sd", "ss")) else "xmm_pd" if mnemonic.endswith(("pd", "ps")) else "xmm_other"] += 1
        if "gather" in mnemonic:
            counts["gathers"] += 1
        if "scatter" in mnemonic:
            counts["scatters"] += 1
        if mnemonic.startswith("call"):
            target = re.search(r"<([^>+]+)", text)
            pending = target.group(1) if target else text
        if mnemonic == "sub" and text.endswith(",%rsp") and not frame:
            frame = int(text.split("$", 1)[1].split(",")[0], 16)
            frame = frame if frame < 1 << 63 else 0       # sub of a negative: no frame
        if mnemonic.startswith("vmov") and widths & {"y", "z"} and re.search(r"\(%r[sb]p", text):
            counts["stack_vector_moves"] += 1
    if pending is not None:
        calls[pending] += 1
    return {**{k: counts[k] for k in ("instructions", "zmm", "ymm", "xmm_pd", "xmm_sd", "xmm_other",
                                      "gathers", "scatters", "stack_vector_moves")},
            "frame_bytes": frame, "calls": dict(calls)}


def variant_flags(march: str) -> list[str]:
    """The flags of one build: the common ones, -march and what follows it.

    >>> variant_flags("icelake-server -mprefer-vector-width=512")
    ['-O3', '-ffp-contract=off', '-march=icelake-server', '-mprefer-vector-width=512']
    """
    first, *rest = march.split()
    return [*OPT, f"-march={first}", *rest]


def build_library(robot: str, tree: Path, compiler: str, march: str) -> Path:
    """The robot's generated C compiled once into an object for both drivers."""
    source = tree / robot / "c" / f"{robot}.c"
    tag = f"{compiler}_{march}".replace(" ", "_")
    # the tree's folder name in the cache name: another tree's build does not replace this one
    built = build(f"batch_isa_{tree.name}_{robot}_{tag}.o", compiler, [source],
                  ["-c", c_harness.C_STD, *variant_flags(march), f"-I{source.parent}"],
                  extra=(tree / robot / "c" / f"{robot}.h",))
    return built.path


_KERNEL = """
/* the batch functions' first stage alone: sin/cos of each of the robot's joint angles over
   blocks of 64 configurations by the kernel of the .c included above, stored in place */
static void kb_kernel_batch(long count, const double *restrict q, double *restrict s, double *restrict c)
{{
    long start;
    int k;
    for (start = 0; start < count; start += 64) {{
        const long size = count - start < 64 ? count - start : 64;
        for (k = 0; k < {angles}; ++k)
            {kernel}(size, q + k*count + start, s + k*count + start, c + k*count + start);
    }}
}}
"""


def kernel_driver(robot: str, tree: Path, angles: int, q: np.ndarray, compiler: str, march: str,
                  workdir: Path) -> c_harness.Prepared:
    """A driver timing the sin/cos stage of the batch functions alone (``kb_kernel_batch``),
    with the generated .c's static kernel functions copied in, on ``q`` ((n, angles))."""
    source = tree / robot / "c" / f"{robot}.c"
    n = q.shape[0]
    kernels = {name: text for name, text in definitions(source.read_text()).items() if name.startswith("kdg_")}
    prelude = "\n".join(["#include <math.h>", *(text + "\n}\n" for text in kernels.values()),
                         # the batch variants' kernel (kdg_sincos before it came)
                         _KERNEL.format(angles=angles, kernel="kdg_sincos_batch" if "kdg_sincos_batch" in kernels
                                        else "kdg_sincos")])
    call = c_harness.CFunction("kernel", f"kb_kernel_batch({n}L, {{in0}}, {{out0}}, {{out1}})",
                               [np.ascontiguousarray(q.T).reshape(1, -1)], [(angles * n, "double")] * 2)
    return c_harness.prepare(re.sub(r"\W+", "_", f"{robot}_kernel_isa_{tree.name}_{compiler}_{march}"), [call], prelude, [],
                             variant_flags(march), workdir, compiler)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", default="lwr4,panda")
    parser.add_argument("--functions", default=",".join(FUNCTIONS))
    parser.add_argument("--marches", default=",".join(MARCHES))
    parser.add_argument("--compilers", default=",".join(COMPILERS))
    parser.add_argument("--n", type=int, default=1000, help="configurations per batch call")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3, help="repetitions per driver run")
    parser.add_argument("--target-ns", type=float, default=1e6, help="length of one repetition")
    parser.add_argument("--generated", type=Path, help="time this generated tree instead")
    parser.add_argument("--baseline", type=Path, help="also time this generated tree (e.g. one of the "
                        "code before a template change), as 'before: <build>' in the same rounds")
    parser.add_argument("--baseline-builds", default="gcc x86-64-v3,gcc native,clang x86-64-v3,clang native",
                        help="the builds (compiler and -march) of the baseline tree")
    parser.add_argument("--out", type=Path, default=RESULTS / "batch_isa.json")
    args = parser.parse_args(argv)
    robots, names = args.robots.split(","), args.functions.split(",")
    work = BUILD / "batch_isa"
    start = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "load": os.getloadavg()}
    tree = args.generated or subset_tree(robots, names, work / "generated")
    # (label, tree, compiler, -march and flags): every build timed in every round
    variants = [(f"{c} {m}", tree, c, m) for c in args.compilers.split(",") for m in args.marches.split(",")]
    if args.baseline:
        variants += [(f"before: {b}", args.baseline, *b.split(" ", 1)) for b in args.baseline_builds.split(",")]
    results = {"machine": {"cpu": cpu_model(), **cpu_identity(), "cores": os.cpu_count(),
                           "gcc": compiler_version("gcc"), "clang": compiler_version("clang")},
               "date": start["date"], "load_average_start": list(start["load"]),
               "flags": OPT + ["-march=<variant>", c_harness.C_STD], "n": args.n, "rounds": args.rounds,
               "repeats": args.repeats, "tree": str(tree), "baseline": str(args.baseline) if args.baseline else None,
               "first_build": variants[0][0], "robots": {}}
    for robot in robots:
        spec = manifest(tree / robot)
        model = load_robot(ROBOTS / f"{robot}.yaml")
        functions = [f for f in spec["functions"] if f["name"] in names]
        samples = {f["name"]: inputs.sample(f, model, args.n) for f in functions}
        drivers, profiles = {}, {}
        for key, tree, compiler, march in variants:
            log(f"{robot}: building {key}")
            obj = build_library(robot, tree, compiler, march)
            dump = subprocess.run(["objdump", "-dr", "--no-show-raw-insn", str(obj)], capture_output=True,
                                  text=True, check=True).stdout
            profiles[key] = {f["name"]: {"batch": vector_profile(dump, f"{f['c_symbol']}_batch"),
                                         "single": vector_profile(dump, f["c_symbol"])} for f in functions}
            profiles[key]["kernels"] = {k: vector_profile(dump, k) for k in ("kdg_sincos8", "kdg_sincos_batch")}
            _, single, batch = c_batch.prepare(tree / robot, functions, samples, args.n, work / robot / re.sub(r"\W+", "_", key),
                                               flags=variant_flags(march), compiler=compiler, sources=[obj],
                                               tag=re.sub(r"\W+", "_", f"_isa_{tree.name}_{compiler}_{march}"))
            kernel = kernel_driver(robot, tree, model.n, inputs.joint_angles(model, args.n), compiler, march,
                                   work / robot / re.sub(r"\W+", "_", key) / "kernel")
            drivers[key] = (single, batch, kernel)
        times, outputs = {}, {}
        load_before = os.getloadavg()
        for r in range(args.rounds):
            log(f"{robot}: round {r + 1}/{args.rounds} (load {os.getloadavg()[0]:.1f})")
            order = variants[r % len(variants):] + variants[:r % len(variants)]   # rotate the start
            for key, *_ in order:
                for impl, prepared in zip(("single", "batch", "kernel"), drivers[key]):
                    measured, checks = c_harness.measure(prepared, args.repeats, args.target_ns)
                    for name, values in measured.items():
                        scale = 1 if impl == "single" else args.n
                        times.setdefault(key, {}).setdefault(name, {}).setdefault(impl, []).extend(
                            v / scale for v in values)
                    outputs.setdefault(key, {})[impl] = checks
        load_after = os.getloadavg()
        first = variants[0][0]
        rows = {}
        for f in functions:
            name = f["name"]
            row = {}
            for key, *_ in variants:
                single, batch = summary(times[key][name]["single"]), summary(times[key][name]["batch"])
                # configuration 0 of the batch (entry k at [k*n]) and of the single call, and of
                # the first build: the same bits everywhere with contraction off
                got_batch = [b.reshape(-1, args.n)[:, 0] for b in outputs[key]["batch"][name]]
                got_single = outputs[key]["single"][name]
                ref_batch = [b.reshape(-1, args.n)[:, 0] for b in outputs[first]["batch"][name]]
                ref_single = outputs[first]["single"][name]
                row[key] = {"batch": batch, "single": single,
                            "single_over_batch": single["median_ns"] / batch["median_ns"],
                            # 0 where both run the same program; fd_derivatives' single call runs
                            # its lane program (another association of the same sums)
                            "batch_vs_single_max_relative": max(
                                float(np.max(np.abs(a - b) / np.maximum(1.0, np.abs(b)), initial=0.0))
                                for a, b in zip(got_batch, got_single)),
                            "same_bits_as_first_build": all(np.array_equal(a, b) for a, b in
                                                            zip(got_single + got_batch, ref_single + ref_batch)),
                            "batch_loop": profiles[key][name]["batch"], "single_call": profiles[key][name]["single"]}
            rows[name] = row
        kernel = {key: summary(times[key]["kernel"]["kernel"]) for key, *_ in variants}
        results["robots"][robot] = {"functions": rows, "batch_kernel_stage": kernel, "load_average_before": list(load_before),
                                    "load_average_after": list(load_after),
                                    "kernels": {k: p["kernels"] for k, p in profiles.items()}}
        print(table(robot, rows), flush=True)
        print("  kernel stage    " + "  ".join(f"{k}: {v['median_ns']:.1f}" for k, v in kernel.items()), flush=True)
    results["load_average_end"] = list(os.getloadavg())

    def both(folder):
        (folder / args.out.name).write_text(strict_json(results, indent=1) + "\n")
        plot(results, folder / args.out.with_suffix(".png").name)
    replace_files(args.out.parent, both)
    log(f"wrote {args.out} and {args.out.with_suffix('.png').name}")
    return 0


def table(robot: str, rows: dict) -> str:
    lines = [robot]
    for name, row in rows.items():
        cells = [f"{key}: {v['batch']['median_ns']:.1f}/{v['single']['median_ns']:.1f} "
                 f"({v['single_over_batch']:.2f}x{'' if v['same_bits_as_first_build'] else ' BITS DIFFER'})"
                 for key, v in row.items()]
        lines.append(f"  {name:15s} " + "  ".join(cells))
    return "\n".join(lines)


def plot(results: dict, path: Path) -> None:
    """Per robot: ns per configuration of the batch (bars) and of single calls (black ticks)
    for every build, functions side by side, log scale."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    robots = results["robots"]
    fig, axes = plt.subplots(1, len(robots), figsize=(7 * len(robots), 6), squeeze=False)
    for ax, (robot, entry) in zip(axes[0], robots.items()):
        names = list(entry["functions"]) + ["sin/cos stage"]
        keys = list(entry["batch_kernel_stage"])
        width = 0.8 / len(keys)
        colors = plt.get_cmap("tab20")
        for k, key in enumerate(keys):
            x = np.arange(len(names)) + (k - (len(keys) - 1) / 2) * width
            batch = [entry["functions"][n][key]["batch"]["median_ns"] for n in names[:-1]]
            single = [entry["functions"][n][key]["single"]["median_ns"] for n in names[:-1]]
            ax.bar(x, batch + [entry["batch_kernel_stage"][key]["median_ns"]], width, color=colors(k), label=key)
            ax.scatter(x[:-1], single, marker="_", color="black", s=40, zorder=3)
        ax.set_xticks(np.arange(len(names)), names, fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("ns per configuration (bars: batch; ticks: single call)")
        load = f"load {entry['load_average_before'][0]:.1f} -> {entry['load_average_after'][0]:.1f}"
        ax.set_title(f"{robot}: -O3 -ffp-contract=off, N = {results['n']} ({load})", fontsize=9)
        ax.legend(fontsize=6, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.08))
    fig.suptitle(f"{results['machine']['cpu']} (family {results['machine'].get('cpu_family')}), "
                 f"{results['date']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
