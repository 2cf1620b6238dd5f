"""The handbook and the README as documents: the MkDocs site builds with --strict (a broken
link or anchor fails), the README is a landing page that still shows the two commands and
links only to pages that exist, and the shell commands of the README, of getting started and
of every tutorial run as written.

The commands run in a scratch folder that holds the checkout's robots/, examples/, tests/ and
generated/ (links) and its virtual environment as .venv (the one running these tests), so what
they write stays out of the checkout. ``make generate`` and ``make test`` are not run here: CI
runs ``make test`` itself, and tests/integration/test_reproducibility.py regenerates generated/.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.harness import HANG_GUARD_S, ROOT

PAGES_RUN = ("README.md", "docs/getting-started.md", "docs/tutorials/identify.md",
             "docs/tutorials/discover.md", "docs/tutorials/plan.md", "docs/tutorials/closed_loops.md",
            "docs/tutorials/mimic_joints.md")


def _shell_blocks(path: Path) -> list[str]:
    """The ```sh blocks of a page; ```text blocks are synopses with placeholders, not run."""
    return re.findall(r"```sh\n(.*?)```", path.read_text(), re.S)


def test_handbook_builds_strictly(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "site" / "tutorials" / "identify" / "index.html").is_file()


def test_readme_is_a_landing_page():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    commands = "\n".join(_shell_blocks(ROOT / "README.md"))
    assert "make generate" in commands and "make test" in commands
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert len([link for link in links if link.startswith("docs/")]) >= 10
    for link in links:
        if not link.startswith("http"):
            assert (ROOT / link).is_file(), f"README links to {link}, which does not exist"


def _workspace(tmp_path: Path) -> Path:
    work = tmp_path / "checkout"
    work.mkdir()
    for name in ("robots", "examples", "tests", "generated", "kindyngen"):
        (work / name).symlink_to(ROOT / name)
    venv = ROOT / ".venv" if (ROOT / ".venv" / "bin" / "python").exists() else Path(sys.prefix)
    (work / ".venv").symlink_to(venv)
    return work


@pytest.mark.parametrize("page", PAGES_RUN)
def test_page_commands_run_as_written(page, tmp_path):
    blocks = [b for b in _shell_blocks(ROOT / page) if not b.lstrip().startswith("make ")]
    assert blocks, f"{page} has no commands to run"
    if shutil.which("cc") is None and "cc -std=c99" in "".join(blocks):
        pytest.skip("no C compiler")
    work = _workspace(tmp_path)
    # no bytecode: `import lwr4` from generated/ (a link to the checkout's) would leave a
    # __pycache__ there, and tests/integration/test_reproducibility.py compares generated/ file by file
    env = {**os.environ, "PYTHONPATH": str(ROOT), "KINDYNGEN_CACHE": str(tmp_path / "cache"),
           "PYTHONDONTWRITEBYTECODE": "1"}
    done = subprocess.run(["bash", "-c", "set -euo pipefail\n" + "\n".join(blocks)], cwd=work, env=env,
                          capture_output=True, text=True, timeout=HANG_GUARD_S)
    assert done.returncode == 0, f"{page}:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
