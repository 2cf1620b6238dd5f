"""Smoke test of the known-truth benchmark of ``discover`` (``benchmarks.discover_truth``):
correctness only, no timing.

The simulator's own pieces are checked against independent computations (its DH builder
against ``tests/reference.py``'s, its noise gain against filtered white noise, each
measurement law against its definition, the sizing against the size it reports); the scorer
against a hand-written discovery.json; then two ``--quick`` trials on the UR5 run the real
``discover``: with nothing hidden, discover's held-out RMS of the nominal model must be at the
noise floor the simulator states (the logs and the nominal description agree), the trial
record must hold exactly what discovery.json says, and a second run resumes without running
anything.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.signal import butter, sosfiltfilt

from benchmarks import truth_simulator as sim
from benchmarks.truth_families import CANDIDATES_TODAY, FAMILIES, family_of, score_trial
from benchmarks.truth_robots import ROBOTS


def _strict(text):
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")
    return json.loads(text, parse_constant=refuse)


@pytest.mark.parametrize("name", ["lwr4", "panda"])
def test_dh_builder_matches_the_reference_model(name):
    from kindyngen.readers.yaml_description import load_robot
    from tests.reference import pinocchio_model
    mine = ROBOTS[name].model()
    ref, ref_data, _ = pinocchio_model(load_robot(f"robots/{name}.yaml"))
    data = mine.createData()
    rng = np.random.default_rng(3)
    for _ in range(10):
        q, v, a = rng.uniform(-1.5, 1.5, (3, mine.nq))
        np.testing.assert_allclose(pin.rnea(mine, data, q, v, a), pin.rnea(ref, ref_data, q, v, a), atol=1e-10)


def test_noise_gain_is_that_of_filtered_white_noise():
    x = np.random.default_rng(0).standard_normal(400000)
    for rate in (200.0, 1000.0):
        filtered = sosfiltfilt(butter(4, 5.0, fs=rate, output="sos"), x)[5000:-5000]
        assert abs(sim.filter_gain(rate) / np.std(filtered) - 1) < 0.03


def test_measurement_laws_act_on_what_is_logged():
    robot = ROBOTS["ur5"]
    lower, upper = robot.limits()
    exc = sim.draw_excitation(np.random.default_rng(1), robot.home, lower, upper, 10.0, True)
    t = np.arange(0.0, 10.0, 0.01)
    q, qd, qdd = exc.motion(t)
    rigid = sim.rnea(robot.model(), q, qd, qdd)
    dq, gt, ce = np.full(6, 0.01), np.linspace(-0.2, 0.2, 6), np.full(6, 1e-4)
    q_log, tau_log, _ = sim.logged(robot, {"encoder_offset": {"dq": dq.tolist()}}, t, q, qd, qdd)
    np.testing.assert_allclose(q_log, q + dq)
    np.testing.assert_allclose(tau_log, rigid, atol=1e-9)
    q_log, tau_log, _ = sim.logged(robot, {"gain": {"gt": gt.tolist()}}, t, q, qd, qdd)
    np.testing.assert_allclose(tau_log, (1 + gt) * rigid, atol=1e-9)
    q_log, tau_log, joint = sim.logged(robot, {"elastic": {"ce": ce.tolist()}, "viscous": {"fv": [1.0] * 6}},
                                       t, q, qd, qdd)
    np.testing.assert_allclose(joint, rigid + qd, atol=1e-9)
    np.testing.assert_allclose(q_log, q + ce * (rigid + qd), atol=1e-12)
    # the excitation starts and ends at rest, inside the limits less the margin
    assert np.all(np.abs(qd[:40]) < 1e-12) and np.all(np.abs(qd[-40:]) < 1e-12)
    assert np.all(q > lower + sim.MARGIN - 1e-9) and np.all(q < upper - sim.MARGIN + 1e-9)


@pytest.mark.parametrize("law", ["viscous", "encoder_offset"])
def test_an_effect_is_sized_in_noise_floors(law):
    robot = ROBOTS["ur5"]
    lower, upper = robot.limits()
    rng = np.random.default_rng(2)
    exc = [sim.draw_excitation(rng, robot.home, lower, upper, 12.0, True)]
    floor = 0.05 * sim.filter_gain(200.0)
    params, size = sim.sized(robot, law, sim.draw_shape(law, rng, 6), 7.0, floor, exc, [12.0])
    assert abs(size - 7.0) < 0.07
    # measured again independently: the filtered torque the nominal model misses
    t = np.arange(0.0, 12.0, 0.01)
    q, qd, qdd = exc[0].motion(t)
    q_log, tau_log, _ = sim.logged(robot, {law: params}, t, q, qd, qdd)
    missed = tau_log - sim.rnea(robot.model(), q_log, qd, qdd)        # an offset does not change qd, qdd
    filtered = sosfiltfilt(butter(4, 5.0, fs=100.0, output="sos"), missed, axis=0)[100:-100]
    assert abs(np.max(np.sqrt(np.mean(filtered ** 2, axis=0))) / floor - size) < 0.01 * size


def test_scorer_reads_a_discovery_document():
    family = family_of("pair:torque_offset+payload")
    truth = {"offset": {"f0": [0.5, -0.2, 0.0]}, "payload": {"mass": 1.2, "com": [0, 0, 0.05], "dims": [0.1] * 3}}
    sizes = {"offset": [10.0, 4.0, 0.0], "payload": 8.0}
    doc = {"effects": ["payload", "torque_offset", "armature"], "explained": True,
           "rms_before": [0.3, 0.2, 0.1], "rms_after_all_fitted": [0.011, 0.012, 0.02],
           "noise_floor": {"per_joint": [0.01, 0.01, 0.01]}, "payload_mass": 1.5,
           "model_yaml_values": {"f01": 0.55}, "not_determined": {"f02": {"fitted": -0.1, "reason": "x"}},
           "steps": [], "indistinguishable": []}
    s = score_trial(family, truth, sizes, doc, 0.01, CANDIDATES_TODAY, [0, 0, -9.81])
    assert s["scoring"] == "exact" and not s["correct"] and s["spurious"] == ["armature"] and not s["missed"]
    assert s["truth_explained"] is False and s["verdict_ok"] is False and s["at_floor"] is False
    errors = {c["name"]: c["rel_error"] for c in s["coefficients"]}
    assert errors == pytest.approx({"f01": 0.1, "f02": 0.5, "payload_mass": 0.25})
    # the unseen rule: a stand-in is no spurious name, and "not explained" above the floor is right
    doc.update(effects=["payload"], explained=False)
    s = score_trial(FAMILIES["link_errors"], {"links": {}}, {"links": 5.0}, doc, 0.01, CANDIDATES_TODAY,
                    [0, 0, -9.81])
    assert s["scoring"] == "unseen" and s["correct"] and s["verdict_ok"] and not s["spurious"]


def test_quick_trials_against_discover(tmp_path):
    from benchmarks.discover_truth import main
    out, keep = tmp_path / "out", tmp_path / "keep"
    args = ["--quick", "--trials", "2", "--families", "none,torque_offset", "--robots", "ur5", "--ends", "rest",
            "--out", str(out)]
    assert main(args + ["--keep", str(keep)]) == 0
    doc = _strict((out / "discover_truth.json").read_text())
    assert (out / "discover_truth.md").exists() and (out / "discover_truth.png").exists()
    trials = {t["family"]: t for t in doc["trials"]}
    assert set(trials) == {"none", "torque_offset"}
    for t in doc["trials"]:
        assert "error" not in t, t.get("error")
        found = _strict((keep / f"trial{t['index']:04d}" / "out" / "discovery.json").read_text())
        assert t["named"] == found["effects"] and t["explained"] == found["explained"]
        assert t["rms_before_floors"] == pytest.approx(np.array(found["rms_before"]) / t["floor"])
        # discover's noise floor is the one the simulator states
        assert abs(t["noise_floor_ratio"] - 1) < 0.2, t["noise_floor_ratio"]
        for c in t["coefficients"]:
            assert c["fitted"] is not None, c          # named: the scorer found its coefficients
    # nothing hidden: the nominal model is at the floor on every joint (logs and description agree)
    none = trials["none"]
    assert max(none["rms_before_floors"]) < 1.5 and min(none["rms_before_floors"]) > 0.6, none["rms_before_floors"]
    # the hidden offset is in the log: the nominal model misses it by about its size
    offset = trials["torque_offset"]
    assert max(offset["rms_before_floors"]) > 0.5 * offset["min_size"], (offset["rms_before_floors"], offset["sizes"])
    # a second run finds both trials scored and runs nothing
    assert main(args) == 0
    again = _strict((out / "discover_truth.json").read_text())
    assert [t["spec_hash"] for t in again["trials"]] == [t["spec_hash"] for t in doc["trials"]]
    assert [t["time"] for t in again["trials"]] == [t["time"] for t in doc["trials"]]
    assert math.isfinite(again["summary"]["all"]["correct"])


@pytest.mark.parametrize("module", ["truth_robots", "truth_simulator", "truth_families"])
def test_worked_examples(module):
    import doctest
    import importlib
    result = doctest.testmod(importlib.import_module(f"benchmarks.{module}"))
    assert result.attempted > 0 and result.failed == 0, result


def test_the_benchmark_shares_no_code_with_what_it_measures():
    import ast
    from pathlib import Path
    folder = Path(__file__).resolve().parents[2] / "benchmarks"
    for name in ("discover_truth", "truth_robots", "truth_simulator", "truth_families"):
        tree = ast.parse((folder / f"{name}.py").read_text())
        imported = [a.name for node in ast.walk(tree) if isinstance(node, ast.Import) for a in node.names]
        imported += [node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
        assert not [m for m in imported if m.startswith("kindyngen.") and m != "kindyngen.json_text"], (name, imported)
