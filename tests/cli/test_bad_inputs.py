"""Every bad input issue 25 lists is refused with one ``error:`` line and exit code 2, never a
traceback, and a reused ``--out`` never mixes two runs (logs simulated with Pinocchio's rnea)."""
from __future__ import annotations

import json
import math

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import ROOT
from kindyngen.cli.main import main
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

PANDA = str(ROOT / "robots" / "panda.yaml")


def _run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:   # argparse's own refusals
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _refused(argv, capsys, *phrases):
    code, out, err = _run(argv, capsys)
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert code == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    for phrase in phrases:
        assert phrase in lines[0], lines[0]
    return lines[0]


def _write(path, t, q, tau):
    names = ["t"] + [f"q{i + 1}" for i in range(7)] + [f"tau{i + 1}" for i in range(7)]
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return str(path)


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """8 s of the Panda at 500 Hz inside its joint limits, and the same angles in degrees."""
    root = tmp_path_factory.mktemp("bad")
    model = load_robot(PANDA)
    pm, pd, _ = pinocchio_model(model)
    rng = np.random.default_rng(4)
    lo = np.array([j.lower for j in model.joints])
    hi = np.array([j.upper for j in model.joints])
    t = np.arange(4000) / 500.0
    freq = rng.uniform(0.15, 0.6, size=(7, 3))
    amp = rng.uniform(0.3, 1.0, size=(7, 3))
    amp *= (0.5 * (hi - lo) / 2 / amp.sum(axis=1))[:, None]
    arg = 2 * np.pi * freq[None] * t[:, None, None] + rng.uniform(0, 6.3, size=(7, 3))[None]
    w = 2 * np.pi * freq
    q = (lo + hi) / 2 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    tau = np.array([pin.rnea(pm, pd, a, b, c) for a, b, c in zip(q, qd, qdd)]) + rng.normal(0, 0.02, q.shape)
    return root, _write(root / "run.csv", t, q, tau), _write(root / "degrees.csv", t, np.degrees(q), tau)


def test_angles_in_degrees_are_refused_with_the_hint(log, capsys, tmp_path):
    root, _, degrees = log
    _refused(["identify", "--robot", PANDA, "--data", degrees, "--split", "0.7", "--out", str(tmp_path / "o")],
             capsys, "far outside the joint limits", "look like degrees", "radians")
    assert not (tmp_path / "o").exists()


def test_too_few_samples_per_column_is_refused_unless_overridden(log, capsys, tmp_path):
    root, run, _ = log
    out = tmp_path / "o"
    # unfiltered (--cutoff none), so that no decimation thins the few rows further: the override
    # then fits all of them (decimated by the low-pass's 5, they are rank-deficient and refused as such)
    short = ["identify", "--robot", PANDA, "--data", run, "--split", "0.03", "--cutoff", "none", "--out", str(out)]
    _refused(short, capsys, "per column", "below the minimum of 10", "--accept-poor-fit")
    code, _, err = _run(short + ["--accept-poor-fit", "--quiet"], capsys)
    assert code == 0, err
    notes = json.loads((out / "identification.json").read_text())["notes"]
    assert any(note.startswith("OVERRIDDEN REFUSAL (--accept-poor-fit)") for note in notes)
    assert "OVERRIDDEN REFUSAL" in (out / "report.md").read_text()


def test_condition_number_above_the_limit_is_refused(log, capsys, tmp_path):
    root, run, _ = log
    _refused(["identify", "--robot", PANDA, "--data", run, "--split", "0.7", "--max-condition", "10",
              "--out", str(tmp_path / "o")], capsys, "condition number", "above the limit 10")


@pytest.mark.parametrize("data, extra, phrases", [
    ("degrees", ["--split", "0.7"], ("far outside the joint limits", "look like degrees")),
    ("run", ["--split", "0.03", "--cutoff", "none"], ("per column", "below the minimum of 10")),
    ("run", ["--split", "0.7", "--max-condition", "10"], ("condition number", "above the limit 10"))],
    ids=["degrees", "few-samples", "condition"])
def test_effects_on_the_measurement_are_refused_the_same(log, capsys, tmp_path, data, extra, phrases):
    """Effects on the measurement (here motor-side elasticity) are fitted in memory, not
    streamed: the same data are refused there, with the same reasons."""
    root, run, degrees = log
    path = {"run": run, "degrees": degrees}[data]
    _refused(["identify", "--robot", PANDA, "--data", path, *extra, "--effects", "motor_side_elasticity",
              "--out", str(tmp_path / "o")], capsys, *phrases)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option, value, phrase", [("--holdout", "0.99", "at most 0.8 may be held out"),
                                                   ("--folds", "1", "at least 2 blocks"),
                                                   ("--folds", "500", "at most 50 cross-validation blocks")])
