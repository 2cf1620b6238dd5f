"""The operation-count table of a robot, as JSON (for tools) and Markdown (for people).

For the KUKA LWR the forward- and inverse-kinematics rows stand beside the kinematics
paper's Table II (Hartl-Nesic and Meiringer: Maple 2018, with and without optimisation).
"""
from __future__ import annotations

from .optimize import IN_PLACE_BOUND, Program
from ..model.user_text import markdown

# Kinematics paper, Table II: (add, mult, calls); "derived" = without code optimisation.
PAPER_TABLE_II = {
    "fk_hom": {"derived": (88, 238, 327), "optimised": (40, 87, 14)},
    "fk_dq": {"derived": (312, 1576, 880), "optimised": (38, 88, 14)},
    "ik_hom": {"optimised": (1461, 2570, 52)},
    "ik_dq": {"optimised": (1070, 2258, 184)},
}


def opcounts_json(programs: list[Program], float_error: dict | None = None) -> dict:
    """``{name: {"before": {add, mul, call}, "after": {...}}}`` in generation order; a function
    chosen among routes also has ``"route"`` (the chosen one) and ``"routes"`` (each one's
    count after CSE); ``"critical_path"``: cycles and operations of the longest chain of
    dependent operations (:func:`kindyngen.codegen.opcount.program_critical_path`); a function
    whose C single call is a lane program has ``"c_lanes"`` (:meth:`kindyngen.codegen.optimize.LaneProgram.to_json`:
    lanes, the counts once and per lane, those executed, its critical path), one whose C single
    call runs joint loops ``"c_loops"`` (:meth:`kindyngen.codegen.optimize.JointLoopProgram.to_json`:
    each piece's count and runs, those executed); with ``--scalar float``
    each measured function has ``"float_error"`` (kindyngen/runtime/float_accuracy.py); a bundle
    ``"members"`` and ``"members_after"`` (their count called one by one)."""
    float_error = float_error or {}
    return {p.function.name: {"before": p.before.to_json(), "after": p.after.to_json(),
                              "critical_path": p.critical.to_json(), **_routes_json(p),
                              **({"c_lanes": p.lanes.to_json()} if p.lanes is not None else {}),
                              **({"c_loops": p.joint_loops.to_json()} if p.joint_loops is not None else {}),
                              **_bundle_json(p),
                              **({"float_error": float_error[p.function.name].to_json()}
                                 if p.function.name in float_error else {})}
            for p in programs}


def _bundle_json(p: Program) -> dict:
    """A bundle's members and their count after CSE called one by one (kindyngen/codegen/bundles.py)."""
    if "members" not in p.function.metadata:
        return {}
    return {"members": list(p.function.metadata["members"]),
            "members_after": p.function.metadata["members_after"].to_json()}


def _routes_json(p: Program) -> dict:
    if not p.routes:
        return {}
    return {"route": p.function.metadata.get("route"), "routes": {name: c.to_json() for name, c in p.routes}}


def _row(values) -> str:
    return " | ".join(str(v) for v in values)


def _critical_markdown(programs) -> list[str]:
    from .trig_kernel import kernel_latency
    from .opcount import LATENCY
    table = ", ".join(f"{k} {v}" for k, v in LATENCY.items() if k not in ("kernel", "call"))
    lines = ["", "## Critical path", "",
             "The longest chain of dependent operations of the generated C as printed (strict C99: no "
             "contraction, sums and products left to right), in cycles of a stated latency table (AMD Zen 4: "
             f"{table}; a libm call as 40; sin/cos of q and of half angles from the sincos kernel "
             f"{kernel_latency()}, its own chain, after its last argument). A single call waits at least this long however many units the core has; "
             "docs/latency.md compares it with measured times.", "",
             "| function | cycles | operations on it | add + mul + call after CSE |", "|---|---|---|---|"]
    for p in programs:
        lines.append(f"| {p.function.name} | {p.critical.cycles} | {p.critical.operations} | {p.after.total} |")
    return lines


