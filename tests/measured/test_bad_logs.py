"""A log is checked against the robot it claims to record, in one place
(:mod:`kindyngen.measured.log_checks`), by every command that reads logs: ``identify`` (streamed
and in memory) and ``discover`` refuse the same bad logs with one ``error:`` line naming the file,
the column and the reason, exit code 2, and no output folder.  Logs are the Panda simulated with
Pinocchio's rnea inside its joint limits, then spoiled one way each."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import ROOT
from kindyngen.cli.main import main
from kindyngen.measured.identify import IdentificationRequest, identify
from kindyngen.measured.log_checks import JointRange, LogBounds, check_samples
from kindyngen.measured.log_formats import write_parquet
from kindyngen.measured.log_reading import LogError, RawLog
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

PANDA = str(ROOT / "robots" / "panda.yaml")
RATE = 500.0


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


def _write(path, t, q, tau, qd=None, qdd=None):
    n = q.shape[1]
    groups = [("q", q)] + [(name, a) for name, a in (("qd", qd), ("qdd", qdd)) if a is not None] + [("tau", tau)]
    names = ["t"] + [f"{name}{i + 1}" for name, a in groups for i in range(n)]
    np.savetxt(path, np.column_stack([t] + [a for _, a in groups]), delimiter=",", header=",".join(names),
               comments="", fmt="%.17g")
    return str(path)


@pytest.fixture(scope="module")
def motion():
    """8 s of the Panda at 500 Hz inside its joint limits: t, q, qd, qdd, tau (rnea plus noise)."""
    model = load_robot(PANDA)
    pm, pd, _ = pinocchio_model(model)
    rng = np.random.default_rng(11)
    lo = np.array([j.lower for j in model.joints])
    hi = np.array([j.upper for j in model.joints])
    t = np.arange(4000) / RATE
    freq = rng.uniform(0.15, 0.6, size=(7, 3))
    amp = rng.uniform(0.3, 1.0, size=(7, 3))
    amp *= (0.5 * (hi - lo) / 2 / amp.sum(axis=1))[:, None]
    arg = 2 * np.pi * freq[None] * t[:, None, None] + rng.uniform(0, 6.3, size=(7, 3))[None]
    w = 2 * np.pi * freq
    q = (lo + hi) / 2 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    tau = np.array([pin.rnea(pm, pd, a, b, c) for a, b, c in zip(q, qd, qdd)]) + rng.normal(0, 0.02, q.shape)
    return t, q, qd, qdd, tau


def _spoiled(motion, folder, how):
    """A CSV log of ``motion`` spoiled one way (``how``); returns (path, phrases of the refusal)."""
    t, q, qd, qdd, tau = (a.copy() for a in motion)
    path = folder / f"{how}.csv"
    if how == "degrees":
        return _write(path, t, np.degrees(q), tau), ("field 'q", "far outside the joint limits",
                                                     "look like degrees", "radians")
    if how == "huge_torque":
        tau[1234, 2] = 1e300
        return _write(path, t, q, tau), ("field 'tau3'", "1e+300", "data row 1235", "N m", "bound")
    if how == "huge_torque_column":
        tau[:, 5] *= 1e7
        return _write(path, t, q, tau), ("field 'tau6'", "N m", "bound")
    if how == "nan_torque":
        tau[700, 4] = np.nan
        return _write(path, t, q, tau), ("field 'tau5'", "not finite", "701")
    if how == "inf_position":
        q[900, 1] = np.inf
        return _write(path, t, q, tau), ("field 'q2'", "not finite", "901")
    if how == "time_backwards":
        t[2000] = t[1990]
        return _write(path, t, q, tau), ("field 't'", "time goes backwards", "2001")
    if how == "time_repeated":
        t[2001] = t[2000]          # a new sample under the previous one's stamp
        return _write(path, t, q, tau), ("field 't'", "same time stamp")
    if how == "six_joints":
        return _write(path, t, q[:, :6], tau[:, :6]), ("the file has 6 joints", "the robot has 7")
    if how == "huge_velocity":
        qd[3000, 6] = 5e3
        return _write(path, t, q, tau, qd=qd), ("field 'qd7'", "rad/s", "bound")
    if how == "huge_acceleration":
        qdd[100, 0] = -1e7
        return _write(path, t, q, tau, qd=qd, qdd=qdd), ("field 'qdd1'", "rad/s^2", "bound")
    if how == "milliseconds":
        return _write(path, 1000 * t, q, tau), ("field 't'", "milliseconds", "seconds")
    raise ValueError(how)


SPOILED = ("degrees", "huge_torque", "huge_torque_column", "nan_torque", "inf_position", "time_backwards",
           "time_repeated", "six_joints", "huge_velocity", "huge_acceleration", "milliseconds")

#: the command lines that read a log, each with the options that run it (the in-memory
#: identification is the one with an effect on the measurement)
COMMANDS = {
    "identify": ["identify", "--robot", PANDA, "--split", "0.7"],
    "identify-in-memory": ["identify", "--robot", PANDA, "--split", "0.7", "--effects", "torque_sensor_gain"],
    "discover": ["discover", "--robot", PANDA],
}


@pytest.mark.parametrize("how", SPOILED)
@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_command_refuses_a_bad_log_the_same(motion, tmp_path, capsys, command, how):
    path, phrases = _spoiled(motion, tmp_path, how)
    # milliseconds: without the low-pass, whose Nyquist check would refuse them for another reason
    extra = ["--cutoff", "none"] if how == "milliseconds" else []
    line = _refused(COMMANDS[command] + ["--data", path, "--out", str(tmp_path / "o")] + extra, capsys,
                    path, *phrases)
    assert len(line) < 400, line
    assert not (tmp_path / "o").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("o") and p.name != how + ".csv"]


@pytest.mark.parametrize("command", ["identify", "discover"])
def test_a_refused_log_leaves_the_earlier_results_whole(motion, tmp_path, capsys, command):
    path, phrases = _spoiled(motion, tmp_path, "huge_torque")
    out = tmp_path / "o"
    out.mkdir()
    (out / "report.md").write_text("an earlier run's report\n")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    _refused(COMMANDS[command] + ["--data", path, "--out", str(out)], capsys, *phrases)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.parametrize("command", ["identify", "discover"])
def test_parquet_is_checked_as_it_streams(motion, tmp_path, capsys, command):
    """Parquet goes through the chunked reader (not the CSV reader): checked the same, the row
    counted over the whole log."""
    t, q, qd, qdd, tau = motion
    spoiled = tau.copy()
    spoiled[3210, 0] = -2e6
    path = tmp_path / "run.parquet"
    write_parquet(path, RawLog("run", t, q, spoiled))
    _refused(COMMANDS[command] + ["--data", str(path), "--out", str(tmp_path / "o")], capsys,
             str(path), "field 'tau1'", "-2e+06", "3211", "bound")
    path = tmp_path / "degrees.parquet"
    write_parquet(path, RawLog("run", t, np.degrees(q), tau))
    _refused(COMMANDS[command] + ["--data", str(path), "--out", str(tmp_path / "o")], capsys,
             str(path), "look like degrees")
    assert not (tmp_path / "o").exists()


def test_the_library_identify_refuses_too(motion, tmp_path):
    """``identify()`` called from Python (not only the command line) checks the log against the robot."""
    path, _ = _spoiled(motion, tmp_path, "degrees")
    with pytest.raises(LogError, match="look like degrees"):
        identify(IdentificationRequest(PANDA, (path,), split=0.7))


# -- the checks themselves, on bounds written here ---------------------------------------------

def _samples(m=200, rate=100.0):
    return np.arange(m) / rate, np.zeros((m, 2)), np.zeros((m, 2))


def test_prismatic_positions_in_millimetres_are_named():
    bounds = LogBounds((JointRange("revolute", -2.0, 2.0), JointRange("prismatic", 0.0, 0.3)))
    t, q, tau = _samples()
    q[:, 1] = 0.25
    check_samples("run.csv", bounds, t, q, tau)                   # 0.25 m: inside
    q[:, 1] = 0.345                                              # 0.045 m beyond: within the 0.05 m margin
    check_samples("run.csv", bounds, t, q, tau)
    q[:, 1] = 250.0
    with pytest.raises(LogError, match=r"field 'q2': 250 m at row 1 .* \[0, 0.3\] m .*look like millimetres"):
        check_samples("run.csv", bounds, t, q, tau)
    q[:, 1] = 0.2
    tau[7, 1] = 3e6
    with pytest.raises(LogError, match=r"field 'tau2': 3e\+06 N at row 8 .*\|tau\| <= 1e\+06 N,"):
        check_samples("run.csv", bounds, t, q, tau)


def test_a_joint_without_limits_is_bounded_too():
    bounds = LogBounds((JointRange("revolute", -np.inf, np.inf),))
    t, q, tau = _samples()
    q = 5000.0 * t[:, None]                                       # many turns, unwrapped: fine
    check_samples("run.csv", bounds, t, q, tau[:, :1])
    q[50, 0] = -1e300
    with pytest.raises(LogError, match=r"field 'q1': -1e\+300 rad at data row 51 .*bound \|q\| <= 1e\+06 rad "
                                       r"of a joint without limits"):
        check_samples("run.csv", bounds, t, q, tau[:, :1], row="data row")


@pytest.mark.parametrize("scale, unit", [(1e3, "milliseconds: multiply by 0.001"),
                                         (1e6, "microseconds: multiply by 1e-6"),
                                         (1e9, "nanoseconds: multiply by 1e-9")])
def test_time_stamps_in_other_units_are_named(scale, unit):
    bounds = LogBounds((JointRange("revolute", -2.0, 2.0),) * 2)
    t, q, tau = _samples(rate=1000.0)
    check_samples("run.csv", bounds, t, q, tau)
    with pytest.raises(LogError, match=f"field 't': the median time step .*must be in seconds .*{unit}"):
        check_samples("run.csv", bounds, scale * t, q, tau)


def test_the_first_row_counts_over_the_whole_log():
    bounds = LogBounds((JointRange("revolute", -2.0, 2.0),) * 2)
    t, q, tau = _samples()
    qd = np.zeros_like(q)
    qd[3, 0] = 2e3
    with pytest.raises(LogError, match=r"field 'qd1': 2000 rad/s at sample 20004 \(t = 0.03 s\)"):
        check_samples("bag", bounds, t, q, tau, qd=qd, first_row=20000, row="sample")
