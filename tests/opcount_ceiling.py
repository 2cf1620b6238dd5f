"""The committed ceiling of operation counts after CSE (tests/opcount_ceiling.json): per robot
and function, the additions and multiplications the generated code may cost at most.

A count may fall freely (then lower the table, so that the gain is kept); a rise fails until
the table is edited in the same commit, which makes every rise a visible, reviewed change.
The byte comparison of generated/ (tests/integration/test_reproducibility.py) cannot tell fewer
operations from broken code; this table can tell more from fewer."""
from __future__ import annotations

import json
from pathlib import Path

TABLE = Path(__file__).resolve().parent / "opcount_ceiling.json"
KINDS = ("add", "mul")


def ceiling(table: Path = TABLE) -> dict[str, dict[str, dict[str, int]]]:
    """{robot label: {function: {"add": n, "mul": n}}} (the "about" entry left out)."""
    data = json.loads(table.read_text())
    return {label: functions for label, functions in data.items() if label != "about"}


def compare(label: str, counts: dict[str, dict[str, int]], table: dict) -> tuple[list[str], list[str]]:
    """(rises, falls) of ``counts`` ({function: {"add", "mul", ...}}, as opcounts.json's
    "after") against ``table[label]``, as readable lines. A function the table does not list,
    or one it lists that is no longer generated, is a rise: the table must say so too."""
    if label not in table:
        return [f"{label}: not in {TABLE.name}; add its counts"], []
    limits = table[label]
    rises = [f"{label}.{name}: new function, not in {TABLE.name}" for name in sorted(set(counts) - set(limits))]
    rises += [f"{label}.{name}: in {TABLE.name} but no longer generated" for name in sorted(set(limits) - set(counts))]
    falls = []
    for name in sorted(set(counts) & set(limits)):
        for kind in KINDS:
            got, limit = counts[name][kind], limits[name][kind]
            if got > limit:
                rises.append(f"{label}.{name}.{kind}: {got} > ceiling {limit}")
            elif got < limit:
                falls.append(f"{label}.{name}.{kind}: {got} < ceiling {limit}")
    return rises, falls


def write(table: dict, about: str, path: Path = TABLE) -> None:
    """The table with one function per line (a rise shows as a one-line diff)."""
    lines = ["{", f' "about": {json.dumps(about)},']
    labels = list(table)
    for i, label in enumerate(labels):
        lines.append(f' "{label}": {{')
        names = list(table[label])
        for j, name in enumerate(names):
            entry = ", ".join(f'"{k}": {table[label][name][k]}' for k in KINDS)
            lines.append(f'  "{name}": {{{entry}}}' + ("," if j < len(names) - 1 else ""))
        lines.append(" }" + ("," if i < len(labels) - 1 else ""))
    lines.append("}")
    path.write_text("\n".join(lines) + "\n")


def lowered(table: dict, label: str, counts: dict[str, dict[str, int]]) -> dict:
    """``table`` with ``label``'s entries lowered to ``counts`` where they fell (never raised,
    no function added or removed)."""
    out = {k: {n: dict(v) for n, v in fs.items()} for k, fs in table.items()}
    for name, limits in out.get(label, {}).items():
        for kind in KINDS:
            if name in counts:
                limits[kind] = min(limits[kind], counts[name][kind])
    return out


def generated_counts(root: Path) -> dict[str, dict[str, dict[str, int]]]:
    """{robot: {function: after counts}} of every generated/<robot>/opcounts.json (the
    iterative ik_dls has no "after")."""
    return {path.parent.name: {name: entry["after"] for name, entry in json.loads(path.read_text()).items()
                               if "after" in entry}
            for path in sorted(root.glob("*/opcounts.json"))}


def main() -> int:
    """``python tests/opcount_ceiling.py``: lower the table to the counts of generated/ where
    they fell (after a regeneration that saves operations); rises are left for a hand edit."""
    about = json.loads(TABLE.read_text())["about"]
    table = ceiling()
    for label, counts in generated_counts(TABLE.parents[1] / "generated").items():
        rises, falls = compare(label, counts, table)
        table = lowered(table, label, counts)
        print("\n".join(falls + [f"NOT RAISED (edit by hand): {r}" for r in rises]))
    write(table, about)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
