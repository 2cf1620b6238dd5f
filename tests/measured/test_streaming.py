"""Identification in bounded memory (kindyngen.measured.ls_factor, .streaming, .log_formats)
against the in-memory code path and plain numpy, on Panda logs simulated here with Pinocchio's
rnea (nothing shared with the identification): the chunked parallel filter equals the whole
recording's, the streamed fit (the default low-pass, chunked) equals the in-memory one, one file
equals the same samples in ten files, ten files split each on its own equal the in-memory split,
Dask fleets of 1, 2 and 4 workers give the same bits, and Parquet, rosbag2 (MCAP, SQLite) and
ROS 1 bag files give the CSV's result."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import HANG_GUARD_S, ROOT
from kindyngen.measured.estimation import least_squares
from kindyngen.measured.identify import IdentificationRequest, identify
from kindyngen.measured.log_formats import joint_names_of, read_any, write_parquet, write_rosbag1, write_rosbag2
from kindyngen.measured.log_reading import LogError, RawLog
from kindyngen.measured.log_preparing import LowPass, Preprocessing, parallel_filter, preprocess
from kindyngen.measured.ls_factor import LSFactor, combine, combine_in_order, least_squares_factor
from kindyngen.measured.log_streaming import ChunkedParallelFilter, stream_segments
from kindyngen.measured.streaming import identify_streamed
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

PANDA = ROOT / "robots" / "panda.yaml"


#: the Panda's first three joints and links: a small arm whose regressor every Dask worker
#: derives in well under a second
ARM3 = """name: panda3
dh: modified
gravity: [0, 0, -9.81]
joints:
  - {a: 0, alpha: 0,     d: 0.333, offset: 0, lower: -2.8973, upper: 2.8973}
  - {a: 0, alpha: -pi/2, d: 0,     offset: 0, lower: -1.7628, upper: 1.7628}
  - {a: 0, alpha: pi/2,  d: 0.316, offset: 0, lower: -2.8973, upper: 2.8973}
links:
  - {mass: 4.970684, com: [0.003875, 0.002081, 0.0], inertia: [0.70337, 0.70661, 0.009117, -0.000139, 0.006772, 0.019169]}
  - {mass: 0.646926, com: [-0.003141, -0.02872, 0.003495], inertia: [0.007962, 0.02811, 0.025995, -0.003925, 0.010254, 0.000704]}
  - {mass: 3.228604, com: [0.027518, 0.039252, -0.066502], inertia: [0.037242, 0.036155, 0.01083, -0.004761, -0.011396, -0.012805]}
