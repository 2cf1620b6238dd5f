"""Identification on the real logs beside the project (skipped where ../shared/data is absent,
as in a user's clone): the figures the README quotes, each asserted.

* LWR4+ (FloBaRoID logs, as stored: filtered before saving): train on runs 1 and 2 (one
  trajectory), validate on run 3 (another).
* Panda (Gaz et al. 2019 log): train on the first 60 % of the time span, validate on the last
  40 %, against the published model (its rigid-body parameters plus its published friction)
  evaluated on the same samples under the same preprocessing, rigid bodies by Pinocchio."""
from __future__ import annotations

import csv
import json

import numpy as np
import pinocchio as pin
import pytest

from tests.harness import ROOT
from kindyngen.cli.main import main
from kindyngen.measured.log_preparing import Preprocessing, filtered_rows, load_segments, split_time
from kindyngen.readers.yaml_description import load_robot
from tests.reference import pinocchio_model

DATA = ROOT.parent / "shared" / "data"
LWR = DATA / "lwr4_flobaroid"
PANDA = DATA / "panda_gaz2019"
FRICTION = "viscous_friction,coulomb_friction,torque_offset"


def _identify(tmp_path, name, args):
    out = tmp_path / name
    assert main(["identify", *args, "--out", str(out), "--quiet"]) == 0
    return json.loads((out / "identification.json").read_text()), out


@pytest.mark.skipif(not LWR.is_dir(), reason="the LWR4+ logs (../shared/data/lwr4_flobaroid) are not here")
def test_lwr4_logs_consistent_generalises_better(tmp_path, capsys):
    common = ["--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(LWR / "measurements_1.npz"),
              "--data", str(LWR / "measurements_2.npz"), "--validate", str(LWR / "measurements_3.npz"),
              "--cutoff", "none"]
    rigid, _ = _identify(tmp_path, "rigid", common)
    ols, _ = _identify(tmp_path, "ols", common + ["--effects", FRICTION])
    sdp, out = _identify(tmp_path, "sdp", common + ["--effects", FRICTION, "--consistent"])
    capsys.readouterr()
    sums = {k: sum(d["rms_validation"]) for k, d in (("rigid", rigid), ("ols", ols), ("sdp", sdp))}
    print("LWR4+ validation RMS per joint (N m):")
    for k, d in (("rigid", rigid), ("ols", ols), ("sdp", sdp)):
        print(f"  {k}: {[round(v, 3) for v in d['rms_validation']]} sum {sums[k]:.2f}")
    assert sdp["physically_consistent"] and (out / "model.yaml").is_file()
    assert not ols["physically_consistent"]
    assert sums["sdp"] < 0.45 * sums["ols"]         # 2.76 against 7.23 N m summed, measured


def _published_friction(qd):
    """The Panda paper's friction: phi1 / (1 + exp(-phi2 (qd + phi3))) - phi1 / (1 + exp(-phi2 phi3))."""
    with open(PANDA / "gaz2019_friction_parameters.csv") as f:
        rows = {r[0]: np.array([float(x) for x in r[1:8]]) for r in csv.reader(line for line in f if not line.startswith("#"))
                if r and r[0].startswith("phi")}
    p1, p2, p3 = rows["phi1"], rows["phi2"], rows["phi3"]
    return p1 / (1 + np.exp(-p2 * (qd + p3))) - p1 / (1 + np.exp(-p2 * p3))


