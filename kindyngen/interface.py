"""The interface document of a generated robot (``functions.json``): every function's name,
ports (shape, unit, dtype), C symbol and costs. The pipeline writes it; the python_c renderer
builds its wrappers from it (so the extension follows exactly what the C exports).
"""
from __future__ import annotations

from .ik_dls import applies as dls_applies, dls_manifest_entry
from .model import RobotModel
from .optimize import Program


def manifest(model: RobotModel, programs: list[Program], params: str, trig: str = "kernel") -> dict:
    return {
        "robot": model.identifier,
        "name": model.name,
        "n": model.n,
        "convention": model.convention,
        # a kinematic tree: what it is, and its configuration and velocity sizes
        **({"structure": model.structure_text, "nq": model.nq, "nv": model.nv} if model.structure_text else {}),
        "gravity": [float(v) for v in model.gravity],
        "params": params,
        "trig": trig,    # how the C computes sin/cos of joint angles (kindyngen/c_trig.py)
        "functions": [{
            "name": p.function.name,
            "summary": p.function.summary,
            "conventions": p.function.conventions,
            "c_symbol": f"{model.identifier}_{p.function.name}",
            "inputs": [port.to_json() for port in p.function.inputs],
            "outputs": [port.to_json() for port in p.function.outputs],
            "opcount": {"before": p.before.to_json(), "after": p.after.to_json()},
        } for p in programs] + ([dls_manifest_entry(model, programs)] if dls_applies(model, programs) else []),
    }
