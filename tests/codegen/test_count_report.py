"""The operation-count report of :mod:`kindyngen.codegen.count_report` (``opcounts.json``,
``opcounts.md``) on a two-joint arm (fk_hom, g, M, fd: derived in a fraction of a second):
the "after CSE" additions, multiplications and calls it reports equal those counted here
in the generated C by a small tokenizer that knows nothing of the counter (binary + and -
are additions, * and / multiplications, every libm call and every sin/cos of the sincos
kernel's output that the body reads is a call; unary minus is free, as the README's rule
says); the Markdown tables carry the JSON's numbers, in generation order, with the routes,
the paper's Table II and the float-error sections only where they apply."""
from __future__ import annotations

import re

import pytest

from kindyngen.codegen.count_report import opcounts_json, opcounts_markdown
from kindyngen.codegen.pipeline import build_programs
from kindyngen.codegen.render import RENDERERS
from kindyngen.readers.yaml_description import parse_robot
from kindyngen.runtime.float_accuracy import FloatError

ARM = {"name": "two", "dh": "modified", "gravity": [0, 0, -9.81],
       "joints": [{"a": 0, "alpha": 0, "d": 0.3, "offset": 0, "lower": -2, "upper": 2},
                  {"a": 0.4, "alpha": "pi/2", "d": 0, "offset": 0.1, "lower": -2, "upper": 2}],
       "links": [{"mass": 2.0, "com": [0.01, 0.02, 0.1], "inertia": [0.02, 0.025, 0.015, 0.001, 0.002, 0.003]},
                 {"mass": 1.0, "com": [0.2, 0.01, 0.0], "inertia": [0.01, 0.02, 0.02, 0.001, 0.0, 0.002]}]}
FUNCTIONS = ("fk_hom", "g", "M", "fd")

TOKEN = re.compile(r"(?P<num>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)|(?P<id>[A-Za-z_]\w*)|(?P<op>\S)")
NOT_COUNTED_CALLS = {"kdg_sincos"}


def count_c_operations(body: str) -> dict:
    """add / mul / call of a generated C function body, by tokens (see the module text)."""
    add = mul = 0
    calls, kernel_values = 0, set()
    for line in body.splitlines():
        line = re.sub(r"/\*.*?\*/", "", line).strip()
        if not line or line.startswith(("double sin_q", "kdg_sincos")):
            continue
        tokens = [(m.lastgroup, m.group()) for m in TOKEN.finditer(line)]
        assert not any(text in "?<>" for kind, text in tokens if kind == "op"), line   # no branches here
        for k, (kind, text) in enumerate(tokens):
            previous = tokens[k - 1] if k else ("op", "")
            operand_before = previous[0] in ("num", "id") or previous[1] in (")", "]")
            if kind == "op" and text == "+":
                add += 1
            elif kind == "op" and text == "-" and operand_before:
                add += 1
            elif kind == "op" and text in "*/":
                mul += 1
            elif kind == "id" and text in ("sin_q", "cos_q"):
                kernel_values.add((text, tokens[k + 2][1]))          # sin_q [ k ]
            elif kind == "id" and k + 1 < len(tokens) and tokens[k + 1][1] == "(" \
                    and text not in NOT_COUNTED_CALLS:
                calls += 1
    return {"add": add, "mul": mul, "call": calls + len(kernel_values)}


def c_function_body(source: str, name: str) -> str:
    """The body of ``void <name>(...)`` (not its batch variant)."""
    match = re.search(r"^void " + re.escape(name) + r"\(.*?\)\n\{\n(.*?)^\}", source, re.S | re.M)
    assert match, name
    return match.group(1)


def two_joint_report(functions) -> tuple:
    """(model, programs, C source, opcounts.json) of ``functions`` of the two-joint ARM."""
    model = parse_robot(ARM)
    programs = build_programs(model, only=set(functions), progress=False)
    files = RENDERERS["c"](model, programs)
    source = next(text for filename, text in files.items() if filename.endswith(".c"))
    return model, programs, source, opcounts_json(programs)


@pytest.fixture(scope="module")
def report():
    return two_joint_report(FUNCTIONS)


def test_counts_after_cse_equal_the_operators_of_the_generated_c(report):
    model, programs, source, counts = report
    assert sorted(counts) == sorted(FUNCTIONS)
    for name in FUNCTIONS:
        counted = count_c_operations(c_function_body(source, f"{model.identifier}_{name}"))
        assert counts[name]["after"] == counted, name
        assert counted["add"] + counted["mul"] > 0


