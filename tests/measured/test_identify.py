"""`kindyngen identify` end to end on logs simulated here (Pinocchio for the rigid bodies, the
effect formulas written out below; nothing shared with the identification code): exact
recovery from noise-free data, an identified robot description that reloads and predicts what
the identified model predicts, and one-line refusals of bad requests."""
from __future__ import annotations

import html
import json
import re

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import ROOT, robot
from kindyngen.cli.main import main
from kindyngen.measured.regressor_rows import TorqueRegressor
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

FV = np.array([0.8, 0.7, 0.5, 0.5, 0.3, 0.2, 0.1])
FC = np.array([1.2, 1.1, 0.9, 0.8, 0.5, 0.4, 0.3])
F0 = np.array([0.1, -0.2, 0.0, 0.05, 0.02, -0.01, 0.03])
EFFECTS = "viscous_friction,coulomb_friction,torque_offset"


def _motion(seed, seconds=8.0, rate=200.0):
    """Sums of sines within the LWR's limits: q, qd, qdd analytic."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / rate)
    n = 7
    amp = rng.uniform(0.2, 0.6, size=(n, 3))
    freq = rng.uniform(0.1, 0.6, size=(n, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(n, 3))
    arg = 2 * np.pi * freq[None] * t[:, None, None] + phase[None]
    w = 2 * np.pi * freq[None]
    q = np.sum(amp[None] * np.sin(arg), axis=2)
    qd = np.sum(amp[None] * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp[None] * w ** 2 * np.sin(arg), axis=2)
    return t, q, qd, qdd


def _torques(model_robot, q, qd, qdd, friction=True):
    model, data, _ = pinocchio_model(model_robot)
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    if friction:
        tau = tau + FV * qd + FC * np.sign(qd) + F0
    return tau


def _write_csv(path, t, q, qd, qdd, tau):
    n = q.shape[1]
    header = ["t"] + [f"q{i + 1}" for i in range(n)] + [f"qd{i + 1}" for i in range(n)] + \
             [f"qdd{i + 1}" for i in range(n)] + [f"tau{i + 1}" for i in range(n)]
    np.savetxt(path, np.column_stack([t, q, qd, qdd, tau]), delimiter=",", header=",".join(header), comments="",
               fmt="%.17g")
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    root = tmp_path_factory.mktemp("logs")
    lwr = robot("lwr4")
    paths = []
    for k, seed in enumerate((1, 2)):
        t, q, qd, qdd = _motion(seed)
        paths.append(_write_csv(root / f"run{k + 1}.csv", t, q, qd, qdd, _torques(lwr, q, qd, qdd)))
    return root, paths


def _run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:   # argparse's own refusals
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_noise_free_recovery_and_reloadable_model(logs, capsys):
    root, (train, validate) = logs
    out = root / "ols"
    code, stdout, err = _run(["identify", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(train),
                              "--validate", str(validate), "--effects", EFFECTS, "--cutoff", "none",
                              "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    doc = json.loads((out / "identification.json").read_text())
    lwr = robot("lwr4")
    truth = TorqueRegressor(lwr).base_map @ parameter_vector(lwr)
    np.testing.assert_allclose(doc["base_params"]["values"], truth, rtol=1e-8, atol=1e-8)
    effects = dict(zip(doc["effects"]["names"], doc["effects"]["values"]))
    for i in range(7):
        assert effects[f"fv{i + 1}"] == pytest.approx(FV[i], abs=1e-8)
        assert effects[f"fc{i + 1}"] == pytest.approx(FC[i], abs=1e-8)
        assert effects[f"f0{i + 1}"] == pytest.approx(F0[i], abs=1e-8)
    assert max(doc["rms_validation"]) < 1e-8 and max(doc["rms_train"]) < 1e-8
    assert doc["physically_consistent"] is True
    assert set(doc["base_params"]) == {"names", "values", "std_percent"}
    assert (out / "report.md").is_file() and (out / "validation_torques.png").stat().st_size > 10_000
    # the identified description reloads, and Pinocchio with it plus the friction formulas
    # predicts the validation torques as well as the identified model did
    model = load_robot(out / "model.yaml")
    assert model.effects == ("viscous_friction", "coulomb_friction", "torque_offset")
    t, q, qd, qdd = _motion(2)
    fv = np.array([float(model.friction(i).viscous) for i in range(7)])
    fc = np.array([float(model.friction(i).coulomb) for i in range(7)])
    f0 = np.array([float(model.friction(i).offset) for i in range(7)])
    pm, pd, _ = pinocchio_model(model)
    predicted = np.array([pin.rnea(pm, pd, a, b, c) for a, b, c in zip(q, qd, qdd)]) + fv * qd + fc * np.sign(qd) + f0
    np.testing.assert_allclose(predicted, _torques(lwr, q, qd, qdd), atol=1e-7)


def test_report_shows_the_descriptions_file_name_as_text(logs, capsys, tmp_path):
    """Issue 42: the description's file name is the user's text; report.md, rendered as MkDocs
    renders it, has no element but its own and its heading reads as the name."""
    markdown = pytest.importorskip("markdown")
    root, (train, validate) = logs
    robot_file = tmp_path / "lwr4 <script> *b* [l](u) _i_ `c` | #.yaml"       # no "/" in a file name
    robot_file.write_text((ROOT / "robots" / "lwr4.yaml").read_text())
    out = tmp_path / "out"
    code, _, err = _run(["identify", "--robot", str(robot_file), "--data", str(train), "--validate", str(validate),
                         "--cutoff", "none", "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    page = markdown.markdown((out / "report.md").read_text(), extensions=["tables"])
    assert set(re.findall(r"<(\w+)", page)) <= {"h1", "h2", "p", "table", "thead", "tbody", "tr", "th", "td", "img",
                                                "ul", "li"}
    assert re.search(r"<h1>(.*)</h1>", page).group(1) == html.escape(f"Identification of {robot_file.name}",
                                                                      quote=False)


def test_consistent_identification_on_noise_free_data(logs, capsys):
    root, (train, validate) = logs
    out = root / "sdp"
    code, stdout, err = _run(["identify", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(train),
                              "--validate", str(validate), "--effects", EFFECTS, "--cutoff", "none", "--consistent",
                              "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    doc = json.loads((out / "identification.json").read_text())
    assert doc["physically_consistent"] is True
    # the truth is physical, so the constrained optimum is the truth up to the solver's tolerance
    assert max(doc["rms_validation"]) < 1e-3
    model = load_robot(out / "model.yaml")
    assert all(float(model.friction(i).viscous) >= 0 and float(model.friction(i).coulomb) >= 0 for i in range(7))


def test_noisy_data_validation_error_is_the_noise_level(logs, capsys, tmp_path):
    """With torque noise of 0.05 N m the held-out RMS is that noise level, not less."""
    lwr = robot("lwr4")
    rng = np.random.default_rng(5)
    paths = []
    for seed in (1, 2):
        t, q, qd, qdd = _motion(seed)
        tau = _torques(lwr, q, qd, qdd) + rng.normal(scale=0.05, size=q.shape)
        paths.append(_write_csv(tmp_path / f"noisy{seed}.csv", t, q, qd, qdd, tau))
    code, stdout, err = _run(["identify", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(paths[0]),
                              "--validate", str(paths[1]), "--effects", EFFECTS, "--cutoff", "none",
                              "--out", str(tmp_path / "o"), "--quiet"], capsys)
    assert code == 0, err
    doc = json.loads((tmp_path / "o" / "identification.json").read_text())
    assert all(0.045 < v < 0.06 for v in doc["rms_validation"]), doc["rms_validation"]
    assert all(np.isfinite(doc["base_params"]["std_percent"][:5]))


@pytest.mark.parametrize("extra, message", [
    (["--effects", "viscous"], "unknown effect(s) viscous"),
    (["--split", "1.5"], "expected a fraction between 0 and 1"),
    (["--cutoff", "-3"], "expected a positive frequency"),
])
def test_bad_requests_are_one_line(logs, capsys, extra, message):
    root, (train, validate) = logs
    code, stdout, err = _run(["identify", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(train),
                              "--validate", str(validate), "--out", str(root / "x"), *extra], capsys)
    assert code == 2 and err.count("\n") == 1 and message in err, err


def test_identification_without_validation_is_refused(logs, capsys):
    root, (train, _) = logs
    code, _, err = _run(["identify", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(train),
                         "--out", str(root / "x")], capsys)
    assert code == 2 and "give validation data" in err


def test_bad_log_is_named(logs, capsys, tmp_path):
    root, (train, validate) = logs
    bad = tmp_path / "bad.csv"
    text = train.read_text().splitlines()
    fields = text[5].split(",")
    fields[3] = "nan"
    text[5] = ",".join(fields)
    bad.write_text("\n".join(text) + "\n")
    code, _, err = _run(["identify", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(bad),
                         "--validate", str(validate), "--out", str(tmp_path / "x"), "--quiet"], capsys)
    assert code == 2 and err.count("\n") == 1 and "bad.csv" in err and "q3" in err, err
