"""The progress of a run names what runs now: each function's line appears when its derivation
starts (``k/N name: deriving``), not after it is done, and a long function shows its phases
as they start (CSE, the routes of fd, the lane program of the derivatives), with the time since
the run began (never asserted: tests check no speed)."""
from __future__ import annotations

import io
import re
import sys

from kindyngen.codegen import pipeline
from kindyngen.codegen.pipeline import build_programs
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
