"""Homogeneous transforms against dual quaternions, function by function (the kinematics
paper's question, asked of the dynamics too): ``python -m benchmarks.representations``
writes ``results/representations.json`` and ``results/representations.md``.

Every figure comes from a file the project writes: operation counts (as derived / after
CSE) from ``generated/<robot>/opcounts.json``, C times per call from the last ``make
bench`` (``results/timings.json``, implementation "c"); the single general DH transform is
derived here, with all four DH parameters symbolic (the kinematics paper's eq. 1 and 2)."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import symengine as se

from kindyngen.json_text import strict_json
from kindyngen.output_folder import replace_files

from .common import GENERATED, RESULTS

# (quantity, homogeneous-route function, dual-quaternion-route function)
PAIRS = (("FK", "fk_hom", "fk_dq"), ("Jacobian", "jacobian", "jacobian_dq"),
         ("pose Jacobian", None, "pose_jacobian_dq"), ("IK (8 branches)", "ik_hom", "ik_dq"),
         ("M", "M", "M_dq"), ("g", "g", "g_dq"), ("c", "c", "c_dq"), ("tau", "tau", "tau_dq"),
         ("Y", "Y", "Y_dq"))
PAPER = {"T": {"add": 2, "mul": 6, "call": 4}, "u": {"add": 4, "mul": 20, "call": 4}}   # Maple, optimised


def general_dh_transform() -> dict:
    """Op counts of one standard DH transform with theta, d, a, alpha all symbolic: T (4x4)
    and the dual quaternion u = Rz(theta) T(a, 0, d) Rx(alpha), as derived and after CSE."""
    from kindyngen.algorithms.geometry import rot_x, rot_z
    from kindyngen.algorithms.dualquat.dq_kinematics import dq_mul
    from kindyngen.codegen.optimize import optimize
    from kindyngen.algorithms.symbolic import Port, SymbolicFunction
    theta, d, a, alpha = se.symbols("theta d a alpha")
    c, s, ca, sa = se.cos(theta), se.sin(theta), se.cos(alpha), se.sin(alpha)
    R = rot_z(c, s) * rot_x(ca, sa)
    T = [R[0, 0], R[0, 1], R[0, 2], a * c, R[1, 0], R[1, 1], R[1, 2], a * s, R[2, 0], R[2, 1], R[2, 2], d]
    half = se.Rational(1, 2)
    rz = ((se.cos(theta / 2), 0, 0, se.sin(theta / 2)), (0, 0, 0, 0))
    tr = ((1, 0, 0, 0), (0, half * a, 0, half * d))
    rx = ((se.cos(alpha / 2), se.sin(alpha / 2), 0, 0), (0, 0, 0, 0))
    real, dual = dq_mul(dq_mul(rz, tr), rx)
    u = list(real) + list(dual)
    out = {}
    for name, exprs in (("T", T), ("u", u)):
        f = SymbolicFunction(name=name, summary="", inputs=(Port("dh", (4,), "", ""),),
                             outputs=(Port(name, (len(exprs),), "", ""),), input_symbols=((theta, d, a, alpha),),
                             output_exprs=(tuple(se.sympify(e) for e in exprs),))
        program = optimize(f)
        out[name] = {"before": program.before.to_json(), "after": program.after.to_json(), "paper": PAPER[name]}
    return out


def _counts(robot: str) -> dict:
    path = GENERATED / robot / "opcounts.json"
    return json.loads(path.read_text()) if path.exists() else {}


def _times(timings: dict, robot: str) -> dict:
    if timings.get("robot") == robot:
        functions = timings.get("functions", {})
    else:
        functions = timings.get("robots", {}).get(robot, {}).get("functions", {})
    return {name: impls["c"]["median_ns"] for name, impls in functions.items() if "c" in impls}


def table(robots=("lwr4", "panda"), timings_path: Path = RESULTS / "timings.json") -> dict:
    timings = json.loads(timings_path.read_text()) if timings_path.exists() else {}
    rows = {}
    for robot in robots:
        counts, times = _counts(robot), _times(timings, robot)
        rows[robot] = []
        for quantity, hom, dq in PAIRS:
            row = {"quantity": quantity}
            for form, name in (("homogeneous", hom), ("dual_quaternion", dq)):
                if name is None or name not in counts:
                    row[form] = None
                    continue
                row[form] = {"function": name, "before": counts[name]["before"], "after": counts[name]["after"],
                             "c_ns": times.get(name)}
            rows[robot].append(row)
    return {"general_dh_transform": general_dh_transform(), "robots": rows,
            "timings_date": timings.get("date"), "machine": timings.get("machine")}


def _ops(c: dict) -> str:
    return f"{c['add']} / {c['mul']} / {c['call']}"


def markdown(doc: dict) -> str:
    g = doc["general_dh_transform"]
    lines = ["# Homogeneous transforms against dual quaternions", "",
             "Operations add / mul / call (a select counts as a call), as derived and after CSE; C time per "
             f"call (median, `make bench` of {doc['timings_date'] or 'no run yet'}).", "",
             "One general standard DH transform (theta, d, a, alpha symbolic; the kinematics paper's eq. 1 "
             "and 2, its Maple figures after optimisation beside ours):", "",
             "| form | as derived | after CSE | kinematics paper (Maple, optimised) |", "|---|---|---|---|"]
    for key, label in (("T", "homogeneous T (4x4)"), ("u", "dual quaternion u (8)")):
        lines.append(f"| {label} | {_ops(g[key]['before'])} | {_ops(g[key]['after'])} | {_ops(g[key]['paper'])} |")
    for robot, rows in doc["robots"].items():
        lines += ["", f"## {robot}", "",
                  "| quantity | homogeneous | as derived | after CSE | C ns | dual quaternion | as derived | after CSE "
                  "| C ns |", "|---|---|---|---|---|---|---|---|---|"]
        for row in rows:
            cells = [row["quantity"]]
            for form in ("homogeneous", "dual_quaternion"):
                entry = row[form]
                if entry is None:
                    cells += ["-", "-", "-", "-"]
                else:
                    ns = f"{entry['c_ns']:.0f}" if entry["c_ns"] is not None else "-"
                    cells += [f"`{entry['function']}`", _ops(entry["before"]), _ops(entry["after"]), ns]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.representations", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=RESULTS, help="results folder")
    args = parser.parse_args(argv)
    doc = table()

    def both(folder):          # the JSON and its table, both or neither
        (folder / "representations.json").write_text(strict_json(doc, indent=1) + "\n")
        (folder / "representations.md").write_text(markdown(doc))
    replace_files(args.out, both)
    print(markdown(doc))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
