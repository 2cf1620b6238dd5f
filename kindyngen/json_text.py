"""JSON as every file KinDynGen writes holds it: strict (RFC 8259), with one stated rule for the
numbers JSON cannot spell.

Python's ``json`` writes the tokens ``NaN``, ``Infinity`` and ``-Infinity`` unless told not to;
they are not JSON, and strict parsers (JavaScript's ``JSON.parse``, Go, Rust's serde_json, jq)
refuse the whole file.  :func:`strict_json` never writes them:

* a number that is not finite is written as the **string** ``"NaN"``, ``"Infinity"`` or
  ``"-Infinity"`` (protobuf's JSON mapping of doubles; ``kindyngen eval`` prints its outputs the
  same way).  Such numbers are legitimate results, never echoes of bad input (a log with
  non-finite or implausible values is refused before anything is computed from it,
  :mod:`kindyngen.measured.log_checks`): the relative standard error of a coefficient the data
  does not determine, the condition number of a rank-deficient regressor, a correlation over a
  single function;
* ``null`` stays what a writer chose it to mean: no value (``discovery.json``'s residual in a
  motion phase without samples);
* numpy scalars and arrays become plain numbers and lists; everything else is ``json.dumps``'s
  own (the same bytes as before for documents of finite numbers).

>>> print(strict_json({"rms": [0.5, float("inf")], "std": float("nan"), "none": None}))
{"rms": [0.5, "Infinity"], "std": "NaN", "none": null}
"""
from __future__ import annotations

import json
import math

import numpy as np

__all__ = ["json_number", "plain", "strict_json"]


def json_number(value):
    """A float as JSON: finite numbers as they are, NaN and the infinities as the strings
    ``"NaN"``, ``"Infinity"``, ``"-Infinity"``; nested lists are walked.

    >>> [json_number(v) for v in (1.5, float("nan"), float("-inf"))]
    [1.5, 'NaN', '-Infinity']
    """
    if isinstance(value, list):
        return [json_number(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    return value


def plain(document):
    """``document`` with numpy scalars and arrays as plain numbers and lists, tuples as lists,
    and every non-finite float by the rule of the module text (dict keys are left as they are).

    >>> plain({"a": np.array([1.0, np.inf]), "b": (np.float32(0.5), np.int64(3), True)})
    {'a': [1.0, 'Infinity'], 'b': [0.5, 3, True]}
    """
    if isinstance(document, dict):
        return {key: plain(value) for key, value in document.items()}
    if isinstance(document, (list, tuple)):
        return [plain(value) for value in document]
    if isinstance(document, np.ndarray):
        return plain(document.tolist())
    if isinstance(document, np.generic):
        document = document.item()
    if isinstance(document, float):
        return json_number(float(document))
    return document


def strict_json(document, indent: int | None = None, **options) -> str:
    """``json.dumps`` of :func:`plain` ``(document)`` with ``allow_nan=False``: strict JSON text,
    non-finite numbers written by the rule of the module text.  ``options`` go to ``json.dumps``
    (e.g. ``default``); a value they produce that is still not finite raises ``ValueError``
    rather than being written as a token no parser reads.

    >>> strict_json([1e300 * 1e300, -1e300 * 1e300])
    '["Infinity", "-Infinity"]'
    """
    return json.dumps(plain(document), indent=indent, allow_nan=False, **options)