def test_the_counter_counts_what_the_rule_says():
    """The tokenizer itself on hand-written C (binary vs unary minus, literals with exponents,
    division, libm calls, each kernel value once)."""
    body = """    const double t0 = cos_q[0];
    const double t1 = -t0*sin_q[1] + 1.5e-3;
    const double t2 = 1.0/(t1 - cos_q[0]);
    y[0] = sqrt(t2) - atan2(t1, -t0);"""
    assert count_c_operations(body) == {"add": 3, "mul": 2, "call": 4}


def test_route_counts_and_kept_route(report):
    _, programs, _, counts = report
    fd = counts["fd"]
    assert fd["route"] in fd["routes"]
    assert len(fd["routes"]) >= 2
    # the kept route is the one with the fewest additions + multiplications, and it is what
    # the C counts
    totals = {name: c["add"] + c["mul"] for name, c in fd["routes"].items()}
    assert totals[fd["route"]] == min(totals.values())
    assert fd["routes"][fd["route"]] == fd["after"]
    assert all("route" not in counts[name] for name in FUNCTIONS if name != "fd")


def _table(markdown: str, heading_line: str) -> list[list[str]]:
    """Rows (cells) of the first table after ``heading_line`` (None: the first table)."""
    lines = markdown.splitlines()
    start = lines.index(heading_line) if heading_line else 0
    rows, inside = [], False
    for line in lines[start:]:
        if line.startswith("|"):
            inside = True
            rows.append([c.strip() for c in line.strip("|").split("|")])
        elif inside:
            break
    return rows[2:]         # after the header and the |---| line


def test_markdown_tables_carry_the_json_numbers(report):
    model, programs, _, counts = report
    text = opcounts_markdown(model.name, programs, compare_with_paper=False)
    assert text.startswith(f"# Operation counts: {model.name}\n")
    rows = _table(text, None)
    assert [r[0] for r in rows] == [p.function.name for p in programs]      # generation order
    for r in rows:
        b, a = counts[r[0]]["before"], counts[r[0]]["after"]
        assert [int(v) for v in r[1:]] == [b["add"], b["mul"], b["call"], a["add"], a["mul"], a["call"]]
    for r in _table(text, "## Critical path"):
        c = counts[r[0]]
        assert [int(v) for v in r[1:]] == [c["critical_path"]["cycles"], c["critical_path"]["operations"],
                                           sum(c["after"].values())]
    routes = _table(text, "## Routes")
    assert {(r[0], r[1]) for r in routes} == {("fd", name) for name in counts["fd"]["routes"]}
    assert [r[1] for r in routes if r[5] == "yes"] == [counts["fd"]["route"]]
    for r in routes:
        assert [int(v) for v in r[2:5]] == list(counts["fd"]["routes"][r[1]].values())
    assert "Table II" not in text and "Float error" not in text


def test_paper_section_lists_only_the_functions_built(report):
    model, programs, _, counts = report
    text = opcounts_markdown(model.name, programs, compare_with_paper=True)
    rows = _table(text, "## Beside the kinematics paper (Table II, Maple 2018)")
    assert [r[0] for r in rows] == ["fk_hom"]                      # no fk_dq, ik_* built here
    a, b = counts["fk_hom"]["after"], counts["fk_hom"]["before"]
    # Hartl-Nesic and Meiringer, Table II, fk_hom: optimised 40 / 87 / 14, derived 88 / 238 / 327
    assert rows[0] == ["fk_hom", f"{a['add']} / {a['mul']} / {a['call']}", "40 / 87 / 14",
                       f"{b['add']} / {b['mul']} / {b['call']}", "88 / 238 / 327"]


def test_float_error_section_and_json(report):
    model, programs, _, _ = report
    near = FloatError(3.0e-5, 1.0e-6, 0, 14)
    errors = {"g": FloatError(2.34e-7, 1.06e-7, 0, 1000, near=near),
              "M": FloatError(2.0e-3, 1.0e-4, 3, 1000, near=FloatError(5.0e-3, 1.0e-3, 1, 14))}
    counts = opcounts_json(programs, errors)
    assert counts["g"]["float_error"]["max"] == 2.34e-7 and counts["g"]["float_error"]["acceptable"]
    assert counts["M"]["float_error"]["acceptable"] is False
    assert "float_error" not in counts["fk_hom"]
    rows = _table(opcounts_markdown(model.name, programs, False, errors), "## Float error (--scalar float)")
    assert rows == [["g", "2.3e-07", "1.1e-07", "yes", "0 of 1000", "3.0e-05", "1.0e-06", "yes", "0 of 14"],
                    ["M", "2.0e-03", "1.0e-04", "NO", "3 of 1000", "5.0e-03", "1.0e-03", "NO", "1 of 14"]]
