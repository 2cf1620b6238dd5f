"""Per-call timing from Python of the generated C through the python_c extension ("python_c")
against Pinocchio's Python bindings ("pinocchio_python"), one configuration per call, in the
same run, with python_timing.per_call (K precomputed inputs cycled, iteration count
calibrated to a target duration), repeats interleaved across implementations, median/min/max
over repeats.

What "pinocchio_python" times per generated function (pinocchio_cpp.note_for says the same):

- fk_hom, fk_dq: ``forwardKinematics(model, data, q)`` then ``updateFramePlacement(model,
  data, flange)`` in a two-line Python function (an SE3 object comes back, no array);
- jacobian: ``computeFrameJacobian(model, data, q, flange, LOCAL_WORLD_ALIGNED)``;
- M: ``crba`` (upper triangle only); g: ``computeGeneralizedGravity``;
- c: ``nonLinearEffects`` (c + g: Pinocchio has no Coriolis-only call, and c = nle - g would
  time two passes);
- S: ``computeCoriolisMatrix``; tau: ``rnea``; fd: ``aba``; Y: ``computeJointTorqueRegressor``;
- tau_derivatives, fd_derivatives (when generated): ``computeRNEADerivatives``,
  ``computeABADerivatives``;
- other routes to the same quantity (M_lagrange, tau_dq, ...): their family's algorithm.

Single-call algorithms are bound with functools.partial (no Python frame); those that need
trailing arguments or two calls go through a lambda/def, which adds about 50 ns of Python call
overhead to Pinocchio's figure (said in each row's note). python_c is called directly.
Each pairing is checked once on the first input (max |python_c - Pinocchio|), so a timing row
never compares different quantities by mistake.

    python -m benchmarks.python_c_timing [--robot lwr4 ...] [--quick]

Importable: ``measure(robot_name, ...)`` returns the per-function results as a dict.
"""
from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

import numpy as np

from . import inputs, python_timing
from .common import GENERATED, ROBOTS, ROOT, summary

DEFAULTS = dict(K=1000, repeats=7, target_s=0.05)
QUICK = dict(K=50, repeats=3, target_s=0.002)


def _pinocchio(robot):
    """Pinocchio's model of the DH arm (tests/reference.py, the tests' independent reference)."""
    sys.path.insert(0, str(ROOT / "tests"))
    try:
        from reference import pinocchio_model
    finally:
        sys.path.remove(str(ROOT / "tests"))
    return pinocchio_model(robot)


def pinocchio_calls(model, data, frame) -> dict:
    """Generated function (or family) -> (callable on the generated function's inputs,
    its value as the generated function's first output, note)."""
    import pinocchio as pin
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def fk(q):
        pin.forwardKinematics(model, data, q)
        return pin.updateFramePlacement(model, data, frame)

    def upper(M):
        return np.triu(M) + np.triu(M, 1).T

    return {
        "fk_hom": (fk, lambda r: r.homogeneous, "forwardKinematics + updateFramePlacement (a def)"),
        "fk_dq": (fk, None, "forwardKinematics + updateFramePlacement (a def; SE3, no dual quaternion)"),
        "jacobian": (lambda q: pin.computeFrameJacobian(model, data, q, frame, lwa), lambda r: r,
                     "computeFrameJacobian LOCAL_WORLD_ALIGNED (a lambda)"),
        "M": (functools.partial(pin.crba, model, data), upper, "crba (upper triangle only)"),
        "g": (functools.partial(pin.computeGeneralizedGravity, model, data), lambda r: r,
              "computeGeneralizedGravity"),
        "c": (functools.partial(pin.nonLinearEffects, model, data), None,
              "nonLinearEffects (c + g: no Coriolis-only call)"),
        "S": (functools.partial(pin.computeCoriolisMatrix, model, data), lambda r: r, "computeCoriolisMatrix"),
        "tau": (functools.partial(pin.rnea, model, data), lambda r: r, "rnea"),
        "fd": (functools.partial(pin.aba, model, data), lambda r: r, "aba"),
        "Y": (functools.partial(pin.computeJointTorqueRegressor, model, data), None,
              "computeJointTorqueRegressor (all 10n columns)"),
        "tau_derivatives": (functools.partial(pin.computeRNEADerivatives, model, data), None,
                            "computeRNEADerivatives"),
        "fd_derivatives": (functools.partial(pin.computeABADerivatives, model, data), None,
                           "computeABADerivatives"),
    }


def _family(name: str, calls: dict) -> str | None:
    """The Pinocchio counterpart of a generated function: its own, or its family's (M_dq -> M)."""
    if name in calls:
        return name
    family = name.split("_", 1)[0]
    return family if family in ("M", "g", "c", "tau") else None


