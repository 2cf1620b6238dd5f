"""The progress of a run names what runs now: each function's line appears when its derivation
starts (``k/N name: deriving``), not after it is done, and a long function shows its phases
as they start (CSE, the routes of fd, the lane program of the derivatives), with the time since
the run began (never asserted: tests check no speed)."""
from __future__ import annotations

import io
import re
import sys
from pathlib import Path

import pytest

from kindyngen.codegen import pipeline
from kindyngen.codegen.pipeline import build_programs
from kindyngen.readers.yaml_description import load_robot
from tests.harness import robot

NAMES = ("fk_hom", "M", "fd", "tau_derivatives")
LINE = r"lwr4 \[[#.]+\] (\d+)/(\d+) (\w+): (.+) \(\d+\.\d s\)"


def test_each_line_names_the_function_that_is_starting(monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)             # not a terminal: one line per phase
    started = []
    optimize = pipeline.optimize

    def spy(function, *args, **kwargs):
        """What the user reads while ``function`` is being optimised: the last line written."""
        started.append((function.name, stream.getvalue().splitlines()[-1:]))
        return optimize(function, *args, **kwargs)

    monkeypatch.setattr(pipeline, "optimize", spy)
    programs = build_programs(robot("lwr4"), only=set(NAMES), progress=True)
    assert [p.function.name for p in programs] == list(NAMES)
    assert [name for name, _ in started] == list(NAMES)
    for k, (name, last) in enumerate(started):
        assert last and re.fullmatch(LINE, last[0]), (name, last)
        assert re.fullmatch(LINE, last[0]).groups() == (str(k + 1), str(len(NAMES)), name, "deriving"), last

    lines = stream.getvalue().splitlines()
    phases = [re.fullmatch(LINE, line).groups() for line in lines[:-1]]
    assert all(phases), lines
    by_function = {name: [what for _, _, n, what in phases if n == name] for name in NAMES}
    for name in NAMES:
        assert by_function[name][0] == "deriving" and any("CSE of " in w for w in by_function[name])
    # fd: both routes, each named as it starts; the derivatives' lane program
    assert any(w.startswith("route 1/2 (") for w in by_function["fd"])
    assert any(w.startswith("route 2/2 (") for w in by_function["fd"])
    assert "lane program" in by_function["tau_derivatives"]
    # numbered in order, never a function named after it is done
    assert [int(k) for k, _, _, _ in phases] == sorted(int(k) for k, _, _, _ in phases)
    assert re.fullmatch(r"lwr4: 4 functions derived and optimised in \d+\.\d s", lines[-1]), lines[-1]


ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"


@pytest.mark.parametrize("path, only", [
    ("mimic/gripper.urdf", None),                       # mimic joints: the reduced functions
    ("loops/four_bar.yaml", {"fk_hom", "M", "fd", "loop_residual", "loop_solve", "S", "fk_dq"}),
])
def test_mimic_and_loop_models_count_what_they_derive(monkeypatch, path, only):
    """The k/N of each line counts the functions the run derives: a model with mimic joints or
    closed loops numbers exactly the programs it gets (not the chain's list of functions), a
    description's bundles after them."""
    stream = io.StringIO()
    monkeypatch.setattr(sys, "stderr", stream)
    model = load_robot(EXAMPLES / path, tree=True)
    programs = build_programs(model, only=only, progress=True)
    lines = stream.getvalue().splitlines()
    started = [re.search(r" (\d+)/(\d+) (\w+): deriving", line) for line in lines]
    started = [m.groups() for m in started if m]
    assert [name for _, _, name in started] == [p.function.name for p in programs]
    assert [int(k) for k, _, _ in started] == list(range(1, len(programs) + 1))
    assert {int(total) for _, total, _ in started} == {len(programs)}
    assert lines[-1].endswith(f"{len(programs)} functions derived and optimised in " + lines[-1].split(" in ")[-1])
    names = {p.function.name for p in programs}
    if model.has_loops:
        assert {"loop_residual", "loop_solve", "fk_hom", "M", "fd"} <= names and not {"S", "fk_dq"} & names
    else:
        assert {"fk_hom", "M", "fd_derivatives", "Y"} <= names and not {"S", "M_lagrange", "fk_dq"} & names
