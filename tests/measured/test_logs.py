"""Motion logs (kindyngen.measured.log_preparing): reading CSV / npz, refusing bad data by name, and
preprocessing (repeated rows, gaps, resampling, zero-phase filtering, differentiation).

Expected values come from analytic trajectories, from the filter's physics, or from the
data files read independently with numpy here; never from the code under test."""
from __future__ import annotations

import doctest
from pathlib import Path

import numpy as np
import pytest

import kindyngen.measured.log_preparing as logs
from kindyngen.measured.log_reading import MIN_SAMPLES, LogError, RawLog, read_log, repeated_rows
from kindyngen.measured.log_preparing import (Preprocessing, Segment, concatenate_rows, load_segments,
                                              preprocess, split_time)

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"
PANDA = DATA / "panda_gaz2019" / "measured.csv"
LWR = [DATA / "lwr4_flobaroid" / f"measurements_{k}.npz" for k in (1, 2, 3)]

N_JOINTS = 3
# per joint: (amplitude rad, frequency Hz, phase rad); all far below the 5 Hz cutoff
SINES = [[(0.6, 0.25, 0.0), (0.2, 0.9, 1.0)],
         [(0.4, 0.40, 0.5), (0.1, 1.2, -0.3)],
         [(0.5, 0.15, 2.0), (0.15, 0.7, 0.2)]]
F_MAX = 1.2


def trajectory(t, offset=0.0):
    """Analytic q, qd, qdd and a smooth torque (linear in them, so it holds the same
    frequencies) at times t."""
    t = np.asarray(t, float)[:, None]
    q = np.zeros((t.shape[0], N_JOINTS)) + offset
    qd = np.zeros_like(q)
    qdd = np.zeros_like(q)
    for j, sines in enumerate(SINES):
        for a, f, phi in sines:
            w = 2 * np.pi * f
            q[:, j] += a * np.sin(w * t[:, 0] + phi)
            qd[:, j] += a * w * np.cos(w * t[:, 0] + phi)
            qdd[:, j] -= a * w ** 2 * np.sin(w * t[:, 0] + phi)
    tau = 3.0 * q + 0.5 * qd + 0.2 * qdd + np.array([1.0, -2.0, 0.5])
    return q, qd, qdd, tau


def jittered_times(rng, duration, step=1e-3, start=0.0):
    """Uneven stamps: every step drawn from U(0.6, 1.4) x step, as a real logger's wander."""
    steps = step * rng.uniform(0.6, 1.4, size=int(1.2 * duration / step))
    t = start + np.concatenate([[0.0], np.cumsum(steps)])
    return t[t <= start + duration]


