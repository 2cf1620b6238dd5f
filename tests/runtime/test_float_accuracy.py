"""kindyngen.runtime.float_accuracy's measurement on hand-made outputs (the whole generate-time figure
is exercised in tests/runtime/test_float_code.py): errors are relative to each port's largest |entry|
(rounded to 2 digits), integer outputs count differing states, a non-finite float where the
double is finite is an infinite error, and the near-singular states put one joint near 0."""
from __future__ import annotations

import numpy as np
import pytest

from kindyngen.runtime.float_accuracy import NEAR_ZERO, compare, random_inputs
from kindyngen.readers.yaml_description import load_robot
from tests.harness import ROOT

SPEC = {"outputs": [{"name": "M", "dtype": "double"}, {"name": "status", "dtype": "int"}]}


def test_errors_are_relative_to_the_port_scale():
    double = {"M": np.array([[1.0, 2.0], [4.0, -8.0], [0.5, 0.0]]), "status": np.array([[0], [1], [2]])}
    single = {"M": np.array([[1.0, 2.5], [4.0, -8.0], [0.5, 0.0]]), "status": np.array([[0], [3], [2]])}
    e = compare(double, single, SPEC, 3)
    assert e.scales == (("M", 8.0),) and e.max == 0.062         # 0.5 / 8 to 2 significant digits
    assert e.int_mismatch == 1 and e.states == 3 and not e.acceptable
    assert e.to_json()["scale"] == {"M": 8.0}


def test_rounding_to_float32_is_within_half_an_ulp_of_the_scale():
    rng = np.random.default_rng(9)
    d = rng.uniform(-30, 30, (500, 49))
    e = compare({"M": d, "status": np.zeros((500, 1))}, {"M": d.astype(np.float32), "status": np.zeros((500, 1))},
                SPEC, 500)
    assert e.int_mismatch == 0 and e.acceptable
    assert 0 < e.max <= float(f"{2.0 ** -24:.1e}") * 1.05       # |x| <= scale: at most half a float ulp of it
    assert e.p99 <= e.max


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_non_finite_float_where_double_is_finite_is_not_acceptable():
    spec = {"outputs": [{"name": "x", "dtype": "double"}]}
    d = np.array([[1.0, np.inf], [2.0, 3.0]])
    f = np.array([[1.0, np.inf], [np.nan, 3.0]])               # inf in both: no error; nan in float only: infinite
    e = compare({"x": d}, {"x": f}, spec, 2)
    assert e.scales == (("x", 3.0),) and e.max == np.inf and not e.acceptable
    assert "NOT ACCEPTABLE" in e.text()
    assert compare({"x": d[:, :1] * 0 + 1}, {"x": d[:, :1] * 0 + 1}, spec, 2).acceptable


def test_random_inputs_stay_within_the_limits_and_near_zero_puts_each_joint_near_zero():
    model = load_robot(ROOT / "robots" / "lwr4.yaml")
    spec = {"inputs": [{"name": "q", "shape": [7]}, {"name": "qd", "shape": [7]}, {"name": "qdd", "shape": [7]}]}
    rng = np.random.default_rng(0)
    x = random_inputs(model, None, spec, rng, 70)
    assert np.all((model.lower <= x["q"]) & (x["q"] <= model.upper))
    assert np.abs(x["qd"]).max() <= 2 and np.abs(x["qdd"]).max() <= 5
    near = random_inputs(model, None, spec, rng, 70, near_zero=True)["q"]
    assert np.all(np.abs(near[np.arange(70), np.arange(70) % 7]) <= NEAR_ZERO)


def _two_link_programs():
    from kindyngen.codegen.pipeline import build_programs
    from kindyngen.codegen.interface import manifest
    model = load_robot(ROOT / "examples" / "two_link.yaml")
    programs = build_programs(model, only={"fk_hom"}, progress=False)
    return model, programs, manifest(model, programs, "numeric", "libm", scalar="float")


def test_the_float_measurement_is_a_note_only_without_a_host_compiler(monkeypatch, capsys):
    """No compiler: a note and no figure. A compiler that builds a one-line library but not the
    generated C: the failure is raised, never passed off as a missing compiler."""
    from kindyngen.codegen import pipeline
    from kindyngen.runtime import float_accuracy
    from kindyngen.runtime.evaluate import EvaluationError
    model, programs, document = _two_link_programs()

    def failing(*args, **kwargs):
        raise EvaluationError("compiling two_link.c failed:\nerror: expected ';'")

    monkeypatch.setattr(float_accuracy, "measure", failing)
    with pytest.raises(EvaluationError, match="expected ';'"):
        pipeline.measure_float_error(model, programs, document, "libm")
    monkeypatch.setenv("CC", "/nonexistent/cc")
    assert pipeline.measure_float_error(model, programs, document, "libm") == {}
    assert "note: float error not measured (no working host C compiler)" in capsys.readouterr().err
