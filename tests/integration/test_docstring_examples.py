"""Every worked example in the package's docstrings runs and prints what it says, those marked
``+SKIP`` included: they run from a folder that holds the checkout's robots/ and generated/
(the paths the examples name; whatever an example writes lands there, not in the checkout).
The few that stay skipped are listed in STAYS_SKIPPED with the reason: a long computation that
another test already runs, or an illustration on data (a log, fitted values) that is not in
the checkout."""
from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import kindyngen
import kindyngen.measured
from tests.harness import ROOT

SKIP = doctest.OPTIONFLAGS_BY_NAME["SKIP"]
STAYS_SKIPPED = {
    # long: minutes on a loaded CI core
    "kindyngen.runtime.python_c": "compiles the LWR's extension (tests/runtime/test_python_c.py builds and checks it)",
    "kindyngen.measured.excitation": "optimises a whole excitation (tests/measured/test_excitation.py)",
    "kindyngen.measured.excitation.optimise_excitation": "optimises an excitation (tests/measured/test_excitation.py)",
    "kindyngen.measured.paper_reproduction": "runs the paper's procedure (tests/measured/test_paper_reproduction.py)",
    # illustrations on data the checkout does not hold
    "kindyngen.measured.consistent": "needs a log's q, qd, qdd, tau",
    "kindyngen.measured.discovery": "needs logged segments",
    "kindyngen.measured.discrepancy": "needs log.csv",
    "kindyngen.measured.discovery_fit": "needs a pass over logged data",
    "kindyngen.measured.discovery_report": "needs a discover result",
    "kindyngen.measured.identify": "needs run1.npz",
    "kindyngen.measured.identified_model": "needs identified parameter values",
    "kindyngen.measured.identification_report": "needs a log's t, tau and a prediction",
    "kindyngen.measured.streaming": "needs hour.parquet",
}


def _modules():
    for info in pkgutil.walk_packages(kindyngen.__path__, "kindyngen."):
        if not info.name.endswith(".__main__"):
            yield info.name


def _docstrings(name):
    return doctest.DocTestFinder().find(importlib.import_module(name))


@pytest.fixture
def checkout_view(tmp_path, monkeypatch):
    """A working folder where robots/ and generated/ are the checkout's."""
    for folder in ("robots", "generated"):
        (tmp_path / folder).symlink_to(ROOT / folder, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize("name", sorted(_modules()))
def test_docstring_examples(name, checkout_view):
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    for test in _docstrings(name):
        if test.name not in STAYS_SKIPPED:
            for example in test.examples:
                example.options.pop(SKIP, None)
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed"


def test_what_stays_skipped_is_skipped_today():
    """Each STAYS_SKIPPED entry names a docstring with a skipped example (no stale entry
    excuses nothing)."""
    modules = {name.rsplit(".", 1)[0] if name not in set(_modules()) else name for name in STAYS_SKIPPED}
    skipped = {test.name for module in modules for test in _docstrings(module)
               if any(example.options.get(SKIP) for example in test.examples)}
    assert set(STAYS_SKIPPED) <= skipped, sorted(set(STAYS_SKIPPED) - skipped)