@pytest.mark.skipif(not PANDA.is_dir(), reason="the Panda log (../shared/data/panda_gaz2019) is not here")
def test_panda_consistent_model_beats_the_published_one_on_every_joint(tmp_path, capsys):
    doc, out = _identify(tmp_path, "panda", ["--robot", str(PANDA / "robot.yaml"), "--data", str(PANDA / "measured.csv"),
                                             "--split", "0.6", "--effects", FRICTION, "--consistent"])
    assert doc["physically_consistent"]
    # the published model on the same held-out samples (same preprocessing: predictions from
    # the filtered motion, then filtered with the unfiltered torque, parallel filtering)
    _, validation = split_time(load_segments(PANDA / "measured.csv", 7, Preprocessing()), 0.6)
    model, data, _ = pinocchio_model(load_robot(PANDA / "robot.yaml"))
    ours = load_robot(out / "model.yaml")
    om, od, _ = pinocchio_model(ours)
    f = [ours.friction(i) for i in range(7)]
    fv, fc, f0 = (np.array([float(getattr(x, k)) for x in f]) for k in ("viscous", "coulomb", "offset"))
    tau, published, predicted = [], [], []
    for seg in validation:
        q, qd, qdd = seg.q, seg.qd, seg.qdd
        pub = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)]) + _published_friction(qd)
        # our identified model.yaml, evaluated by Pinocchio plus the documented friction formulas
        mine = np.array([pin.rnea(om, od, a, b, c) for a, b, c in zip(q, qd, qdd)]) + fv * qd + fc * np.sign(qd) + f0
        _, F, measured = filtered_rows(seg, np.stack([pub, mine], axis=2))
        tau.append(measured)
        published.append(F[:, :, 0])
        predicted.append(F[:, :, 1])
    tau, published, predicted = np.concatenate(tau), np.concatenate(published), np.concatenate(predicted)
    rms_published = np.sqrt(np.mean((tau - published) ** 2, axis=0))
    rms_ours = np.sqrt(np.mean((tau - predicted) ** 2, axis=0))
    capsys.readouterr()
    print(f"Panda held-out RMS (N m): ours {np.round(rms_ours, 3).tolist()} sum {rms_ours.sum():.2f}; "
          f"published {np.round(rms_published, 3).tolist()} sum {rms_published.sum():.2f}")
    np.testing.assert_allclose(rms_ours, doc["rms_validation"], rtol=1e-6)
    assert np.all(rms_ours < rms_published)


#: the documented discover commands on both real logs (docs/discovery.md, "Real logs"); the LWR4+
#: nominal is the rigid bodies identified from runs 1 and 2, kept beside the docs' run
DISCOVER_RUNS = {
    "panda": (PANDA, ["--robot", str(PANDA / "robot.yaml"), "--data", str(PANDA / "measured.csv"), "--cutoff", "5",
                      "--rate", "1000"]),
    "lwr4": (LWR, ["--robot", str(ROOT / "docs" / "discovery" / "lwr4" / "nominal_identified_rigid.yaml"),
                   "--data", str(LWR / "measurements_3.npz"), "--cutoff", "none"]),
}


@pytest.mark.parametrize("name", sorted(DISCOVER_RUNS))
def test_discover_model_yaml_carries_over_to_the_held_out_part(tmp_path, capsys, name):
    """discover on a real log: model.yaml, with the rigid bodies, gains and tilt fitted together,
    is better than the nominal model on every joint of the held-out 30 %, and no worse in sum than
    identify's consistent fit trained on the same 70 % (README: LWR4+ 1.33 against 1.77, the
    Panda 0.69 against 0.855). Before, the fit's last Gauss-Newton step was written untried: on
    the Panda model.yaml read 15.8 N m summed over the joints there against the nominal's 2.73;
    later joint 7's gain and friction were dropped together by a first-order refit at the fitted
    point (0.975 summed, joint 7 above the nominal)."""
    folder, common = DISCOVER_RUNS[name]
    if not folder.is_dir():
        pytest.skip(f"the log ({folder}) is not here")
    out = tmp_path / "discover"
    assert main(["discover", *common, "--out", str(out), "--quiet"]) == 0
    doc = json.loads((out / "discovery.json").read_text())
    before, after = np.array(doc["rms_before"]), np.array(doc["rms_after"])        # the held-out part
    identified, _ = _identify(tmp_path, "identify", [*common, "--split", "0.7", "--effects", FRICTION,
                                                     "--consistent"])
    identified_sum = float(np.sum(identified["rms_validation"]))
    capsys.readouterr()
    print(f"{name} held-out RMS sum (N m): nominal {before.sum():.3f}, discover's model.yaml {after.sum():.3f}, "
          f"identify {identified_sum:.3f}; named {doc['effects']}")
    assert np.all(after < before), (after, before)
    assert after.sum() <= identified_sum, (after.sum(), identified_sum)
    assert not any("worse than the nominal" in line for line in doc["unexplained"]), doc["unexplained"]
