"""The interface document of a generated robot (``functions.json``): every function's name,
ports (shape, unit, dtype), C symbol and costs, and (added by the pipeline when it writes the
folder) "files", the relative paths of every file written. The pipeline writes it; the python_c
renderer builds its wrappers from it (so the extension follows exactly what the C exports).
"""
from __future__ import annotations

from ..algorithms.loop_closure import loop_system
from ..ik.damped_least_squares import applies as dls_applies, dls_manifest_entry
from ..model.robot_model import RobotModel
from .optimize import Program


def manifest(model: RobotModel, programs: list[Program], params: str, trig: str = "kernel",
             scalar: str = "double", batch: bool = True, lanes: bool = True, ik_dls: bool = True) -> dict:
    """The interface document. A C library generated with ``--scalar float`` says so
    ("c_scalar": "float", and "dtype": "float" for every port that is not an int; Python and
    CasADi stay double) and has no ik_dls in C (its entry lists the languages it is in, whose
    ports are double); ``--no-batch`` adds "c_batch": false, ``--no-lanes`` "c_lanes": false.
    Default (double, batch, lanes) documents carry none of these keys. A function whose C
    single call is a lane program has its cost in "opcount": "c_lanes", one that runs joint
    loops in "opcount": "c_loops"; a bundle says what it
    bundles in "bundle" (:func:`_bundle`). ``ik_dls``: whether the
    iterative IK was asked for (``--functions``); it is listed where it applies."""
    dls = [dls_manifest_entry(model, programs)] if ik_dls and dls_applies(model, programs) else []
    if scalar == "float":
        for entry in dls:
            entry["languages"] = [lang for lang in entry["languages"] if lang != "c"]
    return {
        "robot": model.identifier,
        "name": model.name,
        "n": model.n,
        "convention": model.convention,
        # a kinematic tree: what it is, and its configuration and velocity sizes
        **({"structure": model.structure_text, "nq": model.nq, "nv": model.nv} if model.structure_text else {}),
        # mimic joints: the inputs are the independent joints, by name, and each mimic's rule
        **({"coordinates": [joint.name for joint in model.coordinate_joints],
            "mimics": [{"joint": joint.name, "mimics": model.joints[joint.mimic.joint].name,
                        "multiplier": float(joint.mimic.multiplier), "offset": float(joint.mimic.offset)}
                       for joint in model.joints if joint.mimic is not None]} if model.has_mimics else {}),
        **(_loops(model) if model.has_loops else {}),
        "gravity": [float(v) for v in model.gravity],
        "params": params,
        "trig": trig,    # how the C computes sin/cos of joint angles (kindyngen/codegen/trig_kernel.py)
        **({"c_scalar": scalar} if scalar != "double" else {}),
        **({"c_batch": False} if not batch else {}),
        **({"c_lanes": False} if not lanes else {}),
        "functions": [{
            "name": p.function.name,
            "summary": p.function.summary,
            "conventions": p.function.conventions,
            "c_symbol": f"{model.identifier}_{p.function.name}",
            "inputs": [_port(port, scalar) for port in p.function.inputs],
            "outputs": [_port(port, scalar) for port in p.function.outputs],
            "opcount": {"before": p.before.to_json(), "after": p.after.to_json(),
                        **({"c_lanes": p.lanes.to_json()} if lanes and p.lanes is not None else {}),
                        **({"c_loops": p.joint_loops.to_json()} if lanes and p.joint_loops is not None else {})},
            **_bundle(p),
        } for p in programs] + dls,
    }


def _loops(model: RobotModel) -> dict:
    """A tree closed by loops: its loop joints, the independent joints (the inputs ``qd``,
    ``qdd``, ``tau``; ``q`` too where the loops have a closed form, else every joint), the
    dependent ones and how they are solved."""
    system = loop_system(model)
    free = system.free

    def body(index):
        return free.joints[index].name if index >= 0 else (free.base_name or "base")

    return {
        "coordinates": list(system.names),
        "dependent": list(system.dependent_names),
        "q_input": "independent joints" if system.closed is not None else "all joints",
        # each loop joint's two bodies named by the joint that moves them (the root: its link's name)
        "loops": [{"name": loop.name, "type": loop.kind, "body1": body(loop.body_a), "body2": body(loop.body_b),
                   "directions": list(loop.directions),
                   "closed_form": next((step[0] for step in system.closed.steps if step[1] == k), None)
                   if system.closed is not None else None}
                  for k, loop in enumerate(model.loops)],
    }


def listed_files(document) -> list[str] | None:
    """The "files" of a functions.json document (relative paths with /), or None where the
    document has no such list (one written before it existed, or not an interface document).
    Only whether a file of the folder is listed matters (kindyngen.output_folder): a listed
    path that is not in the folder means nothing.

    >>> listed_files({"robot": "lwr4", "files": ["c/lwr4.c", "functions.json"]})
    ['c/lwr4.c', 'functions.json']
    >>> listed_files({"functions": []}) is None
    True
    """
    files = document.get("files") if isinstance(document, dict) else None
    if not isinstance(files, list):
        return None
    return [f for f in files if isinstance(f, str)]
def _port(port, scalar: str) -> dict:
    """A port's entry; its "dtype" is the C's scalar (``float`` in a float build) or "int".
    The Python, CasADi, JAX and MATLAB modules compute in double whatever the C's type.

    >>> from kindyngen.algorithms.symbolic import Port
    >>> _port(Port("q", (7,), "joint angles", "rad"), "float")["dtype"], _port(Port("s", (8,), "", "", "int"), "float")["dtype"]
    ('float', 'int')
    """
    entry = port.to_json()
    if entry["dtype"] == "double":
        entry["dtype"] = scalar
    return entry


def _bundle(program: Program) -> dict:
    """A bundle's "bundle" entry: its members (their outputs' order) and their count after CSE
    called one by one (kindyngen/codegen/bundles.py); nothing for other functions."""
    metadata = program.function.metadata
    if "members" not in metadata:
        return {}
    return {"bundle": {"members": list(metadata["members"]), "members_after": metadata["members_after"].to_json()}}