"""


def _simulate(seconds, rate, seed, noise=0.02, robot=PANDA):
    """Sums of sines inside the arm's joint limits; tau = Pinocchio rnea + viscous friction + noise."""
    model = load_robot(robot)
    n = model.n
    pm, pd, _ = pinocchio_model(model)
    rng = np.random.default_rng(seed)
    lo = np.array([j.lower for j in model.joints])
    hi = np.array([j.upper for j in model.joints])
    amp = rng.uniform(0.2, 1.0, size=(n, 3))
    amp *= (0.5 * (hi - lo) / 2 / amp.sum(axis=1))[:, None]
    freq = rng.uniform(0.1, 0.7, size=(n, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(n, 3))
    t = np.arange(int(seconds * rate)) / rate
    w = 2 * np.pi * freq
    arg = w[None] * t[:, None, None] + phase[None]
    q = (lo + hi) / 2 + np.sum(amp * np.sin(arg), axis=2)
    qd = np.sum(amp * w * np.cos(arg), axis=2)
    qdd = -np.sum(amp * w ** 2 * np.sin(arg), axis=2)
    tau = np.array([pin.rnea(pm, pd, a, b, c) for a, b, c in zip(q, qd, qdd)]) + 0.5 * qd
    return t, q, qd, qdd, tau + rng.normal(0.0, noise, size=tau.shape)


def _csv(path, t, q, tau, qd=None, qdd=None):
    n = q.shape[1]
    columns = [t[:, None], q] + ([qd] if qd is not None else []) + ([qdd] if qdd is not None else []) + [tau]
    names = ["t"] + [f"q{i + 1}" for i in range(n)] + ([f"qd{i + 1}" for i in range(n)] if qd is not None else []) \
        + ([f"qdd{i + 1}" for i in range(n)] if qdd is not None else []) + [f"tau{i + 1}" for i in range(n)]
    np.savetxt(path, np.hstack(columns), delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return path


def _values(result):
    return np.concatenate([result.base_values, result.effect_values])


def _relative(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    root = tmp_path_factory.mktemp("stream")
    t, q, qd, qdd, tau = _simulate(12.0, 1000.0, seed=3)
    return root, _csv(root / "run.csv", t, q, tau), (t, q, qd, qdd, tau)


def test_factor_matches_stacked_least_squares_in_any_order():
    rng = np.random.default_rng(0)
    Y = rng.normal(size=(900, 3, 6)) * np.array([1.0, 10.0, 0.1, 1.0, 3.0, 0.5])
    tau = Y @ rng.normal(size=6) + rng.normal(0, 0.1, size=(900, 3)) * np.array([1.0, 3.0, 0.3])
    pieces = [LSFactor.empty(3, 6).fold(Y[a:a + 100], tau[a:a + 100]) for a in range(0, 900, 100)]
    forwards = combine_in_order(pieces)
    shuffled = combine_in_order([pieces[i] for i in rng.permutation(9)])
    tree = combine(combine_in_order(pieces[:4]), combine_in_order(pieces[4:]))
    for weighted in (False, True):
        reference = least_squares(Y, tau, weighted=weighted)
        for factor in (forwards, shuffled, tree):
            fit = least_squares_factor(factor, weighted=weighted)
            assert _relative(fit.values, reference.values) < 1e-12
            assert _relative(fit.std, reference.std) < 1e-10
            assert np.allclose(fit.rms, reference.rms, rtol=1e-10)
            assert fit.condition_number == pytest.approx(reference.condition_number, rel=1e-10)


@pytest.mark.parametrize("total, piece, chunk, decimate", [(30000, 7000, 5000, 25), (29999, 1234, 2500, 25),
                                                         (9001, 9001, 2500, 12), (900, 100, 50, 5)])
def test_chunked_parallel_filter_equals_the_whole_recording(total, piece, chunk, decimate):
    rng = np.random.default_rng(total)
    columns = rng.normal(size=(total, 2, 3)).cumsum(axis=0)      # a random walk: slow content, as motion
    tau = rng.normal(size=(total, 2))
    low_pass = LowPass(1000.0, 5.0, 4, decimate)
    whole_columns, whole_tau = parallel_filter(columns, tau, low_pass)
    flat = np.concatenate([columns.reshape(total, -1), tau], axis=1)
    f = ChunkedParallelFilter(low_pass, overlap=3530, chunk=chunk)
    kept = [out for a in range(0, total, piece) for out in f.push(flat[a:a + piece])] + f.finish()
    chunked = np.concatenate(kept)
    assert len(chunked) == len(whole_tau) == -(-total // decimate)
    assert _relative(chunked[:, :6], whole_columns.reshape(len(whole_tau), -1)) < 1e-12
    assert _relative(chunked[:, 6:], whole_tau) < 1e-12
    if total <= chunk + f.overlap:                # one window: the same operations as the whole
        assert np.array_equal(chunked[:, 6:], whole_tau)


def test_chunked_preprocessing_equals_the_whole_log(log):
    root, path, _ = log
    whole = preprocess(read_any(path, 7))
    (segment,) = whole
    notes = []
    parts = list(stream_segments(path, 7, Preprocessing(), chunk_rows=1500, notes=notes))
    assert len(parts) > 3 and any(note.startswith("streamed in chunks") for note in notes)
    for channel in ("q", "qd", "qdd", "tau", "tau_unfiltered"):
        streamed = np.concatenate([getattr(p, channel) for p in parts])
        expected = getattr(segment, channel)
        assert streamed.shape == expected.shape
        assert _relative(streamed, expected) < 1e-9, channel
    assert all(p.low_pass == segment.low_pass for p in parts)


@pytest.mark.parametrize("options", [dict(), dict(weighted=True, effects=("viscous_friction",))])
def test_streamed_fit_equals_the_in_memory_fit(log, options):
    """The default low-pass: read, preprocessed and parallel-filtered in chunks (1500 rows, so a
    12 s log is many chunks), against identify() filtering each part whole."""
    root, path, _ = log
    request = IdentificationRequest(PANDA, (str(path),), split=0.75, **options)
    memory = identify(request)
    streamed = identify_streamed(request, chunk_rows=1500)
    assert any(note.startswith("streamed in chunks") for note in streamed.preprocessing_notes)
    assert any("in chunks of 1500 samples with 3550 of overlap" in note for note in streamed.preprocessing_notes)
    assert streamed.samples_train == memory.samples_train
    assert streamed.samples_validation == memory.samples_validation
    assert _relative(_values(streamed), _values(memory)) < 1e-9
    assert np.allclose(streamed.rms_validation, memory.rms_validation, rtol=1e-9)
    assert np.allclose(streamed.rms_validation_nominal, memory.rms_validation_nominal, rtol=1e-9)
    assert streamed.condition_number == pytest.approx(memory.condition_number, rel=1e-9)


@pytest.fixture(scope="module")
def ten_files(tmp_path_factory):
    """The same samples of a 3-joint arm (q, qd, qdd given) as one file and as ten of 2 s."""
    root = tmp_path_factory.mktemp("fleet")
    arm = root / "panda3.yaml"
    arm.write_text(ARM3)
    t, q, qd, qdd, tau = _simulate(20.0, 500.0, seed=5, noise=0.05, robot=arm)
    one = _csv(root / "all.csv", t, q, tau, qd, qdd)
    parts = [_csv(root / f"part{k}.csv", t[idx], q[idx], tau[idx], qd[idx], qdd[idx])
             for k, idx in enumerate(np.array_split(np.arange(len(t)), 10))]
    t2, q2, qd2, qdd2, tau2 = _simulate(2.0, 500.0, seed=6, noise=0.05, robot=arm)
    held_out = _csv(root / "validate.csv", t2, q2, tau2, qd2, qdd2)
    return arm, one, parts, held_out


@pytest.mark.parametrize("settings", [Preprocessing(), Preprocessing(cutoff_hz=None)], ids=["low-pass", "unfiltered"])
def test_ten_files_split_each_on_its_own_as_in_memory(ten_files, settings):
    """--split: each file is its own experiment, its first 75 % trains (identify()'s rule), with
    the default low-pass and with none."""
    arm, _, parts, _ = ten_files
    request = IdentificationRequest(arm, tuple(map(str, parts)), split=0.75, preprocessing=settings)
    memory = identify(request)
    streamed = identify_streamed(request)
    assert streamed.samples_train == memory.samples_train
    assert streamed.samples_validation == memory.samples_validation
    assert _relative(_values(streamed), _values(memory)) < 1e-9
    assert np.allclose(streamed.rms_validation, memory.rms_validation, rtol=1e-9)


def test_one_file_and_ten_files_and_dask_workers_agree(ten_files):
    distributed = pytest.importorskip("distributed")
    import dask
    arm, one, parts, held_out = ten_files
    settings = Preprocessing(cutoff_hz=None)
    single = identify_streamed(IdentificationRequest(arm, (str(one),), validate=(str(held_out),),
                                                     preprocessing=settings))
    request = IdentificationRequest(arm, tuple(map(str, parts)), validate=(str(held_out),), preprocessing=settings)
    split = identify_streamed(request)
    assert split.samples_train == single.samples_train == 10000
    assert _relative(_values(split), _values(single)) < 1e-9
    # the fleet runs the default: low-pass, parallel filtering, each file split on its own
    request = IdentificationRequest(arm, tuple(map(str, parts)), validate=(str(held_out),), split=0.75)
    split = identify_streamed(request)
    bits = []
    # Dask's 30 s connect and silent-connection timeouts as hang guards only: four worker
    # processes starting (or computing) on a loaded 2-core machine may take longer
    guard = f"{HANG_GUARD_S}s"
    with dask.config.set({"distributed.comm.timeouts.connect": guard, "distributed.comm.timeouts.tcp": guard}), \
            distributed.LocalCluster(n_workers=4, threads_per_worker=1, processes=True,
                                     dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        for workers in (4, 2, 1):            # one cluster, workers retired between runs (start-up is the cost)
            alive = sorted(client.scheduler_info()["workers"])
            if len(alive) > workers:
                client.retire_workers(alive[workers:], close_workers=True)
            client.wait_for_workers(workers, timeout=HANG_GUARD_S)
            assert len(client.scheduler_info()["workers"]) == workers
            bits.append(_values(identify_streamed(request, client=client)))
    for other in bits:
        assert np.array_equal(other, bits[0])          # the fixed reduction order: same bits
    assert np.array_equal(bits[0], _values(split))     # and the same as in this process


def test_parquet_and_bags_give_the_csv_result(log, tmp_path):
    root, path, (t, q, qd, qdd, tau) = log
    raw = RawLog("sim", t[:8000], q[:8000], tau[:8000])
    csv = _csv(tmp_path / "run.csv", raw.t, raw.q, raw.tau)
    parquet = tmp_path / "run.parquet"
    write_parquet(parquet, raw)
    ros_names = [f"panda_joint{i + 1}" for i in range(7)]
    mcap = tmp_path / "bag_mcap"
    write_rosbag2(mcap, raw, ros_names, storage="mcap")
    sqlite = tmp_path / "bag_sqlite"
    write_rosbag2(sqlite, RawLog("sim", raw.t, raw.q[:, ::-1], raw.tau[:, ::-1]), ros_names[::-1],
                  storage="sqlite3")          # joints in another order: matched by name
    ros1 = tmp_path / "run.bag"
    write_rosbag1(ros1, raw, ros_names)
    reference = _values(identify_streamed(IdentificationRequest(PANDA, (str(csv),), split=0.7)))
    for log_path in (parquet, mcap, sqlite, ros1):
        result = identify_streamed(IdentificationRequest(PANDA, (str(log_path),), split=0.7))
        assert _relative(_values(result), reference) < 1e-9, log_path


def test_bag_joint_names_are_checked(tmp_path):
    t = np.arange(100) * 0.01
    names = joint_names_of(load_robot(PANDA))
    missing = tmp_path / "missing"
    write_rosbag2(missing, RawLog("sim", t, np.zeros((100, 6)), np.zeros((100, 6))), names[:6])
    with pytest.raises(LogError, match="has no joint 'joint7' of the description"):
        read_any(missing, 7, names)
    extra = tmp_path / "extra"
    write_rosbag2(extra, RawLog("sim", t, np.zeros((100, 8)), np.zeros((100, 8))), names + ["gripper"])
    with pytest.raises(LogError, match="names joint\\(s\\) gripper the description does not have"):
        read_any(extra, 7, names)


def test_semidefinite_program_from_the_factor_equals_the_stacked_one(ten_files):
    from kindyngen.measured.consistent import identify_consistent, identify_consistent_factor
    from kindyngen.measured.effect_columns import effect_columns
    from kindyngen.measured.regressor_rows import torque_regressor
    from kindyngen.model.inertial_parameters import parameter_vector
    arm, one, _, _ = ten_files
    model = load_robot(arm)
    raw = read_any(one, 3)
    R = torque_regressor(model)
    Yb = R(raw.q, raw.qd, raw.qdd)
    E = effect_columns(("viscous_friction",), raw.qd, raw.qdd)
    names = tuple(f"fv{i + 1}" for i in range(3))
    prior = parameter_vector(model) * 1.2
    stacked = identify_consistent(Yb @ R.base_map, E, raw.tau, 3, names, prior=prior, base_map=R.base_map)
    factor = LSFactor.empty(3, Yb.shape[2] + 3)
    for a in range(0, len(raw.t), 700):
        factor = factor.fold(np.concatenate([Yb, E], axis=2)[a:a + 700], raw.tau[a:a + 700])
    folded = identify_consistent_factor(factor, R.base_map, names, prior=prior)
    # the same program, given to the solver as a differently shaped (same Gram matrix) term
    assert _relative(folded.base_values, stacked.base_values) < 1e-5
    assert _relative(folded.effect_values, stacked.effect_values) < 1e-5
    assert np.allclose(folded.rms, stacked.rms, rtol=1e-5)
    assert folded.data_term == pytest.approx(stacked.data_term, rel=1e-5)


def test_discover_reads_parquet_like_the_csv(log, tmp_path, capsys):
    """discover's data entry reads every format identify reads (through the streaming reader)."""
    import json
    from kindyngen.cli.main import main
    root, path, (t, q, qd, qdd, tau) = log
    raw = RawLog("sim", t[:6000], q[:6000], tau[:6000])
    csv = _csv(tmp_path / "run.csv", raw.t, raw.q, raw.tau)
    parquet = tmp_path / "run.parquet"
    write_parquet(parquet, raw)
    docs = []
    for data in (csv, parquet):
        code = main(["discover", "--robot", str(PANDA), "--data", str(data), "--candidates", "viscous_friction",
                     "--out", str(tmp_path / data.suffix[1:]), "--quiet"])
        assert code == 0, capsys.readouterr().err
        docs.append(json.loads((tmp_path / data.suffix[1:] / "discovery.json").read_text()))
    assert docs[0]["effects"] == docs[1]["effects"]
    assert docs[0]["effects"]
    assert docs[0]["rms_after"] == pytest.approx(docs[1]["rms_after"], rel=1e-9)