def interleaved(timers: dict, args: list, repeats: int, target_s: float) -> dict:
    """{implementation: stats}: repeats taken in turn (python_c, Pinocchio, python_c, ...), each
    a calibrated per_call run, so that a change in machine load hits all implementations alike."""
    runs = {impl: [] for impl in timers}
    for _ in range(repeats):
        for impl, fn in timers.items():
            runs[impl].append(python_timing.per_call(fn, args, 1, target_s)["median_ns"])
    return {impl: summary(values) for impl, values in runs.items()}


def measure(robot_name: str, K: int = DEFAULTS["K"], repeats: int = DEFAULTS["repeats"],
            target_s: float = DEFAULTS["target_s"], generated=GENERATED, numpy_module: bool = False,
            progress=None) -> dict:
    """{function: {"python_c": stats, "pinocchio_python": stats + note + check, ["python": stats]}}
    for every function of generated/<robot_name> (stats: median_ns, min_ns, max_ns per call)."""
    from kindyngen.runtime import python_c
    from kindyngen.readers.yaml_description import load_robot
    folder = generated / robot_name
    robot = load_robot(ROBOTS / f"{robot_name}.yaml")
    ext = python_c.load(folder)
    numpy_gen = python_timing.load_module(folder / "python" / f"{robot_name}.py")
    manifest = json.loads((folder / "functions.json").read_text())
    try:
        model, data, frame = _pinocchio(robot)
        calls = pinocchio_calls(model, data, frame)
    except ImportError:
        calls = {}
    results = {}
    for f in manifest["functions"]:
        name = f["name"]
        if name not in ext.FUNCTIONS:
            continue
        if progress:
            progress(f"{robot_name}: {name}")
        sample = inputs.sample(f, robot, K, numpy_gen, seed=1)
        args = list(zip(*(sample[p["name"]] for p in f["inputs"])))   # C-contiguous rows: the fast path
        timers = {"python_c": ext.FUNCTIONS[name]}
        counterpart = _family(name, calls)
        if counterpart is not None:
            fn, as_output, note = calls[counterpart]
            timers["pinocchio_python"] = fn
            check = None
            if as_output is not None:
                theirs = as_output(fn(*args[0]))
                mine = ext.FUNCTIONS[name](*args[0])
                check = float(np.max(np.abs((mine[0] if isinstance(mine, tuple) else mine) - theirs)))
        if numpy_module:
            timers["python"] = numpy_gen.FUNCTIONS[name]
        row = interleaved(timers, args, repeats, target_s)
        if counterpart is not None:
            row["pinocchio_python"].update(note=note, max_abs_difference=check)
        results[name] = row
    return results


def table(robot_name: str, results: dict) -> str:
    """A markdown table of medians in microseconds; ratio = python_c / pinocchio_python."""
    has_numpy = any("python" in r for r in results.values())
    lines = [f"### {robot_name}: one configuration per call, median per call (us)", "",
             "| function | python_c | pinocchio_python | ratio |" + (" numpy module |" if has_numpy else "")
             + " what pinocchio_python times |",
             "|---|---:|---:|---:|" + ("---:|" if has_numpy else "") + "---|"]
    for name, r in results.items():
        mine, peer = r["python_c"]["median_ns"] / 1e3, r.get("pinocchio_python")
        line = f"| {name} | {mine:.3f} | "
        line += f"{peer['median_ns'] / 1e3:.3f} | {mine / (peer['median_ns'] / 1e3):.2f} |" if peer else "- | - |"
        if has_numpy:
            line += f" {r['python']['median_ns'] / 1e3:.2f} |"
        lines.append(line + f" {peer['note'] if peer else ''} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Per-call times from Python: python_c (the generated C as a "
                                                 "CPython extension) vs Pinocchio's Python bindings.")
    parser.add_argument("--robot", action="append", help="robot under generated/ (repeatable; default lwr4, panda)")
    parser.add_argument("--quick", action="store_true", help="few inputs and repeats (seconds, noisy)")
    parser.add_argument("--numpy", action="store_true", help="also time the numpy module per call")
    parser.add_argument("--generated", type=Path, default=GENERATED, metavar="DIR",
                        help="generated tree with python_c/ folders (default: generated/)")
    args = parser.parse_args(argv)
    settings = QUICK if args.quick else DEFAULTS
    for robot in args.robot or ["lwr4", "panda"]:
        results = measure(robot, **settings, generated=args.generated, numpy_module=args.numpy,
                          progress=lambda text: print(text, file=sys.stderr, flush=True))
        print(table(robot, results))
        print()
        differences = {n: r["pinocchio_python"]["max_abs_difference"] for n, r in results.items()
                       if "pinocchio_python" in r and r["pinocchio_python"]["max_abs_difference"] is not None}
        print(f"max |python_c - Pinocchio| on the first input: {max(differences.values()):.1e} "
              f"({', '.join(differences)})" if differences else "", file=sys.stderr)
        if any(d > 1e-9 for d in differences.values()):
            print(f"warning: python_c and Pinocchio disagree: {differences}", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
