"""`kindyngen discover` end to end on logs simulated here (Pinocchio plus the hidden effect's
own formula): it names the hidden effect, writes a model.yaml whose generated `tau` reproduces
the reported held-out `rms_after`, and names nothing on data the nominal model explains."""
from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import ROOT, robot
from kindyngen.cli.main import main
from kindyngen.runtime.evaluate import load_generated
from kindyngen.measured.log_preparing import Preprocessing, concatenate_rows, load_segments, split_time
from kindyngen.codegen.pipeline import generate
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

FV = np.array([0.9, 0.8, 0.6, 0.5, 0.3, 0.2, 0.1])
NOISE = 0.02


def _log(path, hidden: bool, seed=3, seconds=30.0, rate=200.0, encoder=None):
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / rate)
    amp = rng.uniform(0.2, 0.6, size=(7, 3))
    w = 2 * np.pi * rng.uniform(0.1, 0.5, size=(7, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(7, 3))
    arg = w[None] * t[:, None, None] + phase[None]
    q = np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    model, data, _ = pinocchio_model(robot("lwr4"))
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    if hidden:
        tau = tau + FV * qd
    tau = tau + rng.normal(scale=NOISE, size=tau.shape)
    if encoder is not None:   # an encoder: quantised positions, no velocities or accelerations logged
        q = np.round(q / encoder) * encoder
        header = ["t"] + [f"{k}{i}" for k in ("q", "tau") for i in range(1, 8)]
        columns = [t, q, tau]
    else:
        header = ["t"] + [f"{k}{i}" for k in ("q", "qd", "qdd", "tau") for i in range(1, 8)]
        columns = [t, q, qd, qdd, tau]
    np.savetxt(path, np.column_stack(columns), delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    return path


def _discover(log, out, capsys, cutoff="none"):
    code = main(["discover", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(log), "--cutoff", cutoff,
                 "--out", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads((out / "discovery.json").read_text())


def test_hidden_viscous_friction_is_named_and_the_model_reproduces_the_gap(tmp_path, capsys):
    doc = _discover(_log(tmp_path / "log.csv", hidden=True), tmp_path / "out", capsys)
    assert doc["effects"] == ["viscous_friction"]
    assert max(doc["rms_before"]) > 10 * NOISE
    assert max(doc["rms_after"]) < 1.5 * NOISE
    values, std = doc["coefficients"], doc["std"]
    for i in range(7):
        assert abs(values[f"fv{i + 1}"] - FV[i]) < 5 * std[f"fv{i + 1}"] + 1e-3
    for name in ("report.md", "report.html", "residuals.png", "steps.png", "heldout_torques.png", "model.yaml"):
        assert (tmp_path / "out" / name).is_file(), name
    # code generated from model.yaml, run along the held-out data, gives the reported rms_after
    model = load_robot(tmp_path / "out" / "model.yaml")
    assert model.effects == ("viscous_friction", "coulomb_friction", "torque_offset")
    lib = load_generated(generate(model, tmp_path / "gen", languages=("python",), progress=False), "python")
    _, heldout = split_time(load_segments(tmp_path / "log.csv", 7, Preprocessing(cutoff_hz=None)), 0.7)
    q, qd, qdd, tau = concatenate_rows(heldout)
    predicted = lib.call("tau", {"q": q, "qd": qd, "qdd": qdd})["tau"]
    np.testing.assert_allclose(np.sqrt(np.mean((tau - predicted) ** 2, axis=0)), doc["rms_after"], rtol=1e-9)


def test_encoder_positions_only(tmp_path, capsys):
    """Positions from a 2^20-count encoder (6e-6 rad steps), torques with sensor noise, no
    velocities or accelerations: the default preprocessing (5 Hz zero-phase filter, central
    differences) recovers them well enough to name the hidden friction, and the held-out error
    falls below the raw torque noise (the filter removes part of it)."""
    log = _log(tmp_path / "encoder.csv", hidden=True, rate=500.0, encoder=2 * np.pi / 2 ** 20)
    doc = _discover(log, tmp_path / "out", capsys, cutoff="5")
    assert doc["effects"] == ["viscous_friction"], doc["notes"]
    assert max(doc["rms_after"]) < 1.5 * NOISE


def test_nothing_is_named_when_the_nominal_model_explains_the_data(tmp_path, capsys):
    doc = _discover(_log(tmp_path / "clean.csv", hidden=False), tmp_path / "out", capsys)
    assert doc["effects"] == [] and doc["steps"] == []
    assert max(doc["rms_before"]) < 1.5 * NOISE and doc["rms_after"] == doc["rms_before"]


@pytest.mark.parametrize("extra, message", [(["--candidates", "gremlins"], "unknown candidate(s) gremlins"),
                                            (["--holdout", "0"], "expected a fraction between 0 and 1")])
def test_bad_requests_are_one_line(tmp_path, capsys, extra, message):
    try:
        code = main(["discover", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", "x.csv",
                     "--out", str(tmp_path), *extra])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
