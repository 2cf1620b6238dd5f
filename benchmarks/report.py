"""`make report`: results/timings.json (+ scaling.json) -> report.md, report.json and plots.

    python -m benchmarks.report [--results DIR] [--out DIR]

Sections: the LWR operation counts beside the kinematics paper's Table II; the speed table
(median per call, and Pinocchio C++ time / our time: above 1 means ours is faster); a bar
chart in the manner of the paper's Fig. 1 with its MATLAB times beside ours; the scaling of
generation time and operation count with the number of joints. If scaling.json is missing it
is computed here (small sizes, short budget) so the report never lacks the section.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402

from kindyngen.json_text import strict_json  # noqa: E402

from . import paper, scaling  # noqa: E402
from .common import GENERATED, RESULTS, manifest  # noqa: E402
from kindyngen.output_folder import replace_files  # noqa: E402

IMPL_ORDER = ("c", "c_native", "casadi_codegen", "pinocchio_cpp", "pinocchio_casadi_c", "python", "python_batch",
              "python_batch_1000", "casadi")
IMPL_LABEL = {"c": "C -O3", "c_native": "C -O3 -march=native", "casadi_codegen": "CasADi codegen C -O3",
              "pinocchio_cpp": "Pinocchio C++", "pinocchio_casadi_c": "Pinocchio in CasADi SX, C -O3 -march=native",
              "python": "numpy, 1 config/call",
              "python_batch": "numpy batch (per config)", "python_batch_1000": "numpy batch N=1000 (per config)",
              "casadi": "CasADi Function from Python", "c_batch": "C batch -O3 -march=native (per config)",
              "python_c": "python_c (generated C from Python)", "pinocchio_python": "Pinocchio's Python bindings"}
RATIO_IMPLS = ("c", "c_native", "casadi_codegen")


def fmt_time(ns: float | None) -> str:
    if ns is None:
        return "-"
    if ns < 1e3:
        return f"{ns:.0f} ns"
    if ns < 1e6:
        return f"{ns / 1e3:.3g} us"
    return f"{ns / 1e6:.3g} ms"


def fmt_count(c) -> str:
    return "-" if not c else f"{c['add']} / {c['mul']} / {c['call']}"


def impls_present(functions: dict) -> list[str]:
    found = {impl for per in functions.values() for impl in per}
    return [i for i in IMPL_ORDER if i in found] + sorted(found - set(IMPL_ORDER))


# --- tables --------------------------------------------------------------------------------
def opcount_rows(counts: dict) -> list[dict]:
    rows = []
    for label, (fname, theirs) in paper.TABLE_II.items():
        ours = counts.get(fname) or {}
        rows.append({"computation": label, "function": fname, "ours_before": ours.get("before"),
                     "ours_after": ours.get("after"),
                     "paper_unoptimized": dict(zip(("add", "mul", "call"), theirs["unoptimized"])) if "unoptimized" in theirs else None,
                     "paper_optimized": dict(zip(("add", "mul", "call"), theirs["optimized"]))})
    covered = {fname for fname, _ in paper.TABLE_II.values()}
    for fname, c in counts.items():
        if fname not in covered and c:
            rows.append({"computation": fname, "function": fname, "ours_before": c.get("before"),
                         "ours_after": c.get("after"), "paper_unoptimized": None, "paper_optimized": None})
    return rows


def opcount_markdown(rows: list[dict]) -> list[str]:
    out = ["| computation | KinDynGen as derived | KinDynGen after CSE | paper unoptimized | paper optimized |",
           "|---|---|---|---|---|"]
    for r in rows:
        label = f"`{r['function']}`" if r["computation"] == r["function"] else f"{r['computation']} (`{r['function']}`)"
        out.append(f"| {label} | {fmt_count(r['ours_before'])} | "
                   f"{fmt_count(r['ours_after'])} | {fmt_count(r['paper_unoptimized'])} | {fmt_count(r['paper_optimized'])} |")
    return out


COMPILED = ("c", "c_native", "casadi_codegen", "pinocchio_cpp", "pinocchio_casadi_c", "c_batch")


def speed_markdown(functions: dict, ratios: dict, compiled: bool) -> list[str]:
    """Compiled implementations with the Pinocchio ratios, or the Python-side ones."""
    impls = [i for i in impls_present(functions) if (i in COMPILED) == compiled]
    if not impls:
        return []
    ratio_cols = [i for i in RATIO_IMPLS if any(f"pinocchio_cpp/{i}" in r for r in ratios.values())] if compiled else []
    head = ["function"] + [IMPL_LABEL.get(i, i) for i in impls] + [f"Pinocchio / {IMPL_LABEL.get(i, i)}" for i in ratio_cols]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for fname, per in functions.items():
        cells = [f"`{fname}`"]
        for i in impls:
            st = per.get(i, {})
            n = f" (N={st['n']})" if "n" in st and i == "python_batch" else ""
            cells.append(fmt_time(st.get("median_ns")) + n)
        cells += [f"{ratios[fname][f'pinocchio_cpp/{i}']:.2f}" if f"pinocchio_cpp/{i}" in ratios.get(fname, {}) else "-"
                  for i in ratio_cols]
        out.append("| " + " | ".join(cells) + " |")
    return out + [""]


# --- plots ---------------------------------------------------------------------------------
def fig1(functions: dict, path: Path) -> dict:
    """Mean time per computation, FK and IK, homogeneous vs dual quaternion, per
    implementation, with the paper's MATLAB times (log scale: they span four decades)."""
    computations = [f for f in ("fk_hom", "fk_dq", "ik_hom", "ik_dq")]
    impls = [i for i in impls_present(functions) if any(i in functions.get(f, {}) for f in computations)]
    series = {IMPL_LABEL.get(i, i): [functions.get(f, {}).get(i, {}).get("median_ns") for f in computations]
              for i in impls}
    series["paper: MATLAB 2017b (i7-6700K)"] = [paper.MATLAB_US[f] * 1e3 for f in computations]
    fig, ax = plt.subplots(figsize=(10, 4.8))
    width = 0.8 / max(len(series), 1)
    for k, (label, values) in enumerate(series.items()):
        xs = [j + (k - (len(series) - 1) / 2) * width for j in range(len(computations))]
        ax.bar([x for x, v in zip(xs, values) if v], [v / 1e3 for v in values if v], width, label=label,
               hatch="//" if label.startswith("paper") else None, edgecolor="black", linewidth=0.4)
    ax.set_xticks(range(len(computations)))
    ax.set_xticklabels(["FK homogeneous", "FK dual quaternion", "IK homogeneous", "IK dual quaternion"])
    ax.set_yscale("log")
    ax.set_ylabel("time per computation [us]\n(ours: median of repeats; paper: mean)")
    ax.set_title("LWR4: time per computation (cf. kinematics paper, Fig. 1)")
    ax.grid(axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return {"computations": computations, "series_ns": series}


PEER_FUNCTIONS = ("fk_hom", "fk_dq", "jacobian", "M", "g", "c", "tau", "fd", "tau_derivatives", "fd_derivatives")
PEER_IMPLS = ("c", "c_native", "c_batch", "pinocchio_casadi_c", "pinocchio_cpp")


def peers_plot(functions: dict, path: Path) -> dict:
    """Median time per call (c_batch: per configuration) of the generated C and of both
    Pinocchio peers, function by function (log scale: FK and the derivatives are two decades
    apart)."""
    names = [f for f in PEER_FUNCTIONS if f in functions]
    series = {i: [functions[f].get(i, {}).get("median_ns") for f in names] for i in PEER_IMPLS
              if any(i in functions[f] for f in names)}
    fig, ax = plt.subplots(figsize=(11, 4.8))
    width = 0.8 / max(len(series), 1)
    for k, (impl, values) in enumerate(series.items()):
        xs = [j + (k - (len(series) - 1) / 2) * width for j in range(len(names))]
        ax.bar([x for x, v in zip(xs, values) if v], [v for v in values if v], width,
               label=IMPL_LABEL.get(impl, impl), edgecolor="black", linewidth=0.4)
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, rotation=20)
    ax.set_yscale("log")
    ax.set_ylabel("ns per call (batch: per configuration)")
    ax.set_title("LWR4: generated C against Pinocchio C++ and Pinocchio traced into CasADi's C (one run)")
    ax.grid(axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return {"functions": names, "series_ns": series}


def scaling_plot(study: dict, path: Path) -> None:
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5))
    for route, entry in study.get("routes", {}).items():
        rows = entry["rows"]
        if not rows:
            continue
        ns = [r["n"] for r in rows]
        line, = left.plot(ns, [r["total_s"] for r in rows], "o-", label=route)
        right.plot(ns, [sum(r["after"].values()) for r in rows], "o-", color=line.get_color(), label=f"{route} after CSE")
        right.plot(ns, [sum(r["before"].values()) for r in rows], ":", color=line.get_color(), alpha=0.6)
    for ax, label in ((left, "generation time (derive + CSE) [s]"), (right, "operations (add + mul + call)")):
        ax.set_yscale("log")
        ax.set_xlabel("number of joints n")
        ax.set_ylabel(label)
        ax.grid(which="both", alpha=0.3)
        ax.legend(fontsize=7)
    right.set_title("solid: after CSE, dotted: as derived", fontsize=9)
    left.set_title("synthetic chains", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def scaling_markdown(study: dict) -> list[str]:
    sizes = study.get("sizes", [])
    out = ["| route | " + " | ".join(f"n={n}" for n in sizes) + " | stopped |", "|" + "---|" * (len(sizes) + 2)]
    for route, entry in study.get("routes", {}).items():
        by_n = {r["n"]: r for r in entry["rows"]}
        cells = [f"{by_n[n]['total_s']:.2g} s, {sum(by_n[n]['after'].values())} ops" if n in by_n else "-" for n in sizes]
        out.append(f"| `{route}` | " + " | ".join(cells) + f" | {entry.get('stopped') or ''} |")
    return out


# --- the report ----------------------------------------------------------------------------
def build_report(timings: dict, study: dict, out: Path, counts: dict | None = None) -> dict:
    """report.md, report.json and the figures in ``out``, all or none
    (kindyngen.output_folder.replace_files). ``counts``: {function: opcount} from
    generated/lwr4/functions.json; default: the copy taken by the benchmark run."""
    summary = {}
    replace_files(out, lambda folder: summary.update(_write_report(timings, study, folder, counts)))
    return summary


def _write_report(timings: dict, study: dict, out: Path, counts: dict | None) -> dict:
    functions, ratios = timings.get("functions", {}), timings.get("ratios", {})
    rows = opcount_rows(counts if counts is not None else timings.get("opcounts", {}))
    figure = fig1(functions, out / "fig1_times.png")
    scaling_plot(study, out / "scaling.png")
    peers = peers_plot(functions, out / "peers.png")
    m = timings.get("machine", {})
    md = [f"# KinDynGen benchmark report ({timings.get('robot', 'lwr4')})", "",
          f"Run {timings.get('date', '?')} on {m.get('cpu', '?')} ({m.get('cores', '?')} cores), "
          f"{m.get('gcc', '?')}, Python {m.get('python', '?')}, numpy {m.get('numpy', '?')}, "
          f"CasADi {m.get('casadi', '?')}, Pinocchio {m.get('pinocchio', '?')}.",
          "Times are medians per call over the repeats; every comparison is a ratio within this one run "
          "(the machine is shared and noisy: absolute times move by tens of percent between runs).", ""]
    if timings.get("notes"):
        md += ["Notes from the run:", ""] + [f"- {n}" for n in timings["notes"]] + [""]
    md += ["## Operation counts (LWR4) beside the kinematics paper's Table II", "",
           "add / mul / call. Paper: Maple 2018 (\"unoptimized\" = plain expressions, \"optimized\" = "
           "after Maple's code optimization); ours: as derived (every shared sub-expression paid each "
           "time) and after common-subexpression elimination (the generated code).", ""]
    md += opcount_markdown(rows) + [""]
    md += ["## Speed (LWR4)", "",
           "Median time per call. Pinocchio / X = Pinocchio C++ time divided by X's time: above 1 means "
           "the generated code is faster. What Pinocchio runs for each row is listed below the table.", ""]
    md += speed_markdown(functions, ratios, compiled=True)
    md += ["From Python (numpy batch: one call on N configurations, time per configuration):", ""]
    md += speed_markdown(functions, ratios, compiled=False)
    notes = {f: per["pinocchio_cpp"].get("note") for f, per in functions.items() if "pinocchio_cpp" in per}
    if notes:
        md += ["Pinocchio counterparts: " + "; ".join(f"`{f}`: {n}" for f, n in notes.items()) + ".", ""]
    pb = timings.get("pinocchio_build")
    if pb:
        cached = " (cached from an earlier run)" if pb["cached"] else ""
        md += [f"Pinocchio C++ is built header-only with g++ -O3 -march=native: {pb['seconds']} s to compile{cached}.", ""]
    if timings.get("build_seconds"):
        md += ["Compile time of the timing drivers with the code under test: "
               + ", ".join(f"{IMPL_LABEL.get(i, i)} {s} s" for i, s in timings["build_seconds"].items() if s is not None) + ".", ""]
    for robot, entry in timings.get("robots", {}).items():
        md += [f"### {robot}", ""] + speed_markdown(entry["functions"], entry.get("ratios", {}), compiled=True)
    md += ["## Against the peers, per function (LWR4)", "", "![peers](peers.png)", ""]
    md += ["## Time per computation (cf. the paper's Fig. 1)", "", "![Fig. 1](fig1_times.png)", "",
           "The paper's bars are MATLAB 2017b on an i7-6700K at 4 GHz (FK 3.642 / 4.398 us, "
           "IK 86.138 / 173.104 us, homogeneous / dual quaternion): another machine and language, "
           "shown for scale, not as a ratio.", ""]
    md += ["## Scaling with the number of joints", "",
           f"Synthetic chains (alternating twists of +-pi/2, some non-zero a and d, full inertias); "
           f"each route stops growing n once its next size is predicted to take over "
           f"{study.get('budget_s', '?')} s.", "", "![scaling](scaling.png)", ""]
    md += scaling_markdown(study) + [""]
    checks = timings.get("checks", {})
    bad = [(impl, f, e) for impl, per in checks.items() for f, e in per.items() if e is None or e > 1e-6]
    md += ["## Wiring checks", "",
           "Every timed implementation's output for the first input was compared with the generated "
           "numpy code (Pinocchio: flange pose and torques): "
           + ("all agree to 1e-6 relative." if not bad else
              "disagreements: " + ", ".join(f"{impl} {f} ({e})" for impl, f, e in bad)), ""]
    (out / "report.md").write_text("\n".join(md))
    summary = {"date": timings.get("date"), "machine": m, "opcounts": rows, "speed": functions, "ratios": ratios,
               "fig1": figure, "peers": peers, "scaling": study, "checks": checks}
    (out / "report.json").write_text(strict_json(summary, indent=1) + "\n")
    return summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS, help="directory with timings.json")
    parser.add_argument("--out", type=Path, default=None, help="where to write the report (default: --results)")
    parser.add_argument("--generated", type=Path, default=GENERATED,
                        help="generated code, for the operation counts (default generated/)")
    args = parser.parse_args(argv)
    timings_path = args.results / "timings.json"
    if not timings_path.exists():
        print(f"no {timings_path}: run `make bench` (python -m benchmarks.run) first", file=sys.stderr)
        return 1
    timings = json.loads(timings_path.read_text())
    scaling_path = args.results / "scaling.json"
    if scaling_path.exists():
        study = json.loads(scaling_path.read_text())
    else:
        print("no scaling.json: computing a small scaling study (n = 2..6)")
        study = scaling.study(range(2, 7), 10.0)
    spec = manifest(args.generated / timings.get("robot", "lwr4"))
    counts = {f["name"]: f.get("opcount") for f in spec["functions"]} if spec else None
    out = args.out or args.results
    build_report(timings, study, out, counts)
    print(f"wrote {out / 'report.md'}, report.json, fig1_times.png, peers.png, scaling.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