def test_discover_refuses_impossible_splits(log, capsys, tmp_path, option, value, phrase):
    root, run, _ = log
    _refused(["discover", "--robot", PANDA, "--data", run, option, value, "--out", str(tmp_path / "o")],
             capsys, phrase)


@pytest.mark.parametrize("command", ["identify", "discover", "excite"])
def test_binary_robot_description_is_refused(log, capsys, tmp_path, command):
    root, run, _ = log
    binary = tmp_path / "robot.yaml"
    binary.write_bytes(bytes(range(256)) * 8)
    argv = {"identify": ["identify", "--robot", str(binary), "--data", run, "--split", "0.5"],
            "discover": ["discover", "--robot", str(binary), "--data", run],
            "excite": ["excite", "--robot", str(binary)]}[command]
    _refused(argv + ["--out", str(tmp_path / "o")], capsys, str(binary), "not a text file")


def test_nul_byte_csv_and_text_npz_are_named(log, capsys, tmp_path):
    nul = tmp_path / "nul.csv"
    nul.write_bytes(b"t,q1\0" + b"\0" * 5000 + b"\n1,2\n")
    line = _refused(["identify", "--robot", PANDA, "--data", str(nul), "--split", "0.5", "--out", str(tmp_path / "o")],
                    capsys, "NUL bytes", "not CSV text")
    assert len(line) < 300
    fake = tmp_path / "fake.npz"
    fake.write_text("t,q1\n0,0\n")
    line = _refused(["identify", "--robot", PANDA, "--data", str(fake), "--split", "0.5", "--out", str(tmp_path / "o")],
                    capsys, "cannot read as an .npz archive: no zip signature")
    assert "pickle" not in line


def test_excite_refuses_infeasible_settings(capsys, tmp_path):
    _refused(["excite", "--robot", PANDA, "--rate", "0.05", "--out", str(tmp_path / "o")], capsys,
             "--rate 0.05 Hz", "row(s)", "at least 50")
    _refused(["excite", "--robot", PANDA, "--velocity", "1e-6", "--iterations", "2", "--harmonics", "2",
              "--out", str(tmp_path / "o")], capsys, "condition number", "raise them")
    assert not (tmp_path / "o").exists()


def test_reused_out_never_mixes_runs(log, capsys, tmp_path):
    root, run, degrees = log
    out = tmp_path / "o"
    out.mkdir()
    (out / "model.yaml").write_text("# an earlier run's model\n")     # this run writes none (not physical)
    (out / "notes.txt").write_text("the user's own file\n")
    code, _, err = _run(["identify", "--robot", PANDA, "--data", run, "--split", "0.7", "--out", str(out), "--quiet"],
                        capsys)
    assert code == 0, err
    doc = json.loads((out / "identification.json").read_text())
    assert not doc["physically_consistent"] and not (out / "model.yaml").exists()
    assert (out / "notes.txt").exists()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    _refused(["identify", "--robot", PANDA, "--data", degrees, "--split", "0.7", "--out", str(out)], capsys, "degrees")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before       # a failed run leaves them whole
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".partial")]
    assert math.isfinite(doc["condition_number"])


PLANAR = """name: planar
dh: standard
gravity: [0, 0, -9.81]
joints:
  - {a: 0.5, alpha: 0, d: 0, offset: 0, lower: -3, upper: 3}
  - {a: 0.4, alpha: 0, d: 0, offset: 0, lower: -3, upper: 3}
links:
  - {mass: 2.0, com: [0.2, 0, 0], inertia: [0.02, 0.02, 0.02, 0, 0, 0]}
  - {mass: MASS, com: [0.2, 0, 0], inertia: [INERTIA, INERTIA, INERTIA, 0, 0, 0]}
"""


def test_float_build_of_a_planar_arm_and_a_constant_float_cannot_hold(capsys, tmp_path):
    """A planar arm (gravity along its joint axes: g is zero, Y_g has no column) builds in float; a
    description whose derived constants fall below float's normal range is refused with the
    reason, not a traceback (both were tracebacks: an empty port in the float-error measurement,
    and float32.c_float's ValueError)."""
    ok = tmp_path / "planar.yaml"
    ok.write_text(PLANAR.replace("MASS", "1.0").replace("INERTIA", "0.01"))
    code, _, err = _run(["generate", str(ok), "--scalar", "float", "--functions", "g,Y_g,M", "--out",
                         str(tmp_path / "o"), "--quiet"], capsys)
    assert code == 0, err
    tiny = tmp_path / "tiny.yaml"
    tiny.write_text(PLANAR.replace("MASS", "1e-41").replace("INERTIA", "1e-43"))
    _refused(["generate", str(tiny), "--scalar", "float", "--functions", "M", "--out", str(tmp_path / "t"),
              "--quiet"], capsys, "tiny.yaml", "--scalar float", "below float's normal range", "--scalar double")
    assert not (tmp_path / "t" / "planar").exists()
