"""`pip install .` (not editable) gives a working `kindyngen` command: the package, with its
templates, is installed into a fresh virtual environment and `generate`, `count` and `eval`
run from a directory outside the checkout.

To keep the suite quick, the new environment sees the pinned dependencies of the project's
own environment (a path file pointing at its site-packages, whose editable hook is not run);
KinDynGen itself comes only from the wheel pip builds from a copy of the sources."""
from __future__ import annotations

import json
import shutil
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from tests.harness import GENERATED, HANG_GUARD_S, ROOT

SOURCES = ("pyproject.toml", "README.md", "LICENSE", "kindyngen")


def _run(cmd, cwd, stdin=None):
    done = subprocess.run(cmd, cwd=cwd, input=stdin, capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert done.returncode == 0, f"{' '.join(map(str, cmd))} failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(bin directory of a fresh venv with KinDynGen installed from a wheel, a work folder)."""
    tmp = tmp_path_factory.mktemp("install")
    src = tmp / "src"
    src.mkdir()
    for name in SOURCES:   # a copy, so the build leaves nothing in the checkout
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(ROOT / name, src / name)
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], cwd=tmp)
    purelib = Path(_run([str(venv / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                        cwd=tmp).strip())
    deps = [p for p in [sysconfig.get_paths()["purelib"], *site.getsitepackages()] if Path(p).is_dir()]
    (purelib / "project_dependencies.pth").write_text("\n".join(dict.fromkeys(deps)) + "\n")
    _run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", "--no-deps", str(src)], cwd=tmp)
    work = tmp / "elsewhere"
    work.mkdir()
    return venv / "bin", work


def test_installed_package_is_not_the_checkout(installed):
    bin_dir, work = installed
    where = _run([str(bin_dir / "python"), "-c", "import kindyngen; print(kindyngen.__file__)"], cwd=work).strip()
    assert Path(where).resolve().is_relative_to(bin_dir.parent.resolve()), where
    assert not Path(where).resolve().is_relative_to(ROOT.resolve())


def test_installed_command_generates_counts_and_evaluates(installed):
    bin_dir, work = installed
    out = work / "gen"
    _run([str(bin_dir / "kindyngen"), "generate", str(ROOT / "robots" / "lwr4.yaml"), "--out", str(out), "--quiet"],
         cwd=work)
    # the installed package writes the same bytes as the checkout's committed tree
    fresh = {p.relative_to(out / "lwr4"): p.read_bytes() for p in (out / "lwr4").rglob("*") if p.is_file()}
    committed = {p.relative_to(GENERATED / "lwr4"): p.read_bytes() for p in (GENERATED / "lwr4").rglob("*") if p.is_file()}
    assert fresh == committed

    counts = json.loads(_run([str(bin_dir / "kindyngen"), "count", str(ROOT / "robots" / "lwr4.yaml"), "--only",
                              "fk_hom", "--format", "json"], cwd=work))
    assert set(counts["lwr4"]) == {"fk_hom"}

    for lang in ("python", "c", "casadi"):
        result = json.loads(_run([str(bin_dir / "kindyngen"), "eval", str(out / "lwr4"), "fk_hom", "--lang", lang],
                                 cwd=work, stdin=json.dumps({"q": [0.0] * 7})))
        # zero configuration of the LWR: the alphas cancel (pi/2 - pi/2 - pi/2 + pi/2 + pi/2 -
        # pi/2), so the flange frame is the base frame lifted by d3 + d5 = 0.79 m
        expected = np.eye(4)
        expected[2, 3] = 0.79
        assert np.allclose(np.array(result["T"]), expected, atol=1e-12), (lang, result)