def opcounts_markdown(robot_name: str, programs: list[Program], compare_with_paper: bool,
                      float_error: dict | None = None) -> str:
    lines = [f"# Operation counts: {markdown(robot_name)}", "",
             "add = additions/subtractions, mul = multiplications/divisions, call = sin, cos, sqrt, "
             "atan2, ... (counting rule in the README). Before = the expression tree as derived; "
             "after = the generated straight-line code after CSE."
             + (" Functions derived with named intermediates (a recursion's per-body quantities: "
                "tree dynamics) count each intermediate's expression once before CSE."
                if any(p.function.stages for p in programs) else ""), "",
             "| function | add before | mul before | call before | add after | mul after | call after |",
             "|---|---|---|---|---|---|---|"]
    for p in programs:
        b, a = p.before, p.after
        lines.append(f"| {p.function.name} | {_row([b.add, b.mul, b.call, a.add, a.mul, a.call])} |")
    lines += _critical_markdown(programs)
    laned = [p for p in programs if p.lanes is not None]
    if laned:
        lines += ["", "## Lane programs (C single calls)", "",
                  "These functions' C single calls run one pass over the model once, then one program per "
                  "lane, in a loop that compilers vectorise across lanes (lane l carries the gradient of the "
                  "joint torques weighted by its seeds and gives row l of the result); lanes are padded to a "
                  "multiple of four. More operations are executed than by the scalar program above, in fewer "
                  "instructions (four lanes per AVX2 instruction; measured in docs/latency.md, \"Lane programs\"). "
                  "`generate --no-lanes` prints the scalar program instead.", "",
                  "| function | once (add / mul / call) | per lane (add / mul) | lanes (kept) | executed (add / mul) "
                  "| critical path cycles |", "|---|---|---|---|---|---|"]
        for p in laned:
            lp = p.lanes
            lines.append(f"| {p.function.name} | {lp.uniform.add} / {lp.uniform.mul} / {lp.uniform.call} | "
                         f"{lp.lane.add} / {lp.lane.mul} | {lp.count} ({lp.used}) | "
                         f"{lp.executed.add} / {lp.executed.mul} | {lp.critical.cycles} |")
    looped = [p for p in programs if p.joint_loops is not None]
    if looped:
        lines += ["", "## Joint loops (C single calls)", "",
                  "These functions' C single calls run the kinematics once, then loops over the joints (padded "
                  "with zero lanes to a multiple of eight) and over pairs of joints that compilers vectorise "
                  "across joints (docs/latency.md, \"Joint loops\"). More operations are executed than by the "
                  "scalar program above, in fewer instructions. `generate --no-lanes` prints the scalar program "
                  "instead.", "",
                  "| function | piece | add / mul / call | runs |", "|---|---|---|---|"]
        for p in looped:
            for piece, (count, runs) in p.joint_loops.parts().items():
                lines.append(f"| {p.function.name} | {piece} | {count.add} / {count.mul} / {count.call} | {runs} |")
            ex = p.joint_loops.executed
            lines.append(f"| {p.function.name} | executed | {ex.add} / {ex.mul} / {ex.call} | |")
    bundled = [p for p in programs if "members" in p.function.metadata]
    if bundled:
        lines += ["", "## Bundles", "",
                  "A bundle computes its members' outputs in one call with one CSE over all of them (the sin/cos "
                  "of q once, equal intermediates once; kindyngen/codegen/bundles.py), against its members "
                  "called one by one:", "",
                  "| bundle | members | add / mul / call after | members one by one | add + mul ratio |",
                  "|---|---|---|---|---|"]
        for p in bundled:
            parts = p.function.metadata["members_after"]
            ratio = (p.after.add + p.after.mul) / max(parts.add + parts.mul, 1)
            lines.append(f"| {p.function.name} | {', '.join(p.function.metadata['members'])} | "
                         f"{p.after.add} / {p.after.mul} / {p.after.call} | {parts.add} / {parts.mul} / {parts.call} | "
                         f"{ratio:.2f} |")
    chosen = [p for p in programs if p.routes]
    if chosen:
        lines += ["", "## Routes", "", "Functions derived by several routes keep the one with the fewest "
                  "additions + multiplications after CSE, or the cheapest whose sin/cos arguments are all "
                  "joint angles or their halves, which the C sincos kernel reads in place from q, where that "
                  f"costs at most {IN_PLACE_BOUND[0]}/{IN_PLACE_BOUND[1]} of the fewest (fk_dq: a route with sums of half angles as arguments "
                  "computes them into an array for the kernel first; docs/latency.md).", "",
                  "| function | route | add after | mul after | call after | kept |", "|---|---|---|---|---|---|"]
        for p in chosen:
            for name, c in p.routes:
                kept = "yes" if name == p.function.metadata.get("route") else ""
                lines.append(f"| {p.function.name} | {name} | {_row([c.add, c.mul, c.call])} | {kept} |")
    if compare_with_paper:
        lines += ["", "## Beside the kinematics paper (Table II, Maple 2018)", "",
                  "| function | KinDynGen after CSE (add / mul / call) | paper optimised | "
                  "KinDynGen as derived | paper without optimisation |", "|---|---|---|---|---|"]
        by_name = {p.function.name: p for p in programs}
        for name, paper in PAPER_TABLE_II.items():
            if name not in by_name:
                continue
            p = by_name[name]
            ours_after = f"{p.after.add} / {p.after.mul} / {p.after.call}"
            ours_before = f"{p.before.add} / {p.before.mul} / {p.before.call}"
            opt = " / ".join(map(str, paper["optimised"]))
            der = " / ".join(map(str, paper["derived"])) if "derived" in paper else "-"
            lines.append(f"| {name} | {ours_after} | {opt} | {ours_before} | {der} |")
    if float_error:
        from ..runtime.float_accuracy import ACCEPTABLE, NEAR_ZERO, SEED
        lines += ["", "## Float error (--scalar float)", "",
                  f"The float C against the double C at {next(iter(float_error.values())).states} random states "
                  f"within the limits (seed {SEED}): |float - double| / the output's scale (its largest "
                  f"|entry|), over all entries and states; acceptable: max <= {ACCEPTABLE:.0e}. Integer "
                  "outputs (IK status): states where they differ. Near singular: as many states with one "
                  f"joint (each in turn) within {NEAR_ZERO:g} rad of 0, errors relative to the same scales.", "",
                  "| function | max | 99th percentile | acceptable | integer outputs differ | "
                  "near singular: max | 99th percentile | acceptable | integer outputs differ |",
                  "|---|---|---|---|---|---|---|---|---|"]
        fmt = (lambda v: "-" if v is None else f"{v:.1e}")
        for name, e in float_error.items():
            n = e.near
            lines.append(f"| {name} | {fmt(e.max)} | {fmt(e.p99)} | {'yes' if e.acceptable else 'NO'} | "
                         f"{e.int_mismatch} of {e.states} | {fmt(n.max)} | {fmt(n.p99)} | "
                         f"{'yes' if n.acceptable else 'NO'} | {n.int_mismatch} of {n.states} |")
    return "\n".join(lines) + "\n"
