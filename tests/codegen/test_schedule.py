"""The register-pressure order of the large functions (kindyngen/codegen/schedule.py): a
permutation of every statement that respects every dependence, fewer temporaries live at
once than demand order on lwr4's derivatives, and the threshold rule of the C renderer
(render.PRESSURE_ORDER_OPERATIONS). The values of the reordered C (the derivatives' scalar
programs, generate --no-lanes) are checked against their lane programs by
tests/codegen/test_lane_programs.py, those against Pinocchio by
tests/algorithms/test_dynamics_derivatives.py (the committed generated/ C)."""
from __future__ import annotations

import pytest
import symengine as se

from kindyngen.codegen import render
from kindyngen.codegen.pipeline import build_programs
from kindyngen.codegen.render import (PRESSURE_ORDER_EXCLUDED, PRESSURE_ORDER_OPERATIONS, demand_order, function_view,
                                      render_c)
from kindyngen.codegen.schedule import graph, max_live, pressure_order
from tests.harness import ROOT
from kindyngen.readers.yaml_description import load_robot

NAMES = ("fd", "tau_derivatives", "fd_derivatives", "fd_derivatives_no_minv")


@pytest.fixture(scope="module")
def programs():
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    return model, {p.function.name: p for p in build_programs(model, only=list(NAMES), progress=False)}


def check_topological(order, assignments, outputs):
    reads_t, reads_o, keys = graph(assignments, outputs)
    expected = [("t", k) for k in range(len(assignments))] + keys
    assert sorted(order, key=str) == sorted(expected, key=str)
    assert len(set(order)) == len(order)
    position = {s: i for i, s in enumerate(order)}
    for k, reads in enumerate(reads_t):
        assert all(position[("t", j)] < position[("t", k)] for j in reads)
    for key, reads in zip(keys, reads_o):
        assert all(position[("t", j)] < position[key] for j in reads)


@pytest.mark.parametrize("name", NAMES)
def test_pressure_order_is_a_topological_order_with_fewer_live(programs, name):
    _, found = programs
    p = found[name]
    order = pressure_order(p.assignments, p.outputs)
    check_topological(order, p.assignments, p.outputs)
    peak, mean = max_live(order, p.assignments, p.outputs)
    demand_peak, demand_mean = max_live(demand_order(p.assignments, p.outputs), p.assignments, p.outputs)
    print(f"{name}: live peak/mean pressure {peak}/{mean:.1f}, demand {demand_peak}/{demand_mean:.1f}")
    assert mean < demand_mean
    if name != "fd":
        assert peak < demand_peak


def test_small_example_frees_early():
    x, y, t0, t1, t2 = se.symbols("x y t0 t1 t2")
    a = [(t0, x + 1), (t1, 2 * y), (t2, t0 * t1)]
    outputs = [(t2, t0 + 1)]
    order = pressure_order(a, outputs)
    check_topological(order, a, outputs)
    # t0's other reader (output entry 1) is printed before t1 is computed
    assert order.index(("out", 0, 1)) < order.index(("t", 1))
    assert max_live(order, a, outputs)[0] == 2 and max_live(demand_order(a, outputs), a, outputs)[0] == 2
    assert max_live(order, a, outputs)[1] < max_live(demand_order(a, outputs), a, outputs)[1]


def test_renderer_uses_pressure_order_above_the_threshold(programs):
    _, found = programs
    for name, p in found.items():
        # the scalar programs (generate --no-lanes)
        view = function_view(p, render.C, "lwr4", "kernel", lanes=False)
        big = p.after.add + p.after.mul > PRESSURE_ORDER_OPERATIONS and name not in PRESSURE_ORDER_EXCLUDED
        assert view.pressure is big, name
        assert view.statements, name          # both are above DEMAND_ORDER_OPERATIONS
        again = function_view(p, render.C, "lwr4", "kernel", lanes=False)
        assert again.statements == view.statements      # deterministic
        # a function printed as a lane program does not order its unused scalar statements
        laned = function_view(p, render.C, "lwr4", "kernel")
        assert (laned.lane is not None) is (p.lanes is not None), name
        if p.lanes is not None:
            assert not laned.pressure and not laned.statements, name
    assert found["tau_derivatives"].lanes is not None and found["fd"].lanes is None
    assert found["tau_derivatives"].after.add + found["tau_derivatives"].after.mul > PRESSURE_ORDER_OPERATIONS
    assert found["fd"].after.add + found["fd"].after.mul <= PRESSURE_ORDER_OPERATIONS


def test_scalar_derivatives_print_in_pressure_and_demand_order():
    """The derivatives' scalar programs (generate --no-lanes; the committed C runs their lane
    programs, tests/codegen/test_lane_programs.py): tau_derivatives in pressure order,
    fd_derivatives in demand order (render.PRESSURE_ORDER_EXCLUDED)."""
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    programs = build_programs(model, only={"tau_derivatives", "fd_derivatives"}, progress=False)
    text = render_c(model, programs, batch=False, lanes=False)["lwr4.c"]
    body = text[text.index("void lwr4_tau_derivatives("):]
    body = body[:body.index("\n}\n")]
    assert "in register-pressure order" in body and "kdg_lane" not in body
    body = text[text.index("void lwr4_fd_derivatives("):]
    body = body[:body.index("\n}\n")]
    assert "in demand order" in body and "register-pressure" not in body
    committed = (ROOT / "generated" / "lwr4" / "c" / "lwr4.c").read_text()
    for name in ("tau_derivatives", "fd_derivatives"):
        body = committed[committed.index(f"void lwr4_{name}("):]
        assert "for (kdg_lane = 0; kdg_lane < 8; ++kdg_lane) {" in body[:body.index("\n}\n")], name


def test_reprs_stay_short(programs):
    """pytest prints a failing test's arguments: the dataclasses' generated repr printed every
    expression as a tree (a DAG's shared nodes once per use), gigabytes for the derivatives."""
    _, found = programs
    p = found["tau_derivatives"]
    for obj in (p, p.function, p.function.lanes, p.lanes, found):
        assert len(repr(obj)) < 1000, type(obj).__name__
    assert "tau_derivatives" in repr(p) and "lanes" in repr(p.function)


def test_a_trees_large_single_calls_keep_cse_order():
    """Demand and pressure order were measured on chains; a tree's single calls print CSE's
    order whatever their size (render.PRESSURE_ORDER_EXCLUDED's note: on the G1 M 1.25x, fd
    1.12x faster). A floating tree's fd (over DEMAND_ORDER_OPERATIONS) and tau_derivatives
    (over PRESSURE_ORDER_OPERATIONS, its scalar program) print as a chain's would not."""
    from kindyngen.readers.urdf import load_urdf
    model = load_urdf(ROOT / "tests" / "data" / "urdf" / "mobile_slider_tree.urdf", floating_base=True)
    assert not model.is_chain
    found = {p.function.name: p for p in build_programs(model, only=["fd", "tau_derivatives"], progress=False)}
    assert found["fd"].after.add + found["fd"].after.mul > render.DEMAND_ORDER_OPERATIONS
    assert found["tau_derivatives"].after.add + found["tau_derivatives"].after.mul > PRESSURE_ORDER_OPERATIONS
    text = render_c(model, list(found.values()), batch=False, lanes=False)[f"{model.identifier}.c"]
    assert "in demand order" not in text and "register-pressure order" not in text
    for p in found.values():
        assert not function_view(p, render.C, model.identifier, "kernel", lanes=False, chain=False).statements
        assert function_view(p, render.C, model.identifier, "kernel", lanes=False).statements    # as a chain's
