"""`kindyngen excite` designs a trajectory that `kindyngen identify` can use: the trajectory is
played on a simulated arm (Pinocchio plus friction formulas written here), and the
identification from that log recovers the truth."""
from __future__ import annotations

import csv
import json

import numpy as np
import pinocchio as pin

from tests.harness import ROOT, robot
from kindyngen.cli.main import main
from kindyngen.model.inertial_parameters import parameter_vector
from kindyngen.measured.regressor_rows import TorqueRegressor
from tests.reference import pinocchio_model


def _run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return (code, *capsys.readouterr())


def test_excite_then_identify_recovers_the_truth(tmp_path, capsys):
    code, out, err = _run(["excite", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--harmonics", "3",
                           "--iterations", "15", "--rate", "100", "--periods", "2", "--out", str(tmp_path / "x"),
                           "--quiet"], capsys)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["feasible"] and summary["condition_number"] < summary["initial_condition_number"]
    with open(tmp_path / "x" / "excitation.csv") as f:
        rows = list(csv.reader(f))
    header, data = rows[0], np.array(rows[1:], float)
    lwr = robot("lwr4")
    assert data[:, 1:8].min(axis=0).tolist() >= (lwr.lower + 0.1 - 1e-9).tolist()
    t, q, qd, qdd = data[:, 0], data[:, 1:8], data[:, 8:15], data[:, 15:22]
    model, mdata, _ = pinocchio_model(lwr)
    fv, fc = np.linspace(0.2, 0.8, 7), np.linspace(0.5, 1.0, 7)
    tau = np.array([pin.rnea(model, mdata, a, b, c) for a, b, c in zip(q, qd, qdd)]) + fv * qd + fc * np.sign(qd)
    log = tmp_path / "played.csv"
    np.savetxt(log, np.column_stack([t, q, qd, qdd, tau]), delimiter=",", comments="", fmt="%.17g",
               header=",".join(header + [f"tau{i + 1}" for i in range(7)]))
    code, out, err = _run(["identify", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--data", str(log),
                           "--split", "0.5", "--effects", "viscous_friction,coulomb_friction", "--cutoff", "none",
                           "--out", str(tmp_path / "id"), "--quiet"], capsys)
    assert code == 0, err
    doc = json.loads((tmp_path / "id" / "identification.json").read_text())
    truth = TorqueRegressor(lwr).base_map @ parameter_vector(lwr)
    np.testing.assert_allclose(doc["base_params"]["values"], truth, rtol=1e-7, atol=1e-8)
    np.testing.assert_allclose(doc["effects"]["values"], np.concatenate([fv, fc]), atol=1e-8)


def test_excite_refuses_bad_requests_in_one_line(tmp_path, capsys):
    code, out, err = _run(["excite", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--harmonics", "0",
                           "--out", str(tmp_path)], capsys)
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1, err
    code, out, err = _run(["excite", "--robot", str(ROOT / "robots" / "lwr4.yaml"), "--velocity", "-1",
                           "--out", str(tmp_path)], capsys)
    assert code == 2 and "expected a positive number" in err
