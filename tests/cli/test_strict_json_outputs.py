"""Every JSON file a command writes is strict JSON (RFC 8259): a strict parser, one that refuses
the NaN / Infinity tokens Python's json writes by default, reads all of them; non-finite numbers
that are legitimate results are written as the strings of :mod:`kindyngen.json_text`'s rule.
The runs are short: an identify, a discover and an excite of the command line, a generate and a
reproduce-identification, on a log of the Panda simulated with Pinocchio's rnea."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import ROOT
from kindyngen.cli.main import main
from kindyngen.measured.excitation import write_trajectory_json
from kindyngen.measured.identify import write_outputs
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

PANDA = str(ROOT / "robots" / "panda.yaml")
LWR4 = str(ROOT / "robots" / "lwr4.yaml")


def _refuse(token):
    raise ValueError(f"not JSON: {token}")


def strict_load(path):
    """The document of ``path`` by a strict parser (NaN, Infinity and -Infinity refused)."""
    return json.loads(path.read_text(), parse_constant=_refuse)


def _ok(argv, capsys):
    code = main(argv + ["--quiet"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """8 s of the Panda at 500 Hz inside its joint limits, with viscous friction and noise."""
    model = load_robot(PANDA)
    pm, pd, _ = pinocchio_model(model)
    rng = np.random.default_rng(5)
    lo, hi = model.lower, model.upper
    t = np.arange(4000) / 500.0
    freq = rng.uniform(0.15, 0.6, size=(7, 3))
    amp = rng.uniform(0.3, 1.0, size=(7, 3))
    amp *= (0.5 * (hi - lo) / 2 / amp.sum(axis=1))[:, None]
    arg = 2 * np.pi * freq[None] * t[:, None, None] + rng.uniform(0, 6.3, size=(7, 3))[None]
    w = 2 * np.pi * freq
    q = (lo + hi) / 2 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    tau = np.array([pin.rnea(pm, pd, a, b, c) for a, b, c in zip(q, qd, qdd)]) + 0.5 * qd
    tau += rng.normal(0, 0.02, q.shape)
    path = tmp_path_factory.mktemp("strict") / "run.csv"
    names = ["t"] + [f"q{i + 1}" for i in range(7)] + [f"tau{i + 1}" for i in range(7)]
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return str(path)


def _every_json(folder):
    files = sorted(folder.rglob("*.json"))
    assert files, f"no JSON written under {folder}"
    return {str(p.relative_to(folder)): strict_load(p) for p in files}


def test_every_written_json_file_is_strict(log, tmp_path, capsys):
    runs = {
        "identify": ["identify", "--robot", PANDA, "--data", log, "--split", "0.7", "--effects", "viscous_friction"],
        "discover": ["discover", "--robot", PANDA, "--data", log, "--candidates", "viscous_friction,torque_offset"],
        "excite": ["excite", "--robot", LWR4, "--harmonics", "2", "--iterations", "4", "--rate", "50"],
        "reproduce": ["reproduce-identification", "--robot", LWR4, "--train", "60", "--validate", "20"],
    }
    written = {}
    for name, argv in runs.items():
        _ok(argv + ["--out", str(tmp_path / name)], capsys)
        written[name] = _every_json(tmp_path / name)
    _ok(["generate", LWR4, "--functions", "fk_hom,g", "--lang", "python", "--out", str(tmp_path / "generate")], capsys)
    written["generate"] = _every_json(tmp_path / "generate")
    assert set(written["identify"]) == {"identification.json"}
    assert set(written["discover"]) == {"discovery.json"}
    assert set(written["excite"]) == {"excitation.json"}
    assert set(written["reproduce"]) == {"reproduction.json"}
    assert set(written["generate"]) == {"lwr4/functions.json", "lwr4/opcounts.json", "lwr4/base_params.json"}
    assert written["discover"]["discovery.json"]["effects"] == ["viscous_friction"]


def test_non_finite_results_are_written_by_the_rule(log, tmp_path, capsys):
    """An unbounded condition number (a rank-deficient regressor, a degenerate starting design)
    and an undetermined relative standard error are written as "Infinity", a NaN as "NaN": the
    files stay strict JSON, where json.dumps(..., allow_nan=False) raised ValueError (a traceback
    after the whole run) and the default json.dumps wrote tokens no strict parser reads."""
    from kindyngen.measured.identify import IdentificationRequest
    from kindyngen.measured.streaming import identify_streamed
    result = identify_streamed(IdentificationRequest(PANDA, (log,), split=0.7))
    std = np.array(result.base_std_percent, float)
    std[0], std[1] = math.inf, math.nan
    spoiled = dataclasses.replace(result, condition_number=math.inf, base_std_percent=std)
    doc = strict_load(write_outputs(spoiled, tmp_path / "id") / "identification.json")
    assert doc["condition_number"] == "Infinity"
    assert doc["base_params"]["std_percent"][:2] == ["Infinity", "NaN"]
    assert all(isinstance(v, float) for v in doc["base_params"]["std_percent"][2:])

    _ok(["excite", "--robot", LWR4, "--harmonics", "2", "--iterations", "4", "--rate", "50",
         "--out", str(tmp_path / "x")], capsys)
    from kindyngen.measured.excitation import optimise_excitation, default_limits
    model = load_robot(LWR4)
    excitation = optimise_excitation(model, default_limits(model), harmonics=2, max_iterations=2)
    write_trajectory_json(tmp_path / "x.json", dataclasses.replace(excitation, initial_condition_number=math.inf))
    assert strict_load(tmp_path / "x.json")["initial_condition_number"] == "Infinity"
