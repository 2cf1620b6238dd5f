"""`kindyngen identify` on a URDF (example-robot-data's Panda, chain to panda_link8, the hand
and locked fingers part of link 7): torques simulated by Pinocchio's own URDF parser, exact
recovery from noise-free data, and a model.yaml (joints by origin and axis, ``dh: none``)
that reloads and predicts Pinocchio's torques."""
from __future__ import annotations

import json

import numpy as np
import pytest
import symengine as se

pin = pytest.importorskip("pinocchio")
from kindyngen.codegen.catalog import derive_all  # noqa: E402
from kindyngen.cli.main import main  # noqa: E402
from kindyngen.readers.yaml_description import load_robot  # noqa: E402
from tests.robot_files import example_robot_data_or_skip  # noqa: E402

FV = np.array([0.6, 0.5, 0.4, 0.4, 0.2, 0.2, 0.1])


@pytest.fixture(scope="module")
def panda_urdf():
    return example_robot_data_or_skip() / "panda_description" / "urdf" / "panda.urdf"


def _pinocchio(path):
    full = pin.buildModelFromUrdf(str(path))
    arm = {f"panda_joint{i}" for i in range(1, 8)}
    lock = [i for i in range(1, full.njoints) if full.names[i] not in arm]
    model = pin.buildReducedModel(full, lock, pin.neutral(full))
    return model, model.createData()


def _motion(seed, lower, upper, seconds=6.0, rate=200.0):
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / rate)
    centre, half = (lower + upper) / 2, (upper - lower) / 2
    amp = rng.uniform(0.1, 0.25, size=(7, 3)) * half[:, None]
    w = 2 * np.pi * rng.uniform(0.1, 0.6, size=(7, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(7, 3))
    arg = w[None] * t[:, None, None] + phase[None]
    q = centre + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    return t, q, qd, qdd


def _log(path, t, q, qd, qdd, tau):
    header = ["t"] + [f"{k}{i}" for k in ("q", "qd", "qdd", "tau") for i in range(1, 8)]
    np.savetxt(path, np.column_stack([t, q, qd, qdd, tau]), delimiter=",", header=",".join(header),
               comments="", fmt="%.17g")
    return path


def test_identify_from_urdf_writes_a_reloadable_model(panda_urdf, tmp_path, capsys):
    model, data = _pinocchio(panda_urdf)
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    runs = []
    for seed in (1, 2):
        t, q, qd, qdd = _motion(seed, lower, upper)
        tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)]) + FV * qd
        runs.append((_log(tmp_path / f"run{seed}.csv", t, q, qd, qdd, tau), (q, qd, qdd, tau)))
    out = tmp_path / "id"
    code = main(["identify", "--robot", str(panda_urdf), "--tip", "panda_link8", "--data", str(runs[0][0]),
                 "--validate", str(runs[1][0]), "--effects", "viscous_friction", "--cutoff", "none",
                 "--out", str(out), "--quiet"])
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "identification.json").read_text())
    assert max(doc["rms_validation"]) < 1e-7
    effects = dict(zip(doc["effects"]["names"], doc["effects"]["values"]))
    np.testing.assert_allclose([effects[f"fv{i}"] for i in range(1, 8)], FV, atol=1e-7)
    # model.yaml: joints by origin and axis; reloaded, its tau reproduces Pinocchio's torques
    assert "dh: none" in (out / "model.yaml").read_text()
    reloaded = load_robot(out / "model.yaml")
    assert [j.name for j in reloaded.joints] == [f"panda_joint{i}" for i in range(1, 8)]
    f = derive_all(reloaded, only={"tau"})[0]
    fn = se.Lambdify([s for syms in f.input_symbols for s in syms], list(f.inlined_outputs()[0]), cse=True)
    q, qd, qdd, tau = runs[1][1]
    predicted = np.array([fn(np.concatenate([a, b, c])) for a, b, c in zip(q[::20], qd[::20], qdd[::20])])
    np.testing.assert_allclose(predicted, tau[::20], atol=1e-6)
