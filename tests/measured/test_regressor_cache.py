"""The compiled regressors are kept on disk between runs, keyed by the geometry and the
derivation's code: a second process loads the same function (equal values), a model that
differs only in its inertial values, name or effects shares it, a changed geometry gets its
own, and a damaged file is derived again."""
from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np

from tests.harness import ROOT, robot
from kindyngen.measured import regressor_rows

SCRIPT = """
import sys, numpy as np
from kindyngen.readers.yaml_description import load_robot
from kindyngen.measured.regressor_rows import torque_regressor
R = torque_regressor(load_robot(sys.argv[1]))
x = np.linspace(-1, 1, 21).reshape(3, 7)
np.save(sys.argv[2], R(x, 0.5 * x, -x))
"""


def _run(cache, out):
    env = {"KINDYNGEN_CACHE": str(cache), "PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    subprocess.run([sys.executable, "-c", SCRIPT, str(ROOT / "robots" / "lwr4.yaml"), str(out)], env=env, check=True,
                   cwd=ROOT)
    return np.load(out)


def test_a_second_run_loads_the_same_regressor(tmp_path):
    cache = tmp_path / "cache"
    first = _run(cache, tmp_path / "a.npy")
    files = sorted((cache / "regressors").iterdir())
    assert len(files) == 1 and files[0].suffix == ".pickle"
    stamp = files[0].stat().st_mtime_ns
    second = _run(cache, tmp_path / "b.npy")
    assert files[0].stat().st_mtime_ns == stamp            # read, not written again
    np.testing.assert_array_equal(first, second)
    files[0].write_bytes(b"not a pickle")                  # damaged: derived again, the same values
    np.testing.assert_array_equal(_run(cache, tmp_path / "c.npy"), first)


def test_the_key_is_the_geometry():
    model = robot("lwr4")
    heavier = replace(model, name="other", links=tuple(replace(l, mass=2 * l.mass) for l in model.links))
    assert regressor_rows.geometry_of(heavier) == regressor_rows.geometry_of(model)
    tilted = replace(model, gravity=(1, 0, -9.81))
    assert regressor_rows.geometry_of(tilted) != regressor_rows.geometry_of(model)
    # the values differ, the compiled function is the same object
    assert regressor_rows.torque_regressor(heavier)._fn is regressor_rows.torque_regressor(model)._fn
