"""Every worked example in the package's docstrings runs and prints what it says (examples
that need generated files or a long derivation are marked ``+SKIP`` in place)."""
from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import kindyngen
import kindyngen.measured


def _modules():
    for package in (kindyngen, kindyngen.measured):
        for info in pkgutil.iter_modules(package.__path__):
            if info.name != "__main__":
                yield f"{package.__name__}.{info.name}"


@pytest.mark.parametrize("name", sorted(_modules()))
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed"