def write_csv(path, t, q, tau, qd=None, qdd=None, names=None):
    columns = [t[:, None], q, tau] + [a for a in (qd, qdd) if a is not None]
    n = q.shape[1]
    if names is None:
        names = ["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"tau{j}" for j in range(1, n + 1)]
        if qd is not None:
            names += [f"qd{j}" for j in range(1, n + 1)]
        if qdd is not None:
            names += [f"qdd{j}" for j in range(1, n + 1)]
    np.savetxt(path, np.hstack(columns), delimiter=",", header=",".join(names), comments="",
               fmt="%.17g")
    return path


def synthetic_log(rng, duration=6.0, repeat_fraction=0.05, q_noise=2e-6, tau_noise=0.01):
    """Jittered stamps, noisy q and tau, and rows that re-send the previous row's values
    under their own new stamp (what the Panda logger does)."""
    t = jittered_times(rng, duration)
    q, _, _, tau = trajectory(t)
    q = q + rng.normal(0.0, q_noise, q.shape)
    tau = tau + rng.normal(0.0, tau_noise, tau.shape)
    chosen = np.sort(rng.choice(np.arange(1, len(t)), size=int(repeat_fraction * len(t)),
                                replace=False))
    for i in chosen:          # in increasing order, so a run copies the run's first row
        q[i] = q[i - 1]
        tau[i] = tau[i - 1]
    return t, q, tau, len(chosen)


# --------------------------------------------------------------------------- preprocessing

def test_uneven_log_with_repeats_recovers_analytic_derivatives(tmp_path):
    rng = np.random.default_rng(1)
    t, q, tau, repeats = synthetic_log(rng)
    path = write_csv(tmp_path / "run.csv", t, q, tau)
    raw = read_log(path, N_JOINTS)
    assert len(raw.t) == len(t) and raw.qd is None and raw.qdd is None
    assert int(repeated_rows(raw).sum()) == repeats
    (segment,) = preprocess(raw)

    assert any(f"dropped {repeats} repeated rows" in note for note in segment.notes)
    # the median of U(0.6, 1.4) ms steps is ~1 ms: the grid is 1 kHz, exactly uniform
    assert segment.dt == pytest.approx(1e-3, rel=1e-12)
    assert np.allclose(np.diff(segment.t), 1e-3, rtol=0, atol=1e-9)
    # trimmed 2 / cutoff = 0.4 s at each end of the data's span
    assert segment.t[0] == pytest.approx(t[0] + 0.4, abs=1.5e-3)
    assert segment.t[-1] == pytest.approx(t[-1] - 0.4, abs=1.5e-3)

    q_true, qd_true, qdd_true, tau_true = trajectory(segment.t)
    # Error budget.  In band (<= 1.2 Hz) the zero-phase 4th-order Butterworth passes
    # 1 / (1 + (1.2/5)^8) = 1 - 1.1e-5 of the amplitude; central differences at 1 ms lose
    # (2 pi 1.2 Hz 1 ms)^2 / 6 = 1e-5.  Noise: 2e-6 rad white at ~1 kHz keeps sqrt(5/500)
    # of its rms below 5 Hz, ~2e-7 rad, i.e. ~1e-4 rad/s^2 after two derivatives (without
    # the filter it would be ~5 rad/s^2); the torque noise 0.01 N m keeps ~1e-3 N m rms.
    # Away from the ends errors are therefore ~1e-5 .. 1e-4 of the amplitudes (bounds below:
    # 10x that); near the trim boundary the filter's edge transient adds up to ~0.5 % of
    # qdd (it decays ~3x per 0.1 s).  A 2 Hz cutoff, which bites into the 1.2 Hz sine
    # (gain 0.983), fails the interior bounds.
    interior = (segment.t > t[0] + 1.5) & (segment.t < t[-1] - 1.5)
    scale_qd = np.abs(qd_true).max(axis=0)
    scale_qdd = np.abs(qdd_true).max(axis=0)
    assert np.all(np.abs(segment.q - q_true)[interior].max(axis=0) < 2e-5)
    assert np.all(np.abs(segment.qd - qd_true)[interior].max(axis=0) < 2e-4 * scale_qd)
    assert np.all(np.abs(segment.qdd - qdd_true)[interior].max(axis=0) < 1e-3 * scale_qdd)
    assert np.all(np.abs(segment.tau - tau_true)[interior].max(axis=0) < 6e-3)   # 6 sigma
    # everywhere kept, including the trim boundary
    assert np.all(np.abs(segment.qd - qd_true).max(axis=0) < 2e-3 * scale_qd)
    assert np.all(np.abs(segment.qdd - qdd_true).max(axis=0) < 1e-2 * scale_qdd)


def test_without_filter_noise_is_not_removed(tmp_path):
    """The same log with cutoff_hz=None: twice-differentiated encoder noise dominates qdd,
    which shows that the previous test's tolerances depend on the filter."""
    rng = np.random.default_rng(1)
    t, q, tau, _ = synthetic_log(rng)
    raw = read_log(write_csv(tmp_path / "run.csv", t, q, tau), N_JOINTS)
    (segment,) = preprocess(raw, Preprocessing(cutoff_hz=None))
    _, _, qdd_true, _ = trajectory(segment.t)
    assert np.abs(segment.qdd - qdd_true).max() > 0.1 * np.abs(qdd_true).max()
    assert "no low-pass (cutoff_hz=None): interpolated values, not filtered" in segment.notes


def test_gap_splits_log_and_no_spike_at_seam(tmp_path):
    """A logger that stopped for 50 ms while the robot moved on: the second part starts
    0.3 rad further.  Interpolating or filtering across would put a huge spike into qd and
    qdd; split segments must each match their own trajectory up to their ends."""
    rng = np.random.default_rng(2)
    t1 = jittered_times(rng, 3.0)
    t2 = jittered_times(rng, 3.0, start=t1[-1] + 0.05)
    q1, _, _, tau1 = trajectory(t1)
    q2, _, _, tau2 = trajectory(t2, offset=0.3)
    path = write_csv(tmp_path / "gap.csv", np.r_[t1, t2], np.r_[q1, q2], np.r_[tau1, tau2])
    segments = load_segments(path, N_JOINTS)

    assert len(segments) == 2
    first, second = segments
    assert first.t[-1] <= t1[-1] - 0.4 + 1e-3
    assert second.t[0] >= t2[0] + 0.4 - 1e-3
    assert any("split at 1 gaps" in note for note in first.notes)
    for segment, offset in ((first, 0.0), (second, 0.3)):
        q_true, qd_true, qdd_true, _ = trajectory(segment.t, offset)
        assert np.abs(segment.q - q_true).max() < 1e-3
        assert np.abs(segment.qd - qd_true).max() < 5e-3 * np.abs(qd_true).max()
        assert np.abs(segment.qdd - qdd_true).max() < 2e-2 * np.abs(qdd_true).max()


def test_clock_with_jittered_stamps_passes_through_unchanged():
    """A 200 Hz clock whose stamps jitter by up to 0.3 of a step (reception times), with
    qd, qdd given and no filter: the values are the stored ones, on the clock's grid."""
    rng = np.random.default_rng(3)
    k = np.arange(1000)
    t_clock = 100.0 + 0.005 * k
    stamps = t_clock + rng.uniform(-0.3, 0.3, k.size) * 0.005
    q, qd, qdd, tau = trajectory(t_clock)
    raw = RawLog("clock", stamps, q, tau, qd, qdd)
    (segment,) = preprocess(raw, Preprocessing(cutoff_hz=None))
    for name, stored in (("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau)):
        assert np.array_equal(getattr(segment, name), stored), name
    assert segment.dt == pytest.approx(0.005, rel=1e-4)
    assert np.abs(segment.t - t_clock).max() < 0.3 * 0.005 * 1.2
    assert np.allclose(np.diff(segment.t), segment.dt, rtol=0, atol=1e-12)
    # with jitter_tolerance=0 the stamps are believed: interpolated, values change
    (interpolated,) = preprocess(raw, Preprocessing(cutoff_hz=None, jitter_tolerance=0))
    assert any(note.startswith("resampled") for note in interpolated.notes)


def test_equal_stamps_exact_repeat_is_dropped_different_values_refused(tmp_path):
    t = np.arange(100) * 0.01
    q, _, _, tau = trajectory(t)
    t[51] = t[50]
    q[51], tau[51] = q[50], tau[50]
    raw = RawLog("same-stamp", t, q, tau)
    assert np.flatnonzero(repeated_rows(raw)).tolist() == [51]
    (segment,) = preprocess(raw, Preprocessing(cutoff_hz=None))
    assert "dropped 1 repeated rows (1.00 % of 100)" in segment.notes
    tau[51, 2] += 1.0
    path = write_csv(tmp_path / "same.csv", t, q, tau)
    with pytest.raises(LogError) as info:
        read_log(path, N_JOINTS)
    assert info.value.field == "t"
    assert "data rows 51" in str(info.value) and "52 have the same time stamp" in str(info.value)


def test_short_piece_dropped_with_note_and_nothing_left_is_an_error():
    rng = np.random.default_rng(4)
    t_short = jittered_times(rng, 0.5)                       # too short for 2 x 0.4 s trim
    t_long = jittered_times(rng, 3.0, start=t_short[-1] + 0.1)
    t = np.r_[t_short, t_long]
    q, _, _, tau = trajectory(t)
    segments = preprocess(RawLog("short", t, q, tau))
    assert len(segments) == 1
    assert segments[0].t[0] > t_long[0]
    assert any(note.startswith("dropped the piece t = 0 .. ") for note in segments[0].notes)
    with pytest.raises(LogError) as info:
        preprocess(RawLog("short", t_short, *trajectory(t_short)[::3]))
    assert "nothing left" in str(info.value)


# --------------------------------------------------------------------------- bad input

def _good_csv(tmp_path, n=N_JOINTS, rows=200, name="good.csv", **optional):
    t = np.arange(rows) * 0.01
    q = np.tile(trajectory(t)[0], (1, 3))[:, :n]
    tau = 2.0 * q
    return tmp_path / name, t, q, tau


def _expect(path, field, *fragments, n=N_JOINTS):
    with pytest.raises(LogError) as info:
        read_log(path, n)
    message = str(info.value)
    assert info.value.field == field, message
    assert message.startswith(f"{path}: field '{field}': "), message
    for fragment in fragments:
        assert fragment in message, message
    assert "np.float64" not in message and "Traceback" not in message
    return message


def test_nan_names_column_and_first_bad_row(tmp_path):
    path, t, q, tau = _good_csv(tmp_path)
    q[16, 2] = np.nan          # data row 17, column q3
    q[40, 0] = np.inf          # a later bad value does not hide the first
    write_csv(path, t, q, tau)
    _expect(path, "q3", "not finite (nan)", "data row 17", "file line 18")


def test_too_few_samples(tmp_path):
    path, t, q, tau = _good_csv(tmp_path, rows=MIN_SAMPLES - 1)
    write_csv(path, t, q, tau)
    _expect(path, "t", f"only {MIN_SAMPLES - 1} samples", f"MIN_SAMPLES = {MIN_SAMPLES}")


def test_decreasing_time_names_row(tmp_path):
    path, t, q, tau = _good_csv(tmp_path)
    t[39] = t[37]              # data row 40 goes back in time
    write_csv(path, t, q, tau)
    _expect(path, "t", "time goes backwards at data row 40", "0.37 s after 0.38 s")


def test_unknown_column_suggests_closest(tmp_path):
    path, t, q, tau = _good_csv(tmp_path)
    names = ["t", "q1", "q2", "q3", "torque1", "tau2", "tau3"]
    write_csv(path, t, q, tau, names=names)
    _expect(path, "torque1", "unknown column", "did you mean 'tau1'?")


def test_missing_columns(tmp_path):
    path, t, q, tau = _good_csv(tmp_path)
    write_csv(path, t, q, tau, names=["time", "q1", "q2", "q3", "tau1", "tau2", "tau3"])
    _expect(path, "time", "unknown column", "did you mean 't'?")
    np.savetxt(path, np.hstack([q, tau]), delimiter=",", comments="",
               header="q1,q2,q3,tau1,tau2,tau3")
    _expect(path, "t", "missing column")
    np.savetxt(path, np.hstack([t[:, None], q[:, [0, 2]], tau]), delimiter=",", comments="",
               header="t,q1,q3,tau1,tau2,tau3")
    _expect(path, "q2", "missing column")
    np.savetxt(path, np.hstack([t[:, None], q]), delimiter=",", comments="", header="t,q1,q2,q3")
    _expect(path, "tau1", "missing column")


def test_wrong_joint_count(tmp_path):
    path, t, q, tau = _good_csv(tmp_path, n=6)
    write_csv(path, t, q, tau)
    _expect(path, "q7", "the file has 6 joints", "the robot has 7", n=7)
    path, t, q, tau = _good_csv(tmp_path, n=8)
    write_csv(path, t, q, tau)
    _expect(path, "q8", "the file has 8 joints", "the robot has 7", n=7)


def test_incomplete_optional_group(tmp_path):
    path, t, q, tau = _good_csv(tmp_path)
    qd = np.gradient(q, 0.01, axis=0)
    names = ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3", "qd1", "qd2"]
    np.savetxt(path, np.hstack([t[:, None], q, tau, qd[:, :2]]), delimiter=",", comments="",
               header=",".join(names))
    _expect(path, "qd3", "optional group qd is incomplete", "qd3 missing")


def test_column_order_is_free_and_optional_groups_read(tmp_path):
    path, t, q, tau = _good_csv(tmp_path)
    qd = np.gradient(q, 0.01, axis=0)
    qdd = np.gradient(qd, 0.01, axis=0)
    names = ["qdd3", "tau2", "q1", "qd1", "t", "q3", "tau1", "qdd1", "qd3", "q2", "tau3",
             "qdd2", "qd2"]
    data = {"t": t[:, None]}
    for prefix, a in (("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau)):
        for j in range(3):
            data[f"{prefix}{j + 1}"] = a[:, [j]]
    np.savetxt(path, np.hstack([data[k] for k in names]), delimiter=",", comments="",
               header=",".join(names), fmt="%.17g")
    raw = read_log(path, 3)
    for name, expected in (("t", t), ("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau)):
        assert np.array_equal(getattr(raw, name), expected), name


def test_bad_cells_and_files(tmp_path):
    path, t, q, tau = _good_csv(tmp_path)
    write_csv(path, t, q, tau)
    lines = path.read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[4], "abc", 1)    # data row 5, column tau1
    path.write_text("\n".join(lines) + "\n")
    _expect(path, "tau1", "cannot read 'abc' as a number at data row 5")
    lines = path.read_text().splitlines()
    lines[5] = "0.05,1,2"
    path.write_text("\n".join(lines) + "\n")
    _expect(path, "<file>", "data row 5 (file line 6) has 3 values, the header has 7")
    path.write_text("0,1,2,3,4,5,6\n" * 60)
    _expect(path, "<file>", "a header row is required")
    _expect(tmp_path / "absent.csv", "<file>", "cannot read")
    (tmp_path / "run.txt").write_text("t,q1\n")
    _expect(tmp_path / "run.txt", "<file>", "unknown extension '.txt'")
    (tmp_path / "broken.npz").write_bytes(b"not a zip archive")
    _expect(tmp_path / "broken.npz", "<file>", "cannot read as an .npz archive")


# --------------------------------------------------------------------------- npz

def _npz_arrays(n=N_JOINTS, rows=300):
    t = 1.46e9 + np.arange(rows) * 0.005        # Unix stamps, as the LWR logs have
    q, qd, qdd, tau = trajectory(t - t[0])
    return {"times": t, "positions": q[:, :n], "velocities": qd[:, :n],
            "accelerations": qdd[:, :n], "torques": tau[:, :n]}


def test_npz_round_trip(tmp_path):
    arrays = _npz_arrays()
    path = tmp_path / "run.npz"
    np.savez(path, **arrays, target_positions=arrays["positions"] + 0.1)
    raw = read_log(path, N_JOINTS)
    for name, key in (("t", "times"), ("q", "positions"), ("qd", "velocities"),
                      ("qdd", "accelerations"), ("tau", "torques")):
        assert np.array_equal(getattr(raw, name), arrays[key]), name
    assert raw.notes == ("ignored target_positions (commanded, not measured)",)
    (segment,) = preprocess(raw, Preprocessing(cutoff_hz=None))
    assert np.array_equal(segment.qdd, arrays["accelerations"])
    # exactly uniform stamps stay as they are, up to rounding of Unix times (2.4e-7 s)
    assert np.abs(segment.t - raw.t).max() < 1e-6
    assert not any("clock" in note for note in segment.notes)
    with pytest.raises(ValueError):
        segment.q[0, 0] = 1.0                   # frozen means frozen
    # the default preprocessing filters what is given and keeps it close (all below 5 Hz)
    (filtered,) = load_segments(path, N_JOINTS)
    inside = np.searchsorted(raw.t, filtered.t[0])
    stored = arrays["accelerations"][inside:inside + len(filtered.t)]
    assert np.abs(filtered.qdd - stored).max() < 2e-2 * np.abs(stored).max()


def test_npz_bad_inputs(tmp_path):
    path = tmp_path / "bad.npz"
    arrays = _npz_arrays()
    np.savez(path, **{("torque" if k == "torques" else k): v for k, v in arrays.items()})
    _expect(path, "torque", "unknown key", "did you mean 'torques'?")
    np.savez(path, **{k: v for k, v in arrays.items() if k != "positions"})
    _expect(path, "positions", "missing key")
    np.savez(path, **_npz_arrays(n=2))
    _expect(path, "positions", "the file has 2 joints", "the robot has 3")
    bad = dict(arrays, torques=arrays["torques"].copy())
    bad["torques"][16, 1] = np.nan
    np.savez(path, **bad)
    _expect(path, "torques", "not finite (nan) at sample 17 (joint 2)")
    np.savez(path, **dict(arrays, times=arrays["times"][:-1]))
    _expect(path, "positions", "expected shape (N, 3) with N = 299")
    np.savez(path, **dict(arrays, positions=arrays["positions"].astype(complex)))
    _expect(path, "positions", "expected real numbers")


# --------------------------------------------------------------------------- using segments

def _two_segments():
    t1 = np.arange(0.0, 2.0, 0.01)
    t2 = np.arange(3.0, 6.0, 0.01)
    parts = []
    for t in (t1, t2):
        q, qd, qdd, tau = trajectory(t)
        parts.append(Segment("demo", t, 0.01, q, qd, qdd, tau, ("made by hand",)))
    return tuple(parts)


@pytest.mark.parametrize("fraction", [0.2, 0.5, 0.7])
def test_split_time_loses_and_duplicates_nothing(fraction):
    segments = _two_segments()
    start, end = 0.0, segments[-1].t[-1]
    cut = start + fraction * (end - start)
    train, valid = split_time(segments, fraction)
    all_t = np.concatenate([s.t for s in segments])
    assert np.array_equal(np.concatenate([s.t for s in train + valid]), all_t)
    for name in ("q", "qd", "qdd", "tau"):
        joined = np.concatenate([getattr(s, name) for s in train + valid])
        assert np.array_equal(joined, np.concatenate([getattr(s, name) for s in segments]))
    assert all(s.t[-1] < cut for s in train) and all(s.t[0] >= cut for s in valid)
    assert sum(len(s.t) for s in train) == int(np.sum(all_t < cut))
    # the segment straddling the cut is cut, both parts say where; the others are untouched
    straddling = [s for s in segments if s.t[0] < cut <= s.t[-1]]
    cut_parts = [s for s in train + valid if len(s.notes) == 2]
    assert len(cut_parts) == 2 * len(straddling)
    for part in cut_parts:
        assert part.notes[0] == "made by hand"
        assert part.notes[1].startswith(f"cut at t = {cut:g} s")


def test_split_time_proportion_on_one_uniform_segment():
    t = np.arange(0.0, 10.0, 0.001)
    q, qd, qdd, tau = trajectory(t)
    train, valid = split_time([Segment("one", t, 0.001, q, qd, qdd, tau)], 0.75)
    assert len(train) == len(valid) == 1
    assert len(train[0].t) / len(t) == pytest.approx(0.75, abs=1e-3)
    assert train[0].duration == pytest.approx(0.75 * 10.0, abs=2e-3)
    with pytest.raises(ValueError):
        split_time(train, 1.0)


def test_concatenate_rows_stacks_in_order():
    segments = _two_segments()
    q, qd, qdd, tau = concatenate_rows(segments)
    assert q.shape == (len(segments[0].t) + len(segments[1].t), N_JOINTS)
    for name, stacked in (("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau)):
        assert np.array_equal(stacked, np.vstack([getattr(s, name) for s in segments]))


def test_settings_are_checked_and_trim_default_stated():
    assert Preprocessing().effective_trim_s == pytest.approx(2 / 5.0)
    assert Preprocessing(cutoff_hz=None).effective_trim_s == 0.0
    assert Preprocessing(trim_s=1.0).effective_trim_s == 1.0
    for bad in ({"cutoff_hz": -1.0}, {"order": 0}, {"gap_factor": 1.0}, {"trim_s": -0.1},
                {"rate_hz": 0.0}, {"jitter_tolerance": 1.0}):
        with pytest.raises(ValueError):
            Preprocessing(**bad)
    t = np.arange(200) * 0.01           # 100 Hz: a 60 Hz cutoff is above Nyquist
    with pytest.raises(LogError, match="not below the Nyquist frequency 50 Hz"):
        preprocess(RawLog("fast", t, *trajectory(t)[::3]), Preprocessing(cutoff_hz=60.0))


def test_docstring_examples():
    result = doctest.testmod(logs, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 10 and result.failed == 0


# --------------------------------------------------------------------------- real logs

@pytest.mark.skipif(not PANDA.exists(), reason=f"real Panda log not present at {PANDA}")
def test_panda_log():
    table = np.loadtxt(PANDA, delimiter=",", skiprows=1)
    # repeated rows counted here, independently: every value but the stamp as the row before
    repeats = int(np.sum(np.all(table[1:, 1:] == table[:-1, 1:], axis=1)))
    raw = read_log(PANDA, 7)
    assert len(raw.t) == table.shape[0] == 20544
    assert raw.qd is not None and raw.qdd is None
    assert np.array_equal(raw.tau, table[:, 15:22])
    assert int(repeated_rows(raw).sum()) == repeats
    assert 0.05 < repeats / len(raw.t) < 0.06

    # the stamps as logged jump by ~8.5 ms four times (at ~5, 10, 15, 20 s): more than
    # 5 x the 1 ms median step, so the default splits the log there
    segments = preprocess(raw)
    assert len(segments) == 5
    starts = [s.t[0] for s in segments]
    assert np.allclose(starts[1:], [4.974 + 0.4, 9.974 + 0.4, 14.974 + 0.4, 19.974 + 0.4],
                       atol=2e-3)
    percent = f"{100 * repeats / len(raw.t):.2f} %"
    for segment in segments:
        assert segment.dt == pytest.approx(1e-3, rel=1e-12)
        assert f"dropped {repeats} repeated rows ({percent} of 20544)" in segment.notes
        assert any(" at 1000 Hz " in note for note in segment.notes)

    # bridging those 8.5 ms dropouts instead: one segment, the full 0 .. 20.999 s at 1 kHz
    (whole,) = preprocess(raw, Preprocessing(gap_factor=10))
    assert f"resampled {len(raw.t) - repeats} -> 21000 samples at 1000 Hz (cubic spline for q, " \
           "linear for tau, qd)" in whole.notes
    assert len(whole.t) == 21000 - 2 * 400
    # physical consistency: the logged velocity, filtered, is the derivative of the filtered
    # position (a time shift between channels would break this)
    derivative = np.gradient(whole.q, whole.dt, axis=0)
    rms = lambda a: np.sqrt(np.mean(a ** 2, axis=0))   # noqa: E731
    assert np.all(rms(derivative - whole.qd) < 0.03 * rms(whole.qd))


@pytest.mark.skipif(not all(p.exists() for p in LWR), reason=f"real LWR4+ logs not present in {DATA}")
@pytest.mark.parametrize("path", LWR, ids=lambda p: p.name)
def test_lwr_logs_as_stored(path):
    with np.load(path) as archive:
        stored = {key: archive[key] for key in archive.files}
    raw = read_log(path, 7)
    assert raw.q.shape == (5027, 7) and raw.n == 7
    assert any("ignored" in note and "target_positions" in note for note in raw.notes)
    (segment,) = preprocess(raw, Preprocessing(cutoff_hz=None))
    for name, key in (("q", "positions"), ("qd", "velocities"), ("qdd", "accelerations"),
                      ("tau", "torques")):
        assert np.array_equal(getattr(segment, name), stored[key]), name
    # the stamps jitter around a 200 Hz clock (steps 3.2 .. 6.8 ms): kept on the clock
    assert segment.dt == pytest.approx(0.005, rel=1e-4)
    assert np.abs(segment.t - stored["times"]).max() < 2e-3
    assert any("uniform 200 Hz clock" in note for note in segment.notes)
    assert "no low-pass (cutoff_hz=None): values as stored" in segment.notes
