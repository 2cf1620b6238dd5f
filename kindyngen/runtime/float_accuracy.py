"""How far ``--scalar float`` C is from the double C: measured at generate time, written into
the float header, ``opcounts.md`` and ``opcounts.json``.

Both C libraries are compiled on the host (strict C99, -O0: IEEE results do not depend on
the level) and called on the same random states within the limits (fixed seed): joint
angles uniform within the joint limits, velocities in +-2 rad/s, accelerations in
+-5 rad/s^2, torques those of the double ``tau`` at random states (else +-20 N m), poses the
double ``fk_hom``/``fk_dq`` of random angles, theta3 within joint 3's limits, anything else
in +-1. The float inputs are the double inputs rounded to float, so the figure is the whole
error a float controller sees: rounding of its inputs included.

For each function: per output port, its scale is the largest |entry| of the double output
over all states; the error of an entry is |float - double| / scale; reported are the largest
and the 99th percentile over all entries and states (integer outputs: how many differ).
Figures are rounded to 2 significant digits (they are measurements, not the code's input:
the float code itself does not depend on them). A function is flagged when its largest
error exceeds ACCEPTABLE.
"""
from __future__ import annotations

import dataclasses
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..json_text import strict_json

STATES = 1000
SEED = 0
NEAR_ZERO = 1e-3
"""The second set of states ("near singular"): as the random set, but one joint angle (each
joint in turn) within +-NEAR_ZERO rad of zero, where serial arms are singular (a stretched
elbow, aligned wrist axes: the LWR's and the Panda's q4 and q6) and the closed-form IK
switches branches."""
ACCEPTABLE = 1e-3
"""Largest error (relative to the output's scale) called acceptable for float: about 2^13
float roundings (float's unit roundoff is 6e-8); beyond it the header says so."""


@dataclass(frozen=True)
class FloatError:
    max: float | None          # None: no double output
    p99: float | None
    int_mismatch: int          # states where an integer output (an IK status) differs
    states: int
    scales: tuple = ()         # (output port, its scale), the scales the errors are relative to
    near: "FloatError | None" = None   # the same at the near-singular states (NEAR_ZERO)

    @property
    def acceptable(self) -> bool:
        """Within ACCEPTABLE at the random states (the near-singular figure is reported beside)."""
        return bool(self.max is not None and np.isfinite(self.max) and self.max <= ACCEPTABLE)

    def text(self) -> str:
        """One line for people.

        >>> FloatError(2.34e-7, 1.06e-7, 0, 1000).text()
        'max 2.3e-07, 99th percentile 1.1e-07 of the output scale (1000 random states)'
        """
        if self.max is None:
            body = "no floating-point output"
        elif not np.isfinite(self.max):
            body = "non-finite float results where the double is finite: NOT ACCEPTABLE in float"
        else:
            body = f"max {self.max:.1e}, 99th percentile {self.p99:.1e} of the output scale"
            if not self.acceptable:
                body += f" (NOT ACCEPTABLE in float: above {ACCEPTABLE:.0e})"
        if self.int_mismatch:
            body += f"; integer output differs in {self.int_mismatch} of {self.states} states"
        text = body + f" ({self.states} random states)"
        if self.near is not None and self.near.max is not None:
            n = self.near
            text += (f"; with one joint within {NEAR_ZERO:g} rad of 0 (singular arm): max {n.max:.1e}, "
                     f"99th percentile {n.p99:.1e}" + ("" if n.acceptable else " (NOT ACCEPTABLE in float)")
                     + (f", integer output differs in {n.int_mismatch} of {n.states}" if n.int_mismatch else ""))
        return text

    def to_json(self) -> dict:
        out = {"max": self.max, "p99": self.p99, "acceptable": self.acceptable,
               "int_mismatch": self.int_mismatch, "states": self.states, "scale": dict(self.scales)}
        if self.near is not None:
            out["near_singular"] = {"max": self.near.max, "p99": self.near.p99, "acceptable": self.near.acceptable,
                                    "int_mismatch": self.near.int_mismatch, "states": self.near.states}
        return out


def _round2(value: float) -> float:
    return float(f"{value:.1e}") if np.isfinite(value) else float("inf")


