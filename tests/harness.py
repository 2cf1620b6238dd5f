"""Evaluate derived or generated functions on batches of numpy inputs, uniformly.

``evaluate(robot_name, lang, function_name, **inputs) -> dict of outputs`` where every input
carries a leading batch dimension and outputs come back with their port shapes after it.

lang "symbolic" evaluates the SymbolicFunction straight from the derivation (symengine
Lambdify), the others run the committed generated code under ``generated/`` through
:mod:`kindyngen.runtime.evaluate`.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import symengine as se

from kindyngen.codegen.catalog import derive_all
from kindyngen.readers.yaml_description import load_robot

ROOT = Path(__file__).resolve().parents[1]
GENERATED = ROOT / "generated"
LANGS = ("python", "c", "casadi")
HANG_GUARD_S = 30 * 60
"""The timeout of every subprocess a test starts: a guard against a hang, never a time limit
(tests assert no speed; timings belong in benchmarks/). The slowest, generating every robot
twice at once (tests/integration/test_reproducibility.py), takes about 3 min on an idle
2-core machine and many times that on a loaded one."""


@lru_cache(maxsize=None)
def robot(name: str):
    return load_robot(ROOT / "robots" / f"{name}.yaml")


@lru_cache(maxsize=None)
def symbolic_function(robot_name: str, function_name: str, params: str = "numeric"):
    found = derive_all(robot(robot_name), params, only={function_name})
    if not found:
        raise KeyError(f"{robot_name} has no function {function_name}")
    return found[0]


@lru_cache(maxsize=None)
def _lambdified(robot_name: str, function_name: str, params: str):
    f = symbolic_function(robot_name, function_name, params)
    args = [s for syms in f.input_symbols for s in syms]
    outs = [e for exprs in f.inlined_outputs() for e in exprs]
    return f, se.Lambdify(args, outs, cse=True)


def evaluate_symbolic(robot_name: str, function_name: str, params: str = "numeric", **inputs):
    f, fn = _lambdified(robot_name, function_name, params)
    arrays = [np.asarray(inputs[p.name], float).reshape(-1, p.size) for p in f.inputs]
    batch = arrays[0].shape[0]
    flat = np.concatenate(arrays, axis=1)
    out = np.array([fn(row) for row in flat]).reshape(batch, -1)
    result, start = {}, 0
    for p in f.outputs:
        result[p.name] = out[:, start:start + p.size].reshape((batch,) + p.shape)
        start += p.size
    return result


def evaluate(robot_name: str, lang: str, function_name: str, **inputs):
    if lang == "symbolic":
        return evaluate_symbolic(robot_name, function_name, **inputs)
    from kindyngen.runtime.evaluate import load_generated
    return load_generated(GENERATED / robot_name, lang).call(function_name, inputs)


def evaluate_function(f, *inputs):
    """The outputs of SymbolicFunction ``f`` at the concatenated ``inputs`` (one symengine
    Lambdify with CSE, no code generation), each reshaped to its port's shape."""
    fn = se.Lambdify([s for syms in f.input_symbols for s in syms],
                     [e for exprs in f.inlined_outputs() for e in exprs], cse=True)
    out = np.ravel(fn(np.concatenate(inputs)))
    result, start = [], 0
    for port in f.outputs:
        result.append(out[start:start + port.size].reshape(port.shape))
        start += port.size
    return result