def random_inputs(model, double_lib, spec: dict, rng: np.random.Generator, count: int,
                  near_zero: bool = False) -> dict:
    """Named double inputs of ``count`` states for ``spec`` (a functions.json entry);
    ``near_zero``: joint k % n of state k within +-NEAR_ZERO of 0 (clipped to the limits)."""
    lower, upper = np.asarray(model.lower, float), np.asarray(model.upper, float)

    def angles():
        q = rng.uniform(lower, upper, size=(count, lower.size))
        if near_zero:
            rows, joints = np.arange(count), np.arange(count) % lower.size
            q[rows, joints] = np.clip(rng.uniform(-NEAR_ZERO, NEAR_ZERO, count), lower[joints], upper[joints])
        return q

    def configurations(shape):
        """q of ``shape``: the coordinates within their limits, or, for the functions of a tree
        closed by loops that take every joint, those closed by the generated loop_solve (the
        loop constraint itself at any configuration: closed ones would leave it only rounding)."""
        if shape == lower.shape or "loop_solve" not in double_lib.functions:
            return angles()
        if spec.get("name") in ("loop_residual", "loop_jacobian"):
            return rng.uniform(-1.0, 1.0, size=(count,) + shape)
        return double_lib.call("loop_solve", {"q": angles(), "q_guess": np.zeros((count,) + shape)})["q_all"]

    q_shape = next((tuple(p["shape"]) for p in spec["inputs"] if p["name"] == "q"), lower.shape)
    out = {}
    for port in spec["inputs"]:
        name, shape = port["name"], tuple(port["shape"])
        if name in ("q", "q0") and (shape == lower.shape or name == "q" and "loop_solve" in double_lib.functions):
            out[name] = configurations(shape)
        elif name == "q_guess":             # loop_solve's Newton steps from the reference
            out[name] = np.zeros((count,) + shape)
        elif name == "qd":
            out[name] = rng.uniform(-2.0, 2.0, size=(count,) + shape)
        elif name == "qdd":
            out[name] = rng.uniform(-5.0, 5.0, size=(count,) + shape)
        elif name == "tau" and "tau" in double_lib.functions:
            out[name] = double_lib.call("tau", {"q": configurations(q_shape), "qd": rng.uniform(-2, 2, (count,) + shape),
                                                "qdd": rng.uniform(-5, 5, (count,) + shape)})["tau"]
        elif name == "T" and shape == (4, 4) and "fk_hom" in double_lib.functions:
            out[name] = double_lib.call("fk_hom", {"q": angles()})["T"]
        elif name == "x" and shape == (8,) and "fk_dq" in double_lib.functions:
            out[name] = double_lib.call("fk_dq", {"q": angles()})["x"]
        elif name == "theta3" and lower.size > 2:
            out[name] = rng.uniform(lower[2], upper[2], size=(count,) + shape)
        else:
            out[name] = rng.uniform(-1.0, 1.0, size=(count,) + shape)
    return out


def compare(double_out: dict, float_out: dict, spec: dict, count: int, given_scales: dict | None = None) -> FloatError:
    """The errors of one function's outputs; ``given_scales``: the ports' scales to use (the
    random states' for the near-singular set), else each port's largest |entry| here."""
    errors, mismatch, scales = [], np.zeros(count, bool), []
    for port in spec["outputs"]:
        d, f = np.asarray(double_out[port["name"]]), np.asarray(float_out[port["name"]])
        if port["dtype"] == "int":
            mismatch |= (d != f).reshape(count, -1).any(axis=1)
            continue
        d, f = d.reshape(count, -1).astype(float), f.reshape(count, -1).astype(float)
        if d.size == 0:         # a port of no entries (a planar arm's empty block): nothing to compare
            continue
        scale = np.max(np.abs(d[np.isfinite(d)])) if np.isfinite(d).any() else 1.0
        scale = _round2(float(scale)) if scale > 0 else 1.0
        scale = given_scales[port["name"]] if given_scales else scale
        if spec.get("name") == "loop_solve" and port["name"] == "r":
            scale = 1.0         # the residual reached, exactly 0: its error in m (rad), not relative
        scales.append((port["name"], scale))
        e = np.abs(f - d) / scale
        e[~np.isfinite(d) & ~np.isfinite(f)] = 0.0          # both non-finite: no error
        e[np.isfinite(d) & ~np.isfinite(f)] = np.inf
        errors.append(e.ravel())
    if not errors:
        return FloatError(None, None, int(mismatch.sum()), count)
    e = np.concatenate(errors)
    return FloatError(_round2(float(e.max())), _round2(float(np.percentile(e, 99))), int(mismatch.sum()), count,
                      tuple(scales))


def measure(model, double_files: dict, float_files: dict, manifest: dict,
            states: int = STATES, seed: int = SEED) -> dict:
    """``{name: FloatError}`` for every C function of ``manifest`` in float: the rendered double
    and float C (``{filename: text}``) compiled in a scratch folder and called on the same
    states. Raises :class:`kindyngen.runtime.evaluate.EvaluationError` when no C compiler works."""
    from .evaluate import load_generated
    libs = {}
    with tempfile.TemporaryDirectory(prefix="kindyngen-float-") as tmp:
        for scalar, files in (("double", double_files), ("float", float_files)):
            folder = Path(tmp) / scalar
            (folder / "c").mkdir(parents=True)
            for name, text in files.items():
                (folder / "c" / name).write_text(text)
            document = {k: v for k, v in manifest.items() if k != "c_scalar"}
            if scalar == "float":
                document["c_scalar"] = "float"
            (folder / "functions.json").write_text(strict_json(document))
            libs[scalar] = load_generated(folder, "c")
        rng = np.random.default_rng(seed)
        result = {}
        for spec in manifest["functions"]:
            if "c" not in spec.get("languages", ("c",)):
                continue
            errors = []
            for near in (False, True):
                inputs = random_inputs(model, libs["double"], spec, rng, states, near_zero=near)
                with np.errstate(all="ignore"):
                    d = libs["double"].call(spec["name"], inputs)
                    f = libs["float"].call(spec["name"], inputs)
                errors.append(compare(d, f, spec, states, dict(errors[0].scales) if near else None))
            result[spec["name"]] = dataclasses.replace(errors[0], near=errors[1])
    return result
